"""Seed 003's global segmented roll fit against its own Table 2.

Two simulated air-bearing runs of a Basic Finner at alpha = 57 deg in seed 003's tunnel
(V 117 ft/s, q 16.3 lb/ft^2), flown by CADRA's roll-bearing dynamics with Eq. 5 and Table 2
as truth (``cadra/aero/models/seed003_romof.toml``), measured at 100 frames/s with 0.25 deg of
white noise; each noise draw is segmented as the paper segments (cadra.studies.segmented_roll) and
fitted globally for all 14 coefficients. Prints a Table-2-like and a Table-3-like table and, as
the last line, JSON: the pull spread, our signal/noise over the paper's, the steady spins of
the fitted coefficients against +0.0280 / -0.0212, the C10-C11 and C10-C30 correlations.

    python tools/validate_roll_seed003.py [--draws N] [--out DIR] [--stepwise]

The case (docs/segmented_roll.md; cadra.validation.seed003_runs does the work): d = 2 in, a
uniform aluminium Basic Finner (cadra.body.finner), pivot at the cg, run 1 released at rest at
phi = 41.16 deg (breaks out positive), run 2 at 42.16 deg (breaks out negative).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.seed003_runs import DEFAULT_DRAWS, run
from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=DEFAULT_DRAWS)
    ap.add_argument("--seed", type=int, default=2003)
    ap.add_argument("--stepwise", action="store_true",
                    help="every draw through the paper's stepwise order (slower; default: "
                         "draw 0 only)")
    ap.add_argument("--out", type=Path, default=None,
                    help="a new folder for the first draw's fit and the tables over the draws "
                         "(report, CSV, Markdown, plot)")
    args = ap.parse_args(argv)
    # a figure one draw cannot give (a spread) is null in the JSON line
    run_tool("validate_roll_seed003", ROOT,
             lambda: run(args.draws, args.seed, args.stepwise, args.out), argv=argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
