"""The bootstrap and the next-shot planner, measured (the figures of ``tools/bench_design.py``;
docs/design.md).

- **bootstrap**: seed 004's seven M2 M0.70 shots flown with the bundled model, read with
  film-level noise (:data:`cadra.flight.data.FILM_SIGMAS`, seed 004's range) and fitted
  together; ``n`` parametric bootstrap refits on Dask. Per parameter the bootstrap sigma over
  the covariance sigma.
- **speed-up**: the same refits on one worker and on two (after a warm-up that loads numba's
  cache in the workers).
- **coverage**: a nonlinear single-shot case, M2-2428 alone (its motion, 21-29 deg, only
  grazes the C_mq peak at 19.6-22.8 deg: the peak's chi^2 is far from quadratic), under
  ``draws`` noise draws of the same truth, each fitted from a start 5-10 % off and
  bootstrapped with ``refits`` refits: how often the 95 % percentile interval CADRA reports
  (the refits' own 2.5-97.5 % quantiles), the basic interval (reflected about the fit) and
  the covariance's +-1.96 sigma cover the truth, with
  Clopper-Pearson intervals, over every parameter and for the peak alone. A parameter a draw
  does not determine (an infinite sigma) is counted apart, not as covered.
- **plan**: the seven M2 shots rendered and read from their images by stage one, fitted; a
  plan over 1,000 candidates (launch angle 0-40 deg, rate 0-300 deg/s, Mach +-10 %) for the
  sigmas of the C_mq parameters, timed; the best candidate flown ``reps`` times (each its own
  trigger offsets, film placement and image noise), rendered, read by stage one and refitted
  with the group: the refit's sigmas against the predicted ones. The gain of the best over a
  random candidate of the same ranges and over the best of a 5-point grid (predicted).
- **seed 004**: the planner on the bundled M1 M1.10 and M2 M0.70 groups at film level
  (:func:`seed004_figures`): the table of docs/design.md.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from cadra.facility.reference import REPO_ROOT
from cadra.flight.data import FILM_SIGMAS
from cadra.validation.stage2_bench import M1_SET, M2_SET, make_problem
from cadra.validation.tool import binomial_rate

#: the C_mq parameters the M2 plans target
M2_TARGETS = ("Cmq_A1", "Cmq_A2")
#: the nonlinear single-shot case of the coverage figures, and its nonlinear parameter
COVERAGE_SHOT = ("m2_2428",)
COVERAGE_PEAK = "Cmq_A2"
#: the M2 plans' candidate ranges (launch angle and rate; Mach: +-10 % of the template's)
ANGLE_RANGE = (0.0, 40.0)
RATE_RANGE = (0.0, 300.0)
MACH_SPREAD = 0.10
#: seed 004's question: launch angles in 10-20 deg
SEED004_ANGLES = (10.0, 20.0)
#: the relative sigma "fixing" the M1 M1.10 peak
FIXED = 0.10


def _fit(names, seed: int, sigmas=FILM_SIGMAS):
    from cadra.fitting.solver import fit

    rng = np.random.default_rng([seed, len(names)])
    sds, ys, model, _, _ = make_problem(names, rng, sigmas)
    return fit(sds, model, ys)


def bootstrap_figures(n: int, workers: int, seed: int = 0) -> dict:
    """The M2 seven-shot bootstrap (module doc)."""
    from cadra.campaign.bootstrap import bootstrap

    res = _fit(M2_SET, seed)
    boot = bootstrap(res, n, workers=workers, seed=seed)
    t = boot.table
    ratio = dict(zip(t["parameter"], t["ratio"].round(4), strict=True))
    out = {"refits": n, "converged": boot.n_converged, "seconds": round(boot.seconds, 1),
           "ratio_by_parameter": ratio, "ratio_min": float(t["ratio"].min()),
           "ratio_max": float(t["ratio"].max()),
           "outside_0_8_1_25": [p for p, r in ratio.items() if not 0.8 <= r <= 1.25],
           "bias_sigma_max_abs": float(t["bias_sigma"].abs().max()),
           "non_gaussian": [r.parameter for r in t.itertuples() if r.non_gaussian is True]}
    return out


def speedup_figures(n: int, seed: int = 0) -> dict:
    """The same ``n`` refits on one worker and on two (module doc)."""
    from cadra.campaign.bootstrap import bootstrap

    res = _fit(M2_SET, seed)
    bootstrap(res, 8, workers=2, seed=seed + 1)           # the workers load numba's cache
    one = bootstrap(res, n, workers=1, seed=seed)
    two = bootstrap(res, n, workers=2, seed=seed)
    same = bool(np.allclose(one.table["sigma_boot"], two.table["sigma_boot"], rtol=1e-9))
    return {"refits": n, "one_worker_s": round(one.seconds, 1),
            "two_workers_s": round(two.seconds, 1),
            "speedup": round(one.seconds / two.seconds, 3), "same_numbers": same}


def _coverage_draw(args) -> dict:
    """One truth draw of the coverage figures: fit from a perturbed start, bootstrap, which
    intervals cover the truth."""
    from cadra.campaign.bootstrap import bootstrap
    from cadra.fitting.solver import fit

    k, refits, seed = args
    rng = np.random.default_rng([seed, k, 2428])
    sds, _, truth, start_model, starts = make_problem(COVERAGE_SHOT, rng, FILM_SIGMAS)
    res = fit(sds, start_model, starts)
    if not res:
        return {"draw": k, "status": res.status}
    boot = bootstrap(res, refits, workers=0, seed=k)
    rows = {}
    for r in boot.table.itertuples():
        v = truth.parameter(r.parameter).value
        if not (math.isfinite(r.sigma_cov) and r.sigma_cov > 0 and math.isfinite(r.lower)):
            rows[r.parameter] = {"determined": False}
            continue
        q_lo, q_hi = r.lower, r.upper        # the table's own ends (interval_ends)
        rows[r.parameter] = {"determined": True,
                             "basic": bool(2 * r.value - q_hi <= v <= 2 * r.value - q_lo),
                             "percentile": bool(q_lo <= v <= q_hi),
                             "studentized": bool(r.t_lower <= v <= r.t_upper),
                             "covariance": bool(abs(r.value - v) <= 1.96 * r.sigma_cov),
                             "ratio": float(r.ratio)}
    return {"draw": k, "status": res.status, "converged_refits": boot.n_converged,
            "params": rows}


def _by_draw(rows: list[dict], kind: str) -> dict:
    """Coverage with its 95 % interval from the draws as the independent units: a draw's
    parameters share its noise, so the binomial interval over all cells is too narrow. Each
    draw's covered fraction of its determined parameters; their mean and a t interval."""
    from scipy.stats import t as student

    f = np.array([np.mean([p[kind] for p in r["params"].values() if p["determined"]])
                  for r in rows])
    if f.size < 2:
        return {"rate": float(f.mean()) if f.size else math.nan, "n": int(f.size)}
    half = student.ppf(0.975, f.size - 1) * f.std(ddof=1) / math.sqrt(f.size)
    return {"rate": round(float(f.mean()), 4), "n": int(f.size),
            "ci95": [round(float(f.mean() - half), 4), round(float(f.mean() + half), 4)]}


