"""The classic motion reduction's outputs: text reports, tables, the report page and plots
(docs/motion.md).

:func:`fit_report` and :func:`coefficients_report` are plain text in lmfit's ``fit_report``
habit (value ± sigma in the one format of :func:`cadra.numfmt.pm`, the fit statistics, the
correlations above a threshold); :func:`write_outputs` writes what ``cadra2 motion`` writes,
reading only what :func:`cadra.flight.classic.analyse_shot` stored.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.atomic import atomic_output_dir
from cadra.io.toml_file import toml_text
from cadra.motion import EpicyclicFit, KBResult, LinearCoefficients
from cadra.numfmt import pm
from cadra.report import figures, markdown

DEG = math.degrees(1.0)
#: the coefficients: (attribute, column stem with unit, label in the report)
LINEAR = (("Cm_alpha", "Cm_alpha_per_rad", "C_mα (per rad)"),
          ("Cmq_sum", "Cmq_sum_per_rad", "C_mq + C_mα̇ (per rad)"),
          ("Cm_p_alpha", "Cm_p_alpha_per_rad", "C_mpα (per rad)"),
          ("C_L_alpha", "C_L_alpha_per_rad", "C_Lα, from the swerve (per rad)"),
          ("spin_from_fit", "spin_from_fit_rad_s", "spin (ω₁ + ω₂) I/I_x (rad/s, a check)"))
KB = (("Cm_alpha0", "Cm_alpha0_per_rad", "C_mα, C_0 (per rad)"),
      ("Cm_alpha2", "Cm_alpha2_per_rad3", "C_mα, C_2 (per rad³)"),
      ("Cmq_sum0", "Cmq_sum0_per_rad", "C_mq + C_mα̇, C_0 (per rad)"),
      ("Cmq_sum2", "Cmq_sum2_per_rad3", "C_mq + C_mα̇, C_2 (per rad³)"),
      ("Cm_p_alpha0", "Cm_p_alpha0_per_rad", "C_mpα, C_0 (per rad)"),
      ("Cm_p_alpha2", "Cm_p_alpha2_per_rad3", "C_mpα, C_2 (per rad³)"))


#: the rate normalisations a report may give its damping and Magnus coefficients in: CADRA's
#: own (rates q d / 2V, p d / 2V) or McCoy's and BRL's (q d / V, p d / V); a coefficient per
#: d/V rate is half the one per d/2V rate
RATES = {"d/2V": 1.0, "d/V": 0.5}
#: the coefficients that multiply a rate
_RATE_ATTRS = ("Cmq_sum", "Cm_p_alpha", "Cmq_sum0", "Cmq_sum2", "Cm_p_alpha0", "Cm_p_alpha2")


def _rated(attr: str, value, rates: str):
    """``value`` of coefficient ``attr`` in the rate normalisation ``rates``."""
    if value is None or attr not in _RATE_ATTRS:
        return value
    return value * RATES[rates]


def _label(attr: str, label: str, rates: str) -> str:
    if attr not in _RATE_ATTRS:
        return label
    rate = "q" if attr.startswith("Cmq") else "p"
    return label.replace("per rad", f"per rad, rate {rate} {rates.replace('/', ' / ')}")


def _unit(r) -> str:
    return "m" if r.variable == "distance" else "s"


def _arms(r) -> list:
    arms = [(str(j), r.fit.arm(j)) for j in (1, 2)]
    if r.fit.layout.trim:
        arms.append(("trim", r.fit.arm(0)))
    return arms


def arms_table(results) -> pd.DataFrame:
    rows = []
    for r in results:
        u = _unit(r)
        for name, a in _arms(r):
            rows.append({"shot_id": r.shot_id, "arm": name, "variable": r.variable,
                         f"s_ref_{u}": r.fit.s_ref, "K_deg": a.K * DEG,
                         "K_sigma_deg": a.K_sigma * DEG, "phase_deg": a.phase * DEG,
                         "phase_sigma_deg": a.phase_sigma * DEG, f"lambda_per_{u}": a.lam,
                         f"lambda_sigma_per_{u}": a.lam_sigma, f"omega_rad_per_{u}": a.omega,
                         f"omega_sigma_rad_per_{u}": a.omega_sigma})
    return pd.DataFrame(rows)


def coefficients_table(results, rates: str = "d/2V") -> pd.DataFrame:
    """Per shot and method, the coefficients and their sigmas; the damping and Magnus
    coefficients in the rate normalisation ``rates`` (:data:`RATES`; its own column)."""
    rows = []
    for r in results:
        c = r.conditions
        base = {"shot_id": r.shot_id, "speed_m_s": c.speed_m_s, "density_kg_m3": c.density_kg_m3,
                "spin_given_rad_s": c.spin_rad_s if c.spin_rad_s else math.nan,
                "rate_normalisation": rates,
                "aliased_arms": "" if r.alias is None else str(r.alias.shifts)}
        lc = r.coefficients
        if lc is not None:
            row = {**base, "method": f"linear theory ({r.variable})"}
            for attr, col, _ in LINEAR:
                v = _rated(attr, getattr(lc, attr), rates)
                s = _rated(attr, getattr(lc, attr + "_sigma"), rates)
                row[col] = math.nan if v is None else v
                row[col.replace("_per", "_sigma_per").replace("_rad_s", "_sigma_rad_s")] = (
                    math.nan if s is None else s)
            rows.append(row)
        if r.kb is not None:
            row = {**base, "method": "Kryloff-Bogoliuboff (time)"}
            for attr, col, _ in KB:
                row[col] = _rated(attr, getattr(r.kb, attr), rates)
                row[col.replace("_per", "_sigma_per")] = _rated(
                    attr, getattr(r.kb, attr + "_sigma"), rates)
            rows.append(row)
    return pd.DataFrame(rows)


def angles_table(results) -> pd.DataFrame:
    rows = []
    for r in results:
        fit = r.fit.predict(r.s)
        if r.fit.nonrolling is not None:   # the fit is in nonrolling axes: back to fixed
            fit = fit * np.exp(-1j * r.fit.nonrolling)
        rows.append(pd.DataFrame({
            "shot_id": r.shot_id, "station": r.stations, "t_s": r.t_s, "x_m": r.x_m,
            "alpha_deg": r.alpha * DEG, "beta_deg": r.beta * DEG,
            "sigma_alpha_deg": r.sigma_alpha * DEG, "sigma_beta_deg": r.sigma_beta * DEG,
            "alpha_fit_deg": fit.imag * DEG, "beta_fit_deg": fit.real * DEG,
            "path_up_deg": r.path_up * DEG, "path_port_deg": r.path_port * DEG}))
    return pd.concat(rows, ignore_index=True)


def _form(r) -> str:
    f = r.fit
    return ("tricyclic (10-constant)" if f.layout.trim else "epicyclic") + (
        " + constant" if f.layout.offset else "") + (
        ", nonrolling-axis correction" if f.nonrolling_iterations else "")


def shot_lines(r, verbose: bool = False, rates: str = "d/2V") -> list[str]:
    """The console's account of one shot (damping and Magnus per ``rates``)."""
    f, u = r.fit, _unit(r)
    lines = [f"{r.shot_id}: {_form(r)} fit in {r.variable}, {f.n_points} stations, rms "
             f"{f.rms * DEG:.3g} deg, chi^2/dof {f.chi2_dof:.3g}"]
    if verbose:
        lines += ["  " + t for t in fit_report(f).splitlines()]
    else:
        for name, a in _arms(r):
            exps = (f"lambda {pm(a.lam, a.lam_sigma, '1/' + u)}, omega "
                    f"{pm(a.omega, a.omega_sigma, 'rad/' + u)}" if name != "trim" else
                    f"rate p {pm(a.omega, None, 'rad/' + u)} (given)")
            lines.append(f"  arm {name}: K {pm(a.K * DEG, a.K_sigma * DEG, 'deg')}, {exps}")
    lines.append(f"  NPR {r.npr.npr:.3f}")
    if r.alias is not None:
        lines.append(f"  {r.alias.note(u)}")
    lc = r.coefficients
    if lc is not None:
        for attr, _, label in LINEAR:
            v = _rated(attr, getattr(lc, attr), rates)
            if v is not None and math.isfinite(v):
                lines.append(f"  {_label(attr, label, rates)}: "
                             f"{pm(v, _rated(attr, getattr(lc, attr + '_sigma'), rates))}")
    if r.kb is not None:
        for attr, _, label in KB:
            v = _rated(attr, getattr(r.kb, attr), rates)
            if math.isfinite(v):
                lines.append(f"  K-B {_label(attr, label, rates)}: "
                             f"{pm(v, _rated(attr, getattr(r.kb, attr + '_sigma'), rates))}")
    return lines


