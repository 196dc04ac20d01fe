"""The summaries of the gap validation's trials: a line per case and the figures of a run.

The rows are :func:`cadra.validation.gap_trials.run_trial`'s. Per library effect: the top-1
rate (the injected effect ranks first; with aliases, also when it is named as
indistinguishable from the first), the size within 2 sigma (a body pair by its magnitude,
and as a vector in the fit's frame beside it), the shrink ratio (max over channels of the
residual rms after the diagnosis over that of a fit of the same shot and noise without the
effect; pooled over the trials; against the diagnosis' final model fitted from the truth;
the fraction of trials above SHRINK_LIMIT beside the fraction a perfect diagnosis would
have, with its tail probability), the rate at which the effect mattered. Null shots: the
rate of "no significant effect"; out of library: reported unexplained with an injected
station/channel named. The extended cases each by their own criterion (:func:`extended_ok`).
"""

from __future__ import annotations

import math

import numpy as np

from cadra.validation.gap_cases import BODY_PAIRS, PAIR_CASES
from cadra.validation.gap_scoring import (
    SHRINK_LIMIT,
    dchi2_expected,
    exceed_expected,
    exceed_observed,
    exceed_pvalue,
    pooled_shrink,
)
from cadra.validation.gap_trials import EXTENDED_CASES, WHERE_ONLY_LAMBDA

__all__ = ["case_line", "extended_ok", "summarize", "trial_notes"]


def extended_ok(case, r) -> bool:
    """Did one trial of an extended case (:data:`~cadra.validation.gap_trials.EXTENDED_CASES`)
    pass its criterion?"""
    if case in PAIR_CASES:
        return r["both_named"]
    if case == "where_only":
        return r["where_found"]
    if case == "held_null":
        return r["clean"] and not r["held_flag"]
    if case == "held":
        return r["flagged"]
    return r["top1_alias"] and r["size_ok"]


def _extended_line(case, rows) -> str:
    """The summary line of an extended case's trials."""
    ok = np.mean([extended_ok(case, r) for r in rows])
    if case == "where_only":
        bs = np.abs([r["bias_sigmas"] for r in rows])
        return (f"found at the right station and channel (unexplained there, or the right "
                f"station effect) {ok:.2f}; the global chi^2 alone passes in "
                f"{np.mean([r['global_passes'] for r in rows]):.2f}; bias {bs.min():.2f}-"
                f"{bs.max():.2f} sigma (noncentrality {WHERE_ONLY_LAMBDA[0]:g}-"
                f"{WHERE_ONLY_LAMBDA[1]:g})")
    if case == "held_null":
        return (f"clean {np.mean([r['clean'] for r in rows]):.2f}, a held parameter flagged "
                f"{np.mean([r['held_flag'] for r in rows]):.2f}")
    if case in PAIR_CASES:
        return f"both effects named {ok:.2f}"
    rchi = [r["base_rchi2"] for r in rows]
    line = (f"named first (or as its alias) with its size within 2 sigma {ok:.2f}; first "
            f"{np.mean([r['top1'] for r in rows]):.2f}, first or alias "
            f"{np.mean([r['top1_alias'] for r in rows]):.2f}, flagged anywhere "
            f"{np.mean([r['flagged'] for r in rows]):.2f}, size within 2 sigma "
            f"{np.mean([r['size_ok'] for r in rows]):.2f}; chi^2/dof of the fit without it "
            f"{min(rchi):.3g}-{max(rchi):.3g}")
    if case == "strong":
        line += (f"; base fit short of convergence at the default budget in "
                 f"{sum(r['fit_status'] != 'converged' for r in rows)} of {len(rows)}")
    return line


def _extended_summary(per) -> dict:
    """The extended cases' keys of the summary (NaN for a case not run)."""
    def rate(case, key):
        rows = per.get(case)
        return float(np.mean([r[key] for r in rows])) if rows else math.nan

    pairs = [c for c in PAIR_CASES if c in per]
    nulls = [r for c in ("null", "held_null") for r in per.get(c, [])]
    out = {
        "where_only_found_rate": rate("where_only", "where_found"),
        "where_only_global_pass_rate": rate("where_only", "global_passes"),
        "strong_effect_diagnosed_rate": (
            float(np.mean([extended_ok("strong", r) for r in per["strong"]]))
            if "strong" in per else math.nan),
        "strong_effect_named_rate": rate("strong", "top1_alias"),
        "shared_density_top1_rate": (
            float(np.mean([extended_ok("shared_density", r) for r in per["shared_density"]]))
            if "shared_density" in per else math.nan),
        "held_param_flag_rate": rate("held", "flagged"),
        "held_param_false_flag_rate": (float(np.mean([r["held_flag"] for r in nulls]))
                                       if nulls else math.nan),
        "held_null_clean_rate": rate("held_null", "clean"),
        "pair_both_named_rate": (min(rate(c, "both_named") for c in pairs) if pairs
                                 else math.nan),
        "pair_both_named_by_case": {c: rate(c, "both_named") for c in pairs},
    }
    return out


