"""Aliased yaw arms: which frequency band each epicyclic arm is in, from the spin.

A station samples the yaw once. An arm that turns more than half a cycle between stations is
aliased: every frequency ``omega + 2 pi k / ds`` (``ds`` the station spacing in the fit's
variable, ``k`` whole) fits the same samples, exactly so for evenly spaced stations. On a spark
range this is the normal case for a spinning bullet's fast arm (the M-80's turns about 1.7
times between stations 4 m apart). The data cannot choose the band; the physics can. For a
spinning symmetric body linear theory gives the sum of the two arms' frequencies:

    omega_1 + omega_2 = (I_x / I) p / V      (per unit distance; p / 1 in time)

(McCoy, *Modern Exterior Ballistics*, ch. 10: the sum of the roots of the yaw equation is
i P), and both arms turn in the sense of the spin. Given the spin (from the gun's twist and
the muzzle velocity), :func:`dealias_arms` tries the bands of both arms that agree with it,
refits the arms from each (the samples of an unevenly spaced record do tell the bands apart,
a little), and keeps the band whose sum matches the spin, reporting how far the next band's
chi^2 is. Pure numpy; the classic reduction (:func:`cadra.flight.classic.analyse_shot`) and the
fit's starting values call it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from cadra.motion.epicyclic import EpicyclicFit, MotionFitError, fit_epicyclic

#: relative miss of the frequency sum that still counts as agreeing with the spin (the
#: twist gives the muzzle spin; the bullet's spin and speed decay along the range)
SUM_TOLERANCE = 0.15
#: chi^2 by which another band must fit better to be taken over the one nearest the physics
CHI2_MARGIN = 9.0
#: relative frequency sums theory's start is tried at (the spin at the range is below the
#: muzzle's by a few per cent; a spin from the twist at the range's speed, above)
SUM_SCAN = np.arange(-0.05, 0.05 + 1e-9, 0.005)


@dataclass(frozen=True)
class AliasBand:
    """One candidate band: whole cycles per station added to each arm, the refitted arms,
    and the relative miss of their frequency sum against the spin's."""

    shifts: tuple[int, int]
    fit: EpicyclicFit
    sum_miss: float


@dataclass(frozen=True)
class Dealiased:
    """The result of :func:`dealias_arms`: the chosen band first in ``bands``."""

    fit: EpicyclicFit
    shifts: tuple[int, int]
    bands: tuple[AliasBand, ...]
    expected_sum: float
    spacing: float

    @property
    def aliased(self) -> bool:
        """An arm was moved out of the band the stations' sampling puts it in."""
        return any(self.shifts)

    @property
    def next_chi2_delta(self) -> float:
        """chi^2 of the next candidate band minus the chosen one's (NaN: no other band)."""
        if len(self.bands) < 2:
            return math.nan
        return float(self.bands[1].fit.chi2 - self.bands[0].fit.chi2)

    def note(self, unit: str = "m") -> str:
        """One line for a report: which arms were aliased and how far the next band is."""
        if not self.aliased:
            text = "no arm aliased: the arms' frequencies agree with the spin as sampled"
        else:
            moved = [f"arm {j + 1} by {k:+d} cycle(s) per station" for j, k in
                     enumerate(self.shifts) if k]
            text = (f"aliased arms put in the spin's bands: {', '.join(moved)} (stations "
                    f"{self.spacing:.4g} {unit} apart)")
        text += f"; frequency sum {100 * self.bands[0].sum_miss:+.1f} % off the spin's"
        if len(self.bands) > 1:
            b = self.bands[1]
            text += (f"; next band {b.shifts} (sum {100 * b.sum_miss:+.1f} %) has chi^2 "
                     f"{self.next_chi2_delta:+.3g}")
        return text


def _omegas(fit: EpicyclicFit) -> tuple[float, float]:
    """The two arms' frequencies of ``fit`` (per unit of its variable)."""
    return tuple(float(fit.values[fit.layout.index(f"omega{j}")]) for j in (1, 2))


def _shifted(fit: EpicyclicFit, dw: tuple[float, float]) -> EpicyclicFit:
    values = fit.values.copy()
    for j, d in enumerate(dw):
        values[fit.layout.index(f"omega{j + 1}")] += d
    return replace(fit, values=values)


def _sampled(w: float, step: float) -> float:
    """``w`` in the band the stations sample: (-step/2, step/2]."""
    return w - step * math.floor(w / step + 0.5)


