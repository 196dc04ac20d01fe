"""End to end: shadowgraphs -> cadra1 -> cadra2 multi-fit, against the simulator's truth.

For a seed-004 case (default the M2 M0.70 set: shots 2425 2426 2427 2428 2429 2431 2433) every
shot is flown and rendered from its sample spec, measured by stage one, and the whole set is
fitted by stage two with the case's Table 4 forms. The fit starts from every free parameter
at ZERO (linear-theory starting values do the rest), so nothing is borrowed from the truth.
Reported per parameter: fit, sigma, truth, pull = (fit - truth) / sigma; the last line is a
JSON object (max_abs_pull, all_within_2_sigma, reduced_chi2, ...).

Rendered shots and stage-one outputs go to ``out/e2e/`` (regenerated: about 30 s a shot to
render and 3-20 s to measure; ``--reuse`` keeps what is already there).

Usage:
    python tools/validate_e2e.py [--case m2_m070 | m1_m110] [--reuse] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASES = {
    "m2_m070": ["m2_2425", "m2_2426", "m2_2427", "m2_2428", "m2_2429", "m2_2431", "m2_2433"],
    "m1_m110": ["m1_2366", "m1_2379", "m1_2380", "m1_2384", "m1_2386", "m1_2388", "m1_2393"],
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--case", default="m2_m070", choices=sorted(CASES))
    parser.add_argument("--out", default=str(ROOT / "out" / "e2e"))
    parser.add_argument("--reuse", action="store_true",
                        help="keep already rendered shots and stage-one outputs")
    parser.add_argument("--fit-out", default=None,
                        help="also write the cadra2 fit outputs (report, plots) here")
    args = parser.parse_args(argv)

    from cadra.fitting import fit_shots
    from cadra.flight import load_shot_data
    from cadra.imaging.shot import measure_shot
    from cadra.report.stage1 import write_stage1
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_render = t_measure = 0.0
    shots, truth_model = [], None
    for name in CASES[args.case]:
        spec = load_shot_spec(ROOT / "sample_shots" / "specs" / f"{name}.toml")
        sim = simulate_shot(spec)
        truth_model = sim.model
        shot_dir, meas_dir = out / name, out / f"{name}_stage1"
        if not (args.reuse and (shot_dir / "shot.toml").is_file()):
            t = time.perf_counter()
            write_shot(sim, shot_dir, images=True, overwrite=True, progress=False)
            t_render += time.perf_counter() - t
        if not (args.reuse and (meas_dir / "trajectory.csv").is_file()):
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
    print(f"\ncadra2 multi-fit of {len(shots)} shots ({args.case}, all free parameters started "
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
    if args.fit_out:
        from cadra.report.fit import write_fit_outputs

        write_fit_outputs(result, shots, args.fit_out, overwrite=True, start_model=start,
                          reference_model=truth_model)
        print(f"fit outputs: {args.fit_out}")
    rms = result.rms()
    summary = {
        "case": args.case, "shots": len(shots), "status": result.status,
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
    print(json.dumps(summary))
    return 0 if result.converged else 1


if __name__ == "__main__":
    sys.exit(main())
