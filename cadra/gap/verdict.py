"""One verdict from every test of a fit's residual (docs/gap.md, "The verdict").

:func:`evidence` runs every test of the normalized residual under "the residual is the
measurement noise", in families:

================  =====================================================================
``global``        chi^2 of the whole fit against its degrees of freedom (the noise floor)
``channel``       per channel: sum of squares against the channel's degrees of freedom
``station``       per station and channel: sum over the shots of the squared standardized
                  residual, chi^2 with one degree per shot
``cross_shot``    per station and channel, several shots: their mean standardized residual
                  (z test): the same misfit in every shot, a facility effect
``runs``          per shot and channel: Wald-Wolfowitz runs of sign in station order
``frequency``     per shot, channel and motion: content at the fitted motion's frequencies
================  =====================================================================

The family-wise false-alarm rate is ``alpha`` over all of them together: each family has a
share of ``alpha`` (:data:`SHARES`) split Bonferroni over its tests. A station's residual is
standardized by sqrt(1 - leverage) (the fit absorbs part of each measurement's noise) and by
the channel's own robust scale when that is above 1 (a channel whose sigmas are stated too
small does not make every station look off).

:func:`localized_cells` picks a misfit at a few stations and channels (station or cross-shot
family): one the global chi^2 dilutes. :func:`compose` writes the verdict.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from cadra.fitting.extras import Extra
from cadra.fitting.result import FitResult
from cadra.flight.data import ShotData
from cadra.gap.where import by_group, frequency_content, motion_frequencies, sequence_tests
from cadra.numfmt import pm

#: each family's share of the family-wise alpha (the cross-shot family exists with several
#: shots; with one its share goes to the station family)
SHARES = {"global": 0.3, "channel": 0.1, "station": 0.15, "cross_shot": 0.15, "runs": 0.15,
          "frequency": 0.15}
#: a misfit at more station-channel cells than this is not localized (a broad misfit: the
#: dynamics or the sigmas), and is not set aside
MAX_LOCALIZED = 3
#: display units of the channels in the verdict's sentences
_UNIT = {"x": ("um", 1e6), "y": ("um", 1e6), "z": ("um", 1e6),
         "theta": ("deg", 180 / math.pi), "psi": ("deg", 180 / math.pi),
         "phi": ("deg", 180 / math.pi)}
_POSITION = ("x", "y", "z")


def _standardized(fit: FitResult) -> pd.DataFrame:
    """The residual table with ``u``: normalized residual / sqrt(1 - leverage), divided by
    the channel's robust scale (1.4826 MAD) where that is above 1."""
    rr = fit.residuals
    h = np.nan_to_num(rr["leverage"].to_numpy(float), nan=0.0)
    u = rr["normalized"].to_numpy(float) / np.sqrt(np.clip(1.0 - h, 0.05, 1.0))
    out = pd.DataFrame({"shot_id": rr["shot_id"].to_numpy(), "station": rr["station"].astype(int),
                        "channel": rr["channel"].to_numpy(), "normalized": rr["normalized"],
                        "u": u})
    scale = out.groupby("channel")["u"].transform(
        lambda v: max(1.0, 1.4826 * float(np.median(np.abs(v - np.median(v))))))
    out["u"] = out["u"] / scale
    return out


