"""Stage two's speed, accuracy and honesty against the simulator's exact truth (the sections of
``tools/bench_cadra2.py``).

Problems (synthetic data from the sample-shot specs; truth = the simulator's truth.csv):
single fit of M2-2429 (model m2_m070, all its free parameters) and the 7-shot M2 M0.70
multi-fit (:data:`M2_SET`); the 7-shot M1 M1.10 multi-fit (:data:`M1_SET`) for accuracy and
pulls. Film noise (:data:`cadra.flight.data.FILM_SIGMAS`: 0.1 mm, 0.1 deg, 10 ns timing).
The "perturbed" start is the true epoch state moved by ~1 mm, 0.5 m/s, 0.5 deg, 0.5 rad/s
(Gaussian, per component) and every free aero value by 5-10 % (random sign); the "auto" start
is :mod:`cadra.fitting.start` (linear theory from the data, seeded with the perturbed model as
the analyst's model file).

Sections (each prints its progress and returns its figures; :func:`figures` makes the
benchmark's JSON line of them):

1-2. :func:`speed_and_baseline`: best-of-3 warm wall time of the single fit and of the 7-shot
     multi-fit, from the perturbed and the automatic start; the SciPy reference fitter
     (:func:`cadra.validation.fit_baseline.baseline_fit`, compiled and plain-Python
     right-hand sides) on the same problems and starts;
3. :func:`cold_start`: the first fit in a fresh Python process, with the on-disk compiled
   caches present and with an empty ``NUMBA_CACHE_DIR``;
4. :func:`noise_free`: the two 7-shot multi-fits on noise-free measurements, max
   |fit - truth| / |truth| over the free parameters;
5. :func:`pulls`: noise realisations of both multi-fits at film and at stage-one sigmas, per
   parameter mean and std of (fit - truth) / sigma and the fraction within 2 sigma.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

from cadra.facility.reference import REPO_ROOT

M2_SET = ("m2_2425", "m2_2426", "m2_2427", "m2_2428", "m2_2429", "m2_2431", "m2_2433")
M1_SET = ("m1_2366", "m1_2379", "m1_2380", "m1_2384", "m1_2386", "m1_2388", "m1_2393")
SINGLE = ("m2_2429",)
#: stage-one-like sigmas (README: whole-shot rms 0.3 um, 0.0012 deg)
STAGE1_SIGMAS = {"position_m": 0.3e-6, "angle_rad": math.radians(0.0012), "time_s": 0.0}
#: "exact" measurements: solve_ivp DOP853 (an integrator independent of the fitter's) at these
#: tolerances from the true epoch state; truth.csv (25 us fixed-step RK4 from launch) is off by
#: up to ~0.16 um where the Table 4 max() forms kink
EXACT_RTOL, EXACT_ATOL = 1e-13, 1e-15

_SIMS: dict = {}


# --- problems -------------------------------------------------------------------------------

def _sim(name):
    """(spec, simulated shot, truth DataFrame, exact truth DataFrame) of a sample shot."""
    if name not in _SIMS:
        import pandas as pd

        from cadra.fitting.sensitivity import observables
        from cadra.synthetic.simulate import load_shot_spec, simulate_shot
        from cadra.validation.fit_baseline import trajectory_ivp

        spec = load_shot_spec(REPO_ROOT / "sample_shots" / "specs" / f"{name}.toml")
        shot = simulate_shot(spec)
        truth = pd.read_csv(REPO_ROOT / "sample_shots" / name / "truth.csv")
        t = truth["t_s"].to_numpy(float)
        k = len(t) // 2
        states = trajectory_ivp(shot.states[k], t[k], t, shot.rigid.phys(),
                                shot.model.compile(), shot.model.values(), rtol=EXACT_RTOL,
                                atol=EXACT_ATOL)
        obs = observables(states, shot.rigid.ref_from_cg_body_m())
        exact = truth.copy()
        exact[["x_m", "y_m", "z_m"]] = obs[:, :3]
        exact["theta_deg"] = np.degrees(obs[:, 3])
        exact["psi_deg"] = np.degrees(obs[:, 4])
        _SIMS[name] = (spec, shot, truth, exact)
    return _SIMS[name]


def make_problem(names, rng, sigmas, *, noise=True, exact=False):
    """Shot data, true epoch states, the truth model and a perturbed start (model, states)."""
    from cadra.fitting.sensitivity import apply_local
    from cadra.flight.data import shot_data_from_truth

    sds, truth_states, starts = [], [], []
    model = None
    for name in names:
        spec, shot, truth, exact_truth = _sim(name)
        sd = shot_data_from_truth(exact_truth if exact else truth, shot.rigid, spec.shot_id,
                                  shot.body.kind, sigma_position_m=sigmas["position_m"],
                                  sigma_angle_rad=sigmas["angle_rad"],
                                  sigma_t_s=sigmas["time_s"] if noise else 0.0,
                                  rng=rng if noise else None)
        y = shot.states[len(truth) // 2].copy()
        u = np.r_[rng.normal(0, 1e-3, 3), rng.normal(0, 0.5, 3),
                  rng.normal(0, math.radians(0.5), 3), rng.normal(0, 0.5, 3)]
        sds.append(sd)
        truth_states.append(y)
        starts.append(apply_local(y, u))
        model = shot.model
    factors = {n: 1 + rng.choice([-1, 1]) * rng.uniform(0.05, 0.10)
               for n in model.free_names()}
    start_model = model.with_values({n: model.parameter(n).value * f
                                     for n, f in factors.items()})
    return sds, truth_states, model, start_model, starts


def _has_auto_start() -> bool:
    try:
        from cadra.fitting.start import initial_states, starting_model  # noqa: F401
    except ImportError:
        return False
    return True


def auto_start(sds, file_model):
    from cadra.fitting.start import initial_states, starting_model

    m = starting_model(sds, file_model)
    return m, initial_states(sds, m)


def truth_errors(names, values, sigmas, model):
    truth = np.array([model.parameter(n).value for n in names])
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.asarray(values) - truth) / np.asarray(sigmas), \
            np.abs(np.asarray(values) - truth) / np.abs(truth)


# --- 1-2: speed and baseline ------------------------------------------------------------

def jacobian_cost(sds, model, starts) -> dict:
    """The first shot's Jacobian at the start, on one thread: forward mode's and complex
    step's cost in float trajectories' time (best of 5 each), the lanes (unknowns), and the
    worst column difference between the two over the column's largest entry."""
    from cadra.fitting.problem import FitProblem
    from cadra.fitting.sensitivity import Integration, predict_states, predict_with_jacobian

    prob = FitProblem(tuple(sds), model, tuple(starts))
    one = Integration(threads=1)
    phys, ref = prob.physics(0, np.zeros(0))
    y0, t0, t = prob.epoch_states[0], prob.epochs[0], sds[0].t_s
    program, params = model.compile(), model.values()
    args = (y0, t0, t, phys, program, params, ref, prob.local_free[0], prob.aero_indices, one)
    jf = predict_with_jacobian(*args, method="forward")[1]
    jc = predict_with_jacobian(*args, method="complex")[1]
    float_s = _best_of(lambda: predict_states(y0, t0, t, phys, program, params, one), 5)[0]
    fwd_s = _best_of(lambda: predict_with_jacobian(*args, method="forward"), 5)[0]
    cpx_s = _best_of(lambda: predict_with_jacobian(*args, method="complex"), 5)[0]
    scale = np.abs(jc).max(axis=(0, 1))
    worst = np.abs(jf - jc).max(axis=(0, 1)) / np.where(scale > 0, scale, 1.0)
    return {"jac_lanes": int(jf.shape[-1]), "jac_forward_equiv": fwd_s / float_s,
            "jac_complex_equiv": cpx_s / float_s, "jac_float_ms": 1e3 * float_s,
            "jac_vs_complex_max_rel": float(worst.max())}


