"""The Kryloff-Bogoliuboff reduction: coefficients quadratic in the amplitude from sectional
fits (seed 000; seed 001 eqs. 16-20 and 39-45).

Model (seed 000 eq. 8-9, time t, constant V and p, no lift: a gimbal or pivot test)

    ξ̈ − [iP + D(|ξ|²)] ξ̇ − [M(|ξ|²) + iT(|ξ|²)] ξ = 0,
    D = (q∞Sd²/2VI)(C_mq+C_mα̇)(|ξ|),  M = (q∞Sd/I) C_mα(|ξ|),  T = p (q∞Sd²/2VI) C_mpα(|ξ|),
    C(|ξ|) = C_0 + C_2 |ξ|²  (|ξ| in rad).

First-order averaging of ``ξ = K_1 e^{iφ_1} + K_2 e^{iφ_2}`` (derived in docs/motion.md):

* frequencies: ``ω_j² − Pω_j + M(δ_ej²) = 0`` with ``δ_ej² = K_j² + 2K_k²``, hence
  ``ω_1ω_2 = M_0 + M_2 δ_e²`` with Murphy's correlator δ_e² (seed 002 eq. 3; seed 000's
  δ_α²): C_mα0, C_mα2 are the intercept and slope of ``ω_1ω_2 I/(q∞Sd)`` against δ_e²;
* amplitudes: ``λ_j(2ω_j − P) + ω̇_j = d_0ω_j + d_2[ω_j(K_1² + K_2²) + ω_kK_k²] + t_0 +
  t_2 δ_ej²`` (the brackets are the averages of |ξ|²ξ̇ and |ξ|²ξ against e^{iφ_j}), linear in
  (d_0, d_2, t_0, t_2) and solved by least squares over both arms of every section. The
  ``ω̇_j`` term is the frequency-variation correction (seed 000 eqs. 12-13: λ* = λ + λ^v);
  for 1-DOF motion it is seed 001 eq. 20's ``K_c = K √ω``.

1-DOF pitch (seed 001 eqs. 15-20, planar, quadratic in α²): ``ω² + λ² = −(q∞Sd/I)(C_mα0 +
¾C_mα2 K²)`` and ``λ + ω̇/(2ω) = (q∞Sd²/2VI)[(C_mq+C_mα̇)_0/2 + (C_mq+C_mα̇)_2 K²/8]``.

Sigmas: weighted least squares over the sections, the covariance scaled by the residual
χ²/dof and by the sections' overlap (window/step), since overlapping sections share data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cadra.motion.coefficients import FlightConditions
from cadra.motion.nonplanar import cubic_correlator
from cadra.motion.sectional import Sections


@dataclass(frozen=True)
class KBResult:
    """Coefficients quadratic in |α| (rad): ``C(|α|) = C_0 + C_2|α|²``, with sigmas.

    ``Cm_p_alpha*`` are NaN for a 1-DOF or non-spinning reduction. ``x_static`` and
    ``y_static`` are the sections' correlator and effective C_mα (for plots)."""

    Cm_alpha0: float
    Cm_alpha0_sigma: float
    Cm_alpha2: float
    Cm_alpha2_sigma: float
    Cmq_sum0: float
    Cmq_sum0_sigma: float
    Cmq_sum2: float
    Cmq_sum2_sigma: float
    Cm_p_alpha0: float
    Cm_p_alpha0_sigma: float
    Cm_p_alpha2: float
    Cm_p_alpha2_sigma: float
    frequency_correction: bool
    n_sections: int
    x_static: np.ndarray
    y_static: np.ndarray

    def total(self, name: str, amplitude: float) -> float:
        """``C_0 + C_2 amplitude²`` for name in Cm_alpha, Cmq_sum, Cm_p_alpha."""
        return getattr(self, name + "0") + getattr(self, name + "2") * amplitude**2


def _wls(A, y, sig, overlap):
    sig = np.maximum(sig, 1e-12 * np.max(np.abs(sig)) + 1e-300)
    Aw, yw = A / sig[:, None], y / sig
    sol, *_ = np.linalg.lstsq(Aw, yw, rcond=None)
    r = Aw @ sol - yw
    dof = max(A.shape[0] - A.shape[1], 1)
    cov = np.linalg.pinv(Aw.T @ Aw) * (r @ r / dof) * overlap
    return sol, np.sqrt(np.clip(np.diag(cov), 0, None))


def _omega_dot(sec: Sections) -> np.ndarray:
    if sec.centre.size < 3:
        raise ValueError("sections: at least 3 sections are needed")
    return np.gradient(sec.omega, sec.centre, axis=0)


_KB_FOR = {"epicyclic": ("two-arm epicyclic", "kb_pitch_reduction"),
           "pitch": ("1-DOF pitch", "kb_reduction")}


def _checked(sections: Sections, kind: str) -> Sections:
    """``sections`` if they are of ``kind`` and fitted in time, else a ValueError naming the
    reduction to use."""
    if sections.kind != kind:
        what, other = _KB_FOR[kind]
        raise ValueError(f"sections: needs {what} sections (use {other})")
    if sections.variable != "time":
        raise ValueError("sections: the K-B reduction takes sections fitted in time")
    return sections


