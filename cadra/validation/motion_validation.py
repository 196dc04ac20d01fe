"""The seeds' evaluations of the classic angular-motion reductions re-run, as the tables and
figures of ``tools/validate_motion.py``: seed 001 Table II, seed 000 Table 2 and seed 001
Table V (:mod:`cadra.validation.motion_cases`), each noise-free and at the seeds' noise
levels; the classic method's errors beside the paper's, CADRA's beside the classic method's,
CADRA's pulls; then the M-80 case's fraction within 2 sigma (:mod:`cadra.validation.m80`)
and the speed and NPR figures (:mod:`cadra.validation.motion_records`). :func:`run` prints
the tables and returns the figures.
"""

from __future__ import annotations

import numpy as np

from cadra.validation.m80 import DRAWS_IN_VALIDATE_MOTION
from cadra.validation.m80 import run as m80_run
from cadra.validation.motion_cases import (
    T2_000,
    T2_001,
    T5_001,
    noise_free,
    noisy,
    sensitivity,
    simulate,
)
from cadra.validation.motion_records import speed_and_npr

__all__ = ["ratio_cells", "run", "table"]


def fmt(x, nd=3):
    """A table cell: ``nd`` significant digits, "-" for a missing or non-finite value."""
    if x is None or not np.isfinite(x):
        return "-"
    return f"{x:.{nd}g}"