def _best_of(fn, n):
    times, out = [], None
    for _ in range(n):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times)), out


#: skip the plain-Python baseline multi-fit when its estimated wall time exceeds this, s
PYTHON_MULTIFIT_LIMIT_S = 600.0


def speed_and_baseline(seed, skip_baseline, quick):
    from cadra.dynamics import tangent
    from cadra.fitting.sensitivity import Integration
    from cadra.fitting.solver import FitOptions, fit
    from cadra.flight.data import FILM_SIGMAS

    tangent.module()          # the forward-mode code compiled (or loaded) before any timing
    out = {}
    python_ms = None                        # plain-Python baseline ms per trajectory (single)
    for label, names in (("single", SINGLE), ("multi", M2_SET)):
        rng = np.random.default_rng([seed, 1, len(names)])
        sds, ytrue, model, start_model, starts = make_problem(names, rng, FILM_SIGMAS)
        fit(sds, start_model, starts)                      # warm (compile / cache load)
        best, med, res = _best_of(lambda: fit(sds, start_model, starts), 3)   # noqa: B023
        pulls, _ = truth_errors(res.aero_names, res.aero_values, res.aero_sigma, model)
        one = FitOptions(integration=Integration(threads=1))
        best1, _, _ = _best_of(lambda: fit(sds, start_model, starts, options=one), 3)  # noqa: B023
        r = {"best_s": best, "median_s": med, "status": res.status, "one_thread_s": best1,
             "iterations": res.iterations, "chi2": res.chi2, "n_free": res.n_free,
             "n_obs": res.n_observations, "max_abs_pull": float(np.max(np.abs(pulls)))}
        r.update(jacobian_cost(sds, start_model, starts))
        print(f"\n== {label} fit ({len(names)} shot(s), {res.n_free} unknowns, "
              f"{res.n_observations} measurements), perturbed start: best of 3 {best:.3f} s "
              f"(median {med:.3f}; one thread {best1:.3f} s), {res.status} in "
              f"{res.iterations} iterations, chi2 "
              f"{res.chi2:.2f}, max |fit-truth|/sigma {r['max_abs_pull']:.2f}")
        print(f"   Jacobian of one shot ({r['jac_lanes']} unknowns, one thread): forward mode "
              f"{r['jac_forward_equiv']:.1f} trajectories' time, complex step "
              f"{r['jac_complex_equiv']:.1f}; worst column difference "
              f"{r['jac_vs_complex_max_rel']:.1e} of its size")
        if _has_auto_start():
            t0 = time.perf_counter()
            auto_model, auto_states = auto_start(sds, start_model)
            t_start = time.perf_counter() - t0

            def run_auto():
                m, ys = auto_start(sds, start_model)           # noqa: B023
                return fit(sds, m, ys)                           # noqa: B023

            abest, amed, ares = _best_of(run_auto, 3)
            ap, _ = truth_errors(ares.aero_names, ares.aero_values, ares.aero_sigma, model)
            r.update({"auto_best_s": abest, "auto_median_s": amed, "auto_start_s": t_start,
                      "auto_status": ares.status, "auto_iterations": ares.iterations,
                      "auto_chi2": ares.chi2,
                      "auto_max_abs_pull": float(np.max(np.abs(ap)))})
            print(f"   automatic start (cadra.fitting.start): start + fit best of 3 "
                  f"{abest:.3f} s (median {amed:.3f}; start alone {t_start:.3f} s), "
                  f"{ares.status} in {ares.iterations} iterations, chi2 {ares.chi2:.2f}, "
                  f"max |fit-truth|/sigma {r['auto_max_abs_pull']:.2f}")
        else:
            print("   automatic start: cadra.fitting.start not available")
        if not skip_baseline:
            r.update(_baseline(label, sds, model, start_model, starts, res, best, best1))
            r.update(_baseline_python(label, sds, model, start_model, starts, res, best,
                                      python_ms, r["baseline_trajectories"]))
            python_ms = r.get("baseline_python_ms_per_trajectory", python_ms)
        out[label] = r
    return out


