"""The outputs of the next-shot planner (:mod:`cadra.studies.design`): its report, its tables
and the plot of predicted sigma against the candidates' launch angle and Mach
(docs/design.md)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.atomic import atomic_output_dir
from cadra.report import figures, markdown
from cadra.studies.candidates import DIMENSIONS

__all__ = ["plan_markdown", "plot_plan", "sequence_table", "write_plan"]

#: file units of the candidates' dimensions (their names carry them)
_LABELS = {"angle_deg": "launch angle (deg)", "rate_deg_s": "launch rate (deg/s)",
           "mach": "Mach", "roll_deg": "roll (deg)", "cg_shift_mm": "cg shift (mm)",
           "stations": "stations"}


def _shown(plan) -> tuple[str, str]:
    """(column, label) the plot colours by: the first target's predicted sigma, or the
    objective."""
    p = plan.planner
    if p.criterion == "sigmas":
        return f"sigma_{p.targets[0]}", f"predicted σ of {p.targets[0]} (SI)"
    return "objective", f"objective ({p.criterion}-optimal; 1 = no gain)"


def plot_plan(plan):
    """Left: every sampled candidate at its launch angle and Mach, coloured by the first
    target's predicted sigma (or the objective), the best ones starred. Right: that figure
    against the launch angle, with the group's sigma now."""
    col, label = _shown(plan)
    t = plan.sampled
    t = t[np.isfinite(t["objective"])]
    fig, (a, b) = figures.subplots(1, 2, figsize=(11.0, 4.2))
    sc = a.scatter(t["angle_deg"], t["mach"], c=t[col], s=12, cmap="viridis_r")
    fig.colorbar(sc, ax=a, label=label)
    a.plot(plan.best["angle_deg"], plan.best["mach"], "*", color="C3", ms=12,
           label="best (after the search)")
    base = plan.planner.template.base
    a.plot([base.angle_deg], [base.mach], "s", color="k", ms=6, mfc="none",
           label=f"template {plan.planner.template.shot.shot_id}")
    a.set_xlabel(_LABELS["angle_deg"])
    a.set_ylabel(_LABELS["mach"])
    a.legend(fontsize="small")
    b.plot(t["angle_deg"], t[col], ".", color="C0", ms=4, label="candidates")
    b.plot(plan.best["angle_deg"], plan.best[col], "*", color="C3", ms=12, label="best")
    if col != "objective":
        now = plan.planner.sigma_now[plan.planner.names.index(plan.planner.targets[0])]
        b.axhline(now, color="0.4", lw=0.8, ls="--", label="now")
    else:
        b.axhline(1.0, color="0.4", lw=0.8, ls="--", label="now")
    b.set_xlabel(_LABELS["angle_deg"])
    b.set_ylabel(label)
    b.legend(fontsize="small")
    fig.suptitle("What to fire next: predicted sigma after one more shot")
    return fig


def plan_markdown(plan, title: str) -> str:
    """The plan's report: the search, the best candidates with what each moves, and every
    shared unknown's sigma now and after each of them (SI)."""
    p = plan.planner
    lines = [f"# What to fire next: {title}", "",
             "```", plan.report(), "```", "",
             "The best candidates (objective: a variance ratio, 1 = no gain; the angles their "
             "motion sweeps over its stations):", ""]
    lines += markdown.table(
        ("#",) + tuple(_LABELS[n] for n in DIMENSIONS) + ("objective", "sweeps (deg)",
                                                          "moves"),
        ((i + 1,) + tuple(f"{r[n]:.4g}" for n in DIMENSIONS)
         + (f"{r['objective']:.4g}", f"{r['flown_min_deg']:.1f}–{r['flown_max_deg']:.1f}",
            ", ".join(f"{n} −{100 * d:.0f} %" for n, d in plan.moves(r)) or "—")
         for i, r in plan.best.iterrows()))
    lines += ["", "Sigmas now and after each of the best (SI):", ""]
    tab = plan.sigmas()
    cols = [c for c in tab.columns if c.startswith("best_")]
    lines += markdown.table(
        ("parameter", "value", "σ now") + tuple(c.replace("_", " ") for c in cols),
        ((r["parameter"], f"{r['value']:.6g}", f"{r['sigma_now']:.3g}")
         + tuple(f"{r[c]:.3g}" for c in cols) for _, r in tab.iterrows()))
    lines += ["", f"Criterion: {p.criterion}"
              + (f" (targets {', '.join(p.targets)})" if p.targets else "") + "."]
    return "\n".join(lines) + "\n"


def sequence_table(plans) -> pd.DataFrame:
    """Shots chosen one after another (:func:`cadra.studies.design.sequence`): per shot its
    candidate, objective and every unknown's predicted sigma once it and those before it
    are fired."""
    rows = []
    for k, pl in enumerate(plans, start=1):
        r = pl.best.iloc[0]
        rows.append({"shot": k, **{n: r[n] for n in DIMENSIONS}, "objective": r["objective"],
                     **{c: r[c] for c in pl.best.columns if c.startswith("sigma_")}})
    return pd.DataFrame(rows)


def write_plan(plans, title: str, out_dir: str | os.PathLike, *,
               overwrite: bool = False) -> Path:
    """``report.md``, ``candidates.csv`` (every scored candidate), ``best.csv``,
    ``sigmas.csv`` and ``plan.png`` (:func:`plot_plan`) of a plan in ``out_dir``,
    atomically; ``plans`` one plan or the plans of shots chosen one after another (the
    first's files, and ``sequence.csv``: :func:`sequence_table`)."""
    out_dir = Path(out_dir)
    plans = list(plans) if isinstance(plans, list | tuple) else [plans]
    plan = plans[0]
    with atomic_output_dir(out_dir, overwrite=overwrite, kind="plan") as tmp:
        text = plan_markdown(plan, title)
        if len(plans) > 1:
            seq = sequence_table(plans)
            seq.to_csv(tmp / "sequence.csv", index=False)
            tg = plan.planner.targets or plan.planner.names
            text += "\n## Shots one after another\n\n" + "\n".join(markdown.table(
                ("shot", "launch angle (deg)", "rate (deg/s)", "Mach", "stations", "objective")
                + tuple(f"σ {t}" for t in tg),
                ((r["shot"], f"{r['angle_deg']:.3g}", f"{r['rate_deg_s']:.3g}",
                  f"{r['mach']:.3g}", int(r["stations"]), f"{r['objective']:.4g}")
                 + tuple(f"{r[f'sigma_{t}']:.3g}" for t in tg)
                 for _, r in seq.iterrows()))) + "\n"
        (tmp / "report.md").write_text(text, encoding="utf-8")
        plan.table.to_csv(tmp / "candidates.csv", index=False)
        plan.best.to_csv(tmp / "best.csv", index=False)
        plan.sigmas().to_csv(tmp / "sigmas.csv", index=False)
        figures.save(plot_plan(plan), tmp / "plan.png")
    return out_dir
