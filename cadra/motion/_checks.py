"""Input checks shared by the motion functions: every bad argument gives a ValueError that
names it (too few points, NaN or infinite values, mismatched lengths, non-positive sigmas,
an independent variable that does not increase)."""

from __future__ import annotations

import numpy as np


def series(name: str, x, n: int | None = None) -> np.ndarray:
    """``x`` as a finite 1-D float array (of length ``n`` when given)."""
    a = np.asarray(x, dtype=float)
    if a.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D series, got shape {a.shape}")
    if n is not None and a.size != n:
        raise ValueError(f"{name}: length {a.size} does not match the independent variable's {n}")
    if not np.all(np.isfinite(a)):
        bad = int(np.flatnonzero(~np.isfinite(a))[0])
        raise ValueError(f"{name}: non-finite value (NaN or inf) at index {bad}")
    return a


def abscissa(name: str, s, min_points: int) -> np.ndarray:
    """The independent variable (time or distance): finite, strictly increasing, long enough."""
    a = series(name, s)
    if a.size < min_points:
        raise ValueError(f"{name}: {a.size} points, at least {min_points} are needed")
    if np.any(np.diff(a) <= 0):
        raise ValueError(f"{name}: must be strictly increasing")
    return a


def sigmas(name: str, sig, n: int) -> np.ndarray:
    """Positive sigmas: None (unit weights), a scalar or a length-``n`` series."""
    if sig is None:
        return np.ones(n)
    a = np.asarray(sig, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    a = series(name, a, n)
    if np.any(a <= 0):
        raise ValueError(f"{name}: sigmas must be positive")
    return a


def positive(name: str, x) -> float:
    v = float(x)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name}: must be a positive finite number, got {x!r}")
    return v