def _baseline(label, sds, model, start_model, starts, res, cadra_s, cadra_one_s):
    from cadra.validation.fit_baseline import baseline_fit

    b = baseline_fit(sds, start_model, starts)
    bp, _ = truth_errors(b.aero_names, b.aero_values, b.aero_sigma, model)
    bp_c, _ = truth_errors(b.aero_names, b.aero_values, res.aero_sigma, model)
    agree = np.abs(b.aero_values - res.aero_values) / res.aero_sigma
    r = {"baseline_s": b.elapsed_s, "baseline_speedup": b.elapsed_s / cadra_s,
         "baseline_ms_per_trajectory": 1e3 * b.elapsed_s / b.n_trajectories,
         "baseline_speedup_one_thread": b.elapsed_s / cadra_one_s,
         "baseline_success": b.success, "baseline_chi2": b.chi2,
         "baseline_trajectories": b.n_trajectories, "baseline_nfev": b.nfev,
         "baseline_njev": b.njev,
         "baseline_max_abs_pull": float(np.max(np.abs(bp))),
         "baseline_max_abs_pull_cadra_sigma": float(np.max(np.abs(bp_c))),
         "baseline_vs_cadra_max_sigma": float(np.max(agree)),
         "baseline_sigma_ratio_min": float(np.min(b.aero_sigma / res.aero_sigma)),
         "baseline_sigma_ratio_max": float(np.max(b.aero_sigma / res.aero_sigma))}
    print(f"   baseline (solve_ivp DOP853 rtol 1e-10 + least_squares 2-point): "
          f"{b.elapsed_s:.2f} s, {b.n_trajectories} trajectories ({b.nfev} evaluations, "
          f"{b.njev} Jacobians; {r['baseline_ms_per_trajectory']:.1f} ms per trajectory), "
          f"success {b.success}: speed-up {r['baseline_speedup']:.1f}x "
          f"({r['baseline_speedup_one_thread']:.1f}x over CADRA on one thread)")
    cadra_pull = float(np.max(np.abs(truth_errors(res.aero_names, res.aero_values,
                                                  res.aero_sigma, model)[0])))
    print(f"   chi2 baseline {b.chi2:.3f} vs CADRA {res.chi2:.3f}; max |fit-truth|/sigma: "
          f"CADRA {cadra_pull:.2f}, "
          f"baseline {r['baseline_max_abs_pull']:.2f} (own sigma) / "
          f"{r['baseline_max_abs_pull_cadra_sigma']:.2f} (CADRA's sigma); "
          f"|baseline - CADRA| <= {r['baseline_vs_cadra_max_sigma']:.3f} sigma; "
          f"baseline sigma / CADRA sigma {r['baseline_sigma_ratio_min']:.2f}-"
          f"{r['baseline_sigma_ratio_max']:.2f}")
    return r


