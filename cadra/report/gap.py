"""Files and the one-page report of a gap diagnosis (docs/gap.md)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from cadra.atomic import atomic_output_dir
from cadra.channels import BY_NAME, NAMES
from cadra.gap.score import size_text
from cadra.gap.where import by_group
from cadra.report import figures, markdown


def summary_markdown(dg, result, where_tables=None) -> str:
    """One page: what (verdict), how much (rms before -> after per channel), where, details."""
    L = ["# Gap diagnosis", "", f"**{dg.verdict}**", "",
         f"Fit: {result.status}, {len(result.shots)} shot(s), chi^2/dof "
         f"{dg.reduced_chi2_before:.3f} -> {dg.reduced_chi2_after:.3f} after the effects "
         "added.", "", "## How much: residual rms per channel", ""]
    sig = result.residuals.groupby("channel")["sigma"].median()
    final = dg.fit_after if dg.fit_after is not None else result
    floor, dof = final.noise_floor(), final.dof_by_channel()
    rows = []
    for ch in NAMES:
        c = BY_NAME[ch]
        u, f = c.residual_label, c.residual_scale
        b, a = dg.rms_before.get(ch, math.nan), dg.rms_after.get(ch, math.nan)
        if math.isnan(b):
            continue
        rows.append((ch, f"{b * f:.4g} {u}", f"{a * f:.4g} {u}",
                     f"{floor.get(ch, math.nan) * f:.4g} {u}",
                     f"{sig.get(ch, math.nan) * f:.4g} {u}", f"{dof.get(ch, math.nan):.1f}"))
    L += markdown.table(("channel", "before", "after", "noise floor after", "σ (median)",
                         "dof after"), rows)
    L += ["", "Noise floor: the rms a correct model leaves on noise of the stated σ, "
          "σ√(1 − leverage) (the fit absorbs the rest); dof: the channel's share of the "
          "degrees of freedom. A channel with few (many free parameters act on it) has an rms "
          "that scatters widely from fit to fit: about 1/√(2 dof) relative."]
    L += _evidence_section(dg)
    L += ["", "## Effects added (greedy, each significant)", ""]
    if dg.added:
        rows = []
        for a in dg.added:
            size = size_text(a)
            if a.get("aliases"):
                size += f"; indistinguishable here: {', '.join(a['aliases'])}"
            rows.append((a["round"], a["effect"], size, f"{a['p_value']:.2g}",
                         f"{a['dchi2']:.1f}"))
        L += markdown.table(("round", "effect", "size ± σ", "p (F test)", "Δχ²"), rows)
    else:
        L.append("None.")
    worst = by_group(dg.where, ["station", "channel"]).head(6)
    L += ["", "## Where the remaining residual lies (largest normalized rms)", ""]
    L += markdown.table(("station", "channel", "rms / σ"),
                        ((r.station, r.channel, f"{r.rms_normalized:.2f}")
                         for r in worst.itertuples()))
    if where_tables is not None:
        L += ["", "## Where the fit as given misses (tests on its normalized residual)", ""]
        L += [f"- {x}" for x in where_tables["findings"]] or ["- no significant runs, "
                                                             "autocorrelation, motion-frequency "
                                                             "or cross-shot pattern"]
        L += ["", "rms / σ per channel: " + ", ".join(
            f"{r['channel']} {r['rms_normalized']:.2f}"
            for _, r in where_tables["by_channel"].iterrows()),
              "", "Tables: where_sequence.csv (runs, lag-1 autocorrelation), "
              "where_frequency.csv (pitch / yaw / roll content), where_cross_shot.csv, "
              "where_by_station.csv, where_stage_one.csv (when stage one's files are given); "
              "plot: where.png."]
    L += ["", "## Ranking (first round, best first)", ""]
    L += markdown.table(
        ("candidate", "Δχ²", "p (adjusted)", "ΔBIC", "refit", "size ± σ"),
        ((row["candidate"] + (" (alias of the first)" if row.get("alias_of_best", False)
                              else ""),
          f"{row['dchi2']:.1f}", f"{row['p_adjusted']:.2g}", f"{row['dbic']:.1f}",
          "yes" if row["refit"] else "linear", row["size"])
         for _, row in dg.ranking.head(15).iterrows()))
    return "\n".join(L) + "\n"


def _evidence_section(dg) -> list[str]:
    """Every test of the final residual, by family, with the family-wise level; the
    misfits set aside, the effects they ruled out, how the fit given was continued."""
    ev = dg.evidence
    if ev is None or not len(ev):
        return []
    L = ["", "## Every test of the residual after the effects (family-wise α over them all)",
         ""]
    L += markdown.table(("family", "tests", "significant", "smallest p (adjusted)"),
                        ((fam, len(grp), int(grp["significant"].sum()),
                          f"{grp['p_adjusted'].min():.2g}")
                         for fam, grp in ev.groupby("family", sort=False)))
    L += ["", "Families: global χ²; per channel; per station and channel (χ² over the shots); "
          "cross-shot repetition (mean over the shots, z test); runs of sign; content at the "
          "motion frequencies. Each has a share of α, split over its tests (docs/gap.md). "
          "All tests: evidence.csv."]
    if dg.set_aside:
        L += ["", "Set aside as unexplained (a misfit at a few stations that stood after the "
              "effects; fitted as an offset there and the ranking redone): "
              + ", ".join(f"station {c['station']} {c['channel']}" for c in dg.set_aside)
              + "."]
    for a in dg.dropped:
        L.append(f"- {a['effect']} was added first but left that misfit standing: not the "
                 "explanation.")
    if dg.base_note:
        L += ["", f"Note: {dg.base_note}."]
    return L


def plot_where(dg, result, path) -> None:
    """Normalized residual per station and channel (mean over shots), before and after the
    effects were added: where the gap lies, at a glance."""
    before = result.residuals.groupby(["station", "channel"])["normalized"].mean().unstack()
    after = dg.where.groupby(["station", "channel"])["normalized"].mean().unstack()
    chans = [c for c in NAMES if c in before.columns]
    fig, axes = figures.subplots(1, 2, figsize=(9, 4.5), sharey=True)
    lim = max(3.0, float(np.nanmax(np.abs(before[chans].to_numpy()))))
    for ax, table, title in ((axes[0], before, "fit as given"),
                             (axes[1], after, "after the effects added")):
        data = table.reindex(columns=chans).to_numpy(float)
        im = ax.imshow(data, aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim,
                       extent=(-0.5, len(chans) - 0.5, table.index.max() + 0.5,
                               table.index.min() - 0.5))
        ax.set_xticks(range(len(chans)), chans)
        ax.set_title(title)
        ax.set_xlabel("channel")
    axes[0].set_ylabel("station")
    fig.colorbar(im, ax=axes, label="mean residual / σ")
    fig.suptitle("Where the residual lies")
    figures.save(fig, path)


def write_diagnosis(dg, result, out_dir: str | os.PathLike, *, overwrite: bool = False,
                    where_tables: dict | None = None) -> Path:
    """report.md (one page first), ranking.csv, where.csv (residual after the effects), the
    "where" tables of the fit as given (``where_tables``, :func:`cadra.gap.where.where_analysis`)
    and where.png; atomically."""
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=overwrite,
                           kind="diagnosis") as tmp:
        dg.ranking.to_csv(tmp / "ranking.csv", index=False)
        if dg.evidence is not None:
            dg.evidence.to_csv(tmp / "evidence.csv", index=False)
        dg.where.assign(normalized=np.round(dg.where["normalized"], 6)).to_csv(
            tmp / "where.csv", index=False)
        for key, table in (where_tables or {}).items():
            if key != "findings" and key != "by_channel":
                table.to_csv(tmp / f"where_{key}.csv", index=False)
        plot_where(dg, result, tmp / "where.png")
        (tmp / "report.md").write_text(summary_markdown(dg, result, where_tables),
                                       encoding="utf-8")
    return out_dir
