"""Pure roll about a roll lock-in trim (seed 001 eqs. 27-31, Table IV): fits of the roll
orientation history and the roll coefficients from them (docs/pureroll.md).

Model (seed 001 eq. 27; γ the roll orientation against the plane of the angle of attack, rad;
time t, s; constant α, q∞ and V; no fin cant)::

    γ̈ − (a_0 + a_2 (γ − π/4)²) γ̇ − A sin 4γ = 0,
    a_0 = L_p0/I_x = (q∞Sd/I_x)(d/2V) C_lp0   (1/s),
    a_2 = L_p2/I_x = (q∞Sd/I_x)(d/2V) C_lp2   (1/(s rad²)),
    A   = L(α)/I_x = (q∞Sd/I_x) C_l(α)         (1/s²).

About the trim γ_T = π/4 (A > 0), x = γ − π/4 obeys ``ẍ + A sin 4x = (a_0 + a_2x²)ẋ``: a
pendulum in 4x of small-amplitude frequency ω_0 = 2√A, slowly damped. Two first-order
averagings of it (the seed's Kryloff-Bogoliuboff approximation, eqs. 28-30, garbled in the
OCR text and derived in docs/pureroll.md):

``"pendulum"`` (exact averaging over the undamped pendulum orbit of peak amplitude K)
    ω(K) = π√A / 𝐊(m), m = sin²2K (𝐊 the complete elliptic integral);
    sin 4K dK/dt = (√2/𝐊(m)) ∫₀^K (a_0 + a_2x²) √(cos 4x − cos 4K) dx  (energy balance);
    the orbit x = ½ arcsin(sin 2K cd(2𝐊ψ/π | m)), whose fundamental is 2√q/(1+q), q the nome.
``"harmonic"`` (the seed's first approximation, γ − π/4 = K cos ψ with K the fundamental)
    ω² = 2A J_1(4K)/K;  dK/dt = K(a_0/2 + a_2K²/8) (seed eq. 30) less K ω̇/(2ω), the
    frequency-variation amplitude correction (the action πωK² is what the damping changes).

Fits: :func:`mdc_fit` is the method of differential corrections (Levenberg-Marquardt by
``scipy.optimize.least_squares``) of the whole record: ``γ(t) = γ_T + x(ψ(t), K(t))`` with
K(t), ψ(t) integrated from the averaged equations above; its parameters are γ_T, K(t_0),
ψ(t_0), A, a_0, a_2 themselves, so :func:`pure_roll_coefficients` only scales them. Its
starting values come from :func:`section_estimates` (sectional 1-DOF fits, ``fit_pitch``,
reduced section by section by the same two averagings). Limit cycle: :func:`limit_cycle_
amplitude_eq31` (seed eq. 31) and :func:`energy_balance_amplitude` (the exact averaged one).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq, least_squares
from scipy.special import ellipj, ellipk, j1, jvp

from cadra.motion import _checks
from cadra.motion._named import ByName
from cadra.motion.epicyclic import MotionFitError, covariance
from cadra.motion.pitch import fit_pitch
from cadra.motion.sectional import Sections, sectional_pitch

MODELS = ("pendulum", "harmonic")
NAMES = ("gamma_T", "K0", "psi0", "A", "a0", "a2")
#: largest peak amplitude about the trim the averaged equations are used at (rad): the
#: pendulum's separatrix is at 45 deg, where the period grows without bound
K_MAX = np.pi / 4 - 0.01

_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)
_PHI = 0.25 * np.pi * (_GL_X + 1.0)     # nodes on (0, pi/2)
_PHI_W = 0.25 * np.pi * _GL_W


# ----------------------------------------------------------------------------------------
# the undamped pendulum sin 4x and the averaged damping

def _m(K):
    return np.sin(2.0 * np.asarray(K, float)) ** 2


def pendulum_frequency(K, A):
    """Frequency (rad/s) of ``ẍ + A sin 4x = 0`` at peak amplitude ``K`` (rad), A in 1/s²:
    ``π√A / 𝐊(sin²2K)`` (2√A at K → 0)."""
    return np.pi * np.sqrt(A) / ellipk(_m(K))


def nome(K):
    """The nome q = exp(−π𝐊'/𝐊) of the pendulum of peak amplitude ``K`` (rad)."""
    m = _m(K)
    return np.exp(-np.pi * ellipk(1.0 - m) / ellipk(m))


def pendulum_fundamental(K):
    """Amplitude (rad) of the fundamental of the pendulum orbit of peak amplitude ``K``
    (rad) about the trim: ``2√q/(1+q)`` (K at K → 0), from θ = 4x = 8 Σ q^{n+½}/((2n+1)
    (1+q^{2n+1})) sin((2n+1)v)."""
    q = nome(K)
    return 2.0 * np.sqrt(q) / (1.0 + q)


def pendulum_third_harmonic_ratio(K):
    """The orbit's third harmonic over its fundamental (cosine form, peak at ψ = 0):
    ``−q(1+q)/(3(1+q³))`` (the softening sin 4x flattens the peaks)."""
    q = nome(K)
    return -q * (1.0 + q) / (3.0 * (1.0 + q**3))


def peak_from_fundamental(b1: float) -> float:
    """The peak amplitude K (rad) whose orbit has fundamental ``b1`` (rad)."""
    b1 = float(b1)
    top = float(pendulum_fundamental(K_MAX))
    if not (0.0 < b1 < top):
        raise ValueError(f"fundamental amplitude {np.degrees(b1):.4g} deg: outside (0, "
                         f"{np.degrees(top):.4g}) deg, the pendulum's range up to "
                         f"{np.degrees(K_MAX):.4g} deg")
    return brentq(lambda K: float(pendulum_fundamental(K)) - b1, 1e-9, K_MAX, xtol=1e-15,
                  rtol=1e-15)


def pendulum_orbit(psi, K):
    """x(ψ) (rad) on the orbit of peak amplitude ``K``: ``½ arcsin(sin 2K cd(2𝐊ψ/π | m))``,
    ψ the phase (rad, 2π per cycle, peak at ψ = 0)."""
    K = np.asarray(K, float)
    m = _m(K)
    u = 2.0 * ellipk(m) * np.asarray(psi, float) / np.pi
    sn, cn, dn, _ = ellipj(u, m)
    return 0.5 * np.arcsin(np.clip(np.sin(2.0 * K) * cn / dn, -1.0, 1.0))


def damping_integrals(K) -> tuple[np.ndarray, np.ndarray]:
    """(G_0, G_2) (1, rad²) with ``dK/dt = a_0 G_0(K) + a_2 G_2(K)`` for the peak amplitude
    ``K`` (rad, 0 < K < π/4) of the damped pendulum, to first order in the damping (the
    energy balance over one undamped orbit; module docstring). G_0 → K/2, G_2 → K³/8 as
    K → 0 (seed eq. 30)."""
    K = np.atleast_1d(np.asarray(K, float))
    if np.any(~np.isfinite(K)) or np.any(K <= 0) or np.any(K >= np.pi / 4):
        raise ValueError("K: peak amplitudes must lie in (0, pi/4) rad")
    x = K[:, None] * np.sin(_PHI)[None, :]
    root = np.sqrt(np.clip(np.cos(4 * x) - np.cos(4 * K)[:, None], 0.0, None))
    wdx = K[:, None] * np.cos(_PHI)[None, :] * _PHI_W[None, :]
    i0 = np.sum(root * wdx, axis=1)
    i2 = np.sum(x * x * root * wdx, axis=1)
    f = np.sqrt(2.0) / (ellipk(_m(K)) * np.sin(4 * K))
    return f * i0, f * i2


@lru_cache(maxsize=1)
def _tables():
    """Splines of G_0/K, G_2/K³ and 𝐊(sin²2K) on (0, K_MAX] (fast ODE right-hand sides)."""
    K = np.linspace(1e-4, K_MAX, 600)
    g0, g2 = damping_integrals(K)
    return (CubicSpline(K, g0 / K), CubicSpline(K, g2 / K**3),
            CubicSpline(K, ellipk(_m(K))))


# ----------------------------------------------------------------------------------------
# limit cycles (seed eq. 31 and the exact averaged balance)

def limit_cycle_amplitude_eq31(Clp0: float, Clp2: float) -> float:
    """Seed 001 eq. 31: ``K = 2√(−C_lp0/C_lp2)`` (rad) where ``dK/dt = K(a_0/2 + a_2K²/8)``
    vanishes. Needs C_lp0 and C_lp2 of opposite signs."""
    Clp0, Clp2 = float(Clp0), float(Clp2)
    if not (np.isfinite(Clp0) and np.isfinite(Clp2)) or Clp0 * Clp2 >= 0:
        raise ValueError(f"Clp0, Clp2: need finite values of opposite signs, got {Clp0}, "
                         f"{Clp2}")
    return 2.0 * np.sqrt(-Clp0 / Clp2)


def energy_balance_amplitude(Clp0: float, Clp2: float) -> float | None:
    """The peak amplitude (rad) about the trim at which the damping's work over one undamped
    pendulum orbit vanishes: the root in (0, K_MAX) of ``C_lp0 G_0 + C_lp2 G_2``; None when
    there is none (the averaged motion then decays, or grows, at every amplitude below the
    separatrix). The pendulum orbit is exact: Eq. 31 is its small-amplitude limit."""
    Clp0, Clp2 = float(Clp0), float(Clp2)
    if not (np.isfinite(Clp0) and np.isfinite(Clp2)):
        raise ValueError("Clp0, Clp2: must be finite")
    grid = np.linspace(1e-3, K_MAX, 400)
    g0, g2 = damping_integrals(grid)
    w = (Clp0 * g0 + Clp2 * g2) / grid
    k = np.flatnonzero(np.sign(w[:-1]) * np.sign(w[1:]) < 0)
    if k.size == 0:
        return None

    def f(K):
        a, b = damping_integrals(K)
        return float(Clp0 * a[0] + Clp2 * b[0])

    return brentq(f, grid[k[0]], grid[k[0] + 1], xtol=1e-13)


# ----------------------------------------------------------------------------------------
# results

@dataclass(frozen=True)
class RollCoefficients:
    """C_lp0, C_lp2 (per rad of γ̇d/2V; C_lp2 per rad² of (γ − π/4)) and the induced roll
    amplitude C_l(α), with sigmas (NaN when not estimated), the averaging (``model``) and
    where they came from (``source``: ``"sections"`` or ``"mdc"``)."""

    Clp0: float
    Clp0_sigma: float
    Clp2: float
    Clp2_sigma: float
    Cl_alpha: float
    Cl_alpha_sigma: float
    model: str
    source: str

    def errors_pct(self, Clp0: float, Clp2: float, Cl_alpha: float) -> dict[str, float]:
        """|output − input| / |input| in percent, seed 001 Table IV's error."""
        return {k: float(abs(getattr(self, k) - v) / abs(v) * 100.0)
                for k, v in (("Clp0", Clp0), ("Clp2", Clp2), ("Cl_alpha", Cl_alpha))}


@dataclass(frozen=True)
class SectionEstimates:
    """Eq. 27's constants from sectional 1-DOF fits: ``A`` (1/s²), ``a0`` (1/s), ``a2``
    (1/(s rad²)) with sigmas, the sections' peak amplitudes ``K`` (rad) and the sections."""

    A: float
    A_sigma: float
    a0: float
    a0_sigma: float
    a2: float
    a2_sigma: float
    K: np.ndarray
    model: str
    sections: Sections


@dataclass(frozen=True)
class RollFit(ByName):
    """Result of :func:`mdc_fit`; ``values``/``sigmas``/``covariance`` follow ``NAMES``:
    γ_T (rad), K0 the amplitude at ``t0`` (rad; the peak for ``"pendulum"``, the fundamental
    for ``"harmonic"``), ψ0 the phase at ``t0`` (rad), A (1/s²), a0 (1/s), a2 (1/(s rad²))."""

    values: np.ndarray
    sigmas: np.ndarray
    covariance: np.ndarray
    model: str
    frequency_correction: bool
    t0: float
    chi2: float
    dof: int
    chi2_dof: float
    rms: float
    n_points: int
    nfev: int

    names = NAMES

    def amplitude(self, t) -> np.ndarray:
        """K(t) (rad) of the fitted averaged motion at times ``t`` (s, increasing, ≥ t0)."""
        return _slow(self.values, self.model, self.frequency_correction, self.t0,
                     self._times(t))[0]

    def predict(self, t) -> np.ndarray:
        """γ(t) (rad) of the fitted model at times ``t`` (s, increasing, ≥ t0)."""
        return _model(self.values, self.model, self.frequency_correction, self.t0,
                      self._times(t))

    def _times(self, t) -> np.ndarray:
        t = _checks.abscissa("t", np.atleast_1d(t), min_points=1)
        if t[0] < self.t0:
            raise ValueError(f"t: the fit starts at t0 = {self.t0} s, got {t[0]} s")
        return t


# ----------------------------------------------------------------------------------------
# the averaged equations and the whole-record model

def _check_model(model):
    if model not in MODELS:
        raise ValueError(f"model: one of {MODELS}, got {model!r}")


def _rates(K, A, a0, a2, model, fc):
    """dK/dt and dψ/dt of the averaged motion at amplitude K."""
    if not (0.0 < K < K_MAX):
        raise MotionFitError(f"amplitude {np.degrees(K):.4g} deg left (0, "
                             f"{np.degrees(K_MAX):.4g}) deg")
    if model == "pendulum":
        g0, g2, kk = _tables()
        return K * (a0 * g0(K) + a2 * K * K * g2(K)), np.pi * np.sqrt(A) / kk(K)
    z = 4.0 * K
    w2 = 2.0 * A * j1(z) / K
    dk = K * (0.5 * a0 + 0.125 * a2 * K * K)
    if fc:   # K ω'(K)/ω = ½ d ln ω²/d ln K = ½ (z J1'(z)/J1(z) − 1)
        dk /= 1.0 + 0.25 * (z * jvp(1, z) / j1(z) - 1.0)
    return dk, np.sqrt(w2)


def _slow(x, model, fc, t0, t):
    """K(t), ψ(t) (t ≥ t0, increasing) from the averaged equations, integrated from t0."""
    _, K0, psi0, A, a0, a2 = x
    if A <= 0:
        raise MotionFitError("A = L(alpha)/Ix must stay positive (a trim at pi/4)")

    def rhs(_t, s):
        return _rates(s[0], A, a0, a2, model, fc)

    if t[-1] <= t0:
        return np.full(t.size, K0), np.full(t.size, psi0)
    sol = solve_ivp(rhs, (t0, t[-1]), [K0, psi0], t_eval=t, method="DOP853", rtol=1e-11,
                    atol=1e-13)
    if not sol.success:
        raise MotionFitError(f"averaged equations: {sol.message}")
    return sol.y[0], sol.y[1]


def _model(x, model, fc, t0, t):
    K, psi = _slow(x, model, fc, t0, t)
    if model == "pendulum":
        return x[0] + pendulum_orbit(psi, K)
    return x[0] + K * np.cos(psi)


# ----------------------------------------------------------------------------------------
# sectional estimates (starting values, and the sections' own reduction)

def _wls(cols, y, sig):
    """Weighted least squares ``y ≈ cols @ c``; sigmas scaled by the residual χ²/dof."""
    sig = np.maximum(sig, 1e-12 * np.max(np.abs(sig)) + 1e-300)
    Aw, yw = cols / sig[:, None], y / sig
    sol, *_ = np.linalg.lstsq(Aw, yw, rcond=None)
    r = Aw @ sol - yw
    dof = max(cols.shape[0] - cols.shape[1], 1)
    cov = covariance(Aw) * max(float(r @ r) / dof, 1e-300)
    return sol, np.sqrt(np.clip(np.diag(cov), 0, None))


def _period_points(t, gamma) -> float:
    """Points per cycle, from the crossings of the record's mean."""
    d = gamma - 0.5 * (gamma.max() + gamma.min())
    cross = np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)
    if cross.size < 9:
        raise ValueError(f"gamma: {cross.size // 2} cycles about the mean, at least 4 are "
                         "needed (record too short, or no oscillation)")
    return 2.0 * float(np.mean(np.diff(cross)))