def _baseline_python(label, sds, model, start_model, starts, res, cadra_s, python_ms,
                     compiled_trajectories):
    """The baseline fit with the plain-Python right-hand side (``rhs="python"``); for the
    multi-fit only if the estimate from the single fit's ms per trajectory is affordable."""
    from cadra.validation.fit_baseline import baseline_fit

    if label != "single":
        estimate = (None if python_ms is None
                    else 1e-3 * python_ms * compiled_trajectories)
        if estimate is None or estimate > PYTHON_MULTIFIT_LIMIT_S:
            why = ("no single-fit timing to estimate from" if estimate is None else
                   f"estimated {estimate:.0f} s = {python_ms:.0f} ms per trajectory x "
                   f"{compiled_trajectories} trajectories (compiled-RHS count) > "
                   f"{PYTHON_MULTIFIT_LIMIT_S:.0f} s")
            print(f"   baseline, plain-Python RHS: skipped ({why})")
            return {"baseline_python_skipped": why}
        print(f"   baseline, plain-Python RHS: estimated {estimate:.0f} s, running")
    b = baseline_fit(sds, start_model, starts, rhs="python")
    bp, _ = truth_errors(b.aero_names, b.aero_values, b.aero_sigma, model)
    agree = np.abs(b.aero_values - res.aero_values) / res.aero_sigma
    r = {"baseline_python_s": b.elapsed_s, "baseline_python_speedup": b.elapsed_s / cadra_s,
         "baseline_python_ms_per_trajectory": 1e3 * b.elapsed_s / b.n_trajectories,
         "baseline_python_success": b.success, "baseline_python_chi2": b.chi2,
         "baseline_python_trajectories": b.n_trajectories,
         "baseline_python_max_abs_pull": float(np.max(np.abs(bp))),
         "baseline_python_vs_cadra_max_sigma": float(np.max(agree))}
    print(f"   baseline, plain-Python RHS (same solve_ivp and least_squares settings): "
          f"{b.elapsed_s:.2f} s, {b.n_trajectories} trajectories "
          f"({r['baseline_python_ms_per_trajectory']:.1f} ms per trajectory), success "
          f"{b.success}: speed-up {r['baseline_python_speedup']:.1f}x")
    print(f"   chi2 python baseline {b.chi2:.3f} vs CADRA {res.chi2:.3f}; max |fit-truth|/sigma "
          f"{r['baseline_python_max_abs_pull']:.2f}; |python baseline - CADRA| <= "
          f"{r['baseline_python_vs_cadra_max_sigma']:.3f} sigma")
    return r


