"""End-to-end runs of the seed-004 seven-shot sets: shadowgraphs -> stage one -> stage two
against the simulator's truth, one set once (:func:`validate_case`) or over many
realisations with a control of honest errors beside each (:func:`run_bench`); the tools
bench_e2e.py and validate_e2e.py are their command lines."""

from __future__ import annotations

import functools
import math
import multiprocessing
import shutil
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from cadra.fitting import fit_shots
from cadra.fitting.sensitivity import Integration
from cadra.fitting.solver import FitOptions
from cadra.flight.data import load_shot_data, shot_data_from_truth
from cadra.imaging.shot import measure_shot
from cadra.report.fit import write_fit_outputs
from cadra.report.stage1 import write_stage1
from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

#: the seven-shot sets of the sample specs (seed 004's M2 M0.70 and M1 M1.10 shots)
SETS = {
    "m2_m070": ["m2_2425", "m2_2426", "m2_2427", "m2_2428", "m2_2429", "m2_2431", "m2_2433"],
    "m1_m110": ["m1_2366", "m1_2379", "m1_2380", "m1_2384", "m1_2386", "m1_2388", "m1_2393"],
}
CHANNEL_NAMES = ("x", "y", "z", "theta", "psi")


def _spec_seed(base: int, seed: int, r: int) -> int:
    """A realisation's spec seed: new for every (bench seed, realisation), stable per shot."""
    return int(np.random.SeedSequence([seed, r, base]).generate_state(1)[0] & 0x7FFFFFFF)


def measure_one(job):
    """Worker: fly, render and measure one shot of one realisation.

    Returns (set, r, name, e2e ShotData, control ShotData, stage-one normalised errors
    (n, 5) with NaN where not measured, seconds). Nothing is left on disk.
    """
    root, set_name, r, name, seed, work = job
    t0 = time.perf_counter()
    spec = load_shot_spec(root / "sample_shots" / "specs" / f"{name}.toml")
    spec = replace(spec, seed=_spec_seed(spec.seed, seed, r))
    sim = simulate_shot(spec)
    tmp = Path(tempfile.mkdtemp(prefix=f"{name}_r{r}_", dir=work))
    try:
        shot_dir, meas_dir = tmp / "shot", tmp / "stage1"
        write_shot(sim, shot_dir, images=True, progress=False)
        write_stage1(measure_shot(shot_dir / "shot.toml", workers=1, progress=False,
                                  overlays=False), meas_dir)
        e2e = load_shot_data(shot_dir / "shot.toml", meas_dir / "trajectory.csv")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    # the images' exact truth at the measured stations (truth.csv is what the images show)
    truth = sim.truth.set_index("station").loc[e2e.stations].reset_index()
    exact = shot_data_from_truth(truth, e2e.rigid, e2e.shot_id, e2e.body_kind,
                                 sigma_position_m=1.0, sigma_angle_rad=1.0).meas
    rng = np.random.default_rng([seed, r, spec.seed, 7])
    measured = np.isfinite(e2e.meas)
    noise = np.zeros_like(exact)        # the required channels' draws (as before the roll)
    noise[:, :5] = rng.standard_normal((exact.shape[0], 5))
    control_meas = np.where(measured, exact + noise * e2e.sigma, np.nan)
    control = replace(e2e, meas=control_meas, source={"origin": "truth + stage-one sigmas"})
    errors = (e2e.meas - exact) / e2e.sigma
    return set_name, r, name, e2e, control, errors, time.perf_counter() - t0


@functools.cache
def truth_model(root: Path, set_name: str):
    """The set's truth aero model (its first shot's spec under ``root``; every shot of a set
    shares it), once per process."""
    spec = load_shot_spec(root / "sample_shots" / "specs" / f"{SETS[set_name][0]}.toml")
    return simulate_shot(spec).model


