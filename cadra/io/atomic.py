"""Atomic file and directory writes: a reader never sees a half-written output.

Every writer in CADRA validates first and writes last, through these helpers: the data go to a
temporary file (or directory) beside the target, are flushed to disk, and are moved into place
with :func:`os.replace`, which is atomic on POSIX and Windows for a path on the same file
system. Existing outputs are refused unless ``overwrite=True``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


def atomic_write_bytes(path: str | os.PathLike, data: bytes, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically.

    Parameters
    ----------
    path : target file; its parent directory is created if needed.
    data : the complete contents.
    overwrite : replace an existing file (default: refuse with :class:`FileExistsError`).

    Returns
    -------
    The target path. On any error nothing is left at ``path`` (nor a temporary file).
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite (pass overwrite=True)")
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        if not overwrite and path.exists():  # appeared while we were writing
            raise FileExistsError(f"{path} exists; refusing to overwrite (pass overwrite=True)")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str, overwrite: bool = False,
                      encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`)."""
    return atomic_write_bytes(path, text.encode(encoding), overwrite=overwrite)


@contextlib.contextmanager
def atomic_output_dir(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Build a directory of outputs in a temporary sibling and move it into place at the end.

    ::

        with atomic_output_dir("out/m2_2429") as tmp:
            (tmp / "shot.toml").write_text(...)
            ...
        # out/m2_2429 now exists, complete; on an exception it does not exist (or is unchanged)

    Parameters
    ----------
    path : the final directory.
    overwrite : replace an existing directory at the end (default: refuse up front with
        :class:`FileExistsError`). The old directory is removed only after the new one is
        complete.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite (pass overwrite=True)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    try:
        yield tmp
        if path.exists():
            if not overwrite:
                raise FileExistsError(f"{path} exists; refusing to overwrite")
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
            os.replace(path, old / "d")  # move aside, then swap in, then delete the old one
            try:
                os.replace(tmp, path)
            except BaseException:
                os.replace(old / "d", path)
                raise
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


__all__ = ["atomic_output_dir", "atomic_write_bytes", "atomic_write_text"]