def coverage_figures(draws: int, refits: int, workers: int, seed: int = 0,
                     progress: bool = True) -> dict:
    """The intervals' coverage on the nonlinear single-shot case (module doc)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from tqdm import tqdm

    ctx = multiprocessing.get_context("spawn")
    jobs = [(k, refits, seed) for k in range(draws)]
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
        rows = list(tqdm(ex.map(_coverage_draw, jobs), total=draws, desc="coverage draws",
                         disable=not progress))
    ok = [r for r in rows if r["status"] == "converged"]
    cells = [p for r in ok for p in r["params"].values() if p["determined"]]
    peak = [r["params"][COVERAGE_PEAK] for r in ok
            if r["params"].get(COVERAGE_PEAK, {}).get("determined")]
    kinds = ("basic", "percentile", "studentized", "covariance")
    by_param = {}
    for name in (ok[0]["params"] if ok else {}):
        ps = [r["params"][name] for r in ok if r["params"][name]["determined"]]
        by_param[name] = {k: round(float(np.mean([p[k] for p in ps])), 3) if ps else None
                          for k in kinds}
        by_param[name]["ratio_median"] = (round(float(np.median([p["ratio"] for p in ps])), 3)
                                          if ps else None)
    return {"shot": COVERAGE_SHOT[0], "draws": draws, "converged_draws": len(ok),
            "refits": refits,
            "by_draw": {k: _by_draw(ok, k) for k in kinds},
            "undetermined_cells": sum(1 for r in ok for p in r["params"].values()
                                      if not p["determined"]),
            **{k: binomial_rate(sum(p[k] for p in cells), len(cells)) for k in kinds},
            "peak": {k: binomial_rate(sum(p[k] for p in peak), len(peak)) for k in kinds},
            "by_parameter": by_param,
            "draw_cells_note": "each draw counts once per determined free parameter "
                               "(correlated within a draw); by_parameter gives each "
                               "parameter's own rate"}


def _m2_space(p):
    from cadra.studies.candidates import CandidateSpace

    b = p.template.base
    return CandidateSpace(b, {"angle_deg": ANGLE_RANGE, "rate_deg_s": RATE_RANGE,
                              "mach": (b.mach * (1 - MACH_SPREAD), b.mach * (1 + MACH_SPREAD))})


def _measured_group(progress: bool):
    """The seven M2 shots, simulated, rendered and read by stage one."""
    from tqdm import tqdm

    from cadra.pipeline import measure, simulate

    out = []
    for name in tqdm(M2_SET, desc="M2 group from images", disable=not progress):
        out.append(measure(simulate(REPO_ROOT / "sample_shots" / "specs" / f"{name}.toml"),
                           workers=None).shot_data())
    return out


def candidate_spec(p, c, seed: int):
    """The shot specification of candidate ``c`` of planner ``p``: the template's own
    specification with the candidate's launch (aimed as given) and station count."""
    from cadra.studies.candidates import candidate_launch
    from cadra.synthetic.simulate import load_shot_spec

    name = p.template.shot.shot_id.lower().replace("-", "_")
    spec = load_shot_spec(REPO_ROOT / "sample_shots" / "specs" / f"{name}.toml")
    if c.cg_shift_mm:
        raise ValueError("candidate_spec: a cg shift is not flown here")
    return replace(spec, launch=candidate_launch(p.template, c), aim="none",
                   n_stations=int(c.stations), seed=int(seed), shot_id=f"{spec.shot_id}-next")


