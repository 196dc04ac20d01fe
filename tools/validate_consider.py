"""Held values with an uncertainty, by pulls: three-shot M1 M1.10 sets flown with the C_mq
peak drawn uniformly in 2.9-4.4 (seed 004 Fig. 15's range), fitted holding it at 3.65 +- 0.43
(the bundled model's; +- 0.75 reported beside it);
the free parameters' pulls with the conditional and with the consider sigma, and those of
the Bayesian fit (the peak free under the prior 3.65 +- 0.43); in the first 20 sets the
hold-one study (the peak held at 2.9, 3.275, 4.025, 4.4) against the linear consider
prediction of each shift (``cadra/validation/consider_runs.py``). Last printed line: a JSON
object.

Usage: python tools/validate_consider.py [--trials 20] [--seed 0] [--workers 2]
(about 15 s a set on one core, 60 s with the hold-one study)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    one_thread()
    from cadra.validation.consider_runs import run

    run_tool("validate_consider", ROOT,
             lambda: run(args.trials, seed=args.seed, workers=args.workers),
             argv=sys.argv[1:] if argv is None else list(argv), seconds_key="seconds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