def case_line(case: str, rows, n_redrawn: int = 0) -> str:
    """The summary line of one case's trials (``n_redrawn``: the draws that did not matter,
    drawn again), after the case's name."""
    if case in EXTENDED_CASES:
        line = _extended_line(case, rows)
    elif case == "null":
        line = f"clean {np.mean([r['clean'] for r in rows]):.2f}"
    elif case == "out_of_library":
        line = (f"unexplained {np.mean([r['unexplained'] for r in rows]):.2f}, "
                f"where named {np.mean([r['where_ok'] for r in rows]):.2f}")
    else:
        sr = [r["shrink_ratio"] for r in rows if math.isfinite(r["shrink_ratio"])]
        sb = [r["after_vs_truth_start"] for r in rows
              if math.isfinite(r["after_vs_truth_start"])]
        line = (f"top-1 {np.mean([r['top1'] for r in rows]):.2f} (with aliases "
                f"{np.mean([r['top1_alias'] for r in rows]):.2f}), size within 2 sigma "
                f"{np.mean([r['size_ok'] for r in rows]):.2f}, shrink ratio max "
                f"{max(sr) if sr else math.nan:.3f} (pooled over the trials "
                f"{pooled_shrink(rows):.3f}; against the same model fitted from the "
                f"truth {max(sb) if sb else math.nan:.3f}; above {SHRINK_LIMIT} in "
                f"{exceed_observed(rows):.2f} of the trials, where a perfect diagnosis "
                f"would be in {exceed_expected(rows):.2f}, p = "
                f"{exceed_pvalue(rows):.2g}), effect matters "
                f"{np.mean([r['matters'] for r in rows]):.2f} ({n_redrawn} draws "
                "that did not matter drawn again)")
    per_p = [r["size_ok_per_parameter"] for r in rows if "size_ok_per_parameter" in r]
    if per_p and case not in BODY_PAIRS:
        line += f"; each parameter alone within 2 sigma {np.sum(per_p) / len(rows):.2f}"
    vec = [r["size_ok_vector"] for r in rows if "size_ok_vector" in r]
    if vec:
        line += (f"; the pair as a vector in the fit's frame (direction too) "
                 f"{np.sum(vec) / len(rows):.2f}")
    return f"{case:16s} {line}"


def trial_notes(case: str, rows, verbose: bool = False) -> list[str]:
    """The lines printed under a case's summary line: each trial that failed its case's
    criterion (the effect not ranked first, a null shot not clean, an effect outside the
    library not found where it lies) with its verdict; ``verbose``: also each trial whose
    effect ranked first with its size or shrink ratio failing."""
    notes = []
    for r in rows:
        if case in EXTENDED_CASES:
            if not extended_ok(case, r):
                notes.append(f"    {r['shot']} (fit {r['fit_status']}, chi^2/dof "
                             f"{r['base_rchi2']:.3g}): {r['verdict'][:240]}")
            continue
        if verbose and case not in ("null", "out_of_library") and r["top1"] and (
                not r["size_ok"] or r["shrink_ratio"] > SHRINK_LIMIT):
            chi2s = "/".join(f"{x:.1f}" for x in r["chi2_after_best_clean"])
            notes.append(f"    {r['shot']} (size ok {r['size_ok']}, shrink "
                         f"{r['shrink_ratio']:.3f} (linearized "
                         f"{r.get('shrink_ratio_linear', math.nan):.3f}, P(> {SHRINK_LIMIT}) "
                         f"{r.get('shrink_exceed_prob', math.nan):.2f}), against the fit "
                         "from the truth "
                         f"{r['after_vs_truth_start']:.3f}; chi^2 after / from the truth / "
                         f"clean {chi2s}, fit {r['fit_status']}, after "
                         f"{r['after_status']}): {r['verdict'][:200]}")
        if (case not in ("null", "out_of_library") and not r["top1"]) or (
                case == "null" and not r["clean"]) or (
                case == "out_of_library" and not r["where_ok"]):
            notes.append(f"    {r['shot']} (fit {r['fit_status']}, rms "
                         f"x{r['rms_raise']:.2f}, shift {r['shift_sigma']:.1f} sigma): "
                         f"{r['verdict'][:160]}")
    return notes