def plan_figures(reps: int, candidates: int, seed: int = 0, progress: bool = True) -> dict:
    """The plan from images, its speed, and its best candidate fired ``reps`` times (module
    doc)."""
    import cadra
    from cadra.fitting.solver import fit
    from cadra.studies.candidates import candidate_shot
    from cadra.studies.design import planner

    group = _measured_group(progress)
    res = cadra.fit(group, "m2_m070")
    if not res:
        raise RuntimeError(f"the M2 group from images did not converge: {res.message}")
    p = planner(res, targets=M2_TARGETS)
    space = _m2_space(p)
    t0 = time.perf_counter()
    plan = p.plan(space, candidates, seed=seed, progress=progress)
    plan_s = time.perf_counter() - t0
    best = plan.best.iloc[0]
    c = plan.best_candidate
    sampled = plan.sampled
    grid = [p.evaluate(g) for g in space.grid(5)]
    grid_best = min(g["objective"] for g in grid)
    cp = candidate_shot(p.template, c, p.problem)
    realised = []
    for r in range(reps):
        sim = cadra.simulate(candidate_spec(p, c, seed=10_000 + r))
        sd = cadra.measure(sim, workers=None).shot_data()
        # from the group's fitted point, the new shot from its predicted state at its epoch
        # station (the same spark: the dynamics do not depend on the clock's origin)
        refit = fit(list(res.problem.shots) + [sd], res.model,
                    list(res.problem.epoch_states) + [cp.epoch_states[0]])
        row = {"rep": r, "status": refit.status}
        for n in M2_TARGETS:
            row[n] = {"sigma": float(refit.sigma(n)), "value": float(refit.value(n)),
                      "predicted": float(best[f"sigma_{n}"]),
                      "ratio": float(refit.sigma(n) / best[f"sigma_{n}"])}
        realised.append(row)
        if progress:
            print(f"  rep {r}: {row['status']}, "
                  + ", ".join(f"{n} {row[n]['ratio']:.3f}" for n in M2_TARGETS), flush=True)
    ok = [r for r in realised if r["status"] == "converged"]
    ratios = [r[n]["ratio"] for r in ok for n in M2_TARGETS]
    scatter = {n: float(np.std([r[n]["value"] for r in ok], ddof=1) / best[f"sigma_{n}"])
               for n in M2_TARGETS} if len(ok) > 1 else {}
    return {"candidates": candidates, "refined": plan.n_refine,
            "plan_seconds": round(plan_s, 1), "best": {k: float(best[k]) for k in
                                                      ("angle_deg", "rate_deg_s", "mach",
                                                       "objective", "flown_min_deg",
                                                       "flown_max_deg")},
            "sigma_now": {n: float(p.sigma_now[p.names.index(n)]) for n in M2_TARGETS},
            "reps": reps, "converged_reps": len(ok),
            "realised_over_predicted_min": min(ratios) if ratios else math.nan,
            "realised_over_predicted_max": max(ratios) if ratios else math.nan,
            "scatter_over_predicted": scatter,
            "gain_over_random": float(np.mean(sampled["objective"]) / best["objective"]),
            "gain_over_grid": float(grid_best / best["objective"]),
            "realised": realised}


