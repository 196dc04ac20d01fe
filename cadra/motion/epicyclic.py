"""Epicyclic and tricyclic fits of an angle history by differential corrections.

The complex angle is ``xi = beta + i alpha`` (docs/motion.md: beta + nose to port of the
wind, alpha + nose up, docs/conventions.md), over an independent variable ``s`` that is time
(s) or distance (m). The model (seed 001 eqs. 1, 5 and 33; seed 002 eqs. 1-2 and 12):

    xi(s) = Σ_j A_j exp[(λ_j + i ω_j) u + i ω̇_j u²/2]      (arms j = 1, 2; u = s - s_ref)
            + A_t exp(i p u)                              (trim arm, tricyclic; p given)
            + A_0                                         (constant, seed 001's K_4)

with complex amplitudes ``A_j = K_j exp(i φ_j0)``: the fit is linear in ``A`` (seed 002's
constants a ... g) and nonlinear in λ, ω, ω̇. Two arms and a trim arm of known rate are seed
002's 10-constant form; the ω̇ (½ φ″ x²) terms make it the 12-constant form. Arm 1 is the arm
of the larger (signed) frequency: the nutation (fast) arm for p ≥ 0.

Differential corrections: Levenberg-Marquardt (scipy.optimize.least_squares, MINPACK) on the
weighted residuals with the analytic Jacobian; starting values from the matrix pencil
(:mod:`cadra.motion.starts`). The covariance is ``(JᵀJ)⁻¹`` scaled by the residual
``χ²/dof`` unless told otherwise (``EpicyclicFit.covariance_scaled`` says which).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import least_squares

from cadra.motion import _checks
from cadra.motion._named import ByName
from cadra.motion.nonrolling import nonrolling_rate
from cadra.motion.starts import fft_exponents, linear_amplitudes, pencil_exponents
from cadra.stats import chi2_p_value


class MotionFitError(RuntimeError):
    """The differential corrections did not converge: there is no result to use."""


@dataclass(frozen=True)
class Layout:
    """Which constants a fit carries and where they sit in the parameter vector."""

    arms: int = 2
    curvature: bool = False        # ω̇ terms: 12-constant form
    trim: bool = False             # trim arm exp(i p u)
    free_trim_rate: bool = False   # p fitted instead of given
    offset: bool = False           # constant A_0

    @property
    def per_arm(self) -> int:
        return 5 if self.curvature else 4

    def names(self) -> tuple[str, ...]:
        out: list[str] = []
        for j in range(1, self.arms + 1):
            out += [f"A{j}_re", f"A{j}_im", f"lambda{j}", f"omega{j}"]
            if self.curvature:
                out.append(f"omega_dot{j}")
        if self.trim:
            out += ["At_re", "At_im"] + (["p"] if self.free_trim_rate else [])
        if self.offset:
            out += ["A0_re", "A0_im"]
        return tuple(out)

    def index(self, name: str) -> int:
        return self.names().index(name)


def model(layout: Layout, x: np.ndarray, u: np.ndarray, p: float | None,
          derivative: bool = False) -> np.ndarray:
    """xi(u) (or dxi/du) for the parameter vector ``x``; ``u = s - s_ref``."""
    out = np.zeros(u.shape, complex)
    k = 0
    for _ in range(layout.arms):
        A = x[k] + 1j * x[k + 1]
        lam, om = x[k + 2], x[k + 3]
        omd = x[k + 4] if layout.curvature else 0.0
        e = A * np.exp((lam + 1j * om) * u + 0.5j * omd * u * u)
        out += e * (lam + 1j * om + 1j * omd * u) if derivative else e
        k += layout.per_arm
    if layout.trim:
        At = x[k] + 1j * x[k + 1]
        pt = x[k + 2] if layout.free_trim_rate else p
        e = At * np.exp(1j * pt * u)
        out += e * 1j * pt if derivative else e
        k += 3 if layout.free_trim_rate else 2
    if layout.offset and not derivative:
        out += x[k] + 1j * x[k + 1]
    return out


def jacobian(layout: Layout, x: np.ndarray, u: np.ndarray, p: float | None) -> np.ndarray:
    """Complex ∂xi/∂x, shape (N, n_params)."""
    cols = []
    k = 0
    for _ in range(layout.arms):
        A = x[k] + 1j * x[k + 1]
        lam, om = x[k + 2], x[k + 3]
        omd = x[k + 4] if layout.curvature else 0.0
        E = np.exp((lam + 1j * om) * u + 0.5j * omd * u * u)
        AE = A * E
        cols += [E, 1j * E, u * AE, 1j * u * AE]
        if layout.curvature:
            cols.append(0.5j * u * u * AE)
        k += layout.per_arm
    if layout.trim:
        At = x[k] + 1j * x[k + 1]
        pt = x[k + 2] if layout.free_trim_rate else p
        E = np.exp(1j * pt * u)
        cols += [E, 1j * E]
        if layout.free_trim_rate:
            cols.append(1j * u * At * E)
        k += 3 if layout.free_trim_rate else 2
    if layout.offset:
        one = np.ones(u.shape, complex)
        cols += [one, 1j * one]
    return np.stack(cols, axis=1)


@dataclass(frozen=True)
class Arm:
    """One fitted arm with its sigmas: ``K exp(λ u) exp(i(φ0 + ω u + ω̇ u²/2))``."""

    K: float
    K_sigma: float
    phase: float
    phase_sigma: float
    lam: float
    lam_sigma: float
    omega: float
    omega_sigma: float
    omega_dot: float = 0.0
    omega_dot_sigma: float = 0.0


@dataclass(frozen=True)
class EpicyclicFit(ByName):
    """The result of :func:`fit_epicyclic` (a failed fit raises :class:`MotionFitError`).

    ``values``, ``sigmas``, ``covariance`` and ``correlation`` follow ``names``; sigmas are
    the square roots of the covariance's diagonal, which is ``(JᵀJ)⁻¹`` times ``chi2_dof``
    when ``covariance_scaled``. ``rms`` is the rms of |xi - xi_fit| (rad), the seed-002
    "rms angle-of-attack deviation"; ``rms_alpha``, ``rms_beta`` per component.
    """

    layout: Layout
    names: tuple[str, ...]
    values: np.ndarray
    sigmas: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    s_ref: float
    trim_rate: float | None
    variable: str
    chi2: float
    dof: int
    chi2_dof: float
    covariance_scaled: bool
    rms: float
    rms_alpha: float
    rms_beta: float
    n_points: int
    nfev: int
    nonrolling_iterations: int = 0
    nonrolling: np.ndarray | None = field(default=None, repr=False)

    @property
    def chi2_p_value(self) -> float:
        """P(chi^2 >= this chi^2) with :attr:`dof` degrees of freedom: how likely the angle
        sigmas alone leave residuals this large (NaN without degrees of freedom)."""
        return chi2_p_value(self.chi2, self.dof)

    def predict(self, s, derivative: bool = False) -> np.ndarray:
        """The fitted xi (or dxi/ds) at ``s``, in the frame the fit was made in."""
        u = np.asarray(s, float) - self.s_ref
        return model(self.layout, self.values, u, self.trim_rate, derivative)

    def arm(self, j: int) -> Arm:
        """Arm ``j`` (1 = larger signed frequency, 2; 0 = trim arm) with propagated sigmas."""
        L = self.layout
        if j == 0:
            if not L.trim:
                raise ValueError("j: this fit has no trim arm")
            k = L.arms * L.per_arm
            p = self.values[k + 2] if L.free_trim_rate else self.trim_rate
            ps = self.sigmas[k + 2] if L.free_trim_rate else 0.0
            K, Ks, ph, phs = self._polar(k)
            return Arm(K, Ks, ph, phs, 0.0, 0.0, float(p), float(ps))
        if not 1 <= j <= L.arms:
            raise ValueError(f"j: arm {j} not in 1..{L.arms}")
        k = (j - 1) * L.per_arm
        K, Ks, ph, phs = self._polar(k)
        v, sg = self.values, self.sigmas
        od, ods = (v[k + 4], sg[k + 4]) if L.curvature else (0.0, 0.0)
        return Arm(K, Ks, ph, phs, float(v[k + 2]), float(sg[k + 2]), float(v[k + 3]),
                   float(sg[k + 3]), float(od), float(ods))

    def _polar(self, k: int) -> tuple[float, float, float, float]:
        re, im = self.values[k], self.values[k + 1]
        C = self.covariance[k:k + 2, k:k + 2]
        K = float(np.hypot(re, im))
        if K == 0.0:
            return 0.0, float(np.sqrt(C[0, 0])), 0.0, float("inf")
        gK = np.array([re, im]) / K
        gp = np.array([-im, re]) / K**2
        ph = float(np.arctan2(im, re))
        return K, float(np.sqrt(gK @ C @ gK)), ph, float(np.sqrt(gp @ C @ gp))


def _starts(layout: Layout, s: np.ndarray, xi: np.ndarray, s_ref: float,
            p: float | None) -> list[np.ndarray]:
    """The matrix-pencil start, and the FFT-peak start too when their arm frequencies differ
    by more than a quarter cycle over the record (short or unevenly sampled records)."""
    n_exp = layout.arms + int(layout.trim) + int(layout.offset)
    a = _start(layout, s, xi, s_ref, p, pencil_exponents(s, xi, n_exp))
    b = _start(layout, s, xi, s_ref, p, fft_exponents(s, xi, n_exp))
    m = layout.per_arm
    idx = [j * m + 3 for j in range(layout.arms)]
    if np.all(np.abs(a[idx] - b[idx]) < 0.5 * np.pi / (s[-1] - s[0])):
        return [a]
    return [a, b]


def _start(layout: Layout, s: np.ndarray, xi: np.ndarray, s_ref: float,
           p: float | None, exponents: np.ndarray) -> np.ndarray:
    r = list(exponents)
    amp = list(np.abs(linear_amplitudes(s, xi, np.asarray(r), s_ref)))
    near = 2 * np.pi / (s[-1] - s[0])      # one cycle over the record

    def drop(target):   # the pole of a known exponent, or the weakest one if none is near it
        k = int(np.argmin([abs(z - target) for z in r]))
        if abs(r[k] - target) > max(near, 0.1 * abs(target)):
            k = int(np.argmin(amp))
        r.pop(k)
        amp.pop(k)

    if layout.trim:
        drop(1j * p)
    if layout.offset:
        drop(0.0)
    arms = sorted(r, key=lambda z: -z.imag)[: layout.arms]
    exps = list(arms)
    if layout.trim:
        exps.append(1j * p)
    if layout.offset:
        exps.append(0.0)
    c = linear_amplitudes(s, xi, np.asarray(exps, complex), s_ref)
    x: list[float] = []
    for j, z in enumerate(arms):
        x += [c[j].real, c[j].imag, z.real, z.imag] + ([0.0] if layout.curvature else [])
    k = layout.arms
    if layout.trim:
        x += [c[k].real, c[k].imag] + ([p] if layout.free_trim_rate else [])
        k += 1
    if layout.offset:
        x += [c[k].real, c[k].imag]
    return np.asarray(x, float)


def covariance(J: np.ndarray, rcond: float = 1e-10) -> np.ndarray:
    """(JᵀJ)⁻¹ from the SVD of J; a parameter with a part in a direction the data do not
    determine (singular value below ``rcond`` times the largest) gets an infinite variance
    and NaN covariances, so it cannot pass for a measured one."""
    _, sv, vt = np.linalg.svd(J, full_matrices=False)
    keep = sv > rcond * sv[0]
    cov = (vt[keep].T / sv[keep] ** 2) @ vt[keep]
    if not np.all(keep):
        bad = np.any(np.abs(vt[~keep]) > 1e-6, axis=0)
        cov[bad, :] = np.nan
        cov[:, bad] = np.nan
        cov[bad, bad] = np.inf
    return cov


def _solve(layout, s, xi, w_b, w_a, s_ref, p, x0, scale_covariance, variable):
    u = s - s_ref
    n = s.size

    def resid(x):
        d = model(layout, x, u, p) - xi
        return np.concatenate([d.real * w_b, d.imag * w_a])

    def jac(x):
        J = jacobian(layout, x, u, p)
        return np.concatenate([J.real * w_b[:, None], J.imag * w_a[:, None]])

    res = least_squares(resid, x0, jac=jac, method="lm", x_scale="jac",
                        xtol=1e-13, ftol=1e-13, gtol=1e-13, max_nfev=200 * (x0.size + 1))
    if res.status <= 0 or not np.all(np.isfinite(res.x)):
        raise MotionFitError(f"epicyclic fit did not converge: {res.message}")
    J = res.jac
    xs = res.x
    if layout.arms == 2 and xs[layout.per_arm + 3] > xs[3]:   # arm 1: the larger ω
        m = layout.per_arm
        perm = np.r_[np.arange(m, 2 * m), np.arange(m), np.arange(2 * m, xs.size)]
        xs, J = xs[perm], J[:, perm]
    dof = 2 * n - x0.size
    chi2 = float(res.fun @ res.fun)
    chi2_dof = chi2 / dof if dof > 0 else float("nan")
    cov = covariance(J)
    if scale_covariance and dof > 0:
        cov = cov * chi2_dof
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sig, sig)
    d = model(layout, xs, u, p) - xi
    return dict(values=xs, sigmas=sig, covariance=cov, correlation=corr, s_ref=s_ref,
                trim_rate=p, variable=variable, chi2=chi2, dof=dof, chi2_dof=chi2_dof,
                covariance_scaled=bool(scale_covariance), rms=float(np.sqrt(np.mean(np.abs(d)**2))),
                rms_alpha=float(np.sqrt(np.mean(d.imag**2))),
                rms_beta=float(np.sqrt(np.mean(d.real**2))), n_points=n, nfev=int(res.nfev))


def _best(layout, s, xi, w_b, w_a, s_ref, p, starts, scale_covariance, variable):
    """The converged fit of lowest χ² over the starts (MotionFitError if none converges)."""
    best, err = None, None
    for x0 in starts:
        try:
            out = _solve(layout, s, xi, w_b, w_a, s_ref, p, x0, scale_covariance, variable)
        except MotionFitError as e:
            err = e
            continue
        if best is None or out["chi2"] < best["chi2"]:
            best = out
    if best is None:
        raise err
    return best


def fit_epicyclic(s, alpha, beta, sigma_alpha=None, sigma_beta=None, *, arms: int = 2,
                  trim_rate: float | None = None, free_trim_rate: bool = False,
                  offset: bool = False, curvature: bool = False, nonrolling: bool = False,
                  nonrolling_iterations: int = 1, variable: str = "time",
                  s_ref: float | None = None, start: EpicyclicFit | None = None,
                  scale_covariance: bool = True, exponents=None) -> EpicyclicFit:
    """Fit the epicyclic (``trim_rate=None``) or tricyclic model to an angle history.

    Parameters
    ----------
    s : (N,) time (s) or distance (m), strictly increasing; ``variable`` says which
    alpha, beta : (N,) angles (rad): alpha + nose up, beta + nose to port of the wind
        (fixed-plane angles when ``nonrolling``; see :func:`cadra.motion.fixed_plane_angles`)
    sigma_alpha, sigma_beta : None (unit weights), scalar or (N,) sigmas (rad)
    arms : 1 (circular motion) or 2
    trim_rate : the trim arm's rate p (rad per unit of s), e.g. the measured spin; None: no
        trim arm. Two arms + trim arm = seed 002's 10-constant form.
    free_trim_rate : fit p too (started at ``trim_rate``)
    offset : add a constant complex angle (seed 001's K_4, a fixed trim)
    curvature : add ω̇_j (12-constant form, seed 002 eq. 12)
    nonrolling : apply seed 002's nonrolling-axis correction (eq. 8), refitting
        ``nonrolling_iterations`` times (the seed: one iteration is generally enough)
    s_ref : where the amplitudes are referred (default: the first point)
    start : an earlier fit to start from (re-referred to ``s_ref``); default: automatic
    exponents : the arms' starting exponents λ_j + iω_j (one per arm; e.g. gyroscopic
        theory's frequencies, which an aliased record's automatic start cannot find), the
        amplitudes then by linear least squares; default: automatic
    scale_covariance : scale the covariance by χ²/dof (default; stated in the result)
    """
    if arms not in (1, 2):
        raise ValueError(f"arms: must be 1 or 2, got {arms!r}")
    if variable not in ("time", "distance"):
        raise ValueError(f"variable: 'time' or 'distance', got {variable!r}")
    if nonrolling and (int(nonrolling_iterations) != nonrolling_iterations
                       or nonrolling_iterations < 1):
        raise ValueError(f"nonrolling_iterations: a positive integer, got "
                         f"{nonrolling_iterations!r}")
    if trim_rate is None and free_trim_rate:
        raise ValueError("free_trim_rate: needs a trim_rate to start from")
    if exponents is not None and (trim_rate is not None or offset or len(exponents) != arms):
        raise ValueError("exponents: one per arm, for a form without a trim arm or offset")
    layout = Layout(arms=arms, curvature=curvature, trim=trim_rate is not None,
                    free_trim_rate=free_trim_rate, offset=offset)
    n_par = len(layout.names())
    s = _checks.abscissa("s", s, min_points=max(n_par // 2 + 2, 6))
    a = _checks.series("alpha", alpha, s.size)
    b = _checks.series("beta", beta, s.size)
    w_a = 1.0 / _checks.sigmas("sigma_alpha", sigma_alpha, s.size)
    w_b = 1.0 / _checks.sigmas("sigma_beta", sigma_beta, s.size)
    if trim_rate is not None and not np.isfinite(trim_rate):
        raise ValueError(f"trim_rate: must be finite, got {trim_rate!r}")
    s_ref = float(s[0]) if s_ref is None else float(s_ref)
    p = None if trim_rate is None else float(trim_rate)
    xi = b + 1j * a
    if start is not None:
        if start.layout != layout:
            raise ValueError("start: its layout (arms, trim, offset, curvature) differs")
        x0 = rereferred(start, s_ref)
    elif curvature:   # the 10-constant fit first, then the ω̇ terms from zero
        flat = Layout(arms=arms, trim=layout.trim, free_trim_rate=free_trim_rate, offset=offset)
        if exponents is not None:
            xf = _solve(flat, s, xi, w_b, w_a, s_ref, p,
                        _start(flat, s, xi, s_ref, p, np.asarray(exponents, dtype=complex)),
                        False, variable)["values"]
        else:
            xf = _best(flat, s, xi, w_b, w_a, s_ref, p, _starts(flat, s, xi, s_ref, p), False,
                       variable)["values"]
        m = flat.per_arm
        x0 = np.concatenate([np.r_[xf[j * m:(j + 1) * m], 0.0] for j in range(arms)]
                            + [xf[arms * m:]])
    else:
        x0 = None
    if x0 is None and exponents is not None:
        x0 = _start(layout, s, xi, s_ref, p, np.asarray(exponents, dtype=complex))
    if x0 is None:
        out = _best(layout, s, xi, w_b, w_a, s_ref, p, _starts(layout, s, xi, s_ref, p),
                    scale_covariance, variable)
    else:
        out = _solve(layout, s, xi, w_b, w_a, s_ref, p, x0, scale_covariance, variable)
    fit = EpicyclicFit(layout=layout, names=layout.names(), **out)
    if not nonrolling:
        return fit
    zeta_f = np.sin(b) + 1j * np.sin(a)
    fine = np.linspace(s[0], s[-1], 16 * (s.size - 1) + 1)
    x_f, dx_f = fit.predict(fine), fit.predict(fine, derivative=True)
    for it in range(1, nonrolling_iterations + 1):
        rate = nonrolling_rate(x_f, dx_f)
        phi_fine = cumulative_trapezoid(rate, fine, initial=0.0)
        phi = np.interp(s, fine, phi_fine)
        z = zeta_f * np.exp(1j * phi)
        xi_nr = np.arcsin(np.clip(z.real, -1, 1)) + 1j * np.arcsin(np.clip(z.imag, -1, 1))
        out = _solve(layout, s, xi_nr, w_b, w_a, s_ref, p, fit.values, scale_covariance,
                     variable)
        fit = EpicyclicFit(layout=layout, names=layout.names(), nonrolling_iterations=it,
                           nonrolling=phi, **out)
        # the next iteration's fixed-plane history: this fit rotated back by phi_hat
        rot = np.exp(-1j * phi_fine)
        x_nr = fit.predict(fine)
        x_f = rot * x_nr
        dx_f = rot * (fit.predict(fine, derivative=True) - 1j * rate * x_nr)
    return fit


def rereferred(fit: EpicyclicFit, s_ref: float) -> np.ndarray:
    """``fit``'s parameter vector with the amplitudes referred to ``s_ref`` instead."""
    L, x = fit.layout, fit.values.copy()
    du = s_ref - fit.s_ref
    k = 0
    for _ in range(L.arms):
        A = (x[k] + 1j * x[k + 1])
        omd = x[k + 4] if L.curvature else 0.0
        A = A * np.exp((x[k + 2] + 1j * x[k + 3]) * du + 0.5j * omd * du * du)
        x[k], x[k + 1] = A.real, A.imag
        if L.curvature:
            x[k + 3] += omd * du
        k += L.per_arm
    if L.trim:
        pt = x[k + 2] if L.free_trim_rate else fit.trim_rate
        A = (x[k] + 1j * x[k + 1]) * np.exp(1j * pt * du)
        x[k], x[k + 1] = A.real, A.imag
    return x
