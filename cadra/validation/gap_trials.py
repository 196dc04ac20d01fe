"""The trials of the gap validation: a shot (or set) simulated with an effect, diagnosed blind.

One trial (:func:`run_trial`) draws a case's shots and effect
(:mod:`cadra.validation.gap_cases`), simulates the shots with the effect, measures them with
stage one's precision (:mod:`cadra.validation.gap_measure`), fits them without it (the shot
file's nominal mass properties, the bundled aero model, no biases) and diagnoses the fit
blind (:func:`cadra.gap.score.diagnose_gap`); the row it returns holds the scores against
the truth (:mod:`cadra.validation.gap_scoring`): the injected effect ranked first (or named
as an alias of the first), its size within 2 sigma, the shrink ratio and its linearized
prediction; for a null shot whether it came out clean; for an effect outside the library
whether the residual was reported unexplained where it lies. A draw whose effect does not
*matter* (the fit without it has a residual rms at least 20 % above the clean fit's in some
channel, or moves an aero coefficient by more than its sigma) is not a trial of its case and
is drawn again (:func:`run_case`).

:func:`multifit_timing` times the diagnosis of a seven-shot M2 multi-fit with a facility
effect. The summaries of the rows are :mod:`cadra.validation.gap_summary`.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import replace

import numpy as np

from cadra.validation.gap_cases import (
    ALL_SHOTS_CASES,
    BODY_CASES,
    BODY_PAIRS,
    LATERAL_OFFSET_M,
    M1_CASES,
    M1_SHOTS,
    MAX_REDRAWS,
    OFFSET_CASES,
    PAIR_CASES,
    SET_CASES,
    SHOTS,
    STRONG_SUBCASES,
    draw_uniform,
    make_case,
    shot_spec,
)
from cadra.validation.gap_measure import measure
from cadra.validation.gap_scoring import (
    body_truth_in_fit_frame,
    effect_size_ok,
    fit_from_truth,
    linear_shrink,
    size_within_2sigma,
)

__all__ = ["AB_ARMS", "CASES", "CASE_OF_EFFECT", "EXTENDED_CASES", "STRONG_RCHI2", "STRONG_REDRAWS",
           "WHERE_ONLY_LAMBDA", "diagnose_with", "finding", "multifit_timing", "run_case",
           "run_trial", "score_extended"]

#: the noncentrality b^2 sum(1 - leverage) of a where-only trial's one-station bias
WHERE_ONLY_LAMBDA = (36.0, 44.0)
#: the cases scored by their own criteria (:func:`score_extended`): a misfit at one
#: station only, strong effects, the range air's shared density gradient, a held
#: parameter wrong (and its null), two effects at once
EXTENDED_CASES = ("where_only", "strong", "shared_density", "held", "held_null",
                  "pair_station", "pair_dynamics")
#: a strong-effect trial's fit without the effect lies in this chi^2/dof range
STRONG_RCHI2 = (20.0, 200.0)
#: a strong-effect draw outside that range is drawn again at most this many times
STRONG_REDRAWS = 5
#: the library case of each effect a strong-effect trial can draw
CASE_OF_EFFECT = {"lateral cg offset": "cg", "density gradient": "density",
                  "cross-flow": "crossflow", "Mach dependence of Cm": "cmM"}

#: every case of the gap validation, in the order it runs them
CASES = ["cg", "inertia_asym", "products", "density", "crossflow", "cm3", "cmq2", "cmM",
         "station_bias", "timing", "scale", "null", "out_of_library", *EXTENDED_CASES]


#: the diagnosis's configurations the speed A/B times (:func:`diagnose_with`): arm ->
#: (sensitivities, the fit's damping schedule). ``before``: complex step and Marquardt's
#: classic schedule, what the diagnosis did before forward mode and the lambda search;
#: ``forward``: forward mode alone; ``now``: forward mode and the lambda search, the default
AB_ARMS = {"before": ("complex", "classic"), "forward": ("forward", "classic"),
           "now": ("forward", "search")}


def diagnose_with(arm: str, res, shots, model):
    """:func:`cadra.gap.score.diagnose_gap` in configuration ``arm`` of :data:`AB_ARMS`
    (through :data:`cadra.fitting.sensitivity.METHOD_ENV` and
    :data:`cadra.fitting.solver.DAMPING_ENV`): (diagnosis, seconds)."""
    from cadra.fitting.sensitivity import METHOD_ENV
    from cadra.fitting.solver import DAMPING_ENV
    from cadra.gap.score import diagnose_gap

    keys = (METHOD_ENV, DAMPING_ENV)
    before = {k: os.environ.get(k) for k in keys}
    os.environ.update(zip(keys, AB_ARMS[arm], strict=True))
    try:
        t0 = time.perf_counter()
        dg = diagnose_gap(res, shots, model)
        return dg, time.perf_counter() - t0
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _first_named(dg):
    return dg.added[0]["effect"] if dg.added else None


def finding(dg) -> tuple:
    """What a diagnosis found, without its sizes: the effects added in order, whether a gap
    is left unexplained, and the misfits set aside."""
    return (tuple(a["effect"] for a in dg.added), bool(dg.unexplained),
            tuple(sorted(map(str, dg.set_aside))))


def run_trial(case, rng, tmpdir, force=False, strong_k=None, _depth=0, ab=None):
    """One trial of ``case`` (its shots simulated with the effect, measured, fitted without it
    and diagnosed blind, the diagnosis scored against the truth): a dict row. ``tmpdir``: where
    an aero case writes its model file. A draw whose effect does not matter returns early (no
    diagnosis) unless ``force``. A strong-effect trial draws one of STRONG_SUBCASES at k times
    its usual size (k log-uniform in 0.01-1 on the M1 sets); when the fit without it lands
    outside STRONG_RCHI2 the same trial (shots, direction, noise) is redone with k rescaled
    towards chi^2/dof ~ 60 (``strong_k``; at most three times). ``ab``: the
    configurations of :data:`AB_ARMS` in the order to run them (e.g. ("before", "now")): the
    fit is diagnosed with each, timed, and scored on the ``now`` diagnosis (the row's
    ``ab_seconds``, ``ab_first``, ``ab_verdicts`` and ``ab_findings`` by arm)."""
    saved = rng.bit_generator.state
    from cadra.dynamics.effects import Effects
    from cadra.fitting import fit_shots
    from cadra.flight.data import CHANNELS
    from cadra.gap.score import diagnose_gap
    from cadra.synthetic.simulate import simulate_shot

    pool = M1_SHOTS if case in M1_CASES else SHOTS
    group = SET_CASES.get(case)
    if group is None:
        names = [pool[int(rng.integers(len(pool)))]]
    elif isinstance(group, int):
        names = list(rng.choice(pool, size=group, replace=False))
    else:
        names = list(group)
    specs = [shot_spec(n) for n in names]
    if case == "strong":
        sub = str(rng.choice(STRONG_SUBCASES))
        k = float(np.exp(rng.uniform(np.log(0.01), np.log(1.0))))
        k = k if strong_k is None else strong_k

        def big(r, lo, hi, k=k):
            return draw_uniform(r, lo * k, hi * k)
        spec_e, edit, expected, truth, where = make_case(sub, rng, specs, tmpdir, draw=big)
    else:
        spec_e, edit, expected, truth, where = make_case(case, rng, specs, tmpdir)
    # a strong-effect trial is one of the library cases at a larger size
    sub = CASE_OF_EFFECT.get(expected, case) if case == "strong" else case
    groups = BODY_PAIRS.get(sub)
    sid = specs[0].shot_id
    if len(specs) > 1 and (sub in BODY_CASES or (case == "strong"
                                                  and sub in ("density", "crossflow"))):
        # a body effect in the set's first shot: parameters per shot, ``name@shot``
        truth = {f"{p}@{sid}": v for p, v in truth.items()}
        if groups is not None:
            groups = [tuple(f"{p}@{sp.shot_id}" for p in g) for sp in specs for g in groups]
    shots, clean_shots, model = [], [], None
    noise = {}          # (shot, station, channel) -> the noise drawn, in sigmas
    for k, spec in enumerate(specs):
        # a body effect is in the first shot only; an aero term in every shot (it is the
        # same air and shape); a measurement edit in every shot (the same stations)
        se = (spec_e if k == 0 else replace(spec, aero_model=spec_e.aero_model,
                                            effects=spec_e.effects)
              if sub in ALL_SHOTS_CASES else spec)
        seed = int(rng.integers(1 << 31))
        sim = simulate_shot(se)
        clean_sim = simulate_shot(spec) if se is not spec else sim
        nominal = clean_sim.rigid.with_effects(Effects())
        offset = (tuple(rng.uniform(-LATERAL_OFFSET_M, LATERAL_OFFSET_M, 2))
                  if case in OFFSET_CASES else (0.0, 0.0))
        shots.append(measure(sim, nominal, spec, seed, edit, offset))
        clean_shots.append(measure(clean_sim, nominal, spec, seed, None, offset))
        free = measure(clean_sim, nominal, spec, None, None, offset)
        e = (clean_shots[-1].meas - free.meas) / free.sigma
        noise.update({(spec.shot_id, int(st), ch): float(e[i, j])
                      for i, st in enumerate(free.stations) for j, ch in enumerate(CHANNELS)})
        model = clean_sim.model
        if k == 0:
            first_model = sim.model        # the aero model the data were simulated with
            first_sim = sim
    if case == "where_only":
        # sized by its noncentrality: the bias b at station st, channel ch in every shot
        # removes b^2 sum(1 - leverage) of chi^2 (a station near the ends of the record is
        # largely absorbed by the initial state: the same b in sigmas matters less there);
        # drawn so that b^2 sum(1 - h) is in WHERE_ONLY_LAMBDA: the global chi^2 test alone
        # then passes in about 60 % of the trials (measured: ``global_pass_rate``)
        clean, _ = fit_shots(clean_shots, model)
        (st, ch), = where
        rr = clean.residuals
        keep = (rr["station"] == st) & (rr["channel"] == ch)
        w = float(np.sum(1.0 - rr.loc[keep, "leverage"].to_numpy(float)))
        sig = clean_shots[0].sigma[list(clean_shots[0].stations).index(st), CHANNELS.index(ch)]
        b = math.copysign(math.sqrt(float(rng.uniform(*WHERE_ONLY_LAMBDA)) / w) * sig,
                          float(rng.choice([-1.0, 1.0])))
        shots = []
        for cs in clean_shots:
            m = cs.meas.copy()
            m[list(cs.stations).index(st), CHANNELS.index(ch)] += b
            shots.append(replace(cs, meas=m))
        truth = {"bias": b, "bias_sigmas": b / sig}
    t0 = time.perf_counter()
    res, _ = fit_shots(shots, model)
    t_fit = time.perf_counter() - t0
    if case != "where_only":
        clean, _ = fit_shots(clean_shots, model)
    rms_c, rms_r = clean.rms(), res.rms()
    ratios0 = [rms_r[c] / rms_c[c] for c in rms_c if math.isfinite(rms_c[c])]
    shifts = [abs(v - clean.value(n)) / s for n, v, s in
              zip(res.aero_names, res.aero_values, clean.aero_sigma, strict=True)
              if math.isfinite(s) and s > 0]
    out = {"case": case, "shot": "+".join(names), "converged": bool(res),
           "fit_status": res.status,
           "matters": bool(max(ratios0) >= 1.2 or (shifts and max(shifts) > 1.0)),
           "rms_raise": float(max(ratios0)), "shift_sigma": float(max(shifts, default=0.0)),
           "base_rchi2": float(res.reduced_chi2),
           "effect_dchi2": float(res.chi2 - clean.chi2)}
    if case == "held":
        # a held parameter's criterion: a held value wrong by an amount that shifts a
        # free parameter by 3 sigma or more
        out["matters"] = out["shift_sigma"] >= 3.0
    if case == "strong":
        # a strong effect: the fit without it at chi^2/dof 20-200; outside, the same trial at
        # a rescaled size (chi^2 of an effect grows about as its size squared)
        out["matters"] = bool(STRONG_RCHI2[0] <= res.reduced_chi2 <= STRONG_RCHI2[1])
        out["strong_k"] = k
        if not out["matters"] and _depth < 3 and not force:
            rng.bit_generator.state = saved
            factor = math.sqrt(61.0 / max(res.reduced_chi2 - 1.0, 1e-2))
            return run_trial(case, rng, tmpdir, force, k * min(factor, 30.0), _depth + 1, ab)
    if (expected is not None and case not in ("where_only", "shared_density")
            and not out["matters"]
            and not force):
        return out             # not a trial of this case: the caller draws another
    if ab:
        runs = {m: diagnose_with(m, res, shots, model) for m in ab}
        dg, t_diag = runs["now"]
        out.update({"ab_seconds": {m: r[1] for m, r in runs.items()},
                    "ab_first": {m: _first_named(r[0]) for m, r in runs.items()},
                    "ab_verdicts": {m: r[0].verdict for m, r in runs.items()},
                    "ab_findings": {m: finding(r[0]) for m, r in runs.items()}})
    else:
        t0 = time.perf_counter()
        dg = diagnose_gap(res, shots, model)
        t_diag = time.perf_counter() - t0
    out.update({"seconds": t_fit + t_diag, "verdict": dg.verdict,
                "after_status": dg.fit_after.status if dg.fit_after is not None else "-"})
    first = dg.added[0] if dg.added else None
    # a freed hold the verdict does not blame (a misfit stands beside it) names nothing
    blamed = [a for a in dg.added
              if a["kind"] != "held" or a.get("held_verdict") != "misfit_standing"]
    named = {a["effect"] for a in blamed} | {x for a in blamed for x in a["aliases"]}
    out["held_flag"] = any(a["kind"] == "held" for a in blamed)
    if case in EXTENDED_CASES:
        return score_extended(case, out, dg, res, expected, truth, where, named, groups, sub,
                              first_sim, sid)
    if expected is not None:
        out["top1"] = first is not None and first["effect"] == expected
        out["top1_alias"] = first is not None and (first["effect"] == expected
                                                   or expected in first["aliases"])
        out["truth"] = {k: float(v) for k, v in truth.items()}
        if out["top1"]:
            if case in BODY_CASES:
                sf = next(f for f in dg.fit_after.shots if f.shot_id == sid)
                truth = body_truth_in_fit_frame(case, truth, first_sim, sf.t0_s,
                                                sf.state[6:10])
                out["truth_fit_frame"] = truth
            # the size of a body pair is its magnitude (frame-free), the pair as a vector in
            # the fit's frame (direction too) printed beside it; any other multi-parameter
            # effect one vector; each parameter alone within 2 sigma is kept beside it
            out["size_ok"] = effect_size_ok(first, truth, groups)
            out["size_ok_per_parameter"] = size_within_2sigma(first, truth)
            out["n_params"] = len(first["params"])
            if groups is not None:
                out["size_ok_vector"] = size_within_2sigma(first, truth, groups)
            # the literal reference: the clean shots' fit (base model); and the diagnosis'
            # final model fitted to the same data from the truth (the injected sizes, the
            # simulator's aero values): the best that model can do on these data. Where the
            # diagnosis reached it, what is left above the clean fit is the same noise seen
            # through another trajectory's Jacobian, not a gap (docs/gap.md, "Shrink ratio")
            rms_a = dg.rms_after
            best = fit_from_truth(dg.fit_after, shots, first_model, truth)
            rms_m = best.rms() if best is not None else rms_a
            out["shrink_ratio"] = float(max(rms_a[c] / rms_c[c] for c in rms_c
                                            if math.isfinite(rms_c[c])))
            out["after_vs_truth_start"] = float(max(rms_a[c] / rms_m[c] for c in rms_m
                                                    if math.isfinite(rms_m[c])))
            out["rms_pairs"] = {c: (float(rms_a[c]), float(rms_c[c])) for c in rms_c
                                if math.isfinite(rms_c[c])}
            # the same ratio predicted from the two fits' Jacobians and the noise drawn, and
            # how often it would exceed SHRINK_LIMIT on other noise (docs/gap.md)
            lin = linear_shrink(clean, dg.fit_after, noise,
                                rng=np.random.default_rng([seed, 1]))
            if lin is not None:
                out["shrink_ratio_linear"], out["shrink_exceed_prob"] = lin["ratio"], lin["prob"]
                out["dchi2_linear"] = (lin["dchi2"], lin["dchi2_mean"], lin["dchi2_var"])
            out["chi2_after_best_clean"] = (float(dg.fit_after.chi2),
                                            float(best.chi2 if best is not None else math.nan),
                                            float(clean.chi2))
        else:
            out["size_ok"] = False
            out["shrink_ratio"] = out["after_vs_truth_start"] = math.nan
    elif where is None:
        out["clean"] = not dg.added and not dg.unexplained
    else:
        named = any(f"station {st} {ch}" in dg.verdict for st, ch in where)
        out["unexplained"] = bool(dg.unexplained)
        out["where_ok"] = bool(dg.unexplained and named)
        out["pinned"] = [a["effect"] for a in dg.added]
    return out


def score_extended(case, out, dg, res, expected, truth, where, named, groups, sub,
                   first_sim, sid):
    """Scores of the :data:`EXTENDED_CASES`, written into ``out`` (the trial row): where-only
    misfits, strong effects, the shared density gradient, held parameters, pairs."""
    from scipy import stats

    first = dg.added[0] if dg.added else None
    out["pinned"] = [a["effect"] for a in dg.added]
    out["unexplained"] = bool(dg.unexplained)
    if case in PAIR_CASES:
        out["both_named"] = all(e in named for e in expected)
        return out
    if case == "where_only":
        (st, ch), = where
        in_verdict = bool(dg.unexplained) and f"station {st} {ch}" in dg.verdict
        out["where_found"] = in_verdict or (expected is not None and expected in named)
        # the global chi^2 test alone, at the diagnosis' alpha, on the fit given
        out["global_passes"] = bool(stats.chi2.sf(res.chi2, max(res.dof, 1)) >= 0.01)
        out["bias_sigmas"] = truth["bias_sigmas"]
        return out
    if case == "held_null":
        out["clean"] = not dg.added and not dg.unexplained
        return out
    out["top1"] = first is not None and first["effect"] == expected
    out["top1_alias"] = first is not None and (first["effect"] == expected
                                               or expected in first["aliases"])
    out["flagged"] = expected in named
    out["base_status"] = (dg.fit_given.status if dg.fit_given is not None else "-")
    out["size_ok"] = False
    out["truth"] = {k: float(v) for k, v in truth.items()}
    if out["top1"]:
        if sub in BODY_CASES:
            sf = next(f for f in dg.fit_after.shots if f.shot_id == sid)
            truth = body_truth_in_fit_frame(sub, truth, first_sim, sf.t0_s, sf.state[6:10])
        out["size_ok"] = effect_size_ok(first, truth, groups)
        out["size_ok_per_parameter"] = size_within_2sigma(first, truth)
        out["n_params"] = len(first["params"])
    return out


def run_case(case, rng, tmpdir, trials: int, progress: bool = False, ab=()):
    """``trials`` trials of ``case`` from the generator ``rng``: ([row, ...], the number of
    draws drawn again). A draw whose effect does not matter (rms up 20 %, or a coefficient
    moved by more than its sigma) is not a trial of the case: it is drawn again, at most
    MAX_REDRAWS times (STRONG_REDRAWS for a strong effect), and counted; the last is kept
    whatever it gives. ``progress``: a progress bar (tqdm). ``ab``: each trial diagnosed
    in these configurations of :data:`AB_ARMS`, in this order in even trials and the
    reverse in odd ones (:func:`run_trial`)."""
    steps = range(trials)
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc=case, unit="shot", leave=False)
    rows, n_redrawn = [], 0
    for i in steps:
        n_max = STRONG_REDRAWS if case == "strong" else MAX_REDRAWS
        order = (None if not ab else tuple(ab) if i % 2 == 0 else tuple(ab)[::-1])
        for attempt in range(n_max + 1):
            row = run_trial(case, rng, tmpdir, force=attempt == n_max, ab=order)
            if "verdict" in row:
                break
            n_redrawn += 1
        rows.append(row)
    return rows, n_redrawn


def multifit_timing(seed: int = 0, methods=None) -> dict:
    """Diagnosis time of one seven-shot M2 multi-fit (every M2 sample shot, stage-one noise, a
    2 um z bias at station 9 in every shot: a facility effect), and what it found.
    ``methods``: also the diagnosis in each of these configurations of
    :data:`AB_ARMS`, timed (``multifit_ab_seconds``, ``multifit_ab_first``)."""
    from cadra.dynamics.effects import Effects
    from cadra.fitting import fit_shots
    from cadra.gap.score import diagnose_gap
    from cadra.gap.where import where_analysis
    from cadra.synthetic.simulate import simulate_shot

    shots, model = [], None
    for k, name in enumerate(SHOTS):
        spec = shot_spec(name)
        sim = simulate_shot(spec)

        def edit(m):
            m[8, 2] += 2e-6               # station 9
            return m
        shots.append(measure(sim, sim.rigid.with_effects(Effects()), spec, seed + k, edit))
        model = sim.model
    t0 = time.perf_counter()
    res, _ = fit_shots(shots, model)
    t1 = time.perf_counter()
    dg = diagnose_gap(res, shots, model)
    tables = where_analysis(res, shots, res.residuals)
    t2 = time.perf_counter()
    out = {"seconds_multifit_fit": t1 - t0, "seconds_multifit_diagnosis": t2 - t1,
           "multifit_verdict": dg.verdict, "multifit_where": tables["findings"][:3]}
    if methods:
        runs = {m: diagnose_with(m, res, shots, model) for m in methods}
        out["multifit_ab_seconds"] = {m: r[1] for m, r in runs.items()}
        out["multifit_ab_first"] = {m: _first_named(r[0]) for m, r in runs.items()}
    return out

