"""The test suite as a new user meets it: a fresh clone of the commit in a brand-new virtual
environment, the README's second command run there several times in a row, the first with an
empty numba cache (tools/time_suite.py). The wall time of each run is the figure the README
states; a run that fails is reported as failed, with pytest's summary line.

Nothing of the developer's machine leaks in: the clone is made from the committed HEAD (not
the working tree), the venv is new (``python -m venv``, no system site packages), the numba
cache is a new folder (``CADRA_CACHE_DIR``), and the command is ``.ci/run``, the one CI runs.
The clone's parent holds nothing else, so a test that reached for a file outside the
repository would fail here.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: pytest's closing line, e.g. "==== 1190 passed, 2 deselected in 351.20s (0:05:51) ===="
_SUMMARY = re.compile(r"=+ (.*\b(?:passed|failed|error)\b.*) in [\d.]+s.* =+")


#: pytest's short test summary lines, e.g. "FAILED tests/test_x.py::test_y - AssertionError"
_FAILED = re.compile(r"^(?:FAILED|ERROR) (\S+)")


def _counts(summary: str) -> dict[str, int]:
    return {word: int(n) for n, word in re.findall(r"(\d+) (\w+)", summary)}


#: lines of a failed run's log (from pytest's FAILURES section) printed with the result
FAILURE_LINES = 300


def fresh_runs(root, runs: int = 3, python: str = sys.executable, keep: bool = False,
               log=print) -> dict:
    """Clone ``root``'s HEAD into a new temporary folder, make a venv with ``python`` there
    and run ``.ci/run`` ``runs`` times (the first with an empty numba cache); per run the wall
    time (s), exit status, pytest's counts and the ids of the tests that failed. ``keep``:
    leave the folder (its path is in the figures)."""
    root = Path(root).resolve()
    commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True, check=True).stdout.strip()
    work = Path(tempfile.mkdtemp(prefix="cadra_fresh_"))
    clone, venv, cache = work / "cadra", work / "venv", work / "numba_cache"
    try:
        subprocess.run(["git", "clone", "-q", str(root), str(clone)], check=True)
        subprocess.run([python, "-m", "venv", str(venv)], check=True)
        env = {k: v for k, v in os.environ.items()
               if k not in ("VIRTUAL_ENV", "PYTHONPATH", "NUMBA_CACHE_DIR", "CADRA_CACHE_DIR")}
        env |= {"VIRTUAL_ENV": str(venv), "CADRA_CACHE_DIR": str(cache),
                "PATH": f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"}
        out = []
        for k in range(runs):
            log(f"run {k + 1}/{runs} ({'cold' if k == 0 else 'warm'} numba cache) in {clone}")
            t0 = time.perf_counter()
            proc = subprocess.run(["bash", ".ci/run"], cwd=clone, env=env, text=True,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
            seconds = time.perf_counter() - t0
            lines = proc.stdout.splitlines()
            summary = next((m.group(1) for line in reversed(lines)
                            if (m := _SUMMARY.search(line))), "")
            (work / f"run_{k + 1}.log").write_text(proc.stdout, encoding="utf-8")
            out.append({"seconds": round(seconds, 1), "status": proc.returncode,
                        "summary": summary, **_counts(summary),
                        "failed_tests": [m.group(1) for line in lines
                                         if (m := _FAILED.match(line))]})
            log(f"  {seconds:.0f} s, exit {proc.returncode}: {summary}")
            if proc.returncode != 0:
                # the failures' text, kept in this tool's output even when the folder goes
                start = next((i for i, line in enumerate(lines) if "= FAILURES =" in line
                              or "= ERRORS =" in line), max(len(lines) - 60, 0))
                log("\n".join(lines[start:start + FAILURE_LINES]))
    finally:
        if not keep:
            shutil.rmtree(work, ignore_errors=True)
    passed = [r["status"] == 0 for r in out]
    return {"commit": commit, "runs": out, "all_passed": all(passed),
            "suite_seconds": [r["seconds"] for r in out],
            "suite_seconds_max": max(r["seconds"] for r in out),
            "suite_minutes_max": round(max(r["seconds"] for r in out) / 60, 1),
            "cores": os.cpu_count(), "folder": str(work) if keep else None}


__all__ = ["fresh_runs"]