def evidence(fit: FitResult, shots: Sequence[ShotData], alpha: float = 0.01) -> pd.DataFrame:
    """Every test of ``fit``'s residual (module doc), one row each: ``family``, where
    (``shot_id``, ``station``, ``channel``, ``motion``; empty where not applicable),
    ``statistic``, ``n``, ``mean_sigma`` (station tests: the mean standardized residual),
    ``same_sign`` (every shot's residual of the same sign), ``p_value``, ``p_adjusted``
    (Bonferroni within the family, over the family's share of ``alpha``) and
    ``significant`` (``p_adjusted < alpha``)."""
    w = _standardized(fit)
    n_shots = w["shot_id"].nunique()
    rows = [{"family": "global", "statistic": float(fit.chi2), "n": int(fit.dof),
             "p_value": float(stats.chi2.sf(fit.chi2, max(fit.dof, 1)))}]
    dof = fit.dof_by_channel()
    for ch, grp in w.groupby("channel", sort=False):
        ss = float(np.sum(grp["normalized"].to_numpy(float) ** 2))
        d = max(float(dof.get(ch, len(grp))), 1.0)
        rows.append({"family": "channel", "channel": ch, "statistic": ss, "n": len(grp),
                     "p_value": float(stats.chi2.sf(ss, d))})
    for (st, ch), grp in w.groupby(["station", "channel"], sort=True):
        u = grp["u"].to_numpy(float)
        same = bool(np.all(u > 0) or np.all(u < 0))
        base = {"station": int(st), "channel": ch, "n": u.size, "mean_sigma": float(u.mean()),
                "same_sign": same}
        rows.append({**base, "family": "station", "statistic": float(u @ u),
                     "p_value": float(stats.chi2.sf(u @ u, u.size))})
        if n_shots > 1 and u.size > 1:
            z = float(u.sum() / math.sqrt(u.size))
            rows.append({**base, "family": "cross_shot", "statistic": z,
                         "p_value": float(2 * stats.norm.sf(abs(z)))})
    times = {(s.shot_id, int(st)): float(t) for s in shots
             for st, t in zip(s.stations, s.t_s, strict=True)}
    wt = w.assign(t_s=[times.get((a, int(b)), math.nan)
                       for a, b in zip(w["shot_id"], w["station"], strict=True)])
    for r in sequence_tests(wt).itertuples():
        if r.n >= 4 and math.isfinite(r.runs_p):
            rows.append({"family": "runs", "shot_id": r.shot_id, "channel": r.channel,
                         "statistic": float(r.runs), "n": int(r.n), "p_value": float(r.runs_p)})
    fr = frequency_content(wt, motion_frequencies(fit, shots))
    for r in fr.itertuples():
        rows.append({"family": "frequency", "shot_id": r.shot_id, "channel": r.channel,
                     "motion": r.motion, "statistic": float(r.dchi2), "n": 2,
                     "mean_sigma": float(r.amplitude_sigma), "p_value": float(r.p_value)})
    ev = pd.DataFrame(rows)
    for col in ("shot_id", "channel", "motion"):
        if col not in ev:
            ev[col] = ""
        ev[col] = ev[col].fillna("")
    shares = dict(SHARES)
    if n_shots < 2:
        shares["station"] += shares.pop("cross_shot")
    size = ev.groupby("family")["p_value"].transform("size")
    share = ev["family"].map(shares).fillna(0.0)
    ev["p_adjusted"] = np.minimum(1.0, ev["p_value"] * size / share.where(share > 0, np.nan)
                                  ).fillna(1.0)
    ev["significant"] = ev["p_adjusted"] < alpha
    return ev.sort_values(["significant", "p_adjusted"], ascending=[False, True],
                          kind="stable").reset_index(drop=True)


def localized_cells(ev: pd.DataFrame) -> list[dict]:
    """The station-channel cells where the station or cross-shot test is significant, most
    significant first, when there are at most :data:`MAX_LOCALIZED` of them (else a broad
    misfit: none). Each: station, channel, mean_sigma, n, same_sign, p_adjusted."""
    sig = ev[ev["significant"] & ev["family"].isin(["station", "cross_shot"])]
    cells = []
    for r in sig.sort_values("p_adjusted", kind="stable").itertuples():
        key = (int(r.station), r.channel)
        if key not in [(c["station"], c["channel"]) for c in cells]:
            cells.append({"station": key[0], "channel": key[1], "mean_sigma": r.mean_sigma,
                          "n": int(r.n), "same_sign": bool(r.same_sign),
                          "p_adjusted": float(r.p_adjusted)})
    return cells if len(cells) <= MAX_LOCALIZED else []


def offset_name(cell: dict) -> str:
    return f"unexplained_st{cell['station']}_{cell['channel']}"


def offset_extras(cells: Sequence[dict]) -> list[Extra]:
    """An offset of each cell's channel at its station (shared by every shot through it)."""
    return [Extra(offset_name(c), station=c["station"],
                  measure=("position_" if c["channel"] in _POSITION else "angle_")
                  + c["channel"]) for c in cells]


def covers(cand, cells: Sequence[dict]) -> bool:
    """The candidate is the same term as one of the cells' offsets (a station's position
    bias in that channel)."""
    return cand.kind == "measurement" and any(
        cand.station == c["station"] and cand.measure == f"position_{c['channel']}"
        for c in cells)
