"""End to end: shadowgraphs -> cadra1 -> cadra2 multi-fit, against the simulator's truth.

For a seed-004 case (default the M2 M0.70 set: shots 2425 2426 2427 2428 2429 2431 2433) every
shot is flown and rendered from its sample spec, measured by stage one, and the whole set is
fitted by stage two with the case's Table 4 forms. The fit starts from every free parameter
at ZERO (linear-theory starting values do the rest), so nothing is borrowed from the truth.
Reported per parameter: fit, sigma, truth, pull = (fit - truth) / sigma; the last line is a
JSON object (max_abs_pull, all_within_2_sigma, reduced_chi2, ...).

Rendered shots and stage-one outputs go to ``out/e2e/`` (regenerated: about 30 s a shot to
render and 3-20 s to measure; ``--reuse`` keeps what is already there).

Usage:
    python tools/validate_e2e.py [--case m2_m070 | m1_m110] [--reuse] [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.e2e import SETS, validate_case
from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--case", default="m2_m070", choices=sorted(SETS))
    parser.add_argument("--out", default=str(ROOT / "out" / "e2e"))
    parser.add_argument("--reuse", action="store_true",
                        help="keep already rendered shots and stage-one outputs")
    parser.add_argument("--fit-out", default=None,
                        help="also write the cadra2 fit outputs (report, plots) here")
    args = parser.parse_args(argv)

    out = run_tool("validate_e2e", ROOT, lambda: validate_case(
        ROOT, args.case, args.out, args.reuse, args.fit_out), argv=argv, seconds_key=None)
    return 0 if out["converged"] else 1


if __name__ == "__main__":
    sys.exit(main())
