"""The test suite from a fresh clone in a brand-new venv, several runs in a row, the first with
a cold numba cache: each run's wall time and result (cadra.validation.suite_runs).

Usage: python tools/time_suite.py [--runs 3] [--python python3.11] [--keep]
(about 3 x 7 min on 2 cores; commit first: the clone is of HEAD). Last line: a JSON object
(suite_seconds per run, suite_seconds_max, all_passed, runs with pytest's counts).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.suite_runs import fresh_runs
from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3, help="runs in a row (default 3)")
    ap.add_argument("--python", default=sys.executable,
                    help="the interpreter the new venv is made from (default: this one)")
    ap.add_argument("--keep", action="store_true", help="leave the clone, venv and logs")
    args = ap.parse_args(argv)
    out = run_tool("time_suite", ROOT, lambda: fresh_runs(
        ROOT, args.runs, args.python, args.keep, log=lambda s: print(s, flush=True)),
        argv=argv, seconds_key=None)
    return 0 if out["all_passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
