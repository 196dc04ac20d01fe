"""Detection near the limit: for each library effect, the size the gap diagnosis detects in
90 % of trials, over the size at which the score test of the true effect alone has 90 % power.

The ratio is the diagnosis's efficiency (acceptance: at most 1.5). The method (the cases, the
reference size, the injection at a random multiple of it, the detection curve fitted by
maximum likelihood) is :mod:`cadra.validation.gap_detection` and
:mod:`cadra.validation.gap_power`; ``tools/validate_gap.py`` runs the same scan unless
``--no-detection``.

Usage:
    python tools/gap_detection.py [--trials 20] [--seed 21] [--cases cg,density,...]

Last line: a JSON object (``detection_efficiency_by_case``, ``detection_efficiency_max``,
``detection_trials_per_case``, ``detection_efficiency_interval_by_case``, ...), also
recorded as ``results/gap_detection.json`` (:func:`cadra.validation.results.record`).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from cadra.validation.gap_detection import CASES, case_line, scan, summarize
from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--seed", type=int, default=21)
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--verbose", action="store_true", help="print every trial")
    args = parser.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        parser.error(f"unknown cases {unknown}; choose from {CASES}")
    run_tool("gap_detection", ROOT, lambda: run(cases, args.trials, args.seed, args.verbose),
             argv=argv, seconds_key="detection_total_seconds")
    return 0


def run(cases, trials: int, seed: int, verbose: bool) -> dict:
    """The scan of ``cases``, a line a case (and its notable trials) printed; the summary."""
    per = scan(cases, trials, seed)
    for case, rows in per.items():
        print(case_line(case, rows))
        for r in rows:
            if "error" in r:
                print(f"    error: {r['error']}")
            elif verbose or (r.get("valid") and not r["detected"] and r["m"] > 1.5):
                print(f"    {r['shot']} m {r['m']:.2f} k {r['k']} detected "
                      f"{r.get('detected')} (first-round dchi2 "
                      f"{r.get('dchi2_first_round', math.nan):.1f}, p_adj "
                      f"{r.get('p_adjusted_first_round', math.nan):.2g}; m^2 lambda90 "
                      f"{r['m'] ** 2 * r.get('lambda90', math.nan):.1f}): "
                      f"{r.get('verdict', '')[:160]}")
    return summarize(per, trials)


if __name__ == "__main__":
    sys.exit(main())