def section_estimates(t, gamma, sigma=None, *, window: int | None = None,
                      step: int | None = None, model: str = "pendulum",
                      frequency_correction: bool = True) -> SectionEstimates:
    """A, a_0, a_2 from overlapping 1-DOF fits (``sectional_pitch``: γ_T + b_1 e^{λu}
    cos(ωu + δ) per window of ``window`` points every ``step``; default about three cycles
    every 1.5), reduced section by section:

    ``"pendulum"``: K from b_1 (:func:`peak_from_fundamental`), A = (ω𝐊(m)/π)², and
    ``b_1λ/(db_1/dK) = a_0G_0(K) + a_2G_2(K)`` over the sections (weighted least squares);
    ``"harmonic"``: K = b_1, A = ω²K/(2J_1(4K)), ``λ + ω̇/(2ω) = a_0/2 + a_2K²/8`` (ω̇ by
    differences between sections; without it when ``frequency_correction`` is False).

    The sigma of A is from ω's alone; those of a_0, a_2 are scaled by the residual χ²/dof.
    """
    _check_model(model)
    t = _checks.abscissa("t", t, min_points=40)
    g = _checks.series("gamma", gamma, t.size)
    sig = _checks.sigmas("sigma", sigma, t.size)
    per = _period_points(t, g)
    window = int(round(3 * per)) if window is None else window
    step = max(1, int(round(1.5 * per))) if step is None else step
    sec = sectional_pitch(t, g, sig, window=window, step=step, trim=True)
    if sec.centre.size < 3:
        raise ValueError(f"gamma: {sec.centre.size} sections of {window} points, at least 3 "
                         "are needed (record too short)")
    b1, lam, om = sec.K[:, 0], sec.lam[:, 0], sec.omega[:, 0]
    lam_s, om_s = sec.lam_sigma[:, 0], sec.omega_sigma[:, 0]
    if model == "pendulum":
        K = np.array([peak_from_fundamental(b) for b in b1])
        A_i = (om * ellipk(_m(K)) / np.pi) ** 2
        h = 1e-6
        db = (pendulum_fundamental(K + h) - pendulum_fundamental(K - h)) / (2 * h)
        y, sy = b1 * lam / db, b1 * lam_s / db
        cols = np.stack(damping_integrals(K), 1)
    else:
        K = b1
        A_i = om**2 * K / (2.0 * j1(4.0 * K))
        wd = np.gradient(om, sec.centre) if frequency_correction else np.zeros_like(om)
        y, sy = lam + wd / (2.0 * om), lam_s
        cols = np.stack([np.full_like(K, 0.5), K**2 / 8.0], 1)
    (A,), (sA,) = _wls(np.ones((K.size, 1)), A_i, 2.0 * A_i * om_s / om)
    (a0, a2), (s0, s2) = _wls(cols, y, sy)
    return SectionEstimates(A=float(A), A_sigma=float(sA), a0=float(a0), a0_sigma=float(s0),
                            a2=float(a2), a2_sigma=float(s2), K=K, model=model, sections=sec)