def console_lines(results, verbose: bool = False, rates: str = "d/2V") -> list[str]:
    return [line for r in results for line in shot_lines(r, verbose, rates)]


def report_markdown(results, rates: str = "d/2V") -> str:
    L = ["# Angular-motion reduction (cadra2 motion)", "",
         "Angles relative to the mean flight path: α = θ − γ (+ nose up), β = ψ − χ (+ nose to "
         "port), ξ = β + iα (docs/motion.md); γ, χ the inclinations of the velocity of a "
         "polynomial fitted to the cg positions against time. First order in the angles; the "
         "swerve's oscillation left in the angles scales the arms' amplitudes by ~(1 + a/r_j) "
         "but leaves their exponents, hence the coefficients, as they are. Arm 1 is the arm of "
         "the larger signed frequency (for p ≥ 0 the nutation arm). Sigmas are 1σ from the "
         "fit's covariance scaled by its χ²/dof. Damping and Magnus coefficients multiply the "
         f"rates q {rates.replace('/', ' / ')} and p {rates.replace('/', ' / ')}.", ""]
    for r in results:
        c, f, u = r.conditions, r.fit, _unit(r)
        L += [f"## {r.shot_id}", "",
              f"{_form(r)} fit in {r.variable}: {f.n_points} stations, {len(f.names)} "
              f"constants, rms {f.rms * DEG:.4g}° (α {f.rms_alpha * DEG:.4g}°, β "
              f"{f.rms_beta * DEG:.4g}°), χ²/dof {f.chi2_dof:.4g}; amplitudes referred to "
              f"{r.variable} {f.s_ref:.6g} {u}.", "",
              "Flight conditions: " + ", ".join([
                  f"m {c.mass_kg * 1e3:.5g} g", f"I_x {c.Ix_kg_m2 * 1e7:.5g} g cm²",
                  f"I {c.I_kg_m2 * 1e7:.5g} g cm²", f"d {c.d_m * 100:.5g} cm",
                  f"S {c.S * 1e4:.5g} cm²", f"ρ {c.density_kg_m3:.5g} kg/m³",
                  f"V {c.speed_m_s:.5g} m/s",
                  f"spin {c.spin_rad_s:g} rad/s" if c.spin_rad_s else "spin not given"]
                  + ([f"C_D {c.drag_coefficient:.4g} (from the deceleration)"]
                     if c.drag_coefficient is not None else [])) + ".", "",
              ]
        L += markdown.table(
            ("arm", "K (deg)", "φ₀ (deg)", f"λ (1/{u})", f"ω (rad/{u})"),
            ((name, pm(a.K * DEG, a.K_sigma * DEG), pm(a.phase * DEG, a.phase_sigma * DEG),
              pm(a.lam, a.lam_sigma) if name != "trim" else "0 (held)",
              pm(a.omega, a.omega_sigma) if name != "trim" else f"{a.omega:.6g} (given)")
             for name, a in _arms(r)))
        L += ["", f"Nonplanar Ratio (bounded form, the two arms): {r.npr.npr:.4f} (seed 002 eq. 18 "
              f"as printed: {r.npr.seed_ratio:.4g}).", ""]
        if r.alias is not None:
            L += [f"Frequency bands from the spin: {r.alias.note(u)}.", ""]
        if r.coefficients is not None:
            L += markdown.table(
                ("coefficient (linear theory)", "value ± σ"),
                ((_label(attr, label, rates),
                  pm(_rated(attr, getattr(r.coefficients, attr), rates),
                     _rated(attr, getattr(r.coefficients, attr + "_sigma"), rates)))
                 for attr, _, label in LINEAR if getattr(r.coefficients, attr) is not None))
            L.append("")
        if r.kb is not None:
            L += [f"Kryloff-Bogoliuboff reduction, C = C_0 + C_2 |α|² (|α| in rad), "
                  f"{r.kb.n_sections} sections of {r.sections.window} stations every "
                  f"{r.sections.step}, frequency-variation correction on"
                  + ("; the constant damping and Magnus terms corrected for the flight path's "
                     "turning by lift (C_Lα from the swerve)" if r.kb_lift_corrected else "")
                  + ":", ""]
            L += markdown.table(("coefficient", "value ± σ"),
                                ((_label(attr, label, rates),
                                  pm(_rated(attr, getattr(r.kb, attr), rates),
                                     _rated(attr, getattr(r.kb, attr + "_sigma"), rates)))
                                 for attr, _, label in KB))
            L.append("")
        if r.notes:
            L += ["Not computed, or approximated:", ""] + [f"- {n}" for n in r.notes] + [""]
    return "\n".join(L)


