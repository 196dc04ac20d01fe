"""A hold at the truth is not blamed for a misfit outside the library: three-shot M1 M1.10
sets flown with the bundled model (the C_mq peak held at the truth, 3.65 +- 0.433), given a
measurement error no library candidate describes (angle biases at one or two stations; a
periodic angle error), fitted and diagnosed; how often the held value is named inconsistent
(``cadra/validation/held_check.py``). Last printed line: a JSON object.

Usage: python tools/validate_held_check.py [--trials 20] [--seed 0] [--workers 2]
(about 1 min a set on one core)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20, help="sets per kind of error")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    one_thread()
    from cadra.validation.held_check import run

    run_tool("validate_held_check", ROOT,
             lambda: run(args.trials, seed=args.seed, workers=args.workers),
             argv=sys.argv[1:] if argv is None else list(argv), seconds_key="seconds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