#: how a refit that did not converge ended, for the verdict
_HOW = {"stalled": "stalled", "max_iterations": "ran out of iterations", "linear": "was not run"}


def _fmt_interval(iv) -> str:
    lo, hi = iv[:2]
    return f"[{lo:.4g}, {hi:.4g}]".replace("inf", "open")


def size_text(a: dict) -> str:
    """An added effect's sizes for the verdict: value ± sigma, or, where the refit did not
    converge, the profile interval (or the warning that the sigma may be far too small)."""
    ivs = a.get("interval_2sigma")
    parts = []
    for k, (n, v, s) in enumerate(zip(a["params"], a["size"], a["sigma"], strict=False)):
        if ivs is not None and ivs[k] is not None:
            parts.append(f"{n} = {v:.4g} (2-sigma profile interval {_fmt_interval(ivs[k])})")
        else:
            parts.append(f"{n} = {pm(v, s)}")
    text = ", ".join(parts)
    if a["refit_status"] != "converged":
        how = _HOW.get(a["refit_status"], "failed")
        ivs = [iv for iv in (ivs or []) if iv is not None]
        if ivs and all(iv[2] for iv in ivs):
            text += f" [the refit {how}: the size is poorly determined; the profile interval is"
            text += " what the data allow]"
        elif ivs:
            text += (f" [size poorly determined: the refit {how}, and so did some of the "
                     "profile's held fits: the interval may still be too narrow]")
        else:
            text += (f" [size poorly determined: the refit {how}; its sigma is a "
                     "linearization and may be far too small]")
    return text




#: what the verdict says of a freed held parameter (:func:`held_verdict`)
HELD_VERDICTS = ("inconsistent", "indistinguishable", "misfit_standing")


def held_verdict(a: dict, unexplained: bool) -> str:
    """What the verdict may say of an added held-parameter effect ``a``: ``"inconsistent"``
    only when freeing it leaves no misfit standing and no other candidate explains as much;
    ``"indistinguishable"`` when another candidate does (its aliases); ``"misfit_standing"``
    when a misfit no library effect explains stays (a localized, periodic or global one):
    the freed value may then only be absorbing part of that misfit, so the hold is not
    blamed (docs/gap.md, "Held parameters")."""
    if unexplained:
        return "misfit_standing"
    return "indistinguishable" if a.get("aliases") else "inconsistent"


def _held_text(a: dict) -> str:
    name = a["params"][0]
    held = f"held {name} = {a.get('held_value', math.nan):.4g}"
    prefer = size_text(a).split(" = ", 1)[1]
    how = a.get("held_verdict", "inconsistent")
    if how == "misfit_standing":
        return (f"freeing {held} lowers chi^2 (the data would put it at {prefer}), but a misfit "
                "that no library effect explains stays: the hold is not shown inconsistent, "
                "the freed value may only absorb part of that misfit")
    if how == "indistinguishable":
        text = (f"either {held} is inconsistent with these data (they prefer {prefer}) or "
                f"{' / '.join(a['aliases'])}: these data cannot tell them apart")
    else:
        text = f"{held} is inconsistent with these data (the data prefer {prefer})"
    moved = [n for n, _ in a.get("moved", [])][:4]
    if moved:
        text += (f"; the sigmas of {' and '.join(moved)} are not valid while it is held "
                 f"(freeing it moves them by "
                 + ", ".join(f"{s:+.1f}" for _, s in a["moved"][:4]) + " sigma)")
    return text


def _effect_text(a: dict) -> str:
    if a["kind"] == "held":
        return _held_text(a)
    text = a["effect"]
    if a.get("aliases"):
        text += f" (or, indistinguishable on these data, {' / '.join(a['aliases'])})"
    text += ": " + size_text(a)
    form = a.get("form")
    if form is not None:
        text += (f" [{form['chosen']}: BIC change {form['dbic_chosen']:.1f} against "
                 f"{form['dbic_other']:.1f} for the {form['other']}"
                 + ("" if form["other_refit"] else " (linear score)") + "]")
    return text