# --- 3: cold start ------------------------------------------------------------------------

COLD_SCRIPT = r"""
import json, math, sys, time
t0 = time.perf_counter()
import numpy as np, pandas as pd
from cadra.aero import load_bundled_model
from cadra.flight.data import FILM_SIGMAS, rigid_body_from_shot, shot_data_from_truth
from cadra.fitting.sensitivity import apply_local
from cadra.fitting.solver import fit
from cadra.io.shotfile import load_shot
from cadra.body import body_from_spec
t_import = time.perf_counter() - t0
root = sys.argv[1]
shot = load_shot(f"{root}/sample_shots/m2_2429/shot.toml")
truth = pd.read_csv(f"{root}/sample_shots/m2_2429/truth.csv")
rng = np.random.default_rng(5)
sd = shot_data_from_truth(truth, rigid_body_from_shot(shot), shot.shot_id,
                          body_from_spec(shot.model).kind,
                          sigma_position_m=FILM_SIGMAS["position_m"],
                          sigma_angle_rad=FILM_SIGMAS["angle_rad"], rng=rng)
row = truth.iloc[sd.epoch_index]
y = row[["x_cg_m", "y_cg_m", "z_cg_m", "vx_m_s", "vy_m_s", "vz_m_s", "q0", "q1", "q2", "q3",
         "p_rad_s", "q_rad_s", "r_rad_s"]].to_numpy(float)
y = apply_local(y, np.r_[1e-3, -1e-3, 1e-3, 0.5, -0.5, 0.5, 0.005, -0.005, 0.005, 0.5, -0.5, 0.5])
model = load_bundled_model("m2_m070")
model = model.with_values({n: model.parameter(n).value * 1.07 for n in model.free_names()})
t1 = time.perf_counter()
res = fit([sd], model, [y])
t2 = time.perf_counter()
print(json.dumps({"import_s": t_import, "first_fit_s": t2 - t1, "to_result_s": t2 - t0,
                  "status": res.status}))
"""


def cold_start():
    out = {}
    for label, env_extra in (("cached", {}), ("no_cache", "tmp")):
        env = dict(os.environ)
        with tempfile.TemporaryDirectory() as tmp:
            if env_extra == "tmp":
                env["NUMBA_CACHE_DIR"] = tmp
            t0 = time.perf_counter()
            p = subprocess.run([sys.executable, "-c", COLD_SCRIPT, str(REPO_ROOT)], env=env,
                               capture_output=True, text=True, cwd=tmp)
            wall = time.perf_counter() - t0
        if p.returncode != 0:
            print(f"   cold start ({label}) failed:\n{p.stderr[-2000:]}")
            out[label] = {"failed": True}
            continue
        r = json.loads(p.stdout.strip().splitlines()[-1])
        r["process_wall_s"] = wall
        out[label] = r
        print(f"   {label:8s}: first fit {r['first_fit_s']:.2f} s, imports {r['import_s']:.2f}"
              f" s, process start to result {r['to_result_s']:.2f} s (wall {wall:.2f} s), "
              f"{r['status']}")
    return out


# --- 4: noise-free ------------------------------------------------------------------------

