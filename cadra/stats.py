"""Small statistics of residuals that several stages read: one home for each test.

:func:`runs_of_sign` is the Wald-Wolfowitz runs test of a residual sequence's signs (seed 003
reads runs of sign as evidence of unmodelled terms): the segmented roll fit's segment table
and the gap diagnosis's sequence tests both use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class Runs:
    """The runs of sign of a sequence (zeros dropped).

    ``n`` signs, ``runs`` runs, the ``longest`` (points), the ``expected`` count under
    independent signs 1 + 2 n+ n- / n, ``z`` = (runs - expected) / sd (negative: fewer runs
    than white noise gives, i.e. correlated residuals) and its two-sided ``p``.
    """

    n: int
    runs: int
    longest: int
    expected: float
    z: float
    p: float


def runs_of_sign(values) -> Runs:
    """The Wald-Wolfowitz runs test of the signs of ``values`` (zeros dropped).

    Edge cases: no signs give zero runs and NaN statistics; a single sign gives NaN
    statistics; n > 1 signs all alike give one run, which the test conditional on the counts
    cannot weigh: it is reported as the extreme, z = -inf and p = 0 (a whole sequence on one
    side is what a systematic misfit makes)."""
    s = np.sign(np.asarray(values, dtype=float))
    s = s[s != 0]
    n = int(s.size)
    if n == 0:
        return Runs(0, 0, 0, math.nan, math.nan, math.nan)
    change = np.flatnonzero(s[1:] != s[:-1])
    lengths = np.diff(np.r_[0, change + 1, n])
    n1, n2 = int((s > 0).sum()), int((s < 0).sum())
    expected = 1.0 + 2.0 * n1 * n2 / n
    if n1 == 0 or n2 == 0:
        z, p = (-math.inf, 0.0) if n > 1 else (math.nan, math.nan)
        return Runs(n, 1, n, expected, z, p)
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n**2 * (n - 1.0))
    runs = int(lengths.size)
    z = (runs - expected) / math.sqrt(var) if var > 0 else 0.0
    return Runs(n, runs, int(lengths.max()), expected, z, float(2 * stats.norm.sf(abs(z))))


__all__ = ["Runs", "runs_of_sign"]