def _cell_text(cell: dict, fit: FitResult | None) -> str:
    ch = cell["channel"]
    unit, f = _UNIT.get(ch, ("", 1.0))
    text = f"station {cell['station']} {ch}"
    name = offset_name(cell)
    if fit is not None and name in fit.param_names:
        text += f": offset {pm(fit.value(name) * f, fit.sigma(name) * f, unit)}"
    n = cell["n"]
    text += (f" (mean residual {cell['mean_sigma']:+.1f} sigma"
             + (f" over {n} shots" if n > 1 else "")
             + (", same sign in every shot" if n > 1 and cell["same_sign"] else "")
             + f"; p = {cell['p_adjusted']:.1g} after every test is counted)")
    return text


def _finding_text(r) -> str:
    """A significant test of the final residual, in a sentence."""
    p = f"p = {r.p_adjusted:.1g} after every test is counted"
    if r.family == "channel":
        return f"channel {r.channel} (sum of squares {r.statistic:.1f} over {r.n}; {p})"
    if r.family in ("station", "cross_shot"):
        return (f"station {int(r.station)} {r.channel} (mean {r.mean_sigma:+.1f} sigma; {p})")
    if r.family == "runs":
        return (f"{r.shot_id} {r.channel}: {int(r.statistic)} runs of sign in {r.n} stations "
                f"({p})")
    if r.family == "frequency":
        return (f"{r.shot_id} {r.channel}: content at the {r.motion} frequency, amplitude "
                f"{r.mean_sigma:.1f} sigma ({p})")
    return ""


def compose(added: Sequence[dict], dropped: Sequence[dict], set_aside: Sequence[dict],
            ev: pd.DataFrame, fit: FitResult, base_note: str, rchi0: float,
            ranking: pd.DataFrame | None) -> tuple[str, bool]:
    """The verdict sentence and whether a gap is left unexplained: the effects added (each
    held-parameter one marked with its ``held_verdict``, :func:`held_verdict`), the
    misfits set aside (unexplained, where), what else the final residual's tests find, the
    effects that left a misfit standing, and how the fit given was continued."""
    unexplained_parts = ["unexplained, at " + _cell_text(c, fit) for c in set_aside]
    sig = ev[ev["significant"]]
    glob = sig[sig["family"] == "global"]
    if len(glob):
        worst = by_group(pd.DataFrame({"station": fit.residuals["station"],
                                       "channel": fit.residuals["channel"],
                                       "normalized": fit.residuals["normalized"]}),
                         ["station", "channel"]).head(3)
        top = ", ".join(f"station {r.station} {r.channel} ({r.rms_normalized:.1f} sigma rms)"
                        for r in worst.itertuples())
        unexplained_parts.append(
            f"unexplained: the residual stays above the noise floor (chi^2/dof = "
            f"{fit.reduced_chi2:.2f}, p = {float(glob['p_value'].iloc[0]):.1e}); it lies "
            f"mostly at {top}")
    others = [_finding_text(r) for r in sig[sig["family"] != "global"].itertuples()]
    others = [t for t in others if t][:4]
    if others:
        unexplained_parts.append(("unexplained patterns in the residual: " if not len(glob)
                                  else "also ") + "; ".join(others))
    unexplained = bool(unexplained_parts)
    for a in added:
        if a["kind"] == "held":
            a["held_verdict"] = held_verdict(a, unexplained)
    parts = [_effect_text(a) for a in added]
    text = "; ".join(parts + unexplained_parts)
    if added and not unexplained:
        text += f" (chi^2/dof {rchi0:.2f} -> {fit.reduced_chi2:.2f})"
    if dropped:
        text += "; " + "; ".join(
            f"{a['effect']} was tried but leaves the misfit at "
            + ", ".join(f"station {c['station']} {c['channel']}" for c in set_aside)
            + " standing: not the explanation" for a in dropped)
    if not text:
        best = ranking.iloc[0] if ranking is not None and len(ranking) else None
        text = (f"no significant unmodelled effect (chi^2/dof = {rchi0:.2f}; best candidate "
                f"{best['candidate'] if best is not None else '-'}, p = "
                f"{best['p_value'] if best is not None else 1:.2g}; every test of the "
                "residual passes)")
    if base_note:
        text = f"{text} [{base_note}]"
    return text, unexplained


__all__ = ["HELD_VERDICTS", "MAX_LOCALIZED", "SHARES", "compose", "covers", "evidence",
           "held_verdict", "localized_cells", "offset_extras", "offset_name", "size_text"]
