"""The house rules of docs/architecture.md: what may import what, and how big a file may grow.

The import rules are import-linter contracts in pyproject.toml (layers, a forbidden list for
the numerical core, no import circles at any depth); this test runs them on the package as it
is, so a change that imports upward or closes a circle fails here with import-linter's own
account of the offending import chain.
"""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: files allowed past :data:`MAX_LINES`, each holding one concept (named here)
ONE_CONCEPT_FILES: dict[str, str] = {}
MAX_LINES = 700


def test_import_contracts_are_kept():
    run = subprocess.run(
        [sys.executable, "-c",
         "import sys; from importlinter.cli import lint_imports; "
         "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True))"],
        cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-2000:]
    assert "0 broken" in run.stdout


def test_no_file_over_the_line_limit_unless_it_holds_one_concept():
    long = {}
    for folder in ("cadra", "tools", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            n = len(path.read_text(encoding="utf-8").splitlines())
            if n > MAX_LINES:
                long[path.relative_to(ROOT).as_posix()] = n
    unexplained = {p: n for p, n in long.items() if p not in ONE_CONCEPT_FILES}
    assert not unexplained, f"files over {MAX_LINES} lines: {unexplained}"