def noise_free(seed):
    from cadra.fitting.sensitivity import Integration
    from cadra.fitting.solver import FitOptions, fit
    from cadra.flight.data import FILM_SIGMAS

    tight = FitOptions(step_tol_sigma=1e-4,
                       integration=Integration(tol_position_m=1e-10, tol_angle_rad=1e-10))
    variants = (("truth_csv", False, FitOptions(),
                 "truth.csv (25 us RK4 truth), default options"),
                ("exact_default", True, FitOptions(),
                 "exact data (solve_ivp rtol 1e-13), default options"),
                ("exact_tight", True, tight,
                 "exact data, step_tol_sigma 1e-4 and tolerance 1e-10"))
    out = {}
    for label, names in (("m2_m070", M2_SET), ("m1_m110", M1_SET)):
        for variant, exact, opts, desc in variants:
            rng = np.random.default_rng([seed, 4, 1 if label == "m2_m070" else 2])
            sds, _, model, start_model, starts = make_problem(names, rng, FILM_SIGMAS,
                                                              noise=False, exact=exact)
            res = fit(sds, start_model, starts, options=opts)
            pulls, rel = truth_errors(res.aero_names, res.aero_values, res.aero_sigma, model)
            i = int(np.nanargmax(rel))
            worst = sorted(zip(rel, res.aero_names, pulls, strict=True), reverse=True)[:3]
            out[f"{label}_{variant}"] = {
                "max_rel_err": float(rel[i]), "worst": res.aero_names[i],
                "max_abs_err_sigma": float(np.max(np.abs(pulls))), "status": res.status,
                "elapsed_s": res.elapsed_s,
                "rel_err": dict(zip(res.aero_names, map(float, rel), strict=True))}
            print(f"   {label} {desc}: max rel err {rel[i]:.2e} ({res.aero_names[i]}), "
                  f"max |err|/sigma {np.max(np.abs(pulls)):.1e}, {res.status} "
                  f"({res.elapsed_s:.1f} s); worst: "
                  + ", ".join(f"{n} {e:.1e} ({p:+.1e} sigma, sigma/|truth| "
                              f"{abs(e / p) if p else float('nan'):.2g})"
                              for e, n, p in worst))
    return out


# --- 5: pulls -------------------------------------------------------------------------------

def _one_realisation(job):
    """Worker: one noisy multi-fit; returns (set, sigmas label, names, values, sigmas, status,
    truth values)."""
    from cadra.fitting.sensitivity import Integration
    from cadra.fitting.solver import FitOptions, fit
    from cadra.flight.data import FILM_SIGMAS

    set_label, sig_label, seed, i = job
    names = M2_SET if set_label == "m2_m070" else M1_SET
    sigmas, exact = (FILM_SIGMAS, False) if sig_label == "film" else (STAGE1_SIGMAS, True)
    rng = np.random.default_rng([seed, 5, len(set_label), len(sig_label), i])
    sds, _, model, start_model, starts = make_problem(names, rng, sigmas, exact=exact)
    res = fit(sds, start_model, starts,
              options=FitOptions(integration=Integration(threads=1)))
    truth = np.array([model.parameter(n).value for n in res.aero_names])
    return (set_label, sig_label, res.aero_names, res.aero_values, res.aero_sigma,
            res.status, truth, res.elapsed_s)


def pulls(seed, n_film, n_stage1, workers):
    from tqdm import tqdm

    for name in M2_SET + M1_SET:        # simulate in the parent: forked workers inherit it
        _sim(name)
    jobs = [(s, "film", seed, i) for s in ("m2_m070", "m1_m110") for i in range(n_film)]
    jobs += [(s, "stage1", seed, i) for s in ("m2_m070", "m1_m110") for i in range(n_stage1)]
    collected: dict = {}
    ctx = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
        futures = [ex.submit(_one_realisation, j) for j in jobs]
        for f in tqdm(as_completed(futures), total=len(futures), desc="pulls", unit="fit"):
            s, g, names, v, sg, status, truth, dt = f.result()
            collected.setdefault((s, g), []).append((names, v, sg, status, truth, dt))
    out = {}
    for (s, g), rows in sorted(collected.items()):
        names = rows[0][0]
        conv = [r for r in rows if r[3] == "converged"]
        P = np.array([(r[1] - r[4]) / r[2] for r in conv])
        std, mean = P.std(axis=0, ddof=1), P.mean(axis=0)
        within = (np.abs(P) < 2).mean(axis=0)
        out[f"{s}_{g}"] = {"n": len(rows), "n_converged": len(conv),
                           "fit_s_mean": float(np.mean([r[5] for r in rows])),
                           "pull_std": dict(zip(names, map(float, std), strict=True)),
                           "pull_mean": dict(zip(names, map(float, mean), strict=True)),
                           "within_2sigma": dict(zip(names, map(float, within),
                                                     strict=True))}
        print(f"\n   {s}, {g} sigmas: {len(conv)}/{len(rows)} converged, "
              f"{np.mean([r[5] for r in rows]):.2f} s per fit (one thread)")
        print("     parameter   pull mean  pull std  within 2 sigma")
        for j, n in enumerate(names):
            print(f"     {n:10s} {mean[j]:+9.3f} {std[j]:9.3f} {within[j]:10.2f}")
        print(f"     pull std range {std.min():.3f}-{std.max():.3f}, overall within 2 sigma "
              f"{(np.abs(P) < 2).mean():.3f} (Gaussian 0.954)")
    return out


