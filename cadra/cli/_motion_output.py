"""What ``cadra2 motion`` writes and prints: tables, report, plots (docs/motion.md). Reads only
what :func:`cadra.flight.classic.analyse_shot` stored; plots with matplotlib's object API
(imported lazily), never pyplot."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.numfmt import pm

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


def coefficients_table(results) -> pd.DataFrame:
    rows = []
    for r in results:
        c = r.conditions
        base = {"shot_id": r.shot_id, "speed_m_s": c.speed_m_s, "density_kg_m3": c.density_kg_m3,
                "spin_given_rad_s": c.spin_rad_s if c.spin_rad_s else math.nan}
        lc = r.coefficients
        if lc is not None:
            row = {**base, "method": f"linear theory ({r.variable})"}
            for attr, col, _ in LINEAR:
                v, s = getattr(lc, attr), getattr(lc, attr + "_sigma")
                row[col] = math.nan if v is None else v
                row[col.replace("_per", "_sigma_per").replace("_rad_s", "_sigma_rad_s")] = (
                    math.nan if s is None else s)
            rows.append(row)
        if r.kb is not None:
            row = {**base, "method": "Kryloff-Bogoliuboff (time)"}
            for attr, col, _ in KB:
                row[col] = getattr(r.kb, attr)
                row[col.replace("_per", "_sigma_per")] = getattr(r.kb, attr + "_sigma")
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


def shot_lines(r, verbose: bool = False) -> list[str]:
    """The console's account of one shot."""
    from cadra.motion import fit_report

    f, u = r.fit, _unit(r)
    lines = [f"{r.shot_id}: {_form(r)} fit in {r.variable}, {f.n_points} stations, rms "
             f"{f.rms * DEG:.3g} deg, chi^2/dof {f.chi2_dof:.3g}"]
    if verbose:
        lines += ["  " + t for t in fit_report(f).splitlines()]
    else:
        for name, a in _arms(r):
            rates = (f"lambda {pm(a.lam, a.lam_sigma, '1/' + u)}, omega "
                     f"{pm(a.omega, a.omega_sigma, 'rad/' + u)}" if name != "trim" else
                     f"rate p {pm(a.omega, None, 'rad/' + u)} (given)")
            lines.append(f"  arm {name}: K {pm(a.K * DEG, a.K_sigma * DEG, 'deg')}, {rates}")
    lines.append(f"  NPR {r.npr.npr:.3f}")
    lc = r.coefficients
    if lc is not None:
        for attr, _, label in LINEAR:
            v = getattr(lc, attr)
            if v is not None and math.isfinite(v):
                lines.append(f"  {label}: {pm(v, getattr(lc, attr + '_sigma'))}")
    if r.kb is not None:
        for attr, _, label in KB:
            v = getattr(r.kb, attr)
            if math.isfinite(v):
                lines.append(f"  K-B {label}: {pm(v, getattr(r.kb, attr + '_sigma'))}")
    return lines


def console_lines(results, verbose: bool = False) -> list[str]:
    return [line for r in results for line in shot_lines(r, verbose)]


