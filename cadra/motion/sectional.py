"""Overlapping sectional fits (seed 000 "Data reduction procedure"; seed 001 section II): the
epicyclic or 1-DOF pitch model fitted to short overlapping windows, giving the motion
parameters K, λ, ω (and their sigmas) against time or distance. Each window starts from the
last solution whose arms are all determined (each amplitude above its sigma), re-referred to
its own centre. An arm that has decayed into the noise is not determined: at a vanishing
amplitude its rate and frequency are flat directions, and a fit started there can wander
along them until it runs out of evaluations, so such a solution is reported but not
carried on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cadra.motion import _checks
from cadra.motion.epicyclic import fit_epicyclic
from cadra.motion.pitch import fit_pitch


@dataclass(frozen=True)
class Sections:
    """Motion parameters per section; arrays are (n_sections, arms) except ``centre``,
    ``rms`` and ``alpha_T`` (n_sections,). Amplitudes are at the section centre."""

    kind: str                  # "epicyclic" or "pitch"
    variable: str
    centre: np.ndarray
    K: np.ndarray
    K_sigma: np.ndarray
    lam: np.ndarray
    lam_sigma: np.ndarray
    omega: np.ndarray
    omega_sigma: np.ndarray
    rms: np.ndarray
    alpha_T: np.ndarray
    window: int
    step: int
    trim_rate: float | None

    @property
    def overlap(self) -> float:
        """How many sections share a data point (window / step, at least 1)."""
        return max(1.0, self.window / self.step)


def _windows(n: int, window: int, step: int) -> list[tuple[int, int]]:
    if window > n:
        raise ValueError(f"window: {window} points, the record has only {n}")
    starts = list(range(0, n - window + 1, step))
    return [(i, i + window) for i in starts]


def _check_window(window, step, minimum):
    if int(window) != window or window < minimum:
        raise ValueError(f"window: an integer number of points >= {minimum}, got {window!r}")
    if int(step) != step or step < 1:
        raise ValueError(f"step: a positive integer, got {step!r}")
    return int(window), int(step)


def _determined(fit, arms) -> bool:
    """Whether every arm of ``fit`` has an amplitude above its sigma (a start to carry on)."""
    return all(a.K > a.K_sigma for a in arms)


def _fit_windows(s, window: int, step: int, fit) -> list[tuple]:
    """``fit(i, j, centre, previous)`` -> (fit, arms, row) over the windows of ``s``, each
    started from the last fit whose arms were all determined; the rows, each led by its
    window's centre."""
    rows, prev = [], None
    for i, j in _windows(s.size, window, step):
        c = 0.5 * (s[i] + s[j - 1])
        f, arms, row = fit(i, j, c, prev)
        if _determined(f, arms):
            prev = f
        rows.append((c, *row))
    return rows


def sectional_epicyclic(s, alpha, beta, sigma_alpha=None, sigma_beta=None, *, window: int,
                        step: int, variable: str = "time", **fit_kwargs) -> Sections:
    """Epicyclic fits (:func:`fit_epicyclic`, two arms) of windows of ``window`` points every
    ``step`` points; ``fit_kwargs`` go to each fit (``trim_rate``, ``curvature``, ...)."""
    s = _checks.abscissa("s", s, min_points=8)
    a = _checks.series("alpha", alpha, s.size)
    b = _checks.series("beta", beta, s.size)
    sa = _checks.sigmas("sigma_alpha", sigma_alpha, s.size)
    sb = _checks.sigmas("sigma_beta", sigma_beta, s.size)
    window, step = _check_window(window, step, 8)

    def fit(i, j, c, prev):
        f = fit_epicyclic(s[i:j], a[i:j], b[i:j], sa[i:j], sb[i:j], s_ref=c, start=prev,
                          variable=variable, **fit_kwargs)
        arms = [f.arm(k) for k in (1, 2)]
        return f, arms, ([m.K for m in arms], [m.K_sigma for m in arms], [m.lam for m in arms],
                         [m.lam_sigma for m in arms], [m.omega for m in arms],
                         [m.omega_sigma for m in arms], f.rms, 0.0)

    rows = _fit_windows(s, window, step, fit)
    return _pack("epicyclic", variable, rows, window, step, fit_kwargs.get("trim_rate"))


def sectional_pitch(s, alpha, sigma_alpha=None, *, window: int, step: int,
                    variable: str = "time", trim: bool = True) -> Sections:
    """1-DOF pitch fits (:func:`fit_pitch`) of overlapping windows."""
    s = _checks.abscissa("s", s, min_points=6)
    a = _checks.series("alpha", alpha, s.size)
    sa = _checks.sigmas("sigma_alpha", sigma_alpha, s.size)
    window, step = _check_window(window, step, 6)

    def fit(i, j, c, prev):
        f = fit_pitch(s[i:j], a[i:j], sa[i:j], trim=trim, variable=variable, s_ref=c,
                      start=prev)
        return f, [f], ([f.K], [f.K_sigma], [f.value("lambda")], [f.sigma("lambda")],
                        [f.value("omega")], [f.sigma("omega")], f.rms, f.value("alpha_T"))

    rows = _fit_windows(s, window, step, fit)
    return _pack("pitch", variable, rows, window, step, None)


def _pack(kind, variable, rows, window, step, trim_rate) -> Sections:
    cols = list(zip(*rows, strict=True))
    arr = [np.asarray(c, float) for c in cols]
    return Sections(kind=kind, variable=variable, centre=arr[0], K=arr[1], K_sigma=arr[2],
                    lam=arr[3], lam_sigma=arr[4], omega=arr[5], omega_sigma=arr[6],
                    rms=arr[7], alpha_T=arr[8], window=window, step=step, trim_rate=trim_rate)