# ----------------------------------------------------------------------------------------
# the method of differential corrections on the whole record

def mdc_fit(t, gamma, sigma=None, *, model: str = "pendulum", frequency_correction: bool = True,
            start: SectionEstimates | None = None, scale_covariance: bool = True) -> RollFit:
    """Fit ``γ(t) = γ_T + x(ψ(t), K(t))`` to a whole roll-orientation record (module
    docstring: K and ψ from the averaged eq. 27 of ``model``, x the pendulum orbit or
    K cos ψ) by differential corrections: Levenberg-Marquardt (``least_squares``, MINPACK,
    forward-difference Jacobian) on the residuals over ``sigma``.

    Parameters
    ----------
    t : (N,) time (s), strictly increasing; t[0] is the reference of K0 and ψ0
    gamma : (N,) roll orientation γ (rad), unwrapped, oscillating about the π/4 trim
    sigma : None (unit weights), scalar or (N,) (rad)
    model : "pendulum" or "harmonic"
    frequency_correction : "harmonic" only: the amplitude correction for the frequency
        variation (module docstring)
    start : section estimates to start from (default: :func:`section_estimates`)
    scale_covariance : scale the covariance by χ²/dof (stated in the result)

    Raises ValueError on a bad record (too short, non-finite, < 4 cycles) and MotionFitError
    when the corrections do not converge.
    """
    _check_model(model)
    t = _checks.abscissa("t", t, min_points=40)
    g = _checks.series("gamma", gamma, t.size)
    w = 1.0 / _checks.sigmas("sigma", sigma, t.size)
    if start is None:
        start = section_estimates(t, g, 1.0 / w, model=model,
                                  frequency_correction=frequency_correction)
    elif start.model != model:
        raise ValueError(f"start: estimates of model {start.model!r}, fitting {model!r}")
    first = _first_section(t, g, w, start.sections.window)
    b1 = first.K
    K0 = peak_from_fundamental(b1) if model == "pendulum" else b1
    x0 = np.array([first.value("alpha_T"), K0, first.delta, start.A, start.a0, start.a2])
    fc = bool(frequency_correction) and model == "harmonic"
    t0 = float(t[0])

    def resid(x):
        try:
            return (_model(x, model, fc, t0, t) - g) * w
        except MotionFitError:
            return np.full(t.size, 1e3) * w

    res = least_squares(resid, x0, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12,
                        gtol=1e-12, max_nfev=400)
    if res.status <= 0 or not np.all(np.isfinite(res.x)):
        raise MotionFitError(f"roll MDC fit did not converge: {res.message}")
    x = res.x.copy()
    x[2] = np.mod(x[2] + np.pi, 2 * np.pi) - np.pi
    dof = t.size - x.size
    chi2 = float(res.fun @ res.fun)
    chi2_dof = chi2 / dof
    cov = covariance(res.jac)
    if scale_covariance:
        cov = cov * chi2_dof
    d = _model(x, model, fc, t0, t) - g
    return RollFit(values=x, sigmas=np.sqrt(np.clip(np.diag(cov), 0, None)), covariance=cov,
                   model=model, frequency_correction=fc, t0=t0, chi2=chi2, dof=dof,
                   chi2_dof=chi2_dof, rms=float(np.sqrt(np.mean(d * d))), n_points=t.size,
                   nfev=int(res.nfev))


