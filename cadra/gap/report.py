"""Files and the one-page report of a gap diagnosis (docs/gap.md)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from cadra.fitting.data import CHANNELS
from cadra.io.atomic import atomic_output_dir

_UNIT = {"x": ("µm", 1e6), "y": ("µm", 1e6), "z": ("µm", 1e6),
         "theta": ("deg", 180 / math.pi), "psi": ("deg", 180 / math.pi)}


def summary_markdown(dg, result) -> str:
    """One page: what (verdict), how much (rms before -> after per channel), where, details."""
    L = ["# Gap diagnosis", "", f"**{dg.verdict}**", "",
         f"Fit: {result.status}, {len(result.shots)} shot(s), chi^2/dof "
         f"{dg.reduced_chi2_before:.3f} -> {dg.reduced_chi2_after:.3f} after the effects "
         "added.", "", "## How much: residual rms per channel", "",
         "| channel | before | after | noise (median sigma) |", "|---|---|---|---|"]
    sig = result.residuals.groupby("channel")["sigma"].median()
    for ch in CHANNELS:
        u, f = _UNIT[ch]
        b, a = dg.rms_before.get(ch, math.nan), dg.rms_after.get(ch, math.nan)
        if math.isnan(b):
            continue
        L.append(f"| {ch} | {b * f:.4g} {u} | {a * f:.4g} {u} | "
                 f"{sig.get(ch, math.nan) * f:.4g} {u} |")
    L += ["", "## Effects added (greedy, each significant)", ""]
    if dg.added:
        L += ["| round | effect | size ± σ | p (F test) | Δχ² |", "|---|---|---|---|---|"]
        for a in dg.added:
            size = "; ".join(f"{n} = {v:.4g} ± {s:.2g}" for n, v, s in
                             zip(a["params"], a["size"], a["sigma"], strict=False))
            L.append(f"| {a['round']} | {a['effect']} | {size} | {a['p_value']:.2g} | "
                     f"{a['dchi2']:.1f} |")
    else:
        L.append("None.")
    worst = (dg.where.assign(sq=dg.where["normalized"] ** 2)
             .groupby(["station", "channel"])["sq"].mean().sort_values(ascending=False))
    L += ["", "## Where the remaining residual lies (largest normalized rms)", "",
          "| station | channel | rms / σ |", "|---|---|---|"]
    for (st, ch), v in worst.head(6).items():
        L.append(f"| {st} | {ch} | {math.sqrt(v):.2f} |")
    L += ["", "## Ranking (first round, best first)", "",
          "| candidate | Δχ² | p (F test) | ΔBIC | size ± σ |", "|---|---|---|---|---|"]
    for _, row in dg.ranking.head(15).iterrows():
        L.append(f"| {row['candidate']} | {row['dchi2']:.1f} | {row['p_value']:.2g} | "
                 f"{row['dbic']:.1f} | {row['size']} |")
    return "\n".join(L) + "\n"


def write_diagnosis(dg, result, out_dir: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """report.md (one page first), ranking.csv, where.csv; atomically."""
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        dg.ranking.to_csv(tmp / "ranking.csv", index=False)
        dg.where.assign(normalized=np.round(dg.where["normalized"], 6)).to_csv(
            tmp / "where.csv", index=False)
        (tmp / "report.md").write_text(summary_markdown(dg, result), encoding="utf-8")
    return out_dir
