"""M-80 rounds on the BRL-like spark range, reduced as a range engineer would
(``tools/validate_spark_range.py``; docs/spark_range.md).

Each round is flown by the bundled simulator on ``facilities/spark_range.toml`` (25 stations
4.0 m apart over 96 m), its coefficients drawn over MR 1833 Table II's ranges (and the yaw
drag CDD2 over 1.5-3.5 per sin^2), its launch yaw and tip-off rates, muzzle velocity and air
drawn too; the spin is that of a 1-in-12 in twist at the muzzle velocity. The measurements are
the exact truth plus film-level noise: 0.1 mm on x, y, z and 0.1 deg on theta, psi. The
reducer is given only the twist and the muzzle velocity (as a shot file's ``[gun]`` gives
them), never the truth:

* **the 6-DOF fit** (:func:`cadra.fitting.fit_shots` from its automatic start, the model
  ``m80`` with CD0, CNA, CDD2, CMA, CMQ, CMPA free). The same fit started at the truth (its
  state and coefficients) gives the truth's chi^2 basin; the automatic fit is *in the basin*
  when it converged and its chi^2 is within 1 of that fit's. A fit outside the basin must not
  be called converged: ``false_converged`` counts those that were (status converged and
  not flagged as a poor minimum), and fits flagged as converged at p(chi^2) < 1e-6.
* **the classic reduction** (:func:`cadra.flight.classic.analyse_shot`, what ``cadra2 motion
  --twist 12`` runs): the 12-constant epicyclic fit in distance with the arms put in the
  spin's frequency bands, C_mα from the arms.

Pulls are (fitted - truth) / sigma per coefficient over the rounds in the basin. The
12-constant fit's sigmas are set beside the 6-DOF fit's per coefficient (CMA, CMQ and CMPA,
MR 1833's normalisation: cadra.motion's d/2V values halved).
"""

from __future__ import annotations

import math
import time
import tomllib
from pathlib import Path

import numpy as np

from cadra.aero import resolve_model
from cadra.flight.data import shot_data_from_truth, with_launch_spin
from cadra.units import M_PER_IN

ROOT = Path(__file__).resolve().parents[2]
SPEC = ROOT / "sample_shots" / "specs" / "m80_spark_1.toml"
#: MR 1833 Table II's ranges (docs/m80.md) and the yaw drag's drawn range
TABLE_II = {"CD0": (0.29, 0.39), "CNA": (2.0, 3.0), "CMA": (1.77, 1.86),
            "CMQ": (-4.5, -2.8), "CMPA": (-0.21, 0.04), "CDD2": (1.5, 3.5)}
FREE = ("CD0", "CNA", "CDD2", "CMA", "CMQ", "CMPA")
#: the classic reduction's coefficients in MR 1833's normalisation: (attribute, factor)
CLASSIC = {"CMA": ("Cm_alpha", 1.0), "CMQ": ("Cmq_sum", 0.5), "CMPA": ("Cm_p_alpha", 0.5)}
TWIST_IN = 12.0
SIGMA_POSITION_M, SIGMA_ANGLE_DEG = 1e-4, 0.1
#: chi^2 above the truth-started fit's that still counts as its basin
BASIN_CHI2 = 1.0


def draw_round(k: int, seed: int):
    """Round ``k``: a simulated shot (truth) and its drawn coefficients and muzzle velocity."""
    from cadra.io.spec_file import spec_from_dict
    from cadra.synthetic.simulate import simulate_shot

    rng = np.random.default_rng([seed, k])
    d = tomllib.loads(SPEC.read_text())
    values = {n: float(rng.uniform(*TABLE_II[n])) for n in FREE}
    v_muzzle = float(rng.uniform(825.0, 850.0))
    spin = 2.0 * math.pi * v_muzzle / (TWIST_IN * M_PER_IN)
    d.update(shot_id=f"SPARK-{k + 1}", seed=int(rng.integers(1, 2**31)),
             aero_values=values, gun={"twist_in_per_turn": TWIST_IN,
                                      "muzzle_velocity_m_s": v_muzzle})
    d["launch"] = {"x_m": -0.5, "speed_m_s": v_muzzle - float(rng.uniform(4.0, 8.0)),
                   "theta_deg": float(rng.uniform(-1.5, 1.5)),
                   "psi_deg": float(rng.uniform(-1.5, 1.5)), "p_rad_s": spin,
                   "q_rad_s": float(rng.uniform(-40, 40)),
                   "r_rad_s": float(rng.uniform(-40, 40))}
    d["range"] = {"pressure_torr": float(rng.uniform(740.0, 780.0)),
                  "temperature_k": float(rng.uniform(273.0, 293.0))}
    return simulate_shot(spec_from_dict(d)), values, v_muzzle


def measured(sim, rng: np.random.Generator, v_muzzle: float | None):
    """The round as the reducer sees it: the truth plus film-level noise, the gun's twist
    and muzzle velocity (None: the twist alone, the spin then at the range's measured
    speed), the body frame (the fit chooses its own)."""
    sd = shot_data_from_truth(sim.truth, sim.rigid.with_frame("body"), sim.spec.shot_id,
                              "bullet", sigma_position_m=SIGMA_POSITION_M,
                              sigma_angle_rad=math.radians(SIGMA_ANGLE_DEG), rng=rng)
    return with_launch_spin(sd, twist_m_per_turn=TWIST_IN * M_PER_IN,
                            muzzle_velocity_m_s=v_muzzle)


