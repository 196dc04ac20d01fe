"""Small statistics of residuals that several stages read: one home for each test.

:func:`runs_of_sign` is the Wald-Wolfowitz runs test of a residual sequence's signs (seed 003
reads runs of sign as evidence of unmodelled terms): the segmented roll fit's segment table
and the gap diagnosis's sequence tests both use it. :func:`chi2_p_value` and
:data:`POOR_MINIMUM_P` say when a converged fit (the 6-DOF fit, the classic reduction, the
roll fit) is far above its noise: converged to a poor minimum; :func:`chi2_quantile` is the
threshold a chi^2 statistic is held to (the wires' agreement tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# scipy.stats' own formulas, from scipy.special: importing scipy.stats costs a process 0.5 s
from scipy.special import chdtrc, gammaincinv, ndtr

#: p-value of chi^2 below which a converged fit is said to have converged to a poor minimum:
#: noise of the stated sigmas alone leaves residuals this large less than once in a million
POOR_MINIMUM_P = 1e-6


def chi2_p_value(chi2: float, dof: int) -> float:
    """P(X >= ``chi2``) for X chi^2-distributed with ``dof`` degrees of freedom (NaN without
    degrees of freedom or a finite chi^2)."""
    if dof <= 0 or not math.isfinite(chi2):
        return math.nan
    return float(chdtrc(dof, chi2))


def chi2_quantile(q: float, dof: float) -> float:
    """The value a chi^2 variable with ``dof`` degrees of freedom stays below with probability
    ``q`` (scipy.stats' ``chi2.ppf``, by its own formula)."""
    return float(2.0 * gammaincinv(0.5 * dof, q))


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
    return Runs(n, runs, int(lengths.max()), expected, z, float(2 * ndtr(-abs(z))))


__all__ = ["POOR_MINIMUM_P", "Runs", "chi2_p_value", "chi2_quantile", "runs_of_sign"]
