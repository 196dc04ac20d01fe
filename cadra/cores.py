"""How many cores this process's work may use: the one home of "all cores".

Stage one's station pool (``workers=None``) and the fit's propagation threads
(``Integration.threads = 0``) use :func:`available` cores: the machine's, unless the caller
runs them under :func:`limit`. A campaign task runs under ``limit(1)``: Dask already gives
each task its own core (one thread per worker process), so the library's own pools give way
to its scheduling instead of running two or more threads on one core (docs/campaign.md,
"On Dask").
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

_LIMIT: ContextVar[int | None] = ContextVar("cadra_cores", default=None)


def available() -> int:
    """The cores the current work may use: :func:`limit`'s, else the machine's."""
    return _LIMIT.get() or os.cpu_count() or 1


@contextmanager
def limit(n: int) -> Iterator[None]:
    """Within the block (this thread and context), "all cores" means ``n`` (>= 1)."""
    if int(n) < 1:
        raise ValueError(f"cores.limit: expected at least 1 core, got {n}")
    token = _LIMIT.set(int(n))
    try:
        yield
    finally:
        _LIMIT.reset(token)


__all__ = ["available", "limit"]