def _grid(n: int):
    cols = min(n, 3)
    return math.ceil(n / cols), cols


def plot_yaw_card(results, path) -> None:
    """α against β (deg): measured points with their sigmas and the fitted epicycle."""
    rows, cols = _grid(len(results))
    fig, axes = figures.subplots(rows, cols, figsize=(4.6 * cols, 4.4 * rows), squeeze=False)
    axes = np.atleast_1d(axes).ravel()
    for ax, r in zip(axes, results, strict=False):
        fine = np.linspace(r.s[0], r.s[-1], 40 * r.s.size)
        xi = r.fit.predict(fine)
        if r.fit.nonrolling is not None:
            xi = xi * np.exp(-1j * np.interp(fine, r.s, r.fit.nonrolling))
        ax.plot(xi.real * DEG, xi.imag * DEG, "-", lw=1, color="C0", label="fitted epicycle")
        ax.errorbar(r.beta * DEG, r.alpha * DEG, xerr=r.sigma_beta * DEG,
                    yerr=r.sigma_alpha * DEG, fmt="o", ms=4, color="C3", label="measured")
        for k in (0, r.s.size - 1):
            ax.annotate(str(r.stations[k]), (r.beta[k] * DEG, r.alpha[k] * DEG), fontsize=8,
                        xytext=(4, 4), textcoords="offset points")
        ax.axhline(0, color="0.7", lw=0.5)
        ax.axvline(0, color="0.7", lw=0.5)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("β, nose to port (deg)")
        ax.set_ylabel("α, nose up (deg)")
        ax.set_title(f"{r.shot_id}: yaw card")
        ax.legend(fontsize=8)
    for ax in axes[len(results):]:
        ax.set_visible(False)
    figures.save(fig, path)


