"""Stage one on the Basic Finner against the renderer's exact truth: roll, position, axis.

Usage::

    python tools/validate_roll_images.py            # 24 stations (~2-3 min on one core)
    python tools/validate_roll_images.py --n 6      # a smoke test

The cases (one HFFAF station each, the Basic Finner at a random roll, axis and position) and
the figures (roll error over its Cramér–Rao bound, sigma over error, position and axis
errors) are described in cadra.validation.roll_images, which does the work. The last printed
line is JSON.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.roll_images import run  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=24, help="stations (two renders each)")
    parser.add_argument("--seed", type=int, default=2020)
    parser.add_argument("--no-crb", action="store_true", help="skip the Cramér–Rao bounds")
    args = parser.parse_args(argv)
    run_tool("validate_roll_images", ROOT, lambda: run(args.n, args.seed, crb=not args.no_crb),
             argv=argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
