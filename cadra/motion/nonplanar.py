"""Seed 002's correlators of nonplanar motion: Murphy's cubic correlator (eqs. 3-4, 10) and the
Nonplanar Ratio (eqs. 13-18).

For ``xi = K_1 e^{iφ_1} + K_2 e^{iφ_2}`` the pitch angle is ``δ = |xi|`` (eq. 13) and the pitch
plane turns at ``ν̇`` (eqs. 14-15); the cross-flow at the nose from coning is ``δ ν̇ l`` and
from pitching ``δ̇ l`` (eqs. 16-17). With ``ξ̇ = (δ̇ + i δ ν̇) e^{iν}`` both come straight from
the complex history: ``δ ν̇ = Im(ξ* ξ̇)/|ξ|`` and ``δ̇ = Re(ξ* ξ̇)/|ξ|``.

NPR. Eq. 18 as printed, ``∫|δν̇| / ∫|δ̇|`` (the coning over the pitching cross-flow), is 0
for planar motion but infinite for circular motion (δ̇ = 0). CADRA's ``nonplanar_ratio`` is
the bounded form ``∫|δν̇| ds / ∫|ξ̇| ds`` (coning cross-flow over the total, |ξ̇|² = δ̇² +
δ²ν̇²): 0 for planar, 1 for circular motion, monotone in the printed ratio for steady
epicycles. The printed ratio is returned too (``seed_ratio``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import trapezoid

from cadra.motion import _checks
from cadra.motion.epicyclic import EpicyclicFit, model


@dataclass(frozen=True)
class CubicCorrelator:
    """δ_e1², δ_e2² (eq. 4 without trim terms) and Murphy's δ_e² (eq. 3), in rad² when the
    amplitudes are in rad; the effective ``C_mα = C + K δ_e²`` for ``C_m = Cα + Kα³``."""

    delta_e1_sq: float
    delta_e2_sq: float
    delta_e_sq: float
    mean_square: float       # δ² = K_1² + K_2² (+ K_3²), seed 002's mean-square angle


def cubic_correlator(K1: float, K2: float, omega1: float, omega2: float,
                     K3: float = 0.0) -> CubicCorrelator:
    """Murphy's cubic correlator (seed 002 eqs. 3-4; Murphy, J. Spacecraft 8 (1971) 259).

    ``δ_e1,2² = K_1,2² + 2K_2,1² + 2K_3²`` and ``δ_e² = (ω_1 δ_e2² − ω_2 δ_e1²)/(ω_1 − ω_2)``
    (seed 000's δ_α², the abscissa of its ω_Nω_P line, is the same expression). The trim
    arm enters as ``2K_3²`` as eq. 4 prints; its further "trim terms" are not given and not
    included. Planar motion (K_1 = K_2 = K/2, ω_1 = −ω_2) gives ¾K².
    """
    for name, v in (("K1", K1), ("K2", K2), ("omega1", omega1), ("omega2", omega2), ("K3", K3)):
        if not np.isfinite(v):
            raise ValueError(f"{name}: must be finite, got {v!r}")
    if omega1 == omega2:
        raise ValueError("omega1, omega2: equal frequencies, the correlator is undefined")
    d1 = K1**2 + 2 * K2**2 + 2 * K3**2
    d2 = K2**2 + 2 * K1**2 + 2 * K3**2
    de = (omega1 * d2 - omega2 * d1) / (omega1 - omega2)
    return CubicCorrelator(float(d1), float(d2), float(de), float(K1**2 + K2**2 + K3**2))


@dataclass(frozen=True)
class NonplanarRatio:
    npr: float              # ∫|δν̇| / ∫|ξ̇|: 0 planar, 1 circular
    seed_ratio: float       # ∫|δν̇| / ∫|δ̇| as eq. 18 prints it (inf for circular motion)


def nonplanar_ratio(s, xi, dxi) -> NonplanarRatio:
    """The Nonplanar Ratio of a complex angle history ``xi`` (rad) and its derivative ``dxi``
    over ``s`` (time or distance; the ratio does not depend on which), integrated by the
    trapezoid rule. Pass a fit's prediction on a fine grid (``fit.predict(s)``,
    ``fit.predict(s, derivative=True)``) or the arms' sum without the trim arm, as the seed
    does."""
    s = _checks.abscissa("s", s, min_points=3)
    x = np.asarray(xi, complex)
    dx = np.asarray(dxi, complex)
    if x.shape != s.shape:
        raise ValueError(f"xi: length {x.size} does not match s's {s.size}")
    if dx.shape != s.shape:
        raise ValueError(f"dxi: length {dx.size} does not match s's {s.size}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(dx))):
        raise ValueError("xi, dxi: non-finite value")
    mag = np.abs(x)
    prod = np.conj(x) * dx
    with np.errstate(invalid="ignore", divide="ignore"):
        coning = np.where(mag > 0, np.abs(prod.imag) / mag, 0.0)
        pitching = np.where(mag > 0, np.abs(prod.real) / mag, np.abs(dx))
    c = trapezoid(coning, s)
    total = trapezoid(np.abs(dx), s)
    p = trapezoid(pitching, s)
    npr = c / total if total > 0 else float("nan")
    seed = c / p if p > 0 else (float("inf") if c > 0 else float("nan"))
    return NonplanarRatio(float(npr), float(seed))


def nonplanar_ratio_of_fit(fit: EpicyclicFit, s_start: float, s_end: float,
                           n: int = 4001) -> NonplanarRatio:
    """The NPR of a fit's two arms alone (trim arm and constant left out, as seed 002 does)
    between ``s_start`` and ``s_end``, on ``n`` points."""
    if fit.layout.arms != 2:
        raise ValueError("fit: needs the two-arm form")
    if not s_end > s_start:
        raise ValueError("s_end: must be after s_start")
    L = fit.layout
    x = fit.values.copy()
    x[L.arms * L.per_arm:] = 0.0          # trim and constant amplitudes (and p) to zero
    s = np.linspace(s_start, s_end, int(n))
    u = s - fit.s_ref
    arms_only = type(L)(arms=2, curvature=L.curvature)
    xa = x[: 2 * L.per_arm]
    return nonplanar_ratio(s, model(arms_only, xa, u, None),
                           model(arms_only, xa, u, None, derivative=True))