def plot_arms(results, path) -> None:
    """The arms' magnitudes K_j e^{λ_j u} and the measured |ξ| against distance."""
    fig, ax = figures.subplots(figsize=(7.5, 4.5))
    for k, r in enumerate(results):
        fine = np.linspace(r.s[0], r.s[-1], 400)
        x_fine = np.interp(fine, r.s, r.x_m)
        u = fine - r.fit.s_ref
        mags = []
        for (name, a), ls in zip(_arms(r), ("-", "--", ":"), strict=False):
            mags.append(a.K * np.exp(a.lam * u) * DEG)
            ax.plot(x_fine, mags[-1], ls, color=f"C{k}", label=f"{r.shot_id} arm {name}")
        ax.fill_between(x_fine, np.abs(mags[0] - mags[1]), mags[0] + mags[1], color=f"C{k}",
                        alpha=0.12, lw=0, label=f"{r.shot_id} |K₁ − K₂| … K₁ + K₂")
        ax.plot(r.x_m, np.hypot(r.alpha, r.beta) * DEG, "o", ms=4, color=f"C{k}",
                label=f"{r.shot_id} |ξ| measured")
    ax.set_xlabel("distance x (m)")
    ax.set_ylabel("arm magnitude (deg)")
    ax.set_ylim(bottom=0)
    ax.set_title("Arms against distance")
    ax.legend(fontsize=8)
    figures.save(fig, path)