def report_markdown(results) -> str:
    L = ["# Angular-motion reduction (cadra2 motion)", "",
         "Angles relative to the mean flight path: α = θ − γ (+ nose up), β = ψ − χ (+ nose to "
         "port), ξ = β + iα (docs/motion.md); γ, χ the inclinations of the velocity of a "
         "polynomial fitted to the cg positions against time. First order in the angles; the "
         "swerve's oscillation left in the angles scales the arms' amplitudes by ~(1 + a/r_j) "
         "but leaves their exponents, hence the coefficients, as they are. Arm 1 is the arm of "
         "the larger signed frequency (for p ≥ 0 the nutation arm). Sigmas are 1σ from the "
         "fit's covariance scaled by its χ²/dof.", ""]
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
              "| arm | K (deg) | φ₀ (deg) | λ (1/" + u + ") | ω (rad/" + u + ") |",
              "|---|---|---|---|---|"]
        for name, a in _arms(r):
            lam = pm(a.lam, a.lam_sigma) if name != "trim" else "0 (held)"
            om = pm(a.omega, a.omega_sigma) if name != "trim" else f"{a.omega:.6g} (given)"
            L.append(f"| {name} | {pm(a.K * DEG, a.K_sigma * DEG)} | "
                     f"{pm(a.phase * DEG, a.phase_sigma * DEG)} | {lam} | {om} |")
        L += ["", f"Nonplanar Ratio (bounded form, the two arms): {r.npr.npr:.4f} (seed 002 eq. 18 "
              f"as printed: {r.npr.seed_ratio:.4g}).", ""]
        if r.coefficients is not None:
            L += ["| coefficient (linear theory) | value ± σ |", "|---|---|"]
            for attr, _, label in LINEAR:
                v = getattr(r.coefficients, attr)
                if v is not None:
                    L.append(f"| {label} | {pm(v, getattr(r.coefficients, attr + '_sigma'))} |")
            L.append("")
        if r.kb is not None:
            L += [f"Kryloff-Bogoliuboff reduction, C = C_0 + C_2 |α|² (|α| in rad), "
                  f"{r.kb.n_sections} sections of {r.sections.window} stations every "
                  f"{r.sections.step}, frequency-variation correction on"
                  + ("; the constant damping and Magnus terms corrected for the flight path's "
                     "turning by lift (C_Lα from the swerve)" if r.kb_lift_corrected else "")
                  + ":", "", "| coefficient | value ± σ |", "|---|---|"]
            for attr, _, label in KB:
                L.append(f"| {label} | {pm(getattr(r.kb, attr), getattr(r.kb, attr + '_sigma'))}"
                         " |")
            L.append("")
        if r.notes:
            L += ["Not computed, or approximated:", ""] + [f"- {n}" for n in r.notes] + [""]
    return "\n".join(L)


def _grid(n: int):
    cols = min(n, 3)
    return math.ceil(n / cols), cols


def plot_yaw_card(results, path) -> None:
    """α against β (deg): measured points with their sigmas and the fitted epicycle."""
    from matplotlib.figure import Figure

    rows, cols = _grid(len(results))
    fig = Figure(figsize=(4.6 * cols, 4.4 * rows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
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
    fig.savefig(path, dpi=110)


def plot_arms(results, path) -> None:
    """The arms' magnitudes K_j e^{λ_j u} and the measured |ξ| against distance."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 4.5), layout="constrained")
    ax = fig.subplots()
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
    fig.savefig(path, dpi=110)


def plot_sectional(results, path) -> None:
    """Per section: the effective C_mα and C_mq + C_mα̇ against the amplitude (Murphy's δ_e),
    with the K-B lines C_0 + C_2 δ_e²."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 4), layout="constrained")
    a1, a2 = fig.subplots(1, 2)
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
    fig.savefig(path, dpi=110)


def write_outputs(results, out_dir: str | os.PathLike, *, overwrite: bool = False,
                  command: dict | None = None) -> list[str]:
    """Every file, atomically; returns their names."""
    from cadra.io.atomic import atomic_output_dir
    from cadra.io.toml_file import toml_text

    files = ["report.md", "angles.csv", "arms.csv", "coefficients.csv", "yaw_card.png",
             "arms.png"]
    sectional = any(r.kb is not None for r in results)
    with atomic_output_dir(Path(out_dir), overwrite=overwrite) as tmp:
        (tmp / "report.md").write_text(report_markdown(results), encoding="utf-8")
        angles_table(results).to_csv(tmp / "angles.csv", index=False, float_format="%.10g")
        arms_table(results).to_csv(tmp / "arms.csv", index=False, float_format="%.10g")
        coefficients_table(results).to_csv(tmp / "coefficients.csv", index=False,
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
