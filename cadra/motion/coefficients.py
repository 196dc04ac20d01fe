"""Linear-theory coefficients from fitted arms, the lift slope from the swerve, and the cg
transfer of moment coefficients.

Equation of the angular motion (seed 000 eq. 2, seed 001 eq. 32, in time t, constant V and p,
``xi = beta + i alpha``, docs/motion.md):

    ξ̈ − (iP + D − a) ξ̇ − (M + iT + iPa) ξ = 0,
    P = p I_x/I,  D = (M_q + M_α̇)/I,  M = M_α/I,  T = p M_pα/I,  a = ρ S V C_Lα/(2m),

with ``M_α = C_mα q∞ S d``, ``M_q + M_α̇ = (C_mq + C_mα̇) q∞ S d²/(2V)``,
``M_pα = C_mpα q∞ S d²/(2V)`` and ``a`` the flight-path turning by lift (0 on a gimbal or
pivot: give no lift slope). Its roots ``r_j = λ_j + iω_j`` are the arms' exponents, so exactly

    ω_1 + ω_2 = P,   λ_1 + λ_2 = D − a,   r_1 r_2 = −(M + iT + iPa),

i.e. ``C_mα = I(ω_1ω_2 − λ_1λ_2)/(q∞Sd)`` (seed 001 eq. 36 without the λ_1λ_2 term),
``C_mq + C_mα̇ = (λ_1 + λ_2 + a) 2VI/(q∞Sd²)`` (seed 001 eq. 37 with the lift term),
``C_mpα = −[I(λ_1ω_2 + λ_2ω_1) + I P a] 2V/(p q∞ S d²)``; the first-order expansion of the
roots gives back seed 000 eq. 4 / seed 001 eq. 34 and Murphy (BRL 1216) / McCoy (Modern
Exterior Ballistics, ch. 9) with their lift and drag terms. A fit in distance x (m) is
converted with ``d/dt = V d/dx`` and ``dV/dx = −k_D V``, ``k_D = ρ S C_D/(2m)``: the
damping gains the drag term ``−k_D`` of Murphy's H.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cadra.motion import _checks
from cadra.motion.epicyclic import EpicyclicFit
from cadra.motion.pitch import PitchFit


@dataclass(frozen=True)
class FlightConditions:
    """Body and stream for a coefficient reduction (SI): mass, axial and transverse inertia
    about the cg, reference diameter d (S = πd²/4), air density, speed, spin (rad/s, right
    hand about the nose) and, for fits in distance, the drag coefficient."""

    mass_kg: float
    Ix_kg_m2: float
    I_kg_m2: float
    d_m: float
    density_kg_m3: float
    speed_m_s: float
    spin_rad_s: float = 0.0
    drag_coefficient: float | None = None

    def __post_init__(self):
        for name in ("mass_kg", "Ix_kg_m2", "I_kg_m2", "d_m", "density_kg_m3", "speed_m_s"):
            _checks.positive(name, getattr(self, name))
        if not np.isfinite(self.spin_rad_s):
            raise ValueError(f"spin_rad_s: must be finite, got {self.spin_rad_s!r}")

    @property
    def S(self) -> float:
        return np.pi * self.d_m**2 / 4

    @property
    def q_inf(self) -> float:
        return 0.5 * self.density_kg_m3 * self.speed_m_s**2

    def scales(self) -> tuple[float, float, float]:
        """(I/(q∞Sd), 2VI/(q∞Sd²), P per p): the factors from motion rates to coefficients."""
        qsd = self.q_inf * self.S * self.d_m
        return (self.I_kg_m2 / qsd, 2 * self.speed_m_s * self.I_kg_m2 / (qsd * self.d_m),
                self.Ix_kg_m2 / self.I_kg_m2)


def _domain(variable: str, c: FlightConditions) -> tuple[float, float]:
    """(V_s, k): rates per unit s times V_s are per second; k the drag term per unit s."""
    if variable == "time":
        return 1.0, 0.0
    if c.drag_coefficient is None:
        raise ValueError("conditions: drag_coefficient is needed to reduce a fit in distance")
    return c.speed_m_s, c.density_kg_m3 * c.S * c.drag_coefficient / (2 * c.mass_kg)


@dataclass(frozen=True)
class LinearCoefficients:
    """Linear-theory coefficients with 1-σ from the fit's covariance (and the lift slope's).
    ``spin_from_fit`` = (ω_1 + ω_2) I/I_x (rad/s), a check on the given spin."""

    Cm_alpha: float
    Cm_alpha_sigma: float
    Cmq_sum: float
    Cmq_sum_sigma: float
    Cm_p_alpha: float
    Cm_p_alpha_sigma: float
    spin_from_fit: float
    spin_from_fit_sigma: float
    C_L_alpha: float | None = None
    C_L_alpha_sigma: float | None = None


def linear_coefficients(fit: EpicyclicFit, conditions: FlightConditions,
                        lift: tuple[float, float] | None = None, *, swerve=None,
                        gravity: float = 0.0) -> LinearCoefficients:
    """C_mα, C_mq + C_mα̇ and C_mpα from a two-arm fit (module docstring for the formulas).

    ``lift = (C_Lα, sigma)`` adds the flight-path terms of free flight; ``swerve = (s, y, z)``
    or ``(s, y, z, sigma)`` (the cg's lateral positions, m) measures it first with
    :func:`lift_from_swerve` (``gravity`` passed on). With neither the motion is taken as
    purely angular (gimbal, pivot). C_mpα is NaN when the spin is zero (it does not act).
    """
    if fit.layout.arms != 2:
        raise ValueError("fit: needs the two-arm (epicyclic or tricyclic) form")
    if swerve is not None:
        if lift is not None:
            raise ValueError("swerve: give either lift or swerve, not both")
        if len(swerve) not in (3, 4):
            raise ValueError("swerve: expected (s, y, z) or (s, y, z, sigma)")
        sw = lift_from_swerve(fit, *swerve[:3], swerve[3] if len(swerve) == 4 else None,
                              conditions=conditions, gravity=gravity)
        lift = (sw.C_L_alpha, sw.C_L_alpha_sigma)
    c = conditions
    Vs, k = _domain(fit.variable, c)
    idx = [fit.layout.index(n) for n in ("lambda1", "omega1", "lambda2", "omega2")]
    l1, w1, l2, w2 = fit.values[idx]
    C = fit.covariance[np.ix_(idx, idx)]
    cl, cl_sig = (0.0, 0.0) if lift is None else (float(lift[0]), float(lift[1]))
    a = c.density_kg_m3 * c.S * c.speed_m_s * cl / (2 * c.mass_kg)
    da_dcl = a / cl if cl else c.density_kg_m3 * c.S * c.speed_m_s / (2 * c.mass_kg)
    re, im = l1 * l2 - w1 * w2, l1 * w2 + l2 * w1
    g_re = np.array([l2, -w2, l1, -w1])
    g_im = np.array([w2, l2, w1, l1])
    P = Vs * (w1 + w2)
    g_P = Vs * np.array([0.0, 1.0, 0.0, 1.0])
    s_m, s_d, ix_over_i = c.scales()
    M, g_M = -Vs**2 * re, -Vs**2 * g_re
    D, g_D = Vs * (l1 + l2 - k) + a, Vs * np.array([1.0, 0.0, 1.0, 0.0])
    T, g_T = -Vs**2 * im - P * a, -Vs**2 * g_im - a * g_P

    def sig(g, g_cl=0.0):
        return float(np.sqrt(g @ C @ g + (g_cl * cl_sig) ** 2))

    p = c.spin_rad_s
    if p != 0.0:
        cmpa, cmpa_sig = s_d * T / p, sig(s_d * g_T / p, -s_d * P * da_dcl / p)
    else:
        cmpa, cmpa_sig = float("nan"), float("nan")
    return LinearCoefficients(
        Cm_alpha=float(s_m * M), Cm_alpha_sigma=sig(s_m * g_M),
        Cmq_sum=float(s_d * D), Cmq_sum_sigma=sig(s_d * g_D, s_d * da_dcl),
        Cm_p_alpha=float(cmpa), Cm_p_alpha_sigma=cmpa_sig,
        spin_from_fit=float(P / ix_over_i), spin_from_fit_sigma=sig(g_P / ix_over_i),
        C_L_alpha=None if lift is None else cl, C_L_alpha_sigma=None if lift is None else cl_sig)


def planar_coefficients(omega: float, lam: float, conditions: FlightConditions,
                        variable: str = "time") -> tuple[float, float]:
    """C_mα and C_mq + C_mα̇ of one planar oscillation ``e^(λs) cos(ωs)`` in ``variable``
    (seed 001 eqs. 10-12, exact in λ): roots λ ± iω of α̈ − Dα̇ − Mα = 0 give
    M = −(ω² + λ²), D = 2λ, so ``C_mα = −I(ω² + λ²)/(q∞Sd)`` (eq. 11 without λ²) and
    ``C_mq + C_mα̇ = 2λ · 2VI/(q∞Sd²) = 8Iλ/(ρVSd²)`` (eq. 12, whose OCR drops the square on
    D); in distance the rates are per metre and the damping gains the drag term. The one
    home of this conversion: the 1-DOF pitch fit's coefficients and the fit's starting
    values from the damped sines both use it."""
    Vs, k = _domain(variable, conditions)
    s_m, s_d, _ = conditions.scales()
    return (float(-Vs**2 * (omega**2 + lam**2) * s_m), float(Vs * (2 * lam - k) * s_d))


def pitch_coefficients(fit: PitchFit, conditions: FlightConditions) -> LinearCoefficients:
    """C_mα and C_mq + C_mα̇ of a 1-DOF pitch fit (seed 001 eqs. 10-12, exact in λ):
    roots λ ± iω of α̈ − Dα̇ − Mα = 0 give M = −(ω² + λ²), D = 2λ, so
    ``C_mα = −I(ω² + λ²)/(q∞Sd)`` (eq. 11 without λ²) and
    ``C_mq + C_mα̇ = 2λ · 2VI/(q∞Sd²) = 8Iλ/(ρVSd²)`` (eq. 12, whose OCR drops the square
    on D)."""
    c = conditions
    Vs, _ = _domain(fit.variable, c)
    lam, om = fit.value("lambda"), fit.value("omega")
    C = fit.covariance[3:5, 3:5]
    s_m, s_d, _ = c.scales()
    g_M = -Vs**2 * np.array([2 * lam, 2 * om]) * s_m
    g_D = Vs * np.array([2.0, 0.0]) * s_d
    nan = float("nan")
    cm_alpha, cmq_sum = planar_coefficients(om, lam, c, fit.variable)
    return LinearCoefficients(
        Cm_alpha=cm_alpha, Cm_alpha_sigma=float(np.sqrt(g_M @ C @ g_M)),
        Cmq_sum=cmq_sum, Cmq_sum_sigma=float(np.sqrt(g_D @ C @ g_D)),
        Cm_p_alpha=nan, Cm_p_alpha_sigma=nan, spin_from_fit=nan, spin_from_fit_sigma=nan)


@dataclass(frozen=True)
class SwerveFit:
    """C_Lα from the swerve, with its sigma (conditional on the fitted arms, whose own
    uncertainty is not propagated), the lateral-position rms (m) and χ²/dof."""

    C_L_alpha: float
    C_L_alpha_sigma: float
    rms: float
    chi2_dof: float
    #: the fitted swerve Z = c_0 + c_1 u - i g u^2 / 2 + c G(u) (lift_from_swerve's doc):
    #: c_0 (m), c_1 (per unit of the fit's variable), c, and g in that variable
    c0: complex = complex("nan")
    c1: complex = complex("nan")
    c: complex = complex("nan")
    g_s: float = 0.0

    def lateral(self, fit: EpicyclicFit, s: float) -> tuple[complex, complex]:
        """The fitted cg lateral position Z = y + i z (m) and its slope dZ/ds (per unit of
        the fit's variable) at ``s``; ``fit`` is the arms' fit the swerve was fitted with."""
        u = float(s) - fit.s_ref
        L, x = fit.layout, fit.values
        G = dG = 0j
        for j in range(1, L.arms + 1):
            arm = fit.arm(j)
            r = arm.lam + 1j * arm.omega
            A = x[L.index(f"A{j}_re")] + 1j * x[L.index(f"A{j}_im")]
            e = A * np.exp(r * u + 0.5j * arm.omega_dot * u * u)
            G += e / r**2
            dG += e / r
        if L.trim or L.offset:
            raise ValueError("lateral: the swerve of a fit with a trim arm or offset is not "
                             "evaluated")
        return (complex(self.c0 + self.c1 * u - 0.5j * self.g_s * u * u + self.c * G),
                complex(self.c1 - 1j * self.g_s * u + self.c * dG))


def lift_from_swerve(fit: EpicyclicFit, s, y, z, sigma=None, *,
                     conditions: FlightConditions, gravity: float = 0.0) -> SwerveFit:
    """The lift slope from the cg's swerve about the mean flight path.

    The cg's complex lateral position ``Z = y + i z`` (m; y + port, z + up, facility axes of
    docs/conventions.md, flight along +x) obeys ``Z̈ = V a ξ − i g`` in time (``Z'' = a_x ξ −
    i g/V²`` in distance), so with the fitted arms held
    ``Z = c_0 + c_1 u − i g u²/2 + c Σ_j A_j e^{r_j u}/r_j²`` is linear in (c_0, c_1, c)
    and ``C_Lα = 2 m c/(ρ S V²)`` (time; ``2 m c/(ρ S)`` in distance). ``fit`` must be a fit
    of the angle of attack (the axis relative to the flight path). ``gravity`` (m/s²): 0 for
    a horizontal stream, 9.80665 for a range.
    """
    s = _checks.abscissa("s", s, min_points=6)
    y = _checks.series("y", y, s.size)
    z = _checks.series("z", z, s.size)
    w = 1.0 / _checks.sigmas("sigma", sigma, s.size)
    c = conditions
    Vs = c.speed_m_s
    u = s - fit.s_ref
    L, x = fit.layout, fit.values
    G = np.zeros(u.shape, complex)
    for j in range(1, L.arms + 1):
        arm = fit.arm(j)
        r = arm.lam + 1j * arm.omega
        A = x[L.index(f"A{j}_re")] + 1j * x[L.index(f"A{j}_im")]
        G += A * np.exp(r * u + 0.5j * arm.omega_dot * u * u) / r**2
    if L.trim:
        arm = fit.arm(0)
        A = x[L.index("At_re")] + 1j * x[L.index("At_im")]
        G += A * np.exp(1j * arm.omega * u) / (1j * arm.omega) ** 2
    if L.offset:
        G += (x[L.index("A0_re")] + 1j * x[L.index("A0_im")]) * u * u / 2
    g_s = gravity if fit.variable == "time" else gravity / Vs**2
    target = (y + 1j * z) + 1j * g_s * u * u / 2
    one = np.ones_like(u)
    cols = [one + 0j, 1j * one, u + 0j, 1j * u, G]
    A_ = np.stack(cols, axis=1)
    Ar = np.concatenate([A_.real * w[:, None], A_.imag * w[:, None]])
    br = np.concatenate([target.real * w, target.imag * w])
    sol, *_ = np.linalg.lstsq(Ar, br, rcond=None)
    r_ = Ar @ sol - br
    dof = Ar.shape[0] - Ar.shape[1]
    chi2_dof = float(r_ @ r_ / dof)
    cov = np.linalg.pinv(Ar.T @ Ar) * chi2_dof
    scale = 2 * c.mass_kg / (c.density_kg_m3 * c.S) / (c.speed_m_s**2 if fit.variable == "time"
                                                      else 1.0)
    resid = (A_ @ sol) - target
    return SwerveFit(C_L_alpha=float(scale * sol[4]),
                     C_L_alpha_sigma=float(scale * np.sqrt(cov[4, 4])),
                     rms=float(np.sqrt(np.mean(np.abs(resid) ** 2))), chi2_dof=chi2_dof,
                     c0=complex(sol[0], sol[1]), c1=complex(sol[2], sol[3]),
                     c=complex(sol[4]), g_s=float(g_s))


@dataclass(frozen=True)
class MomentDerivatives:
    """Static and damping derivatives about one reference point (body axes of
    docs/conventions.md: C_m nose up, C_Z along z_b, i.e. C_Zα = −C_Nα)."""

    Cm_alpha: float
    Cmq_sum: float
    CZ_alpha: float
    CZq_sum: float = 0.0


def transfer_cg(coeffs: MomentDerivatives, x_over_d: float) -> MomentDerivatives:
    """The derivatives about a point ``x_over_d`` calibres ahead (toward the nose, +x_b).

    Seed 001 eqs. 13-14 (eq. 14 is garbled in the OCR; derived here): the moment about the new
    point is ``C_m' = C_m + x C_Z``, and pitching about it at rate q moves the old point with a
    plunge ``x d q``, so ``α_old = α + 2x q̂``:

        C_mα' = C_mα + x C_Zα                                        (13)
        (C_mq + C_mα̇)' = (C_mq + C_mα̇) + x (C_Zq + C_Zα̇) + 2x C_mα + 2x² C_Zα
                       ⇔ (C_mq + C_mα̇)' − 2x C_mα' = (C_mq + C_mα̇) + x (C_Zq + C_Zα̇)   (14)
        (C_Zq + C_Zα̇)' = (C_Zq + C_Zα̇) + 2x C_Zα,   C_Zα' = C_Zα.
    """
    x = float(x_over_d)
    if not np.isfinite(x):
        raise ValueError(f"x_over_d: must be finite, got {x_over_d!r}")
    c = coeffs
    return MomentDerivatives(
        Cm_alpha=c.Cm_alpha + x * c.CZ_alpha,
        Cmq_sum=c.Cmq_sum + x * c.CZq_sum + 2 * x * c.Cm_alpha + 2 * x * x * c.CZ_alpha,
        CZ_alpha=c.CZ_alpha, CZq_sum=c.CZq_sum + 2 * x * c.CZ_alpha)


@dataclass(frozen=True)
class CgSeriesFit:
    """Seed 001 Table I: eqs. 13-14 fitted over several cg positions (values about x = 0)."""

    Cm_alpha: float
    Cm_alpha_sigma: float
    CZ_alpha: float
    CZ_alpha_sigma: float
    Cmq_sum: float
    Cmq_sum_sigma: float
    CZq_sum: float
    CZq_sum_sigma: float


def fit_cg_series(x_over_d, cm_alpha, cm_alpha_sigma, cmq_sum, cmq_sum_sigma) -> CgSeriesFit:
    """Weighted straight lines of eq. 13 (C_mα against x) and eq. 14 (C_mq + C_mα̇ − 2x C_mα
    against x) through coefficients measured about cg positions ``x_over_d`` (calibres,
    + toward the nose). Sigmas are the formal ones (from the given sigmas, not rescaled)."""
    x = _checks.series("x_over_d", x_over_d)
    if x.size < 3:
        raise ValueError(f"x_over_d: {x.size} positions, at least 3 are needed")
    ca = _checks.series("cm_alpha", cm_alpha, x.size)
    sa = _checks.sigmas("cm_alpha_sigma", cm_alpha_sigma, x.size)
    cq = _checks.series("cmq_sum", cmq_sum, x.size)
    sq = _checks.sigmas("cmq_sum_sigma", cmq_sum_sigma, x.size)
    A = np.stack([np.ones_like(x), x], axis=1)

    def line(yv, sv):
        Aw = A / sv[:, None]
        cov = np.linalg.inv(Aw.T @ Aw)
        sol = cov @ Aw.T @ (yv / sv)
        return sol, np.sqrt(np.diag(cov))

    (m0, czq), (m0s, czs) = line(ca, sa)
    yq = cq - 2 * x * ca
    sy = np.sqrt(sq**2 + (2 * x * sa) ** 2)
    (d0, czq2), (d0s, czq2s) = line(yq, sy)
    return CgSeriesFit(float(m0), float(m0s), float(czq), float(czs), float(d0), float(d0s),
                       float(czq2), float(czq2s))