def table(title: str, names, columns: dict) -> None:
    """Print a Markdown table: one row per coefficient in ``names``, one column per entry of
    ``columns`` (coefficient -> value)."""
    print(f"\n{title}")
    print("| coefficient | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for k in names:
        print(f"| {k} | " + " | ".join(fmt(col.get(k)) for col in columns.values()) + " |")


def ratio_cells(ours: dict, paper: dict, label: str) -> list[tuple[float, str]]:
    """(ours / paper, where) for every coefficient with a nonzero paper error."""
    return [(ours[k] / p, f"{label} {k}") for k, p in paper.items() if p and k in ours]


def run(draws: int = 10, seed: int = 1, with_sensitivity: bool = True) -> dict:
    """Every case (module doc) with ``draws`` noise draws per noise level from ``seed``;
    prints the tables and returns the figures (the run time left to the caller)."""
    rng = np.random.default_rng(seed)
    out: dict[str, object] = {}
    over_paper: list[tuple[float, str]] = []
    cadra_over_classic: list[tuple[float, str]] = []
    pull_std: list[tuple[float, str]] = []
    noisy_ratio: list[tuple[float, str]] = []

    for key, case, levels in (
            ("seed001_tableII", T2_001, {"0.05 deg": np.radians(0.05)}),
            ("seed000_table2", T2_000, {"0.25 deg as 3 sigma": np.radians(0.25 / 3),
                                        "0.25 deg as sigma": np.radians(0.25),
                                        "1 deg as 3 sigma": np.radians(1.0 / 3),
                                        "1 deg as sigma": np.radians(1.0)}),
            ("seed001_tableV", T5_001, {})):
        names = list(case.truth)
        rec = simulate(case)
        nf = noise_free(case, rec)
        print(f"\n## {case.name}")
        table("noise-free: % error of each coefficient", names, {
            "input": case.truth, "paper %": case.paper, "classic %": nf["classic"],
            "classic, no freq. corr. %": nf["classic_no_freq"],
            "paper, no freq. corr. %": case.paper_noise.get("nofreq", {}),
            "CADRA 6-DOF %": nf["cadra"],
            "CADRA / classic": {k: nf["cadra"][k] / nf["classic"][k] for k in names}})
        print(f"CADRA fit: {nf['cadra_status']}, {nf['cadra_s']:.1f} s")
        res = {"noise_free": {k: {c: round(v, 5) for c, v in nf[k].items()}
                              for k in ("classic", "classic_no_freq", "cadra")}}
        over_paper += ratio_cells(nf["classic"], case.paper, f"{key} noise-free")
        if "nofreq" in case.paper_noise:
            over_paper += ratio_cells(nf["classic_no_freq"], case.paper_noise["nofreq"],
                                      f"{key} no-freq-corr")
        cadra_over_classic += [(nf["cadra"][k] / nf["classic"][k], f"{key} noise-free {k}")
                               for k in names]
        for label, sig in levels.items():
            n = noisy(case, rec, sig, draws, rng)
            paper = case.paper_noise.get(label.split(" ")[0], {})
            table(f"noise {label} ({n['sigma_deg']:.3g} deg rms), {draws} draws: mean "
                  f"|% error|; CADRA pulls", names, {
                      "paper %": paper, "classic %": n["classic"], "CADRA %": n["cadra"],
                      "CADRA / classic": {k: n["cadra"][k] / n["classic"][k] for k in names},
                      "pull mean": n["pull_mean"], "pull std": n["pull_std"]})
            print(f"CADRA converged {n['n_cadra']}/{draws} ({n['restarts']} restarted), "
                  f"classic {n['n_classic']}/{draws}, mean chi2/nu "
                  f"{n['reduced_chi2_mean']:.3f}")
            for f in n["failures"][:3]:
                print("  failure:", f)
            over_paper += ratio_cells(n["classic"], paper, f"{key} {label}")
            pull_std += [(v, f"{key} {label} {k}") for k, v in n["pull_std"].items()
                         if np.isfinite(v)]
            noisy_ratio += [(n["cadra"][k] / n["classic"][k], f"{key} {label} {k}")
                            for k in names if np.isfinite(n["cadra"][k] / n["classic"][k])]
            res[label] = {k: ({c: round(v, 4) for c, v in n[k].items()}
                              if isinstance(n[k], dict) else n[k])
                          for k in ("classic", "cadra", "pull_mean", "pull_std",
                                    "reduced_chi2_mean", "n_cadra", "n_classic", "restarts")}
        if case.kind == "gimbal" and with_sensitivity:
            sens = sensitivity(case)
            print(f"classic method over {sens.pop('n_variants')} variants of the unstated "
                  "record (spin x1, x1.5; arm split; sections x0.5, 1, 1.5), noise-free % error "
                  "min-max: " + ", ".join(f"{k} {a:.2g}-{b:.2g}" for k, (a, b) in sens.items()))
            res["classic_sensitivity_pct"] = {k: [round(a, 3), round(b, 3)]
                                              for k, (a, b) in sens.items()}
        out[key] = res

    worst = max(over_paper)
    out["classic_over_paper_error_max"] = round(worst[0], 3)
    out["classic_over_paper_error_max_where"] = worst[1]
    worst = max(c for c in over_paper if "noise-free" in c[1] or "no-freq" in c[1])
    out["classic_over_paper_error_max_noise_free"] = round(worst[0], 3)
    out["classic_over_paper_error_max_noise_free_where"] = worst[1]
    out["classic_over_paper_above_2"] = [f"{w} ({r:.2f})" for r, w in over_paper if r > 2]
    worst = max(cadra_over_classic)
    out["cadra_over_classic_error_max"] = float(f"{worst[0]:.3g}")
    out["cadra_over_classic_error_max_where"] = worst[1] + " (noise-free records)"
    if noisy_ratio:
        worst = max(noisy_ratio)
        out["cadra_over_classic_noisy_max"] = round(worst[0], 3)
        out["cadra_over_classic_noisy_max_where"] = worst[1] + " (mean |error| over the draws)"
    if pull_std:
        out["cadra_pull_std_min"] = round(min(pull_std)[0], 3)
        out["cadra_pull_std_max"] = round(max(pull_std)[0], 3)
        out["cadra_pull_std_min_where"] = min(pull_std)[1]
        out["cadra_pull_std_max_where"] = max(pull_std)[1]
        out["cadra_pull_draws"] = draws
    # the M-80 case (tools/validate_m80.py, docs/m80.md): rendered rounds M80-1 and M80-2 ->
    # cadra1 -> the 6-DOF fit of both; the fraction of fitted coefficients within 2 sigma of
    # the truth over a few draws (validate_m80.py --draws 20 for the acceptance's 20)
    m80 = m80_run(draws=DRAWS_IN_VALIDATE_MOTION, film=False, verbose=False)
    out["m80_within_2sigma_frac"] = m80["m80_within_2sigma_frac"]
    out["m80_linear_within_2sigma_frac"] = m80["m80_linear_within_2sigma_frac"]
    out["m80_pull_std"] = {n: r["pull_std"] for n, r in m80["six_dof"].items()}
    out["m80_note"] = (f"{m80['draws']} draws x {len(m80['six_dof'])} coefficients, "
                       "6-DOF fit from images; python tools/validate_m80.py --draws 20 for the "
                       "acceptance's 20 draws")
    print(f"\nM-80: {out['m80_within_2sigma_frac']} of the 6-DOF coefficients within 2 sigma "
          f"({m80['draws']} draws), linear theory {out['m80_linear_within_2sigma_frac']}")
    out |= speed_and_npr(rng)
    print(f"\nclassic over paper > 2: {out['classic_over_paper_above_2']}")
    return out
