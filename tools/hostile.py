"""Hostile inputs: image headers, option values and output paths against every input kind,
each a real cadra1/cadra2 process under a timeout, every input tree hashed before and after.

The cases and the work folder are :mod:`cadra.validation.hostile`'s. Figures: the number of
cases (image, option and output), ``uncaught`` (a traceback), ``hangs`` (the timeout),
``input_changes`` (a hashed input changed) and ``unexpected`` (another exit status than the
case's), each to be 0, and the failed cases.

Usage: python tools/hostile.py [--keep DIR]
Last line: a JSON object with those keys.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--keep", default=None,
                        help="build the work folder here and keep it (default: a temporary)")
    args = parser.parse_args()
    from cadra.validation.hostile import run

    def compute():
        if args.keep:
            return run(Path(args.keep))
        with tempfile.TemporaryDirectory() as tmp:
            return run(Path(tmp) / "work")

    run_tool("hostile", ROOT, compute)


if __name__ == "__main__":
    main()