# --- figures -------------------------------------------------------------------------------

def figures(sp: dict, cold: dict | None, nf: dict | None, pl: dict | None,
            seconds: float) -> dict:
    """The benchmark's figures (its JSON line) from the sections' results:
    :func:`speed_and_baseline` (``sp``; with or without the baselines), :func:`cold_start`
    and :func:`noise_free` (``cold``, ``nf``; None: sections 1-2 only), :func:`pulls` (``pl``;
    None: skipped) and the benchmark's wall time ``seconds``."""
    s, m = sp["single"], sp["multi"]
    result = {
        "single_fit_s": round(s["best_s"], 4), "single_fit_median_s": round(s["median_s"], 4),
        "single_status": s["status"], "single_iterations": s["iterations"],
        "single_fit_one_thread_s": round(s["one_thread_s"], 4),
        "multifit_s": round(m["best_s"], 4),
        "multifit_one_thread_s": round(m["one_thread_s"], 4),
        "multifit_median_s": round(m["median_s"], 4),
        "multifit_status": m["status"], "multifit_iterations": m["iterations"],
        "jacobian_unknowns": s["jac_lanes"],
        "jacobian_trajectory_equivalents": round(s["jac_forward_equiv"], 2),
        "jacobian_complex_trajectory_equivalents": round(s["jac_complex_equiv"], 2),
        "jacobian_vs_complex_max_rel": float(f"{s['jac_vs_complex_max_rel']:.2e}"),
        "multifit_jacobian_vs_complex_max_rel": float(f"{m['jac_vs_complex_max_rel']:.2e}"),
        "float_trajectory_ms": round(s["jac_float_ms"], 3),
    }
    for key, r in (("single", s), ("multifit", m)):
        if "auto_best_s" in r:
            result[f"{key}_auto_start_fit_s"] = round(r["auto_best_s"], 4)
            result[f"{key}_auto_start_only_s"] = round(r["auto_start_s"], 4)
            result[f"{key}_auto_status"] = r["auto_status"]
            result[f"{key}_auto_max_abs_pull"] = round(r["auto_max_abs_pull"], 3)
    if "baseline_s" in s:
        result.update({
            "baseline_single_fit_s": round(s["baseline_s"], 3),
            "baseline_speedup": round(s["baseline_speedup"], 1),
            "baseline_multifit_s": round(m["baseline_s"], 3),
            "baseline_multifit_speedup": round(m["baseline_speedup"], 1),
            "baseline_speedup_one_thread": round(s["baseline_speedup_one_thread"], 1),
            "baseline_multifit_speedup_one_thread": round(m["baseline_speedup_one_thread"], 1),
            "baseline_single_trajectories": s["baseline_trajectories"],
            "baseline_multifit_trajectories": m["baseline_trajectories"],
            "cadra_single_max_abs_pull": round(s["max_abs_pull"], 3),
            "baseline_single_max_abs_pull": round(s["baseline_max_abs_pull"], 3),
            "cadra_multifit_max_abs_pull": round(m["max_abs_pull"], 3),
            "baseline_multifit_max_abs_pull": round(m["baseline_max_abs_pull"], 3),
            "baseline_single_chi2": round(s["baseline_chi2"], 4),
            "cadra_single_chi2": round(s["chi2"], 4),
            "baseline_multifit_chi2": round(m["baseline_chi2"], 4),
            "cadra_multifit_chi2": round(m["chi2"], 4),
            "baseline_vs_cadra_single_max_sigma": round(s["baseline_vs_cadra_max_sigma"], 4),
            "baseline_vs_cadra_multifit_max_sigma": round(m["baseline_vs_cadra_max_sigma"], 4),
            "baseline_single_ms_per_trajectory": round(s["baseline_ms_per_trajectory"], 2),
            "baseline_multifit_ms_per_trajectory": round(m["baseline_ms_per_trajectory"], 2),
            "baseline_python_single_fit_s": round(s["baseline_python_s"], 3),
            "baseline_python_speedup": round(s["baseline_python_speedup"], 1),
            "baseline_python_single_ms_per_trajectory":
                round(s["baseline_python_ms_per_trajectory"], 2),
            "baseline_python_single_trajectories": s["baseline_python_trajectories"],
            "baseline_python_single_success": s["baseline_python_success"],
            "baseline_python_single_max_abs_pull": round(s["baseline_python_max_abs_pull"], 3),
            "baseline_python_single_chi2": round(s["baseline_python_chi2"], 4),
            "baseline_python_vs_cadra_single_max_sigma":
                round(s["baseline_python_vs_cadra_max_sigma"], 4),
        })
        if "baseline_python_s" in m:
            result.update({
                "baseline_python_multifit_s": round(m["baseline_python_s"], 3),
                "baseline_python_multifit_speedup": round(m["baseline_python_speedup"], 1),
                "baseline_python_multifit_ms_per_trajectory":
                    round(m["baseline_python_ms_per_trajectory"], 2),
                "baseline_python_multifit_trajectories": m["baseline_python_trajectories"],
                "baseline_python_multifit_max_abs_pull":
                    round(m["baseline_python_max_abs_pull"], 3),
                "baseline_python_multifit_chi2": round(m["baseline_python_chi2"], 4),
                "baseline_python_vs_cadra_multifit_max_sigma":
                    round(m["baseline_python_vs_cadra_max_sigma"], 4),
            })
        else:
            result["baseline_python_multifit_skipped"] = m["baseline_python_skipped"]
    else:
        result["baseline_speedup"] = result["baseline_single_fit_s"] = None
    if cold is None:
        result["bench_seconds"] = round(seconds, 1)
        return result
    c = cold.get("cached", {})
    result["cold_start_s"] = round(c["first_fit_s"], 3) if "first_fit_s" in c else None
    result["cold_start_process_s"] = round(c["to_result_s"], 3) if "to_result_s" in c else None
    nc = cold.get("no_cache", {})
    result["cold_start_no_cache_s"] = (round(nc["first_fit_s"], 3) if "first_fit_s" in nc
                                       else None)
    result["noise_free_max_rel_err"] = max(nf["m2_m070_exact_tight"]["max_rel_err"],
                                           nf["m1_m110_exact_tight"]["max_rel_err"])
    for k, v in nf.items():
        result[f"noise_free_{k}_max_rel_err"] = v["max_rel_err"]
        result[f"noise_free_{k}_worst"] = v["worst"]
    if pl is not None:
        film = [pl[k] for k in ("m2_m070_film", "m1_m110_film")]
        stds = [x for r in film for x in r["pull_std"].values()]
        result["pull_std_min"] = round(min(stds), 3)
        result["pull_std_max"] = round(max(stds), 3)
        result["pull_mean_abs_max"] = round(max(abs(x) for r in film
                                                for x in r["pull_mean"].values()), 3)
        result["within_2sigma_min"] = round(min(x for r in film
                                                for x in r["within_2sigma"].values()), 3)
        for k, r in pl.items():
            result[f"pulls_{k}_n"] = r["n_converged"]
            result[f"pulls_{k}_std"] = {n: round(x, 3) for n, x in r["pull_std"].items()}
            result[f"pulls_{k}_mean"] = {n: round(x, 3) for n, x in r["pull_mean"].items()}
            result[f"pulls_{k}_within_2sigma"] = {n: round(x, 3)
                                                  for n, x in r["within_2sigma"].items()}
        st1 = [pl[k] for k in ("m2_m070_stage1", "m1_m110_stage1") if k in pl]
        if st1:
            s1 = [x for r in st1 for x in r["pull_std"].values()]
            result["stage1_pull_std_min"] = round(min(s1), 3)
            result["stage1_pull_std_max"] = round(max(s1), 3)
    else:
        result["pull_std_min"] = result["pull_std_max"] = None
    result["bench_seconds"] = round(seconds, 1)
    return result


__all__ = ["M1_SET", "M2_SET", "SINGLE", "STAGE1_SIGMAS", "cold_start", "figures",
           "make_problem", "noise_free", "pulls", "speed_and_baseline"]
