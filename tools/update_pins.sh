#!/usr/bin/env bash
# Move the pins: install the newest releases of every dependency in a brand-new venv, run the
# test suite there, and only if it passes write them to constraints.txt.
#   bash tools/update_pins.sh            (from the repository root; ~5 min)
# Then record the date in docs/install.md and commit constraints.txt with the test figures.
set -euo pipefail
cd "$(dirname "$0")/.."
venv="$(mktemp -d)/venv"
python3.11 -m venv "$venv" 2>/dev/null || python -m venv "$venv"
"$venv/bin/python" -m pip install -q -U pip
"$venv/bin/python" -m pip install -q -U -e ".[test]"
"$venv/bin/python" -m pytest -m "not slow" -q -p no:cacheprovider
{
  echo "# Pinned versions of every dependency (runtime and test), for Python 3.11 on Linux x86-64."
  echo "# Used by the README's Quick start: pip install -c constraints.txt ..."
  echo "# Made by tools/update_pins.sh in a brand-new venv; last moved $(date -u +%F) (see docs/install.md)."
  "$venv/bin/python" -m pip freeze --exclude-editable
} > constraints.txt
echo "constraints.txt written from $venv"
