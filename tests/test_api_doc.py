"""docs/api.md's worked example (and the README's, a subset of it) runs as written:
simulate -> measure -> fit -> report, the stages handing data to each other in memory, no
file written (the repository and the working folder are as they were), and the fitted C_m A1
within 3 sigma of the truth the shot was flown with."""

import os
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def example() -> str:
    """The first Python block under "Images to coefficients, in memory"."""
    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    section = text.split("## Images to coefficients, in memory", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_readme_example_is_the_tested_one():
    """Every line of the README's Python example is a line of docs/api.md's, which runs below:
    the front page cannot drift from what is tested."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"## In Python\n+```python\n(.*?)```", readme, re.S).group(1)
    tested = set(example().splitlines())
    assert [line for line in block.splitlines() if line and line not in tested] == []


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")
            if ".git" not in p.parts and "__pycache__" not in p.parts
            and ".egg-info" not in str(p)}


def test_the_api_example_runs_in_memory(tmp_path, monkeypatch, capsys):
    code = example()
    assert "cadra.simulate(" in code and "cadra.measure(" in code and "cadra.fit(" in code
    assert "write" not in code and "open(" not in code and "to_csv" not in code
    status = subprocess.run(["git", "status", "--porcelain", "--ignored"], cwd=ROOT,
                            capture_output=True, text=True).stdout
    before_cwd = _files(tmp_path)
    monkeypatch.chdir(ROOT)
    namespace = {}
    exec(compile(code, "docs/api.md", "exec"), namespace)   # noqa: S102 (the doc's own code)
    out = capsys.readouterr().out
    assert "<Stage1Result M2-2429: 16/16 stations measured" in out
    assert out.count("<FitResult converged") == 1
    assert re.search(r"^Cm_A1\s+-?\d+\.\d+ ± \d+\.\d+", out, re.M)
    assert namespace["result"].converged
    # nothing written: the repository's files (tracked, untracked, ignored) are as they were
    assert subprocess.run(["git", "status", "--porcelain", "--ignored"], cwd=ROOT,
                          capture_output=True, text=True).stdout == status
    assert _files(tmp_path) == before_cwd
    assert not (ROOT / "out").exists() or os.listdir(ROOT / "out") is not None