def seed004_figures(candidates: int = 300, seed: int = 0, max_shots: int = 8) -> dict:
    """Seed 004's decision (module doc): the M1 M1.10 peak freed and the M2 M0.70 C_mq
    parameters, planned on the bundled groups at film level."""
    from cadra.studies.candidates import CandidateSpace
    from cadra.studies.design import planner, sequence

    out = {}
    res = _fit(M1_SET, seed)
    low = [sd.shot_id for sd, h in zip(res.problem.shots, res.problem.histories(), strict=True)
           if np.degrees(h["air"]["sigma_rad"]).max() < SEED004_ANGLES[0]]
    peak = abs(res.model.parameter("Cmq_A2").value)
    p = planner(res, targets=("Cmq_A2",), free=("Cmq_A2",))
    i = p.names.index("Cmq_A2")
    m1 = {"shots": len(res.problem.shots), "rel_sigma_now": float(p.sigma_now[i] / peak),
          "low_angle_shots": low}
    high = [n for n, sd in zip(M1_SET, res.problem.shots, strict=True) if sd.shot_id not in low]
    res_high = _fit(tuple(high), seed)
    ph = planner(res_high, targets=("Cmq_A2",), free=("Cmq_A2",))
    m1["rel_sigma_without_low"] = float(ph.sigma_now[ph.names.index("Cmq_A2")] / peak)
    b = ph.template.base
    for label, angles in (("in_10_20", SEED004_ANGLES), ("in_0_40", ANGLE_RANGE)):
        space = CandidateSpace(b, {"angle_deg": angles, "rate_deg_s": RATE_RANGE})
        seq = sequence(ph, space, max_shots, n_candidates=candidates, refine=1,
                       refine_evaluations=30, seed=seed, n_best=1)
        rel = [float(s.best.iloc[0]["sigma_Cmq_A2"] / peak) for s in seq]
        need = next((k + 1 for k, r in enumerate(rel) if r <= FIXED), None)
        m1[f"without_low_{label}"] = {"rel_sigma_after": [round(r, 4) for r in rel],
                                      "shots_to_10pct": need,
                                      "angles": [round(float(s.best.iloc[0]["angle_deg"]), 1)
                                                 for s in seq]}
    out["m1_m110"] = m1
    res2 = _fit(M2_SET, seed)
    p2 = planner(res2, targets=M2_TARGETS)
    space2 = _m2_space(p2)
    best = p2.plan(space2, candidates, seed=seed).best.iloc[0]
    restricted = p2.plan(replace(space2, ranges={**space2.ranges, "angle_deg": SEED004_ANGLES}),
                         candidates, seed=seed).best.iloc[0]
    out["m2_m070"] = {
        "group_flown_deg": [float(min(np.degrees(h["air"]["sigma_rad"]).min()
                                      for h in res2.problem.histories())),
                            float(max(np.degrees(h["air"]["sigma_rad"]).max()
                                      for h in res2.problem.histories()))],
        "best_angle_deg": float(best["angle_deg"]), "best_rate_deg_s": float(best["rate_deg_s"]),
        "best_mach": float(best["mach"]), "best_objective": float(best["objective"]),
        "best_flown_deg": [float(best["flown_min_deg"]), float(best["flown_max_deg"])],
        "best_sweeps_10_20": bool(best["flown_min_deg"] <= SEED004_ANGLES[0]
                                  and best["flown_max_deg"] >= SEED004_ANGLES[1]),
        "sigma_now": {n: float(p2.sigma_now[p2.names.index(n)]) for n in M2_TARGETS},
        "sigma_best": {n: float(best[f"sigma_{n}"]) for n in M2_TARGETS},
        "launch_10_20_objective": float(restricted["objective"]),
        "launch_10_20_angle_deg": float(restricted["angle_deg"])}
    return out