def kb_reduction(sections: Sections, conditions: FlightConditions, *,
                 frequency_correction: bool = True) -> KBResult:
    """The 3-DOF reduction (seed 000; seed 001 eqs. 39-45) of two-arm sectional fits in
    time; see the module docstring. Magnus terms are solved for only when the spin is
    nonzero."""
    sec, c = _checked(sections, "epicyclic"), conditions
    s_m, s_d, ix_i = c.scales()
    P = c.spin_rad_s * ix_i
    K1, K2 = sec.K[:, 0], sec.K[:, 1]
    l1, l2 = sec.lam[:, 0], sec.lam[:, 1]
    w1, w2 = sec.omega[:, 0], sec.omega[:, 1]
    sw1, sw2 = sec.omega_sigma[:, 0], sec.omega_sigma[:, 1]
    corr = [cubic_correlator(a, b, x, y) for a, b, x, y in zip(K1, K2, w1, w2, strict=True)]
    de = np.array([q.delta_e_sq for q in corr])
    d1 = np.array([q.delta_e1_sq for q in corr])
    d2 = np.array([q.delta_e2_sq for q in corr])
    y = (w1 * w2 - l1 * l2) * s_m
    sy = s_m * np.hypot(w2 * sw1, w1 * sw2)
    (m0, m2), (m0s, m2s) = _wls(np.stack([np.ones_like(de), de], 1), y, sy, sec.overlap)
    wd = _omega_dot(sec) if frequency_correction else np.zeros_like(sec.omega)
    rows, rhs, sig = [], [], []
    for j, k in ((0, 1), (1, 0)):
        Kj, Kk = sec.K[:, j], sec.K[:, k]
        wj, wk = sec.omega[:, j], sec.omega[:, k]
        dej = d1 if j == 0 else d2
        den = 2 * wj - P
        cols = [wj, wj * (Kj**2 + Kk**2) + wk * Kk**2]
        if P != 0.0:
            cols += [np.ones_like(wj), dej]
        rows.append(np.stack(cols, 1))
        rhs.append(sec.lam[:, j] * den + wd[:, j])
        sig.append(np.abs(den) * sec.lam_sigma[:, j])
    A, b, sb = np.concatenate(rows), np.concatenate(rhs), np.concatenate(sig)
    sol, ss = _wls(A, b, sb, sec.overlap)
    nan = float("nan")
    t0 = t2 = t0s = t2s = nan
    if P != 0.0:
        f = s_d / c.spin_rad_s
        t0, t2, t0s, t2s = sol[2] * f, sol[3] * f, ss[2] * abs(f), ss[3] * abs(f)
    return KBResult(
        Cm_alpha0=float(m0), Cm_alpha0_sigma=float(m0s), Cm_alpha2=float(m2),
        Cm_alpha2_sigma=float(m2s), Cmq_sum0=float(sol[0] * s_d), Cmq_sum0_sigma=float(ss[0] * s_d),
        Cmq_sum2=float(sol[1] * s_d), Cmq_sum2_sigma=float(ss[1] * s_d),
        Cm_p_alpha0=float(t0), Cm_p_alpha0_sigma=float(t0s), Cm_p_alpha2=float(t2),
        Cm_p_alpha2_sigma=float(t2s), frequency_correction=frequency_correction,
        n_sections=int(sec.centre.size), x_static=de, y_static=y)


def kb_pitch_reduction(sections: Sections, conditions: FlightConditions, *,
                       frequency_correction: bool = True) -> KBResult:
    """The 1-DOF reduction (seed 001 eqs. 16-20) of sectional pitch fits in time: C_mα and
    C_mq + C_mα̇ quadratic in the angle (α², rad²); see the module docstring."""
    sec, c = _checked(sections, "pitch"), conditions
    s_m, s_d, _ = c.scales()
    K, lam, om = sec.K[:, 0], sec.lam[:, 0], sec.omega[:, 0]
    x = 0.75 * K**2
    y = -(om**2 + lam**2) * s_m
    sy = 2 * s_m * np.hypot(om * sec.omega_sigma[:, 0], lam * sec.lam_sigma[:, 0])
    (m0, m2), (m0s, m2s) = _wls(np.stack([np.ones_like(x), x], 1), y, sy, sec.overlap)
    lc = lam + (_omega_dot(sec)[:, 0] / (2 * om) if frequency_correction else 0.0)
    A = np.stack([np.ones_like(K), K**2 / 4], 1)
    (e0, e2), (e0s, e2s) = _wls(A, 2 * lc * s_d, 2 * s_d * sec.lam_sigma[:, 0], sec.overlap)
    nan = float("nan")
    return KBResult(
        Cm_alpha0=float(m0), Cm_alpha0_sigma=float(m0s), Cm_alpha2=float(m2),
        Cm_alpha2_sigma=float(m2s), Cmq_sum0=float(e0), Cmq_sum0_sigma=float(e0s),
        Cmq_sum2=float(e2), Cmq_sum2_sigma=float(e2s), Cm_p_alpha0=nan, Cm_p_alpha0_sigma=nan,
        Cm_p_alpha2=nan, Cm_p_alpha2_sigma=nan, frequency_correction=frequency_correction,
        n_sections=int(sec.centre.size), x_static=x, y_static=y)
