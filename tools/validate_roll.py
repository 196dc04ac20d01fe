"""Rolling finned missiles, every acceptance figure of issue 20 in one run (last line JSON).

Four parts; the first three are their own tools, run here as subprocesses (each prints a
JSON last line, merged below), the fourth is this file's:

1. ``validate_roll_seed001.py`` -- seed 001 Table IV (roll lock-in from 70 deg): the MDC
   pure-roll reduction's errors beside the paper's, stage two's fit of the same record, the
   limit cycle of Eq. 31 (docs/pureroll.md);
2. ``validate_roll_seed003.py`` -- seed 003 Table 2 as truth: segmented roll-bearing records,
   the global fit of the 14 coefficients over noise draws, pulls, signal/noise against the
   paper's, the steady spins of the fitted coefficients, the correlations
   (docs/segmented_roll.md);
3. ``validate_roll_images.py`` -- the roll from Basic Finner renders at default realism:
   error against the Cramer-Rao bound, sigma / actual, position and axis against the
   capsule's figures (docs/stage1.md, "Roll of a finned body");
4. the finned range shot end to end: FINNER-1 (sample_shots/specs/finner_1.toml, canted fins
   rolling the model up from rest) flown with new seeds, rendered, measured by cadra1 (roll
   included) and fitted by cadra2 with the bundled ``basic_finner`` forms from automatic
   starting values; the pulls (fit - truth) / sigma of every free coefficient, the roll
   coefficients (Cl_delta, Clp_0) named.

Usage::

    python tools/validate_roll.py                       # all parts (about 25 min)
    python tools/validate_roll.py --parts e2e --e2e-realisations 2
    python tools/validate_roll.py --seed003-draws 10 --images-n 8

The last printed line is a JSON object with at least lockin_cadra_over_mdc_error_max,
limit_cycle_rel_err, seed003_pull_std_min, seed003_pull_std_max, seed003_snr_over_paper_min,
steady_spin_rel_err_max, roll_crb_ratio, roll_sigma_ratio_min, roll_sigma_ratio_max,
finner_e2e_within_2sigma_frac.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("seed001", "seed003", "images", "e2e")
#: the roll coefficients of the finned range shot's model
ROLL_COEFFICIENTS = ("Cl_delta", "Clp_0")


def run_tool(script: str, args: list[str]) -> dict:
    """Run ``tools/<script>`` and return its last line's JSON (its table goes to stdout)."""
    cmd = [sys.executable, str(ROOT / "tools" / script), *args]
    print(f"$ {' '.join(cmd[1:])}", flush=True)
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    print(proc.stdout.rstrip("\n"), flush=True)
    if proc.returncode != 0:
        print(proc.stderr, file=sys.stderr)
        raise SystemExit(f"{script} failed (exit {proc.returncode})")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def finner_realisation(r: int, seed: int, work: Path) -> dict:
    """FINNER-1 with a new seed: images -> cadra1 -> cadra2; pulls of the free coefficients."""
    from cadra.fitting import fit_shots
    from cadra.flight.data import load_shot_data
    from cadra.measure.shot import measure_shot
    from cadra.report.stage1 import write_stage1
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    spec = load_shot_spec(ROOT / "sample_shots" / "specs" / "finner_1.toml")
    spec = replace(spec, seed=int(np.random.SeedSequence([seed, r]).generate_state(1)[0]
                                  & 0x7FFFFFFF))
    sim = simulate_shot(spec)
    tmp = Path(tempfile.mkdtemp(prefix=f"finner_r{r}_", dir=work))
    t0 = time.perf_counter()
    try:
        write_shot(sim, tmp / "shot", images=True, progress=False)
        t1 = time.perf_counter()
        write_stage1(measure_shot(tmp / "shot" / "shot.toml", workers=1, progress=False,
                                  overlays=False), tmp / "stage1")
        t2 = time.perf_counter()
        shot = load_shot_data(tmp / "shot" / "shot.toml", tmp / "stage1" / "trajectory.csv")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    truth = sim.truth.set_index("station").loc[shot.stations]
    # the cruciform's roll is known to a quarter turn (its fins look alike): error mod 90 deg
    d = np.degrees(shot.meas[:, 5]) - truth["phi_deg"].to_numpy()
    phi_err = d - 90.0 * np.floor((d + 45.0) / 90.0)
    res, _ = fit_shots([shot], sim.model)
    t3 = time.perf_counter()
    pulls = {}
    for name in res.aero_names:
        true = sim.model.parameter(name).value
        pulls[name] = {"truth": true, "fit": res.value(name), "sigma": res.sigma(name),
                       "pull": (res.value(name) - true) / res.sigma(name)}
    rr = res.residuals
    dof_ch = res.dof_by_channel()
    chi2nu_ch = {ch: float(np.sum((rr.loc[rr["channel"] == ch, "residual"]
                                   / rr.loc[rr["channel"] == ch, "sigma"]) ** 2) / dof_ch[ch])
                 for ch in dof_ch if dof_ch[ch] > 0}
    return {"realisation": r, "status": res.status, "reduced_chi2": res.reduced_chi2,
            "chi2nu_by_channel": chi2nu_ch,
            "dof": res.dof, "roll_measured": int(np.isfinite(shot.meas[:, 5]).sum()),
            "stations": len(shot.t_s),
            "roll_error_rms_deg": float(np.sqrt(np.nanmean(phi_err ** 2))),
            "roll_sigma_median_deg": float(np.degrees(np.nanmedian(shot.sigma[:, 5]))),
            "pulls": pulls, "seconds": {"render": t1 - t0, "cadra1": t2 - t1,
                                        "cadra2": t3 - t2}}