def fit_round(sim, values: dict, sd, model) -> dict:
    """The 6-DOF fit from the automatic start and from the truth; the classic reduction."""
    from cadra.fitting import fit_shots
    from cadra.flight.classic import analyse_shot
    from cadra.flight.data import launch_spin
    from cadra.flight.estimates import estimate_motion
    from cadra.flight.starts import cm_alpha_of

    t0 = time.perf_counter()
    res, _ = fit_shots([sd], model)
    seconds = time.perf_counter() - t0
    truth_model = model.with_values(values)
    k = sd.epoch_index
    ref, _ = fit_shots([sd], truth_model, auto_start=False, initial=[sim.states[k]])
    in_basin = bool(res.converged and ref.converged and res.chi2 <= ref.chi2 + BASIN_CHI2)
    row = {"shot_id": sd.shot_id, "status": res.status, "verdict": res.verdict,
           "chi2": res.chi2, "chi2_truth_start": ref.chi2, "dof": res.dof,
           "in_basin": in_basin, "seconds": seconds, "iterations": res.iterations,
           "false_converged": bool(res.verdict == "converged" and not in_basin)}
    idx = {n: i for i, n in enumerate(res.aero_names)}
    for n in FREE:
        v, s = float(res.aero_values[idx[n]]), float(res.aero_sigma[idx[n]])
        row[f"{n}_value"], row[f"{n}_sigma"], row[f"{n}_truth"] = v, s, values[n]
        row[f"{n}_pull"] = (v - values[n]) / s if s > 0 else math.nan
    try:
        motion = analyse_shot(sd, spin=launch_spin(sd, estimate_motion(sd).speed_m_s),
                              trim=False, curvature=True,
                              cm_alpha_guess=cm_alpha_of(model), window=None)
        lc = motion.coefficients
        for n, (attr, f) in CLASSIC.items():
            v, s = f * getattr(lc, attr), f * getattr(lc, attr + "_sigma")
            row[f"classic_{n}_value"], row[f"classic_{n}_sigma"] = v, s
            row[f"classic_{n}_pull"] = (v - values[n]) / s if s > 0 else math.nan
        row["classic_aliased"] = None if motion.alias is None else list(motion.alias.shifts)
    except Exception as exc:  # noqa: BLE001 -- a failed reduction is a figure, not a crash
        row["classic_error"] = str(exc)
    return row


def run(rounds: int = 20, seed: int = 1880, muzzle_velocity: bool = True) -> dict:
    """Fly, measure and reduce ``rounds`` rounds; the figures (module doc). Without
    ``muzzle_velocity`` the reducer has the twist alone."""
    model = resolve_model("m80").with_vary({"CDD2": True})
    rows = []
    for k in range(rounds):
        sim, values, v_m = draw_round(k, seed)
        sd = measured(sim, np.random.default_rng([seed, k, 1]),
                      v_m if muzzle_velocity else None)
        rows.append(fit_round(sim, values, sd, model))
    return {**summarise(rows), "muzzle_velocity_given": bool(muzzle_velocity)}


def summarise(rows: list[dict]) -> dict:
    """The JSON figures of :func:`run` from its per-round rows."""
    basin = [r for r in rows if r["in_basin"]]
    pulls = {n: np.array([r[f"{n}_pull"] for r in basin]) for n in FREE}
    stds = {n: float(np.std(p, ddof=1)) if p.size > 1 else math.nan for n, p in pulls.items()}
    within = {n: float(np.mean(np.abs(p) <= 2.0)) if p.size else math.nan
              for n, p in pulls.items()}
    classic = [r for r in rows if "classic_CMA_pull" in r]
    ratios = {n: float(np.median([r[f"classic_{n}_sigma"] / r[f"{n}_sigma"] for r in basin
                                  if f"classic_{n}_sigma" in r]))
              for n in CLASSIC} if basin else {}
    return {
        "rounds": len(rows),
        "right_basin_frac": len(basin) / len(rows) if rows else math.nan,
        "false_converged": int(sum(r["false_converged"] for r in rows)),
        "flagged_poor_minimum": int(sum(r["verdict"] == "poor_minimum" for r in rows)),
        "not_converged": int(sum(r["status"] != "converged" for r in rows)),
        "pull_std": stds,
        "pull_std_min": min(stds.values()), "pull_std_max": max(stds.values()),
        "within_2sigma": within,
        "within_2sigma_frac": float(np.mean(np.concatenate(
            [np.abs(p) <= 2.0 for p in pulls.values()]))) if basin else math.nan,
        "within_2sigma_frac_min": min(within.values()),
        "classic_over_6dof_sigma": ratios,
        "motion_cma_within_2sigma_frac": float(np.mean(
            [abs(r["classic_CMA_pull"]) <= 2.0 for r in classic])) if classic else math.nan,
        "motion_pull_std": {n: float(np.std([r[f"classic_{n}_pull"] for r in classic],
                                            ddof=1)) for n in CLASSIC} if len(classic) > 1
        else {},
        "motion_failed": len(rows) - len(classic),
        "seconds_per_fit_median": float(np.median([r["seconds"] for r in rows])),
        "seconds_per_fit_max": float(np.max([r["seconds"] for r in rows])),
        "iterations_median": float(np.median([r["iterations"] for r in rows])),
        "per_round": [{k: r[k] for k in ("shot_id", "verdict", "in_basin", "chi2",
                                         "chi2_truth_start", "dof", "seconds")}
                      for r in rows],
    }


__all__ = ["FREE", "TABLE_II", "draw_round", "fit_round", "measured", "run", "summarise"]