def fit_one(job):
    """Worker: the zero-start multi-fit of one realisation's set (e2e or control)."""
    root, set_name, r, kind, shots = job
    vc = kind == "e2e_vc"
    truth = truth_model(root, set_name)
    zero = truth.with_values({n: 0.0 for n in truth.free_names()})
    t0 = time.perf_counter()
    res, _ = fit_shots(shots, zero, options=FitOptions(integration=Integration(threads=1)),
                       variance_components=vc)
    scales = res.options.get("variance_components", {}).get("sigma_scale", {})
    values = np.array([truth.parameter(n).value for n in res.aero_names])
    return dict(set=set_name, r=r, kind=kind, names=res.aero_names,
                pulls=(np.asarray(res.aero_values) - values) / np.asarray(res.aero_sigma),
                chi2=res.chi2, dof=res.dof, status=res.status, iterations=res.iterations,
                sigma_scale=scales,
                chi2_before=res.options.get("variance_components", {}).get(
                    "reduced_chi2_before", res.chi2 / max(res.dof, 1)),
                seconds=time.perf_counter() - t0)


def stage1_summary(errors_by_shot):
    """Per channel: std of the normalised errors, and the shot-wide variance ratio."""
    out = {}
    for j, c in enumerate(CHANNEL_NAMES):
        within, means, counts = [], [], []
        for e in errors_by_shot:
            v = e[:, j][np.isfinite(e[:, j])]
            if len(v) < 3:
                continue
            within.append(v - v.mean())
            means.append(v.mean())
            counts.append(len(v))
        if not means:
            continue
        allv = np.concatenate([e[:, j][np.isfinite(e[:, j])] for e in errors_by_shot])
        w = np.concatenate(within)
        var_within = float(np.sum(w ** 2) / (len(w) - len(means)))
        n_mean = float(np.mean(counts))
        ratio = float(np.var(means, ddof=1) * n_mean / var_within) if len(means) > 1 else math.nan
        out[c] = {"std": float(allv.std()), "mean": float(allv.mean()),
                  "within_shot_std": math.sqrt(var_within),
                  "shot_mean_variance_ratio": ratio, "shots": len(means)}
    return out


def summarise(fits, label):
    """Pull statistics of one (set, kind)."""
    conv = [f for f in fits if f["status"] == "converged"]
    names = fits[0]["names"]
    P = np.array([f["pulls"] for f in conv])
    chi2nu = np.array([f["chi2"] / f["dof"] for f in conv])
    dof = float(np.median([f["dof"] for f in conv]))
    scatter = math.sqrt(2.0 / dof)                  # 1-sigma scatter of chi^2/nu about 1
    std, mean = P.std(axis=0, ddof=1), P.mean(axis=0)
    within = (np.abs(P) <= 2).mean(axis=0)
    print(f"\n== {label}: {len(conv)}/{len(fits)} converged")
    print(f"   {'parameter':10s} {'pull mean':>9s} {'pull std':>9s} {'within 2σ':>9s}")
    for j, n in enumerate(names):
        print(f"   {n:10s} {mean[j]:+9.3f} {std[j]:9.3f} {within[j]:9.2f}")
    med = float(np.median(chi2nu))
    print(f"   pull std {std.min():.3f}-{std.max():.3f}, |mean| max {np.abs(mean).max():.3f}, "
          f"within 2σ {(np.abs(P) <= 2).mean():.3f} (Gaussian 0.954); chi²/ν median "
          f"{med:.3f} (1 ± {scatter:.3f} for ν = {dof:.0f})")
    return {"n": len(fits), "converged": len(conv),
            "pull_std": dict(zip(names, map(float, std), strict=True)),
            "pull_mean": dict(zip(names, map(float, mean), strict=True)),
            "within_2sigma": dict(zip(names, map(float, within), strict=True)),
            "pull_std_min": float(std.min()), "pull_std_max": float(std.max()),
            "pull_abs_mean_max": float(np.abs(mean).max()),
            "within_2sigma_frac": float((np.abs(P) <= 2).mean()),
            "chi2nu_median": med, "chi2nu_scatter": scatter, "dof": dof,
            "chi2nu_median_within_scatter": bool(abs(med - 1.0) <= scatter)}


