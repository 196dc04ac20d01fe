"""Campaigns at scale: N synthetic shots of mixed bodies (capsules in groups of five with the
M2 M0.70 model, sphere calibration shots, M80 bullets), each flown, rendered and reduced end to
end, on one and on two local Dask workers; per-stage costs, the speed-up, peak memory per
worker, a run stopped midway (SIGTERM) and resumed, one shot changed and rerun, and the
projected cost of a 1,000-shot campaign. Last printed line: a JSON object.

Usage: python tools/bench_campaign.py [--shots N] [--memory-sizes 20,100] [--quick] [--work DIR]
(--quick: 10 shots, about 10 min on 2 cores; the figures: --shots 100 --memory-sizes 20, about
80 min).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

ROOT = Path(__file__).resolve().parents[1]


def _without(argv: list[str], option: str) -> list[str]:
    """``argv`` without ``option`` and its value: where the work goes changes no figure, and
    the recorded command names no folder of this machine."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a == option:
            skip = True
        elif not a.startswith(option + "="):
            out.append(a)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shots", type=int, default=100)
    ap.add_argument("--memory-sizes", default="", help="e.g. 20,100: peak memory at each size")
    ap.add_argument("--quick", action="store_true", help="10 shots")
    ap.add_argument("--work", default=None, help="where the campaigns go (default: temporary)")
    args = ap.parse_args(argv)
    one_thread()
    from cadra.validation.campaign_runs import bench

    n = 10 if args.quick else args.shots
    sizes = [int(s) for s in args.memory_sizes.split(",") if s.strip()]
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="cadra_bench_"))
    shown = _without(sys.argv[1:] if argv is None else list(argv), "--work")
    run_tool("bench_campaign", ROOT, lambda: bench(n, work, memory_sizes=sizes), argv=shown,
             seconds_key="seconds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
