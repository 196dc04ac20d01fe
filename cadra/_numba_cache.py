"""Keep numba's on-disk caches consistent across modules.

numba (``cache=True``) invalidates a cached function only when *its own* source file changes;
a caller in another module keeps a stale copy of an inlined callee (e.g. the integrator in
``cadra/dynamics`` of the aero evaluator in ``cadra/aero/program.py``). This guard hashes the
sources of every module that uses numba (in the packages listed below) and, when the hash
changes, deletes the packages' cache files before anything is compiled or loaded. Runs once
per process, at import of :mod:`cadra`; a read-only install simply skips it.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

_ROOT = Path(__file__).resolve().parent
_JIT_PACKAGES = ("aero", "dynamics", "synthetic", "measure", "body", "fitting", "calibration", "gap")


def ensure_fresh_cache() -> None:
    digest = hashlib.sha256()
    for pkg in _JIT_PACKAGES:
        for path in sorted((_ROOT / pkg).glob("*.py")):
            source = path.read_bytes()
            if b"numba" not in source:
                continue  # no compiled code here: editing it must not drop the caches
            digest.update(path.name.encode())
            digest.update(source)
    stamp = _ROOT / "__pycache__" / "numba_sources.sha256"
    current = digest.hexdigest()
    try:
        if stamp.is_file() and stamp.read_text() == current:
            return
        for pkg in _JIT_PACKAGES:
            for cache in (_ROOT / pkg / "__pycache__").glob("*.nb[ic]"):
                cache.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_suffix(f".tmp{id(stamp)}")
        tmp.write_text(current)
        tmp.replace(stamp)
    except OSError:
        pass