def run_bench(root, realisations: int, sets, seed: int, workers: int,
              variance_components: bool) -> dict:
    """The end-to-end pulls of ``sets`` over ``realisations`` (tools/bench_e2e.py): every
    shot flown, rendered and measured in ``workers`` processes, then each realisation's
    e2e, control and (``variance_components``) variance-component multi-fits; the tables
    printed, the figures returned."""
    root = Path(root)
    t_start = time.perf_counter()
    ctx = multiprocessing.get_context("fork")
    shots: dict = {}
    errors: dict = {}
    with tempfile.TemporaryDirectory(prefix="cadra_bench_e2e_") as work:
        jobs = [(root, s, r, name, seed, work) for s in sets
                for r in range(realisations) for name in SETS[s]]
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
            futures = [ex.submit(measure_one, j) for j in jobs]
            for f in tqdm(as_completed(futures), total=len(futures),
                          desc="phase 1/2: render + stage one", unit="shot"):
                s, r, name, e2e, control, err, _ = f.result()
                shots.setdefault((s, r), {})[name] = (e2e, control)
                errors.setdefault(s, []).append(err)
    fit_jobs = []
    for (s, r), by_name in sorted(shots.items()):
        ordered = [by_name[n] for n in SETS[s]]
        fit_jobs.append((root, s, r, "e2e", [e for e, _ in ordered]))
        fit_jobs.append((root, s, r, "control", [c for _, c in ordered]))
        if variance_components:
            fit_jobs.append((root, s, r, "e2e_vc", [e for e, _ in ordered]))
    fits: dict = {}
    for s in sets:          # once, in the parent: forked workers inherit it
        truth_model(root, s)
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
        futures = [ex.submit(fit_one, j) for j in fit_jobs]
        for f in tqdm(as_completed(futures), total=len(futures),
                      desc="phase 2/2: cadra2 multi-fits", unit="fit"):
            out = f.result()
            if out["status"] != "converged":
                tqdm.write(f"{out['set']} r{out['r']} {out['kind']}: {out['status']} after "
                           f"{out['iterations']} iterations, chi2/nu "
                           f"{out['chi2'] / out['dof']:.3f}")
            fits.setdefault((out["set"], out["kind"]), []).append(out)
    elapsed = time.perf_counter() - t_start

    result: dict = {"sets": {}}
    for s in sets:
        st1 = stage1_summary(errors[s])
        print(f"\n== {s}: stage one, (measured - truth) / sigma over "
              f"{realisations * len(SETS[s])} shots")
        print(f"   {'channel':8s} {'mean':>7s} {'std':>7s} {'shot-wide variance ratio':>25s}")
        for c, v in st1.items():
            print(f"   {c:8s} {v['mean']:+7.3f} {v['std']:7.3f} "
                  f"{v['shot_mean_variance_ratio']:25.2f}")
        e2e = summarise(fits[(s, "e2e")], f"{s}: end to end")
        control = summarise(fits[(s, "control")], f"{s}: control (truth + stage-one sigmas)")
        result["sets"][s] = {"e2e": e2e, "control": control, "stage1": st1}
        if variance_components:
            vc = summarise(fits[(s, "e2e_vc")], f"{s}: end to end, variance components")
            conv = [f for f in fits[(s, "e2e_vc")] if f["status"] == "converged"]
            vc["sigma_scale_median"] = {
                ch: float(np.median([f["sigma_scale"][ch] for f in conv if ch in
                                     f["sigma_scale"]])) for ch in CHANNEL_NAMES}
            vc["chi2nu_before_median"] = float(np.median([f["chi2_before"] for f in conv]))
            print("   sigma scales (median): " + ", ".join(
                f"{c} ×{v:.3f}" for c, v in vc["sigma_scale_median"].items()))
            result["sets"][s]["e2e_vc"] = vc
    sets = result["sets"].values()
    result.update(
        e2e_pull_std_min=min(v["e2e"]["pull_std_min"] for v in sets),
        e2e_pull_std_max=max(v["e2e"]["pull_std_max"] for v in sets),
        e2e_pull_abs_mean_max=max(v["e2e"]["pull_abs_mean_max"] for v in sets),
        e2e_within_2sigma_frac=min(v["e2e"]["within_2sigma_frac"] for v in sets),
        e2e_chi2nu_median=max(v["e2e"]["chi2nu_median"] for v in sets),
        e2e_chi2nu_median_within_scatter=all(
            v["e2e"]["chi2nu_median_within_scatter"] for v in sets),
        control_pull_std_min=min(v["control"]["pull_std_min"] for v in sets),
        control_pull_std_max=max(v["control"]["pull_std_max"] for v in sets),
        control_within_2sigma_frac=min(v["control"]["within_2sigma_frac"] for v in sets),
        control_chi2nu_median=max(v["control"]["chi2nu_median"] for v in sets),
        **({"e2e_vc_pull_std_min": min(v["e2e_vc"]["pull_std_min"] for v in sets),
            "e2e_vc_pull_std_max": max(v["e2e_vc"]["pull_std_max"] for v in sets),
            "e2e_vc_pull_abs_mean_max": max(v["e2e_vc"]["pull_abs_mean_max"] for v in sets),
            "e2e_vc_within_2sigma_frac": min(v["e2e_vc"]["within_2sigma_frac"] for v in sets)}
           if variance_components else {}),
        realisations=realisations,
        seconds_per_realisation=elapsed / (realisations * len(sets)),
        seconds=elapsed)
    return result


