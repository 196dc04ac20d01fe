"""The statistics of the gap diagnosis's detection efficiency: a score test's power and the
detection curve.

Pure functions of numbers and arrays (:mod:`cadra.validation.gap_detection` runs the trials):
:func:`lambda90`, the noncentrality at which a chi^2 test of k parameters has 90 % power;
:func:`projected_noncentrality`, a signature's noncentrality for a candidate's score test at a
fit; :func:`detection_probability` and its maximum-likelihood fit :func:`fit_m90`;
:func:`rate_by_bin`, the raw detection rate per bin of the size.

m is the size injected in units of s_ref, the size at which the true effect's k-parameter
score test alone has 90 % power (:mod:`cadra.validation.gap_detection`).

**The detection curve.** P(detect | m) is fitted by maximum likelihood with one parameter:
the diagnosis behaves as the true effect's k-parameter test with an effective threshold
c, ``P(m) = P(ncx2(k, m^2 lambda90(k)) > c)``, parametrized by m90, the multiple of s_ref
detected in 90 % (``c = ncx2.isf(0.9, k, m90^2 lambda90(k))``; each trial with its own
k). At m90 = 1 the diagnosis is the single test. Efficiency = m90, with its 95 %
profile-likelihood interval (-2 log L within 3.84 of its minimum). The raw detection rate
per bin of m is printed beside it. With every trial detected (or none) m90 is only
bounded (the interval reaches the grid's end, :data:`M90_GRID`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize, stats

__all__ = ["ALPHA", "INTERVAL_LEVEL", "M90_GRID", "M_BINS", "POWER", "detection_probability",
           "fit_m90", "lambda90", "orth", "projected_noncentrality", "rate_by_bin"]

#: the diagnosis's family-wise alpha (``diagnose_gap``'s default) and the power of the
#: reference
ALPHA = 0.01
POWER = 0.9
#: bins of m for the raw detection rates
M_BINS = (0.6, 0.9, 1.2, 1.5, 2.2)
#: the grid of m90 searched by the maximum-likelihood fit
M90_GRID = (0.1, 10.0)
#: likelihood-ratio level of the m90 interval (95 %, one parameter)
INTERVAL_LEVEL = 0.95


def lambda90(k: int, alpha: float = ALPHA, power: float = POWER) -> float:
    """The noncentrality at which a chi^2 test of k parameters at level ``alpha`` has
    ``power``: P(ncx2(k, lambda) > chi2.isf(alpha, k)) = power."""
    c = float(stats.chi2.isf(alpha, k))

    def f(lam):
        return float(stats.ncx2.sf(c, k, lam)) - power

    hi = 1.0
    while f(hi) < 0.0:
        hi *= 2.0
    return float(optimize.brentq(f, 1e-12, hi, xtol=1e-12, rtol=1e-13))


def orth(A: np.ndarray, rcond: float = 1e-10) -> np.ndarray:
    """An orthonormal basis of A's columns (``cadra.gap.score._orth``: the same rank cut)."""
    from cadra.gap.score import _orth

    return _orth(A, rcond)


def projected_noncentrality(J: np.ndarray, C: np.ndarray, d: np.ndarray) -> dict:
    """Noncentralities per unit size of a signature ``d`` (weighted, in sigmas) at a fit of
    weighted Jacobian ``J``: ``lambda_cand`` = |P_C d|^2 with P_C the projector on the
    candidate's columns ``C`` made orthogonal to J (the candidate's k-parameter score test),
    ``lambda_full`` = |P_perp d|^2 (a test along d itself), ``k`` the rank of the projected
    columns and ``coverage`` = lambda_cand / lambda_full."""
    Q = orth(J)
    Cp = C - Q @ (Q.T @ C)
    Qc = orth(Cp)
    dp = d - Q @ (Q.T @ d)
    lam_full = float(dp @ dp)
    proj = Qc.T @ dp
    lam_cand = float(proj @ proj)
    return {"k": int(Qc.shape[1]), "lambda_cand": lam_cand, "lambda_full": lam_full,
            "coverage": lam_cand / lam_full if lam_full > 0 else math.nan}


def detection_probability(m, k, m90: float, power: float = POWER, alpha: float = ALPHA):
    """P(detect) at multiples ``m`` of s_ref for a diagnosis that behaves as the k-parameter
    test with the threshold that puts its 90 % point (``power``) at ``m90``."""
    m = np.asarray(m, float)
    k = np.broadcast_to(np.asarray(k, int), m.shape)
    out = np.empty(m.shape)
    for kk in np.unique(k):
        lam = lambda90(int(kk), alpha, power)
        c = stats.ncx2.isf(power, kk, m90 ** 2 * lam)
        sel = k == kk
        out[sel] = stats.ncx2.sf(c, kk, m[sel] ** 2 * lam)
    return out


def fit_m90(m, k, detected, power: float = POWER, alpha: float = ALPHA,
            level: float = INTERVAL_LEVEL, grid=M90_GRID, n_grid: int = 600) -> dict:
    """Maximum-likelihood m90 of :func:`detection_probability` from outcomes ``detected`` at
    multiples ``m`` (each trial with its own ``k``), and its profile-likelihood interval at
    ``level``. Returns ``m90``, ``lower``, ``upper``, ``censored`` (the maximum at an end of
    the grid: every trial detected or none), ``n``."""
    m = np.asarray(m, float)
    y = np.asarray(detected, bool)
    k = np.broadcast_to(np.asarray(k, int), m.shape)
    if m.size == 0:
        return {"m90": math.nan, "lower": math.nan, "upper": math.nan, "censored": True,
                "n": 0}
    g = np.geomspace(*grid, n_grid)
    lam = {int(kk): lambda90(int(kk), alpha, power) for kk in np.unique(k)}
    L = np.zeros(g.size)
    for kk, lk in lam.items():
        sel = k == kk
        c = stats.ncx2.isf(power, kk, g ** 2 * lk)                      # (grid,)
        p = stats.ncx2.sf(c[:, None], kk, (m[sel] ** 2 * lk)[None, :])  # (grid, trials)
        p = np.clip(p, 1e-12, 1 - 1e-12)
        L += np.where(y[sel][None, :], np.log(p), np.log1p(-p)).sum(axis=1)

    def nll(logm90):
        q = np.clip(detection_probability(m, k, math.exp(logm90), power, alpha),
                    1e-12, 1 - 1e-12)
        return -float(np.sum(np.where(y, np.log(q), np.log1p(-q))))

    i = int(np.argmax(L))
    censored = i in (0, g.size - 1)
    best, lmax = g[i], L[i]
    if not censored:
        r = optimize.minimize_scalar(nll, bounds=(math.log(g[i - 1]), math.log(g[i + 1])),
                                     method="bounded", options={"xatol": 1e-6})
        if r.success and -r.fun >= lmax:
            best, lmax = math.exp(r.x), -r.fun
    inside = g[2.0 * (lmax - L) <= stats.chi2.ppf(level, 1)]
    return {"m90": float(best), "lower": float(inside.min()), "upper": float(inside.max()),
            "censored": bool(censored), "n": int(m.size)}


def rate_by_bin(m, detected, bins=M_BINS) -> list:
    """Raw detection rate per bin of m: [(lo, hi, n, rate), ...]."""
    m = np.asarray(m, float)
    y = np.asarray(detected, bool)
    out = []
    for lo, hi in zip(bins[:-1], bins[1:], strict=True):
        sel = (m >= lo) & ((m < hi) if hi < bins[-1] else (m <= hi))
        out.append((lo, hi, int(sel.sum()), float(y[sel].mean()) if sel.any() else math.nan))
    return out
