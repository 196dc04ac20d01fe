"""The finned range shot end to end (the fourth part of ``tools/validate_roll.py``): FINNER-1
(``sample_shots/specs/finner_1.toml``, canted fins rolling the model up from rest) flown with
new seeds, rendered, measured by stage one (roll included) and fitted by stage two with the
bundled ``basic_finner`` forms from automatic starting values; the pulls (fit - truth) /
sigma of every free coefficient, the roll coefficients (:data:`ROLL_COEFFICIENTS`) named.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

__all__ = ["ROLL_COEFFICIENTS", "finner_e2e", "finner_realisation"]

#: the sample shots' specs
SPECS_DIR = Path(__file__).resolve().parents[2] / "sample_shots" / "specs"
#: the roll coefficients of the finned range shot's model
ROLL_COEFFICIENTS = ("Cl_delta", "Clp_0")


def finner_realisation(r: int, seed: int, work: Path) -> dict:
    """FINNER-1 with a new seed: images -> cadra1 -> cadra2; pulls of the free coefficients."""
    from cadra.fitting import fit_shots
    from cadra.flight.data import load_shot_data
    from cadra.imaging.shot import measure_shot
    from cadra.report.stage1 import write_stage1
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    spec = load_shot_spec(SPECS_DIR / "finner_1.toml")
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
    """``n`` realisations of FINNER-1 end to end (:func:`finner_realisation`, each printed);
    the figures over them: the roll coefficients' pulls within 2 sigma, all pulls, chi^2/nu,
    the roll's measured error."""
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