def finner_e2e(n: int, seed: int) -> dict:
    work = Path(tempfile.mkdtemp(prefix="validate_roll_"))
    rows = []
    try:
        for r in range(n):
            row = finner_realisation(r, seed, work)
            rows.append(row)
            p = row["pulls"]
            print(f"FINNER-1 realisation {r}: {row['status']}, chi2/nu "
                  f"{row['reduced_chi2']:.3f}, roll measured at {row['roll_measured']}/"
                  f"{row['stations']} stations, roll error rms {row['roll_error_rms_deg']:.4f}"
                  f" deg (median sigma {row['roll_sigma_median_deg']:.4f}); chi2/nu by channel "
                  + " ".join(f"{c} {v:.2f}" for c, v in row["chi2nu_by_channel"].items())
                  + "; "
                  + ", ".join(f"{k} {v['fit']:.4g} ± {v['sigma']:.2g} (truth {v['truth']:.4g},"
                              f" pull {v['pull']:+.2f})" for k, v in p.items()), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    allp = np.array([v["pull"] for row in rows for v in row["pulls"].values()])
    rollp = np.array([row["pulls"][k]["pull"] for row in rows for k in ROLL_COEFFICIENTS
                      if k in row["pulls"]])
    return {"finner_e2e_within_2sigma_frac": float(np.mean(np.abs(rollp) <= 2.0)),
            "finner_e2e_all_within_2sigma_frac": float(np.mean(np.abs(allp) <= 2.0)),
            "finner_e2e_roll_pulls": [round(float(v), 3) for v in rollp],
            "finner_e2e_converged_frac": float(np.mean([row["status"] == "converged"
                                                         for row in rows])),
            "finner_e2e_chi2nu_median": float(np.median([row["reduced_chi2"] for row in rows])),
            "finner_e2e_chi2nu_by_channel_median": {
                ch: float(np.median([row["chi2nu_by_channel"][ch] for row in rows]))
                for ch in rows[0]["chi2nu_by_channel"]},
            "finner_e2e_roll_error_rms_deg": float(np.sqrt(np.mean(
                [row["roll_error_rms_deg"] ** 2 for row in rows]))),
            "finner_e2e_realisations": n,
            "finner_e2e_seconds_per_realisation": float(np.mean(
                [sum(row["seconds"].values()) for row in rows]))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--parts", default=",".join(PARTS),
                    help=f"comma-separated parts to run (default: {','.join(PARTS)})")
    ap.add_argument("--seed003-draws", type=int, default=50,
                    help="noise draws of seed 003's records (default: 50)")
    ap.add_argument("--images-n", type=int, default=24,
                    help="Basic Finner stations rendered for the roll from images (default: 24)")
    ap.add_argument("--e2e-realisations", type=int, default=4,
                    help="realisations of the finned range shot end to end (default: 4)")
    ap.add_argument("--seed", type=int, default=20, help="seed of the end-to-end part "
                    "(default: 20)")
    args = ap.parse_args(argv)
    parts = [p.strip() for p in args.parts.split(",") if p.strip()]
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        ap.error(f"unknown part(s) {unknown}; choose from {list(PARTS)}")
    t0 = time.perf_counter()
    out: dict = {}
    if "seed001" in parts:
        out.update(run_tool("validate_roll_seed001.py", []))
    if "seed003" in parts:
        out.update(run_tool("validate_roll_seed003.py", ["--draws", str(args.seed003_draws)]))
    if "images" in parts:
        out.update(run_tool("validate_roll_images.py", ["--n", str(args.images_n)]))
    if "e2e" in parts:
        out.update(finner_e2e(args.e2e_realisations, args.seed))
    out["parts"] = parts
    out["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out, default=lambda v: None if isinstance(v, float) and math.isnan(v)
                     else str(v)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