def _first_section(t, g, w, window):
    return fit_pitch(t[:window], g[:window], 1.0 / w[:window], trim=True, s_ref=t[0])


# ----------------------------------------------------------------------------------------
# coefficients

def pure_roll_coefficients(source: RollFit | SectionEstimates, *, Ix: float, q: float,
                           S: float, d: float, V: float) -> RollCoefficients:
    """C_lp0, C_lp2, C_l(α) from a whole-record fit or section estimates, given the roll
    inertia ``Ix`` (kg m²), dynamic pressure ``q`` (Pa), reference area ``S`` (m²) and
    length ``d`` (m) and the speed ``V`` (m/s): ``C_l(α) = A I_x/(q S d)``, ``C_lp0 =
    a_0 I_x/(q S d · d/2V)``, ``C_lp2 = a_2 I_x/(q S d · d/2V)`` (module docstring)."""
    Ix, q, S, d, V = (_checks.positive(n, v) for n, v in
                      (("Ix", Ix), ("q", q), ("S", S), ("d", d), ("V", V)))
    s_m = Ix / (q * S * d)
    s_d = s_m * 2.0 * V / d
    if isinstance(source, RollFit):
        v = {n: (source.value(n), source.sigma(n)) for n in ("A", "a0", "a2")}
        src = "mdc"
    elif isinstance(source, SectionEstimates):
        v = {"A": (source.A, source.A_sigma), "a0": (source.a0, source.a0_sigma),
             "a2": (source.a2, source.a2_sigma)}
        src = "sections"
    else:
        raise ValueError(f"source: a RollFit or SectionEstimates, got {type(source).__name__}")
    return RollCoefficients(
        Clp0=v["a0"][0] * s_d, Clp0_sigma=v["a0"][1] * s_d, Clp2=v["a2"][0] * s_d,
        Clp2_sigma=v["a2"][1] * s_d, Cl_alpha=v["A"][0] * s_m, Cl_alpha_sigma=v["A"][1] * s_m,
        model=source.model, source=src)
