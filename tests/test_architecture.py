"""The house rules of docs/architecture.md: what may import what, and how big a file may grow.

The import rules are import-linter contracts in pyproject.toml (layers, a forbidden list for
the numerical core, no import circles at any depth); this test runs them on the package as it
is, so a change that imports upward or closes a circle fails here with import-linter's own
account of the offending import chain.
"""

import ast
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


def _cli_imports(path: Path) -> list[str]:
    """What a file imports from ``cadra.cli``, as ``module:name`` (a module imported whole
    as ``module:*``)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and (
                node.module == "cadra.cli" or node.module.startswith("cadra.cli.")):
            out += [f"{node.module}:{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            out += [f"{a.name}:*" for a in node.names if a.name.startswith("cadra.cli")]
    return out


def test_tests_and_tools_reach_the_command_lines_only_through_main():
    """The command lines hold no library logic anyone needs: a test or a tool imports from
    ``cadra.cli`` only a console script's ``main`` (the library never does: the contract
    "The command lines are thin" in pyproject.toml)."""
    bad = {}
    for folder in ("tests", "tools"):
        for path in (ROOT / folder).rglob("*.py"):
            names = [n for n in _cli_imports(path)
                     if n.split(":")[1] != "main" or n.split(":")[0] == "cadra.cli"]
            if names:
                bad[path.relative_to(ROOT).as_posix()] = names
    assert not bad, bad


def test_no_test_or_tool_bends_the_import_path():
    """Shared code is imported from the package: no test or tool puts a folder on sys.path,
    loads a file by path, or imports another test module."""
    test_modules = {p.stem for p in (ROOT / "tests").glob("test_*.py")}
    bad = {}
    for folder in ("tests", "tools"):
        for path in (ROOT / folder).rglob("*.py"):
            text = path.read_text(encoding="utf-8")
            found = [w for w in ("sys.path", "spec_from_file_location", "importlib.util")
                     if w in text and path.name != "test_architecture.py"]
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.ImportFrom) and node.module in test_modules:
                    found.append(f"from {node.module} import")
                elif isinstance(node, ast.Import):
                    found += [f"import {a.name}" for a in node.names if a.name in test_modules]
            if found:
                bad[path.relative_to(ROOT).as_posix()] = found
    assert not bad, bad
