"""Plain-text reports of the motion fits and reductions (lmfit's ``fit_report`` habit):
value ± sigma in the one format of :func:`cadra.numfmt.pm`, the fit statistics, and the
correlations above a threshold. Pure formatting: it only reads what the fit stored."""

from __future__ import annotations

import math

import numpy as np

from cadra.motion.coefficients import LinearCoefficients
from cadra.motion.epicyclic import EpicyclicFit
from cadra.motion.kb import KBResult
from cadra.numfmt import pm


def fit_report(fit: EpicyclicFit, min_correlation: float = 0.5) -> str:
    """The arms (K and φ_0 in degrees, λ and ω per unit of the fit's variable), the fit
    statistics and the correlations with |ρ| ≥ ``min_correlation``."""
    unit = "1/s" if fit.variable == "time" else "1/m"
    form = ("12-constant" if fit.layout.curvature else "10-constant") if fit.layout.trim else (
        "epicyclic" + (" + ω̇" if fit.layout.curvature else ""))
    lines = [f"{form} fit in {fit.variable}: {fit.n_points} points, {len(fit.names)} constants,"
             f" {fit.nfev} evaluations",
             f"  rms {math.degrees(fit.rms):.4g}° (α {math.degrees(fit.rms_alpha):.4g}°, "
             f"β {math.degrees(fit.rms_beta):.4g}°), χ²/dof {fit.chi2_dof:.4g} "
             f"({'covariance scaled by it' if fit.covariance_scaled else 'formal covariance'})"]
    if fit.nonrolling_iterations:
        lines.append(f"  nonrolling-axis correction: {fit.nonrolling_iterations} iteration(s), "
                     f"|φ̂| ≤ {math.degrees(float(np.max(np.abs(fit.nonrolling)))):.3g}°")
    for j in range(1, fit.layout.arms + 1):
        a = fit.arm(j)
        row = (f"  arm {j}: K {pm(math.degrees(a.K), math.degrees(a.K_sigma), 'deg')}, "
               f"φ0 {pm(math.degrees(a.phase), math.degrees(a.phase_sigma), 'deg')}, "
               f"λ {pm(a.lam, a.lam_sigma, unit)}, "
               f"ω {pm(a.omega, a.omega_sigma, 'rad' + unit[1:])}")
        if fit.layout.curvature:
            row += f", ω̇ {pm(a.omega_dot, a.omega_dot_sigma)}"
        lines.append(row)
    if fit.layout.trim:
        a = fit.arm(0)
        lines.append(f"  trim arm: K {pm(math.degrees(a.K), math.degrees(a.K_sigma), 'deg')}, "
                     f"φ0 {pm(math.degrees(a.phase), math.degrees(a.phase_sigma), 'deg')}, "
                     f"p {pm(a.omega, a.omega_sigma if fit.layout.free_trim_rate else None)}")
    lines.append(f"  (amplitudes referred to {fit.variable} {fit.s_ref:.6g})")
    corr = fit.correlation
    pairs = [(abs(corr[i, k]), fit.names[i], fit.names[k], corr[i, k])
             for i in range(len(fit.names)) for k in range(i + 1, len(fit.names))
             if np.isfinite(corr[i, k]) and abs(corr[i, k]) >= min_correlation]
    if pairs:
        lines.append(f"  correlations |ρ| ≥ {min_correlation}:")
        lines += [f"    {a} – {b}: {r:+.3f}" for _, a, b, r in sorted(pairs, reverse=True)]
    return "\n".join(lines)


def coefficients_report(lc: LinearCoefficients | None = None, kb: KBResult | None = None) -> str:
    """Linear-theory coefficients and/or a K-B reduction, value ± sigma per line."""
    lines = []
    if lc is not None:
        lines += ["linear theory (per rad):",
                  f"  C_mα        {pm(lc.Cm_alpha, lc.Cm_alpha_sigma)}",
                  f"  C_mq + C_mα̇ {pm(lc.Cmq_sum, lc.Cmq_sum_sigma)}",
                  f"  C_mpα       {pm(lc.Cm_p_alpha, lc.Cm_p_alpha_sigma)}",
                  f"  spin from the fit {pm(lc.spin_from_fit, lc.spin_from_fit_sigma, 'rad/s')}"]
        if lc.C_L_alpha is not None:
            lines.append(f"  C_Lα        {pm(lc.C_L_alpha, lc.C_L_alpha_sigma)}")
    if kb is not None:
        lines.append(f"Kryloff-Bogoliuboff, C = C_0 + C_2 |α|² (|α| in rad), {kb.n_sections} "
                     f"sections, frequency-variation correction "
                     f"{'on' if kb.frequency_correction else 'off'}:")
        for name, label in (("Cm_alpha", "C_mα       "), ("Cmq_sum", "C_mq + C_mα̇"),
                            ("Cm_p_alpha", "C_mpα      ")):
            c0 = pm(getattr(kb, name + "0"), getattr(kb, name + "0_sigma"))
            c2 = pm(getattr(kb, name + "2"), getattr(kb, name + "2_sigma"))
            lines.append(f"  {label} C_0 {c0}, C_2 {c2}")
    return "\n".join(lines)
