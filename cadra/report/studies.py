"""The outputs of seed 004's studies: the quasi-linear trend plot, the hold-one plot (Fig. 15)
and the folders ``cadra2 single`` and ``cadra2 holdone`` write (docs/fitting.md).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.aero import AeroModel
from cadra.atomic import atomic_output_dir
from cadra.numfmt import pm
from cadra.report import figures, markdown
from cadra.studies.bootstrap import MIN_TO_FLAG
from cadra.studies.single import check_single_fits, quasi_linear_summary


def plot_quasi_linear(table: pd.DataFrame, coefficient: str = "Cmq_0",
                      against: str = "alpha_rms_deg", ax=None, **summary_kw):
    """Average coefficient against amplitude, 1-sigma error bars, the weighted line.

    Points labelled with their shot ids; the legend gives the line's slope, intercept and
    chi^2 p-value (:func:`quasi_linear_summary`, whose keywords ``summary_kw`` are passed on).
    Returns the figure (never shown).
    """
    s = quasi_linear_summary(table, coefficient, against, **summary_kw)
    if ax is None:
        fig, ax = figures.subplots(figsize=(6.5, 4.5))
    else:
        fig = ax.figure
    ax.errorbar(s["x"], s["y"], yerr=s["sigma"], fmt="o", ms=5, capsize=3, color="C0",
                ecolor="C0", label=f"single fits ({s['n']})")
    for xi, yi, sid in zip(s["x"], s["y"], s["shot_id"], strict=True):
        ax.annotate(str(sid), (xi, yi), textcoords="offset points", xytext=(4, 4),
                    fontsize=7, color="0.3")
    if math.isfinite(s["slope"]):
        xs = np.linspace(0.0, max(float(np.max(s["x"])), 1e-12) * 1.05, 50)
        p = "" if not math.isfinite(s["p_value"]) else f", p = {s['p_value']:.2g}"
        ax.plot(xs, s["intercept"] + s["slope"] * xs, "-", color="C3", lw=1,
                label=(f"line: {pm(s['intercept'], s['intercept_sigma'])} "
                       f"+ ({pm(s['slope'], s['slope_sigma'])}) x{p}"))
    ax.set_xlabel(against)
    ax.set_ylabel(f"{coefficient} (quasi-linear)")
    ax.set_title(f"{coefficient} vs {against}", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def plot_hold_one(table: pd.DataFrame, name: str | None = None, ax=None):
    """Fig. 15 style: fit quality and the other parameters against the held value.

    ``ax`` None: a new figure with one panel of residual rms (theta, psi, sigma in deg) and
    one panel per other free parameter (value with 1-sigma bars). A single Axes: only the rms
    panel, drawn there. A sequence of Axes: the rms panel and then the parameter panels, as
    many as given. Non-converged refits are drawn hollow; a table with ``<parameter>_linear``
    columns (:func:`cadra.studies.holdone.with_linear_prediction`) adds them dashed. Returns
    the figure (never shown).
    """
    name = name or (str(table["held"].iloc[0]) if "held" in table and len(table) else "held")
    t = table.sort_values("value")
    x = t["value"].to_numpy(float)
    ok = t["status"].to_numpy() == "converged" if "status" in t else np.ones(len(t), bool)
    skip = {"held", "value", "status", "converged", "iterations", "chi2", "n_observations",
            "dof", "reduced_chi2"}
    params = [c for c in t.columns if c not in skip and not c.endswith(("_sigma", "_scaled"))
              and not c.endswith(("_rms_m", "_rms_deg")) and f"{c}_sigma" in t]
    if ax is None:
        n = 1 + len(params)
        ncol = min(n, 3)
        nrow = math.ceil(n / ncol)
        fig, axs = figures.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.2 * nrow), squeeze=False)
        axes = list(axs.ravel())
        for a in axes[n:]:
            a.set_visible(False)
        axes = axes[:n]
    elif hasattr(ax, "plot"):
        axes = [ax]
        fig = ax.figure
    else:
        axes = list(ax)
        fig = axes[0].figure
    a0 = axes[0]
    for col, style in (("theta_rms_deg", "C0"), ("psi_rms_deg", "C1"), ("sigma_rms_deg", "C3")):
        if col in t and np.any(np.isfinite(t[col].to_numpy(float))):
            y = t[col].to_numpy(float)
            a0.plot(x, y, "-", color=style, lw=1, label=col.replace("_rms_deg", " rms"))
            a0.plot(x[ok], y[ok], "o", color=style, ms=4)
            a0.plot(x[~ok], y[~ok], "o", mfc="none", color=style, ms=4)
    a0.set_xlabel(f"{name} (held)")
    a0.set_ylabel("residual rms (deg)")
    a0.set_title("fit quality", fontsize=10)
    a0.grid(alpha=0.3)
    a0.legend(fontsize=7)
    for a, p in zip(axes[1:], params, strict=False):
        y = t[p].to_numpy(float)
        e = t[f"{p}_sigma"].to_numpy(float)
        e = np.where(np.isfinite(e), e, 0.0)
        a.errorbar(x[ok], y[ok], yerr=e[ok], fmt="o-", ms=4, capsize=2, color="C0", lw=1)
        if (~ok).any():
            a.plot(x[~ok], y[~ok], "o", mfc="none", color="C0", ms=4)
        if f"{p}_linear" in t:    # the first-order prediction from the base fit
            a.plot(x, t[f"{p}_linear"].to_numpy(float), "--", color="C3", lw=1,
                   label="linear (consider)")
            a.legend(fontsize=7)
        a.set_xlabel(f"{name} (held)")
        a.set_ylabel(p)
        a.grid(alpha=0.3)
    return fig




def write_single_fits(table: pd.DataFrame, model: AeroModel, out_dir: str | os.PathLike, *,
                      overwrite: bool = False) -> list[str]:
    """Write seed 004 steps 1-2 to ``out_dir`` atomically: ``single_fits.csv``, the
    quasi-linear trend of every free coefficient vs alpha_rms and sigma_rms
    (``quasi_linear.json``, ``plots/quasi_linear_<coef>_<against>.png``) and ``report.md``
    (with :func:`cadra.studies.single.check_single_fits`'s warnings). Returns the report's
    lines."""
    checks = check_single_fits(table)
    names = model.free_names()
    lines = [f"# Single fits with {model.name} (seed 004 step 1) and quasi-linear "
             "trends (step 2)", ""]
    lines += markdown.table(
        ("shot", "status", "chi2/dof", *names),
        ((row["shot_id"], row["status"], f"{row['reduced_chi2']:.3g}",
          *(pm(row[n], row[n + "_sigma"]) for n in names))
         for _, row in table.iterrows()))
    against = [c for c in ("alpha_rms_deg", "sigma_rms_deg") if c in table] if checks.trends \
        else []
    summaries, trend_rows = {}, []
    with atomic_output_dir(Path(out_dir), overwrite=overwrite, kind="single fits") as tmp:
        table.to_csv(tmp / "single_fits.csv", index=False)
        (tmp / "plots").mkdir()
        for name in names:
            for col in against:
                try:
                    q = quasi_linear_summary(table, name, col)
                except ValueError as exc:
                    trend_rows.append((name, col, str(exc), "", ""))
                    continue
                summaries[f"{name}:{col}"] = q
                trend_rows.append((name, col, pm(q["slope"], q["slope_sigma"]),
                                   pm(q["intercept"], q["intercept_sigma"]),
                                   q["p_value"] if q["p_value"] is not None else "—"))
                figures.save(plot_quasi_linear(table, name, col),
                             tmp / "plots" / f"quasi_linear_{name}_{col}.png")
        if checks.trends:
            lines += ["", "## Quasi-linear trends (weighted straight line vs amplitude)", ""]
            lines += markdown.table(("coefficient", "against", "slope ± σ", "intercept ± σ",
                                     "p (line)"), trend_rows)
        else:    # one line saying why, not NaN rows
            lines += ["", "## Quasi-linear trends", "", checks.trends_note]
        (tmp / "quasi_linear.json").write_text(
            json.dumps(summaries, indent=2,
                       default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)),
            encoding="utf-8")
        if checks.warnings:
            lines += ["", "## Warnings", "", *(f"- {w}" for w in checks.warnings)]
        (tmp / "report.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return lines


def write_hold_one(table: pd.DataFrame, name: str, out_dir: str | os.PathLike, *,
                   overwrite: bool = False) -> Path:
    """``hold_one.csv`` (:func:`cadra.studies.holdone.hold_one_study`'s table) and
    ``hold_one.png`` (:func:`plot_hold_one`) in ``out_dir``, atomically."""
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=overwrite, kind="hold-one study") as tmp:
        table.to_csv(tmp / "hold_one.csv", index=False)
        figures.save(plot_hold_one(table, name), tmp / "hold_one.png")
    return out_dir




def single_fits_lines(table: pd.DataFrame, model: AeroModel, verbose: bool = False
                      ) -> list[str]:
    """The console's table of single fits: shot, status, chi^2/nu and every free parameter
    ``value ± sigma``; ``verbose`` adds each fit's message."""
    names = model.free_names()
    lines = [f"{'shot':10s} {'status':10s} {'chi^2/nu':>9s}  " + "  ".join(names)]
    for _, row in table.iterrows():
        cells = [pm(row[n], row[f"{n}_sigma"]) for n in names]
        lines.append(f"{row['shot_id']:10s} {row['status']:10s} {row['reduced_chi2']:9.3g}  "
                     + "  ".join(cells))
        if verbose:
            lines.append(f"  {row['message']}")
    return lines





def bootstrap_markdown(boot, title: str) -> str:
    """A bootstrap's report (:class:`cadra.studies.bootstrap.BootstrapResult`): per parameter
    value ± covariance sigma, the bootstrap sigma and the ratio, the bias in sigmas, the 95 %
    percentile interval and the flag (SI)."""
    judged = boot.n_converged >= MIN_TO_FLAG
    lines = [f"# Bootstrap: {title}", "",
             f"{boot.n_converged} of {boot.n_requested} refits converged ({boot.noise} noise: "
             + ("each measurement's own sigma" if boot.noise == "white" else
                "the fit's standardized residuals resampled in blocks of stations")
             + "). Values SI; the interval is the 95 % percentile interval"
             + ("." if judged else f"; fewer than {MIN_TO_FLAG} refits: whether an interval is "
                "Gaussian is not judged."), ""]
    profiled = "profile_lower" in boot.table
    lines += markdown.table(
        ("parameter", "value ± σ (covariance)", "σ bootstrap", "ratio", "bias / σ",
         "95 % interval") + (("95 % profile-likelihood interval",) if profiled else ())
        + ("non-Gaussian",),
        ((r.parameter, pm(r.value, r.sigma_cov), f"{r.sigma_boot:.3g}", f"{r.ratio:.3f}",
          f"{r.bias_sigma:+.2f}", f"[{r.lower:.6g}, {r.upper:.6g}]")
         + ((f"[{r.profile_lower:.6g}, {r.profile_upper:.6g}]",) if profiled else ())
         + ({True: "**yes**", False: "no"}.get(r.non_gaussian, "—"),)
         for r in boot.table.itertuples(index=False)))
    if len(boot.derived):
        lines += ["", "Derived quantities, from each refit's model (σ bootstrap is their only "
                  "sigma; bias in that sigma):", ""]
        lines += markdown.table(
            ("quantity", "value", "σ bootstrap", "bias / σ", "95 % interval"),
            ((r.parameter, f"{r.value:.6g}", f"{r.sigma_boot:.3g}", f"{r.bias_sigma:+.2f}",
              f"[{r.lower:.6g}, {r.upper:.6g}]") for r in boot.derived.itertuples(index=False)))
    return "\n".join(lines) + "\n"


def plot_bootstrap(boot, title: str):
    """Bootstrap sigma over covariance sigma per parameter, with the band a sample std of
    that many refits scatters in (±2 standard errors about 1)."""
    t = boot.table
    fig, ax = figures.subplots(figsize=(7.0, 0.35 * len(t) + 1.5))
    y = np.arange(len(t))
    ax.plot(t["ratio"], y, "o", color="C0")
    n = max(boot.n_converged, 2)
    se = 1.0 / np.sqrt(2.0 * (n - 1))
    ax.axvspan(1 - 2 * se, 1 + 2 * se, color="0.85", zorder=0,
               label=f"±2 standard errors of a std of {n}")
    ax.axvline(1.0, color="0.4", lw=0.8)
    ax.set_yticks(y, t["parameter"])
    ax.invert_yaxis()
    ax.set_xlabel("σ bootstrap / σ covariance")
    ax.set_title(f"Bootstrap: {title}")
    ax.legend(loc="lower right", fontsize="small")
    return fig


def write_bootstrap(boot, title: str, out_dir: str | os.PathLike, *,
                    overwrite: bool = False) -> Path:
    """``report.md``, ``bootstrap.csv`` (per parameter), ``bootstrap_samples.csv`` (per
    refit) and ``bootstrap.png`` (:func:`plot_bootstrap`) in ``out_dir``, atomically."""
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=overwrite, kind="bootstrap") as tmp:
        (tmp / "report.md").write_text(bootstrap_markdown(boot, title), encoding="utf-8")
        boot.table.to_csv(tmp / "bootstrap.csv", index=False)
        boot.samples.to_csv(tmp / "bootstrap_samples.csv", index=False)
        if len(boot.derived):
            boot.derived.to_csv(tmp / "bootstrap_derived.csv", index=False)
        figures.save(plot_bootstrap(boot, title), tmp / "bootstrap.png")
    return out_dir


__all__ = ["bootstrap_markdown", "plot_bootstrap", "plot_hold_one", "plot_quasi_linear",
           "single_fits_lines", "write_bootstrap", "write_hold_one", "write_single_fits"]