def dealias_arms(fit: EpicyclicFit, s, alpha, beta, sigma_alpha, sigma_beta, *,
                 expected_sum: float, expected_product: float | None = None,
                 k_max: int = 4, keep: int = 3) -> Dealiased:
    """Put the two arms of ``fit`` into the frequency bands the spin says (module doc).

    ``s``, ``alpha``, ``beta`` and their sigmas are the history ``fit`` was made from;
    ``expected_sum`` is (I_x / I) p / V per metre for a fit in distance ((I_x / I) p in
    time), signed as the spin. Bands up to ``k_max`` whole cycles per station from each arm's
    sampled frequency are tried; both arms must turn in the spin's sense and their sum be
    within :data:`SUM_TOLERANCE` of ``expected_sum``. Shifting either arm by a band moves the
    sum alike, so ``expected_product`` (omega_1 omega_2 from the starting C_m_alpha, linear
    theory's M) tells such bands apart; without it the pair further apart (the larger
    gyroscopic stability factor S_g = (w1 + w2)^2 / 4 w1 w2) is preferred, as a spin-
    stabilised projectile's slow arm is the one its stations sample. The ``keep`` candidates
    nearest the expected sum and product are refitted; the nearest wins unless another fits
    better by a chi^2 of more than :data:`CHI2_MARGIN` (evenly spaced stations cannot tell
    the bands apart at all).
    With ``expected_product`` the arms are also refitted from gyroscopic theory's own
    frequencies (the roots of w^2 - sum w + product = 0): an aliased record's automatic fit
    can land an arm where no band agrees with the spin (two arms of one sign, one of them
    spurious), and the theory's start then finds the true pair. Raises ``ValueError`` when no
    band agrees with the spin (the arms belong to another spin, or the record shows one arm
    only).
    """
    if fit.layout.arms != 2:
        raise ValueError("fit: needs the two-arm (epicyclic or tricyclic) form")
    if not (np.isfinite(expected_sum) and expected_sum != 0.0):
        raise ValueError(f"expected_sum: a finite, non-zero frequency sum, got {expected_sum!r}")
    s = np.asarray(s, dtype=float)
    spacing = float(np.median(np.diff(s)))
    step = 2.0 * math.pi / spacing
    w = _omegas(fit)
    sign = math.copysign(1.0, expected_sum)
    use_product = expected_product is not None and np.isfinite(expected_product) and (
        expected_product > 0)

    def distance(w1, w2):
        d = abs((w1 + w2) / expected_sum - 1.0)
        if use_product:
            return d + abs(math.log(w1 * w2 / expected_product))
        # no product: the arms further apart (the larger S_g = (w1 + w2)^2 / 4 w1 w2) first
        return d + 0.1 * 4.0 * w1 * w2 / (w1 + w2) ** 2

    cands = []
    for k1 in range(-k_max, k_max + 1):
        for k2 in range(-k_max, k_max + 1):
            w1, w2 = w[0] + k1 * step, w[1] + k2 * step
            if w1 * sign <= 0 or w2 * sign <= 0:
                continue
            if abs((w1 + w2) / expected_sum - 1.0) <= SUM_TOLERANCE:
                cands.append((distance(w1, w2), (k1, k2)))
    cands.sort()
    options = dict(trim_rate=fit.trim_rate, offset=fit.layout.offset,
                   curvature=fit.layout.curvature, variable=fit.variable, s_ref=fit.s_ref,
                   scale_covariance=fit.covariance_scaled)
    refits = []
    for _, (k1, k2) in cands[:keep]:
        try:
            refits.append(fit_epicyclic(s, alpha, beta, sigma_alpha, sigma_beta,
                                        start=_shifted(fit, (k1 * step, k2 * step)), **options))
        except MotionFitError:
            continue
    if use_product and fit.trim_rate is None and not fit.layout.offset:
        # the spin is known to a few per cent (the twist gives the muzzle's; it decays), which
        # over a long record is radians of the fast arm's phase: theory's roots at a scan of
        # sums, each a local fit
        for f in SUM_SCAN:
            total = expected_sum * (1.0 + f)
            disc = total**2 - 4.0 * expected_product
            if disc <= 0:
                continue
            roots = 0.5 * (total + np.array([1.0, -1.0]) * sign * math.sqrt(disc))
            try:
                refits.append(fit_epicyclic(s, alpha, beta, sigma_alpha, sigma_beta,
                                            exponents=1j * roots, **options))
            except MotionFitError:
                pass
    bands = []
    for refit in sorted(refits, key=lambda r: r.chi2):
        w1, w2 = _omegas(refit)
        if w1 * sign <= 0 or w2 * sign <= 0:
            continue
        miss = (w1 + w2) / expected_sum - 1.0
        if abs(miss) > SUM_TOLERANCE:
            continue
        # whole cycles per station from the band the stations put each arm in
        shifts = tuple(int(round((wj - _sampled(wj, step)) / step)) for wj in (w1, w2))
        if any(b.shifts == shifts for b in bands):
            continue               # one fit per band: the best (refits go by chi^2)
        bands.append(AliasBand(shifts, refit, miss))
    if not bands:
        raise ValueError(
            f"no band of the arms ({w[0]:.4g}, {w[1]:.4g} rad per unit, stations {spacing:.4g} "
            f"apart) sums to the spin's {expected_sum:.4g} within {SUM_TOLERANCE:.0%}: the "
            "spin given does not belong to this motion, or one arm is not seen")
    bands.sort(key=lambda b: distance(*_omegas(b.fit)))
    best = bands[0]
    for b in bands[1:]:
        if b.fit.chi2 < best.fit.chi2 - CHI2_MARGIN:
            best = b
    bands = [best] + [b for b in bands if b is not best]
    return Dealiased(best.fit, best.shifts, tuple(bands), float(expected_sum), spacing)


__all__ = ["CHI2_MARGIN", "SUM_TOLERANCE", "AliasBand", "Dealiased", "dealias_arms"]