def validate_case(root, case: str, out, reuse: bool = False, fit_out=None) -> dict:
    """One seven-shot set end to end (tools/validate_e2e.py): rendered and measured into
    ``out`` (``reuse``: keep what is there), fitted from zero; the pulls against the truth
    printed and returned (``converged`` says whether the fit did)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t_render = t_measure = 0.0
    shots, truth_model = [], None
    for name in SETS[case]:
        spec = load_shot_spec(Path(root) / "sample_shots" / "specs" / f"{name}.toml")
        sim = simulate_shot(spec)
        truth_model = sim.model
        shot_dir, meas_dir = out / name, out / f"{name}_stage1"
        if not (reuse and (shot_dir / "shot.toml").is_file()):
            t = time.perf_counter()
            write_shot(sim, shot_dir, images=True, overwrite=True, progress=False)
            t_render += time.perf_counter() - t
        if not (reuse and (meas_dir / "trajectory.csv").is_file()):
            t = time.perf_counter()
            res = measure_shot(shot_dir / "shot.toml", progress=False, overlays=False)
            write_stage1(res, meas_dir, overwrite=True)
            t_measure += time.perf_counter() - t
            print(f"{name}: stage one {res.seconds:.1f} s, "
                  f"{int((res.trajectory['status'] != 'failed').sum())}/{len(res.trajectory)} "
                  "stations")
        shots.append(load_shot_data(shot_dir / "shot.toml", meas_dir / "trajectory.csv"))
    zero = truth_model.with_values({n: 0.0 for n in truth_model.free_names()})
    t = time.perf_counter()
    result, start = fit_shots(shots, zero)
    t_fit = time.perf_counter() - t
    print(f"\ncadra2 multi-fit of {len(shots)} shots ({case}, all free parameters started "
          f"at 0): {result.status}, {result.iterations} iterations, {t_fit:.2f} s, "
          f"chi2/dof = {result.reduced_chi2:.3f}")
    print(f"{'parameter':10s} {'fit':>12s} {'sigma':>10s} {'truth':>10s} {'pull':>7s}")
    pulls = {}
    for n, v, s in zip(result.aero_names, result.aero_values, result.aero_sigma, strict=True):
        tv = truth_model.parameter(n).value
        pulls[n] = float((v - tv) / s)
        print(f"{n:10s} {v:12.6g} {s:10.2g} {tv:10.6g} {pulls[n]:+7.2f}")
    for w in result.warnings:
        print(f"warning: {w}")
    if fit_out:
        write_fit_outputs(result, shots, fit_out, overwrite=True, start_model=start,
                          reference_model=truth_model)
        print(f"fit outputs: {fit_out}")
    rms = result.rms()
    summary = {
        "case": case, "shots": len(shots), "status": result.status,
        "reduced_chi2": result.reduced_chi2, "fit_s": t_fit, "render_s": t_render,
        "stage1_s": t_measure,
        "max_abs_pull": max(abs(p) for p in pulls.values()),
        "all_within_2_sigma": all(abs(p) <= 2 for p in pulls.values()),
        "n_within_2_sigma": sum(abs(p) <= 2 for p in pulls.values()),
        "n_parameters": len(pulls), "pulls": pulls,
        "rms_position_um": 1e6 * float(np.sqrt(np.mean([rms[c]**2 for c in "xyz"]))),
        "rms_angle_deg": float(np.degrees(np.sqrt(np.mean([rms["theta"]**2,
                                                           rms["psi"]**2])))),
    }
    summary["converged"] = bool(result.converged)
    return summary


__all__ = ["CHANNEL_NAMES", "SETS", "run_bench", "validate_case"]
