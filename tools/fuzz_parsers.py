"""Fuzz the input parsers: every generated input must give a result or the project's own error.

Parsers: the aero expression parser, aero model files, trajectory files, shot files, the
facility reference file, shot specifications, truth tables, bias-table CSVs and station
histories; inputs are valid seeds mutated at random, and random text
(:mod:`cadra.validation.fuzz`). Anything but a result or the parser's own error class counts
as uncaught and is printed with its input.

    python tools/fuzz_parsers.py [--n 10000] [--seed 0] [--parsers facility_file,shot_spec]

The last line printed is a JSON object: per parser the inputs tried, how many parsed, how many
were refused with the parser's error, and the number of uncaught exceptions; it is also
recorded in ``results/fuzz_parsers.json``. ``tests/test_fuzz_parsers.py`` drives the same
mutators from hypothesis.
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

from cadra.validation.fuzz import PARSERS, run
from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=10000, help="inputs per parser")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--parsers", default=",".join(PARSERS),
                    help=f"comma-separated, of {', '.join(PARSERS)} (default: all)")
    args = ap.parse_args(argv)
    kinds = args.parsers.split(",")
    unknown = sorted(set(kinds) - set(PARSERS))
    if unknown:
        ap.error(f"unknown parser(s) {unknown}; known: {', '.join(PARSERS)}")
    log = functools.partial(print, flush=True)
    result = run_tool("fuzz_parsers", ROOT, lambda: run(kinds, args.n, args.seed, log=log),
                      argv=argv, seconds_key=None)
    return 1 if result["uncaught"] else 0


if __name__ == "__main__":
    sys.exit(main())
