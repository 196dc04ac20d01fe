"""Regenerate docs/validation.md and the README's headline figures from results/*.json.

Every benchmark and validation in tools/ records its figures (its last printed line) in
results/<tool>.json when it runs; this script turns them into the two pages
(cadra.validation.figures). tests/test_validation_doc.py fails when a page is stale.

Usage: python tools/make_validation_doc.py [--check]
"""

import argparse
import sys
from pathlib import Path

from cadra.validation.figures import stale, update

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="only say which page is stale (exit status 1 if any)")
    args = parser.parse_args(argv)
    if args.check:
        out = stale(ROOT)
        for path in out:
            print(f"stale: {path}")
        return 1 if out else 0
    for path in update(ROOT):
        print(f"wrote {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
