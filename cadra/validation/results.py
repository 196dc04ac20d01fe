"""Each tool's figures as a file: ``results/<tool>.json``.

A benchmark or validation in ``tools/`` prints its figures with the last line a JSON object
and records the same object here (:func:`record`), with what made it: the command line, the
date, the commit and the machine. ``docs/validation.md`` and the README's headline figures
are generated from these files (:mod:`cadra.validation.figures`), never copied by hand.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

from cadra.io.plain import plain

#: the format tag of a results file
FORMAT = "cadra.tool-results/1"


def _commit(root: Path) -> str:
    try:
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def machine() -> str:
    """The machine in a few words: cores, processor, Python."""
    return (f"{os.cpu_count()} cores, {platform.machine()}, "
            f"Python {platform.python_version()}")


def record(tool: str, figures: dict, root: str | os.PathLike, *,
           argv: list[str] | None = None, seconds: float | None = None) -> Path:
    """Write ``<root>/results/<tool>.json``: the tool's figures (its JSON last line) and how
    they were made. ``argv``: the tool's arguments (default ``sys.argv[1:]``). The file is
    replaced atomically; returns its path."""
    from cadra.atomic import atomic_write_text

    root = Path(root)
    argv = list(sys.argv[1:] if argv is None else argv)
    data = {"format": FORMAT, "tool": tool,
            "command": " ".join(["python", f"tools/{tool}.py", *argv]),
            "date": datetime.now(UTC).strftime("%Y-%m-%d"),
            "commit": _commit(root), "machine": machine(),
            "seconds": None if seconds is None else round(float(seconds), 1),
            "figures": plain(figures)}
    path = root / "results" / f"{tool}.json"
    path.parent.mkdir(exist_ok=True)
    return atomic_write_text(path, json.dumps(data, indent=1, sort_keys=False) + "\n",
                             overwrite=True)


def load_results(root: str | os.PathLike) -> dict[str, dict]:
    """Every results file under ``<root>/results``, by tool name."""
    out = {}
    for path in sorted((Path(root) / "results").glob("*.json")):
        data = json.loads(path.read_text(encoding="utf-8"))
        if data.get("format") != FORMAT:
            raise ValueError(f"{path}: not a tool results file (format "
                             f"{data.get('format')!r}, expected {FORMAT!r})")
        out[data["tool"]] = data
    return out


__all__ = ["FORMAT", "load_results", "machine", "record"]
