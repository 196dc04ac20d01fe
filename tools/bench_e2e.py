"""End-to-end honesty: shadowgraphs -> cadra1 -> cadra2 over many realisations (issue 18).

For each seed-004 set (the M2 M0.70 and M1 M1.10 seven-shot sets of the sample specs) and
each realisation r, every shot is flown with its spec but a new seed (new trigger offsets,
new fixed illumination and clutter pattern, new film grain and noise), rendered, measured by
stage one, and the set is fitted by stage two with the case's Table 4 forms, every free
parameter started at ZERO (the automatic starting values do the rest). Reported per
parameter over the realisations: the pulls (fit - truth) / sigma, their mean and standard
deviation, the fraction within 2 sigma; and chi^2/nu against the scatter that chi^2 with the
fit's degrees of freedom allows.

A third fit of the same end-to-end data uses cadra2's per-channel variance components
(``fit_shots(..., variance_components=True)``, ``cadra2 fit --variance-components``): each
channel's sigmas rescaled by the factor the fit's own residuals ask for.

Beside each realisation runs the CONTROL: the same stations and the same stage-one sigmas,
but the measurements replaced by the images' exact truth plus Gaussian noise of those sigmas.
The control has honest errors by construction, so its pulls check the benchmark itself.

Stage one's own errors are summarised too: (measured - truth) / sigma per channel, their
standard deviation, and the shot-wide part (the variance of each shot's mean error, times
the stations per shot, over the within-shot variance: 1 for independent errors).

Usage::

    python tools/bench_e2e.py                    # 20 realisations a set (23 min; 40: 45 min)
    python tools/bench_e2e.py --realisations 3   # a smoke run

The last printed line is a JSON object (e2e_pull_std_min/max, e2e_pull_abs_mean_max,
e2e_within_2sigma_frac, e2e_chi2nu_median, control_pull_std_max, realisations,
seconds_per_realisation, and per-set details).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import multiprocessing
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from pathlib import Path

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
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
    from cadra.flight.data import load_shot_data, shot_data_from_truth
    from cadra.imaging.shot import measure_shot
    from cadra.report.stage1 import write_stage1
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    set_name, r, name, seed, work = job
    t0 = time.perf_counter()
    spec = load_shot_spec(ROOT / "sample_shots" / "specs" / f"{name}.toml")
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
def truth_model(set_name: str):
    """The set's truth aero model (its first shot's spec; every shot of a set shares it),
    once per process."""
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    spec = load_shot_spec(ROOT / "sample_shots" / "specs" / f"{SETS[set_name][0]}.toml")
    return simulate_shot(spec).model


def fit_one(job):
    """Worker: the zero-start multi-fit of one realisation's set (e2e or control)."""
    from cadra.fitting import fit_shots
    from cadra.fitting.sensitivity import Integration
    from cadra.fitting.solver import FitOptions

    set_name, r, kind, shots = job
    vc = kind == "e2e_vc"
    truth = truth_model(set_name)
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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--realisations", type=int, default=20,
                        help="realisations per set (default 20)")
    parser.add_argument("--sets", nargs="+", default=list(SETS), choices=list(SETS),
                        help="seven-shot sets (default both)")
    parser.add_argument("--seed", type=int, default=18, help="benchmark seed (default 18)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="processes (default: the cores)")
    parser.add_argument("--no-variance-components", dest="variance_components",
                        action="store_false",
                        help="skip the third fit of each realisation, the end-to-end fit "
                             "with cadra2's per-channel variance components")
    args = parser.parse_args(argv)
    from tqdm import tqdm

    t_start = time.perf_counter()
    ctx = multiprocessing.get_context("fork")
    shots: dict = {}
    errors: dict = {}
    with tempfile.TemporaryDirectory(prefix="cadra_bench_e2e_") as work:
        jobs = [(s, r, name, args.seed, work) for s in args.sets
                for r in range(args.realisations) for name in SETS[s]]
        with ProcessPoolExecutor(max_workers=args.workers, mp_context=ctx) as ex:
            futures = [ex.submit(measure_one, j) for j in jobs]
            for f in tqdm(as_completed(futures), total=len(futures),
                          desc="phase 1/2: render + stage one", unit="shot"):
                s, r, name, e2e, control, err, _ = f.result()
                shots.setdefault((s, r), {})[name] = (e2e, control)
                errors.setdefault(s, []).append(err)
    fit_jobs = []
    for (s, r), by_name in sorted(shots.items()):
        ordered = [by_name[n] for n in SETS[s]]
        fit_jobs.append((s, r, "e2e", [e for e, _ in ordered]))
        fit_jobs.append((s, r, "control", [c for _, c in ordered]))
        if args.variance_components:
            fit_jobs.append((s, r, "e2e_vc", [e for e, _ in ordered]))
    fits: dict = {}
    for s in args.sets:          # once, in the parent: forked workers inherit it
        truth_model(s)
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=ctx) as ex:
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
    for s in args.sets:
        st1 = stage1_summary(errors[s])
        print(f"\n== {s}: stage one, (measured - truth) / sigma over "
              f"{args.realisations * len(SETS[s])} shots")
        print(f"   {'channel':8s} {'mean':>7s} {'std':>7s} {'shot-wide variance ratio':>25s}")
        for c, v in st1.items():
            print(f"   {c:8s} {v['mean']:+7.3f} {v['std']:7.3f} "
                  f"{v['shot_mean_variance_ratio']:25.2f}")
        e2e = summarise(fits[(s, "e2e")], f"{s}: end to end")
        control = summarise(fits[(s, "control")], f"{s}: control (truth + stage-one sigmas)")
        result["sets"][s] = {"e2e": e2e, "control": control, "stage1": st1}
        if args.variance_components:
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
           if args.variance_components else {}),
        realisations=args.realisations,
        seconds_per_realisation=elapsed / (args.realisations * len(args.sets)),
        seconds=elapsed)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
