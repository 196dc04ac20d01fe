"""Benchmark and check of cadra.motion: speed of the epicyclic fit and of the sectional
Kryloff-Bogoliuboff reduction, their accuracy on solve_ivp histories, and the Nonplanar Ratio
of planar and circular motion (the records and parts: cadra.validation.motion_records).

Usage: python tools/bench_motion.py [--reps 30] [--seed 1] [--draws 5]
Last line: a JSON object with epicyclic_fit_ms (200-point tricyclic fit, median; target
< 50 ms), kb_reduction_s (sectional K-B reduction of a 2000-point record; target < 2 s),
npr_planar, npr_circular, and the accuracy figures printed above it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.motion_records import run  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=30)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--draws", type=int, default=5, help="noise draws per seed-000 case")
    args = ap.parse_args(argv)
    run_tool("bench_motion", ROOT, lambda: run(args.reps, args.seed, args.draws), argv=argv,
             seconds_key=None)


if __name__ == "__main__":
    main()
