"""1-DOF pitch fits (seed 001 eqs. 6-12 and 16): ``alpha = alpha_T + K e^{λu} cos(ωu + δ)``.

The real angle history of a model on a pitch pivot (or one plane of a planar motion) is fitted
by differential corrections as ``alpha_T + e^{λu}(a cos ωu + b sin ωu)``, ``u = s - s_ref``,
so ``K = √(a² + b²)`` and ``δ = atan2(-b, a)``; Levenberg-Marquardt with the analytic
Jacobian, starts from the matrix pencil, covariance scaled by χ²/dof (stated).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from cadra.motion import _checks
from cadra.motion._named import ByName
from cadra.motion.epicyclic import MotionFitError, covariance
from cadra.motion.starts import pencil_exponents

NAMES = ("alpha_T", "a", "b", "lambda", "omega")


@dataclass(frozen=True)
class PitchFit(ByName):
    """Result of :func:`fit_pitch`; ``values``/``sigmas``/``covariance`` follow ``NAMES``."""

    values: np.ndarray
    sigmas: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    s_ref: float
    variable: str
    trim: bool
    chi2: float
    dof: int
    chi2_dof: float
    covariance_scaled: bool
    rms: float
    n_points: int
    nfev: int

    names = NAMES

    @property
    def K(self) -> float:
        return float(np.hypot(self.values[1], self.values[2]))

    @property
    def K_sigma(self) -> float:
        a, b = self.values[1], self.values[2]
        g = np.array([a, b]) / max(np.hypot(a, b), 1e-300)
        return float(np.sqrt(g @ self.covariance[1:3, 1:3] @ g))

    @property
    def delta(self) -> float:
        return float(np.arctan2(-self.values[2], self.values[1]))

    def predict(self, s) -> np.ndarray:
        return _model(self.values, np.asarray(s, float) - self.s_ref)


def _model(x, u):
    e = np.exp(x[3] * u)
    return x[0] + e * (x[1] * np.cos(x[4] * u) + x[2] * np.sin(x[4] * u))


def _jac(x, u):
    e = np.exp(x[3] * u)
    c, s = np.cos(x[4] * u), np.sin(x[4] * u)
    osc = x[1] * c + x[2] * s
    dosc = -x[1] * s + x[2] * c
    return np.stack([np.ones_like(u), e * c, e * s, u * e * osc, u * e * dosc], axis=1)


def fit_pitch(s, alpha, sigma_alpha=None, *, trim: bool = True, variable: str = "time",
              s_ref: float | None = None, start: PitchFit | None = None,
              scale_covariance: bool = True) -> PitchFit:
    """Fit ``alpha_T + K e^{λu} cos(ωu + δ)`` to a real angle history.

    Parameters
    ----------
    s : (N,) time (s) or distance (m), strictly increasing
    alpha : (N,) angle (rad)
    sigma_alpha : None (unit weights), scalar or (N,) (rad)
    trim : fit the constant alpha_T (else held at 0)
    s_ref : reference of the amplitude and phase (default: first point)
    start : an earlier fit to start from (re-referred)
    """
    if variable not in ("time", "distance"):
        raise ValueError(f"variable: 'time' or 'distance', got {variable!r}")
    s = _checks.abscissa("s", s, min_points=6)
    y = _checks.series("alpha", alpha, s.size)
    w = 1.0 / _checks.sigmas("sigma_alpha", sigma_alpha, s.size)
    s_ref = float(s[0]) if s_ref is None else float(s_ref)
    u = s - s_ref
    if start is not None:
        x0 = start.values.copy()
        du = s_ref - start.s_ref
        A = (x0[1] - 1j * x0[2]) * np.exp((x0[3] + 1j * x0[4]) * du)
        x0[1], x0[2] = A.real, -A.imag
        if not trim:
            x0[0] = 0.0
    else:
        r = pencil_exponents(s, y.astype(complex), 3 if trim else 2)
        r = r[np.argsort(np.abs(r))]
        osc = r[1:] if trim else r
        z = osc[np.argmax(osc.imag)]
        lam, om = z.real, abs(z.imag)
        E = np.exp(lam * u)
        M = np.stack([np.ones_like(u), E * np.cos(om * u), E * np.sin(om * u)], axis=1)
        if not trim:
            M = M[:, 1:]
        c, *_ = np.linalg.lstsq(M * w[:, None], y * w, rcond=None)
        x0 = np.r_[c if trim else np.r_[0.0, c], lam, om]
    mask = np.ones(5, bool)
    mask[0] = trim
    x_fixed = x0.copy()

    def full(xf):
        x = x_fixed.copy()
        x[mask] = xf
        return x

    def resid(xf):
        return (_model(full(xf), u) - y) * w

    def jac(xf):
        return (_jac(full(xf), u) * w[:, None])[:, mask]

    res = least_squares(resid, x0[mask], jac=jac, method="lm", x_scale="jac", xtol=1e-13,
                        ftol=1e-13, gtol=1e-13, max_nfev=2000)
    if res.status <= 0 or not np.all(np.isfinite(res.x)):
        raise MotionFitError(f"pitch fit did not converge: {res.message}")
    x = full(res.x)
    if x[4] < 0:   # the same motion with ω > 0
        x[4], x[2] = -x[4], -x[2]
    J = _jac(x, u) * w[:, None]
    dof = s.size - int(mask.sum())
    chi2 = float(res.fun @ res.fun)
    chi2_dof = chi2 / dof if dof > 0 else float("nan")
    cov = np.zeros((5, 5))
    sub = covariance(J[:, mask])
    if scale_covariance and dof > 0:
        sub = sub * chi2_dof
    cov[np.ix_(mask, mask)] = sub
    sig = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sig, sig)
    d = _model(x, u) - y
    return PitchFit(values=x, sigmas=sig, covariance=cov, correlation=corr, s_ref=s_ref,
                    variable=variable, trim=trim, chi2=chi2, dof=dof, chi2_dof=chi2_dof,
                    covariance_scaled=bool(scale_covariance),
                    rms=float(np.sqrt(np.mean(d * d))), n_points=s.size, nfev=int(res.nfev))