def summarize(per: dict, redrawn: dict, trials: int) -> dict:
    """The figures of a validation run (the JSON line's keys up to
    ``seconds_per_diagnosis``): ``per`` the rows by case, in the order run, ``redrawn``
    the draws drawn again by case, ``trials`` per case. Rates per case and their
    minimum over the library effects; the shrink ratio, pooled, against the fit from the
    truth and against its linearized prediction; the chi^2 change after the diagnosis and
    what a perfect diagnosis gives; the null, out-of-library and extended cases' rates;
    the median time per diagnosis."""
    cases = list(per)
    eff = [c for c in cases if c not in ("null", "out_of_library") and c not in EXTENDED_CASES]
    return {
        "trials_per_case": trials,
        "top1_rate_min": min((np.mean([r["top1"] for r in per[c]]) for c in eff),
                             default=math.nan),
        "top1_rate_by_case": {c: float(np.mean([r["top1"] for r in per[c]])) for c in eff},
        "top1_alias_rate_min": min((np.mean([r["top1_alias"] for r in per[c]]) for c in eff),
                                   default=math.nan),
        "size_within_2sigma_by_case": {c: float(np.mean([r["size_ok"] for r in per[c]]))
                                       for c in eff},
        # each parameter alone within 2 sigma: what the effect-as-a-vector score replaced
        # for effects of more than one parameter (kept to compare)
        "size_per_parameter_by_case": {
            c: float(np.sum([r["size_ok_per_parameter"] for r in per[c]
                             if "size_ok_per_parameter" in r]) / len(per[c])) for c in eff},
        "size_as_vector_by_case": {
            c: float(np.sum([r["size_ok_vector"] for r in per[c]
                             if "size_ok_vector" in r]) / len(per[c]))
            for c in eff if c in BODY_PAIRS},
        "matters_rate_by_case": {c: float(np.mean([r["matters"] for r in per[c]]))
                                 for c in cases},
        "redrawn_by_case": redrawn,
        "size_within_2sigma_rate_min": min((np.mean([r["size_ok"] for r in per[c]])
                                            for c in eff), default=math.nan),
        "shrink_ratio_max": max((r["shrink_ratio"] for c in eff for r in per[c]
                                 if math.isfinite(r["shrink_ratio"])), default=math.nan),
        "shrink_ratio_by_case": {c: max((r["shrink_ratio"] for r in per[c]
                                         if math.isfinite(r["shrink_ratio"])), default=math.nan)
                                 for c in eff},
        "shrink_ratio_pooled_max": max((pooled_shrink(per[c]) for c in eff),
                                       default=math.nan),
        "shrink_ratio_pooled_by_case": {c: pooled_shrink(per[c]) for c in eff},
        "shrink_exceed_rate_by_case": {c: exceed_observed(per[c]) for c in eff},
        "shrink_exceed_expected_by_case": {c: exceed_expected(per[c]) for c in eff},
        "shrink_exceed_pvalue_by_case": {c: exceed_pvalue(per[c]) for c in eff},
        # chi^2 after minus that of the clean fit, mean over the trials: an effect of k
        # parameters, exactly the one injected, gives -k on average
        "chi2_after_minus_clean_mean_by_case": {
            c: float(np.mean([r["chi2_after_best_clean"][0] - r["chi2_after_best_clean"][2]
                              for r in per[c] if "chi2_after_best_clean" in r]))
            for c in eff if any("chi2_after_best_clean" in r for r in per[c])},
        # ... and what a perfect diagnosis gives: mean and sigma of that mean, from
        # ``linear_shrink``'s draws
        "chi2_after_minus_clean_expected_by_case": {
            c: dchi2_expected(per[c]) for c in eff if any("dchi2_linear" in r for r in per[c])},
        "shrink_linear_deviation_max": max(
            (abs(r["shrink_ratio"] / r["shrink_ratio_linear"] - 1.0) for c in eff
             for r in per[c] if "shrink_ratio_linear" in r), default=math.nan),
        "after_vs_truth_start_max": max(
            (r["after_vs_truth_start"] for c in eff for r in per[c]
             if math.isfinite(r["after_vs_truth_start"])), default=math.nan),
        "null_clean_rate": (float(np.mean([r["clean"] for r in per["null"]]))
                            if "null" in per else math.nan),
        "out_of_library_unexplained_rate": (
            float(np.mean([r["where_ok"] for r in per["out_of_library"]]))
            if "out_of_library" in per else math.nan),
        **_extended_summary(per),
        "seconds_per_diagnosis": float(np.median([r["seconds"] for c in per for r in per[c]])),
    }