def plot_sectional(results, path) -> None:
    """Per section: the effective C_mα and C_mq + C_mα̇ against the amplitude (Murphy's δ_e),
    with the K-B lines C_0 + C_2 δ_e²."""
    fig, (a1, a2) = figures.subplots(1, 2, figsize=(9, 4))
    for k, r in enumerate(results):
        if r.sections is None or r.kb is None:
            continue
        kb, sec, c = r.kb, r.sections, r.conditions
        amp = np.sqrt(kb.x_static)
        grid = np.linspace(0, amp.max() * 1.05, 100)
        a1.plot(amp * DEG, kb.y_static, "o", ms=4, color=f"C{k}", label=f"{r.shot_id} sections")
        a1.plot(grid * DEG, kb.Cm_alpha0 + kb.Cm_alpha2 * grid**2, "-", color=f"C{k}",
                label=f"{r.shot_id} K-B")
        _, s_d, _ = c.scales()
        lift = 0.0
        if r.kb_lift_corrected:
            lift = (c.density_kg_m3 * c.S * c.speed_m_s * r.coefficients.C_L_alpha
                    / (2 * c.mass_kg))
        damp = (sec.lam.sum(axis=1) + lift) * s_d
        a2.plot(amp * DEG, damp, "o", ms=4, color=f"C{k}", label=f"{r.shot_id} sections")
        a2.plot(grid * DEG, kb.Cmq_sum0 + kb.Cmq_sum2 * grid**2, "-", color=f"C{k}",
                label=f"{r.shot_id} K-B")
    a1.set_ylabel("C_mα (per rad)")
    a2.set_ylabel("C_mq + C_mα̇ (per rad)")
    for ax in (a1, a2):
        ax.set_xlabel("amplitude δ_e (deg)")
        ax.legend(fontsize=8)
    fig.suptitle("Sectional coefficients against amplitude")
    figures.save(fig, path)


def write_outputs(results, out_dir: str | os.PathLike, *, overwrite: bool = False,
                  command: dict | None = None, rates: str = "d/2V") -> list[str]:
    """Every file, atomically; returns their names. ``rates``: the damping and Magnus
    coefficients' rate normalisation (:data:`RATES`), named in every file."""
    files = ["report.md", "angles.csv", "arms.csv", "coefficients.csv", "yaw_card.png",
             "arms.png"]
    sectional = any(r.kb is not None for r in results)
    with atomic_output_dir(Path(out_dir), overwrite=overwrite,
                           kind="motion") as tmp:
        (tmp / "report.md").write_text(report_markdown(results, rates), encoding="utf-8")
        angles_table(results).to_csv(tmp / "angles.csv", index=False, float_format="%.10g")
        arms_table(results).to_csv(tmp / "arms.csv", index=False, float_format="%.10g")
        coefficients_table(results, rates).to_csv(tmp / "coefficients.csv", index=False,
                                           float_format="%.10g")
        plot_yaw_card(results, tmp / "yaw_card.png")
        plot_arms(results, tmp / "arms.png")
        if sectional:
            plot_sectional(results, tmp / "sectional.png")
            files.append("sectional.png")
        if command is not None:
            config = {k: ("" if v is None else v) for k, v in command.items() if k != "func"}
            (tmp / "config.toml").write_text(
                toml_text(config, "cadra2 motion: the command's settings"), encoding="utf-8")
            files.append("config.toml")
    return files


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


__all__ = ["RATES", "angles_table", "arms_table", "coefficients_report", "coefficients_table",
           "console_lines", "fit_report", "plot_arms", "plot_sectional", "plot_yaw_card",
           "report_markdown", "shot_lines", "write_outputs"]
