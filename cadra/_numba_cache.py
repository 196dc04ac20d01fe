"""Where numba keeps CADRA's compiled code: a folder keyed by the compiled sources.

numba (``cache=True``) invalidates a cached function only when *its own* source file changes;
a caller in another module keeps a stale copy of an inlined callee (e.g. the integrator in
``cadra/dynamics`` inlines the aero evaluator of ``cadra/aero/program.py``). Instead of
deleting stale files (which breaks read-only installs and races with a second process that is
loading them), every build of the compiled sources gets a cache folder of its own:

    <base>/<key>/        key = sha256 of every CADRA module that uses numba (name and bytes),
                         the numba version and the Python version

so a changed source simply looks in an empty folder, and nothing is ever deleted under a
running process. ``<base>`` is, in order: ``$CADRA_CACHE_DIR``, ``$NUMBA_CACHE_DIR`` (numba's
own setting, kept as the base), ``$XDG_CACHE_HOME/cadra/numba``, ``~/.cache/cadra/numba``;
the first that can be written to is used, else a per-user folder in the temporary directory.
Nothing is written inside the package, so a read-only install works; numba writes its cache
files by rename, so concurrent processes are safe.

CADRA deletes only what it provably made: each key folder it creates holds a marker file
(:data:`MARKER`), and a folder of another key is removed only if it is named like a key, holds
that marker and has been unused for :data:`PRUNE_AFTER_DAYS` (best effort: a folder in use is
touched at each start). Anything else under the base -- numba's caches of other projects in a
shared ``$NUMBA_CACHE_DIR``, a user's own folders -- is never touched.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

_ROOT = Path(__file__).resolve().parent
#: other keys' folders untouched this long are pruned
PRUNE_AFTER_DAYS = 30
#: the file that marks a key folder as CADRA's (only marked folders are ever pruned)
MARKER = ".cadra-numba-cache"
#: a key folder's name: :func:`sources_key`'s 20 hex digits
_KEY_NAME = re.compile(r"[0-9a-f]{20}")


def sources_key(root: Path = _ROOT) -> str:
    """Hex key of the compiled sources under ``root``: every ``*.py`` that mentions numba,
    with its path relative to ``root``, plus the numba and Python versions."""
    from importlib.metadata import PackageNotFoundError, version

    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        source = path.read_bytes()
        if b"numba" not in source:
            continue  # no compiled code here: editing it must not change the key
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(source)
    try:
        digest.update(version("numba").encode())
    except PackageNotFoundError:
        pass
    digest.update(sys.version.encode())
    return digest.hexdigest()[:20]


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
        return True
    except OSError:
        return False


def _bases(environ, key: str) -> list[Path]:
    out = []
    for name in ("CADRA_CACHE_DIR", "NUMBA_CACHE_DIR"):
        if environ.get(name):
            base = Path(environ[name])
            # a worker process inherits NUMBA_CACHE_DIR = <base>/<key> from its parent
            out.append(base.parent if base.name == key else base)
    xdg = environ.get("XDG_CACHE_HOME")
    if xdg:
        out.append(Path(xdg) / "cadra" / "numba")
    out.append(Path.home() / ".cache" / "cadra" / "numba")
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    out.append(Path(tempfile.gettempdir()) / f"cadra-numba-{uid}")
    return out


def _ours(folder: Path) -> bool:
    """A key folder CADRA made: named like a key, a real folder, holding the marker."""
    return (bool(_KEY_NAME.fullmatch(folder.name)) and folder.is_dir()
            and not folder.is_symlink() and (folder / MARKER).is_file())


def _prune(base: Path, keep: str) -> None:
    cutoff = time.time() - PRUNE_AFTER_DAYS * 86400.0
    try:
        for child in base.iterdir():
            if child.name != keep and _ours(child) and child.stat().st_mtime < cutoff:
                shutil.rmtree(child, ignore_errors=True)
    except OSError:
        pass


def cache_folder(environ=None, root: Path = _ROOT) -> Path | None:
    """The cache folder for this build of the compiled sources (created), or None when no
    candidate base can be written to (numba then compiles in memory)."""
    environ = os.environ if environ is None else environ
    key = sources_key(root)
    for base in _bases(environ, key):
        folder = base / key
        if _writable(folder):
            try:
                (folder / MARKER).touch()   # CADRA's folder (the only kind ever pruned)
                os.utime(folder)            # in use: not pruned by another build's start
            except OSError:
                pass
            _prune(base, key)
            return folder
    return None


def configure() -> Path | None:
    """Point numba's cache at :func:`cache_folder`; runs once, at ``import cadra``.

    Sets ``NUMBA_CACHE_DIR`` for numba (read when numba is first imported, and inherited by
    worker processes) and, if numba is already imported, its live setting too."""
    folder = cache_folder()
    if folder is None:
        return None
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    numba_config = sys.modules.get("numba.core.config")
    if numba_config is not None:
        numba_config.CACHE_DIR = str(folder)
    return folder
