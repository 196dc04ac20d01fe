"""TOML files at the file boundary: the shared reading and validation helpers of
:mod:`cadra.fields` (``read_toml`` naming the file, ``Fields`` naming the key path,
``prefixed_by``) and the atomic writer :func:`write_toml`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from cadra.atomic import atomic_write_text
from cadra.fields import Fields, prefixed_by, read_toml


def toml_text(data: Mapping, header: str = "") -> str:
    """TOML text of ``data`` (``tomli_w``), after ``header`` as comment lines (``# ...``)."""
    import tomli_w

    text = tomli_w.dumps(dict(data))
    if header:
        text = "".join(f"# {line}\n" if line else "#\n" for line in header.split("\n")) + text
    return text


def write_toml(path: str | os.PathLike, data: Mapping, *, header: str = "",
               overwrite: bool = False) -> Path:
    """Write :func:`toml_text` of ``data`` atomically (:func:`cadra.atomic.atomic_write_text`);
    an existing file is refused (:class:`FileExistsError`) unless ``overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite (pass overwrite=True)")
    return atomic_write_text(path, toml_text(data, header), overwrite=overwrite)


__all__ = ["Fields", "prefixed_by", "read_toml", "toml_text", "write_toml"]
