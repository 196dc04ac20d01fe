"""The 7.62 mm M-80 end to end: shadowgraphs -> cadra1 -> linear theory and the 6-DOF fit,
against the simulator's truth (BRL MR 1833 Table II values, docs/m80.md); the work of
``tools/validate_m80.py``.

Each noise draw flies the sample rounds M80-1 and M80-2 (``sample_shots/specs/m80_*.toml``,
the small-arms range), renders their 120 shadowgraphs (draw 0 with the specs' own seeds,
draw k with seed + 1000 k: other image noise, film placement and trigger offsets), measures
them with stage one (one process; :func:`measure_draw`), and then

* **linear theory** (the classic method, per round; :func:`linear_theory`): the tricyclic fit
  of the measured angles with the trim arm at the spin from the twist, C_L_alpha from the
  swerve, and C_M_alpha, C_Mq + C_Malphadot and C_Mpalpha from the arms
  (``cadra.flight.classic.analyse_shot``, docs/motion.md), in MR 1833's normalisation (q d/V,
  p d/V: cadra.motion's p d/2V values divided by 2);
* **the 6-DOF fit** (:func:`six_dof`: ``cadra.fitting.fit_shots``, both rounds together, the
  model ``m80`` with CD0, CNA, CMA, CMQ, CMPA free), started from the rounds' mean
  linear-theory values and each round's spin from the twist: p0 = 2 pi V_muzzle / twist
  (1 turn in 12 in at 838 m/s), as a range engineer knows it. Nothing is borrowed from the
  truth.

:func:`run` reports per coefficient value, sigma, truth, pull = (value - truth) / sigma; over
the draws the fraction of |pull| <= 2 (``m80_within_2sigma_frac``, 6-DOF) and the pulls'
mean and standard deviation. Then one round with film-range noise (0.1 mm, 0.1 deg: stage
one's sigmas on real film, cadra.flight.FILM_SIGMAS) added to the exact truth gives a
realistic per-round sigma of CMQ to set beside the round-to-round spread of MR 1833 Table II
(-2.8 to -4.5; :func:`film_sigma`).

A draw whose stage-one output the fit refuses to load (``FitDataError``: stage one can write
an angle sigma of hundreds of degrees where the axis lies almost in a view's plane,
docs/m80.md) is listed in ``failures`` and left out of the fractions.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import time
from pathlib import Path

import numpy as np

__all__ = ["BRL_TABLE_II", "DRAWS_IN_VALIDATE_MOTION", "FREE", "LINEAR", "SPECS",
           "linear_theory", "measure_draw", "muzzle_spin_rad_s", "run", "six_dof"]

REPO_ROOT = Path(__file__).resolve().parents[2]
#: the sample rounds' specs
SPECS_DIR = REPO_ROOT / "sample_shots" / "specs"
#: where :func:`run` writes the draws' shots and stage-one outputs by default
DEFAULT_OUT = REPO_ROOT / "out" / "m80"
SPECS = ("m80_1", "m80_2")
#: the gun: 1 turn in 12 in (M14/M60 7.62 mm barrels), M-80 muzzle velocity 2750 ft/s
TWIST_M = 12 * 0.0254
MUZZLE_SPEED_M_S = 838.0
#: coefficients fitted by the 6-DOF fit (names of the bundled model ``m80``)
FREE = ("CD0", "CNA", "CMA", "CMQ", "CMPA")
#: linear theory's coefficients, MR 1833's normalisation; CLA is the lift slope
#: C_L_alpha = CNA - CD0 of the model's linear terms
LINEAR = ("CMA", "CMQ", "CMPA", "CLA")
#: MR 1833 Table II (docs/m80.md)
BRL_TABLE_II = {"CD0": (0.29, 0.39), "CNA": (2.0, 3.0), "CMA": (1.77, 1.86),
                "CMQ": (-4.5, -2.8), "CMPA": (-0.21, 0.04), "Sg": (2.1, 2.4)}
FILM_POSITION_M, FILM_ANGLE_RAD = 1.0e-4, math.radians(0.1)
#: draws tools/validate_motion.py runs for its m80_within_2sigma_frac (about 50 s each)
DRAWS_IN_VALIDATE_MOTION = 3


def muzzle_spin_rad_s() -> float:
    """The spin the twist gives at the muzzle: p = 2 pi V / twist (rad/s)."""
    return 2.0 * math.pi * MUZZLE_SPEED_M_S / TWIST_M


def truth_model():
    """The truth aerodynamics of the sample rounds (the bundled model ``m80``)."""
    from cadra.aero import resolve_model

    return resolve_model("m80")


def linear_truth(model) -> dict:
    """Linear theory's truth values (MR 1833 normalisation) from the model's parameters."""
    v = {p.name: p.value for p in model.parameters}
    return {"CMA": v["CMA"], "CMQ": v["CMQ"], "CMPA": v["CMPA"], "CLA": v["CNA"] - v["CD0"]}


def gyroscopic_stability(Ix, Iy, p, rho, V, d, cma) -> float:
    """S_g = I_x^2 p^2 / (2 rho I_y S d V^2 C_Malpha) (McCoy, Modern Exterior Ballistics)."""
    S = math.pi * d * d / 4.0
    return Ix * Ix * p * p / (2.0 * rho * Iy * S * d * V * V * cma)


def measure_draw(k: int, out: Path, keep_images: bool = False, reuse: bool = False):
    """Fly, render and measure every round of draw ``k``; returns (ShotData list, seconds).
    ``reuse``: keep a round's earlier shot file and stage-one output when both are there."""
    from cadra.flight import load_shot_data
    from cadra.imaging.shot import measure_shot
    from cadra.report.stage1 import write_stage1
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    shots, t0 = [], time.perf_counter()
    for name in SPECS:
        spec = load_shot_spec(SPECS_DIR / f"{name}.toml")
        if k:
            spec = dataclasses.replace(spec, seed=spec.seed + 1000 * k)
        shot_dir, meas_dir = out / f"draw_{k}" / name, out / f"draw_{k}" / f"{name}_stage1"
        if reuse and (shot_dir / "shot.toml").is_file() and (
                meas_dir / "trajectory.csv").is_file():
            shots.append(load_shot_data(shot_dir / "shot.toml", meas_dir / "trajectory.csv"))
            continue
        write_shot(simulate_shot(spec), shot_dir, images=True, overwrite=True, progress=False)
        write_stage1(measure_shot(shot_dir / "shot.toml", workers=1, progress=False,
                                  overlays=False), meas_dir, overwrite=True)
        if not keep_images:
            shutil.rmtree(shot_dir / "images", ignore_errors=True)
        shots.append(load_shot_data(shot_dir / "shot.toml", meas_dir / "trajectory.csv"))
    return shots, time.perf_counter() - t0


def linear_theory(shot) -> tuple[dict, dict, float]:
    """The classic reduction of one round: (values, sigmas) in MR 1833's normalisation, and
    C_D from the deceleration (cadra.flight.estimates.estimate_motion)."""
    from cadra.flight.classic import analyse_shot
    from cadra.flight.estimates import estimate_motion

    c = analyse_shot(shot, spin=muzzle_spin_rad_s()).coefficients
    val = {"CMA": c.Cm_alpha, "CMQ": c.Cmq_sum / 2, "CMPA": c.Cm_p_alpha / 2,
           "CLA": c.C_L_alpha}
    sig = {"CMA": c.Cm_alpha_sigma, "CMQ": c.Cmq_sum_sigma / 2,
           "CMPA": c.Cm_p_alpha_sigma / 2, "CLA": c.C_L_alpha_sigma}
    return val, sig, float(estimate_motion(shot).cd)


def starting_states(shots) -> list[np.ndarray]:
    """Each round's starting state: positions, velocity and axis from its measurements
    (cadra.fitting.start), the spin from the twist (the images do not show it)."""
    from cadra.fitting.start import state_candidates

    out = []
    for s in shots:
        y = state_candidates(s)[0].copy()
        y[10] = muzzle_spin_rad_s()
        out.append(y)
    return out


def six_dof(shots, start_values: dict, model=None):
    """The 6-DOF fit of ``shots`` from ``start_values`` (the free coefficients)."""
    from cadra.fitting import fit_shots
    from cadra.fitting.sensitivity import Integration
    from cadra.fitting.solver import FitOptions

    model = (model or truth_model()).with_values(start_values)
    opts = FitOptions(integration=Integration(threads=1))
    result, _ = fit_shots(shots, model, auto_start=False, initial=starting_states(shots),
                          options=opts)
    return result


def start_from_linear(lin: list[tuple[dict, dict, float]]) -> dict:
    """The 6-DOF fit's start: the rounds' mean linear-theory values (CNA = C_L_alpha + C_D)."""
    cd = float(np.mean([c for _, _, c in lin]))
    mean = {k: float(np.mean([v[k] for v, _, _ in lin])) for k in LINEAR}
    return {"CD0": cd, "CNA": mean["CLA"] + cd, "CMA": mean["CMA"], "CMQ": mean["CMQ"],
            "CMPA": mean["CMPA"]}


def film_sigma(rng: np.random.Generator) -> dict:
    """Round M80-1 with film-range noise on the exact truth: the 6-DOF fit's per-round
    sigmas (and pulls) where stage one measures 0.1 mm and 0.1 deg."""
    from cadra.flight.data import shot_data_from_truth
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    sim = simulate_shot(load_shot_spec(SPECS_DIR / f"{SPECS[0]}.toml"))
    shot = shot_data_from_truth(sim.truth, sim.rigid, sim.spec.shot_id, "bullet",
                                sigma_position_m=FILM_POSITION_M,
                                sigma_angle_rad=FILM_ANGLE_RAD, rng=rng)
    res = six_dof([shot], start_from_linear([linear_theory(shot)]))
    truth = truth_model()
    return {"status": res.status,
            "sigma": {n: float(s) for n, s in zip(res.aero_names, res.aero_sigma, strict=True)},
            "pull": {n: float((v - truth.parameter(n).value) / s) for n, v, s in
                     zip(res.aero_names, res.aero_values, res.aero_sigma, strict=True)}}


def conditions() -> dict:
    """S_g and the linear-theory arm frequencies of each round at its first station."""
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    cma = truth_model().parameter("CMA").value
    out = {}
    for name in SPECS:
        sim = simulate_shot(load_shot_spec(SPECS_DIR / f"{name}.toml"))
        rb, t = sim.rigid, sim.truth
        I = rb.inertia_body_kg_m2
        sg = [gyroscopic_stability(I[0, 0], I[1, 1], p, rb.density_kg_m3, V, rb.d_m, cma)
              for p, V in zip(t.p_rad_s, t.airspeed_m_s, strict=True)]
        out[name] = {"Sg_first": round(sg[0], 3), "Sg_last": round(sg[-1], 3),
                     "mach_first": round(float(t.mach.iloc[0]), 3),
                     "mach_last": round(float(t.mach.iloc[-1]), 3),
                     "sigma_max_deg": round(float(t.sigma_deg.max()), 2)}
    return out


def run(draws: int = 8, out: Path | None = None, keep_images: bool = False,
        film: bool = True, seed: int = 1, verbose: bool = True, reuse: bool = False) -> dict:
    """Every draw (module doc); returns the summary (the JSON of :func:`main`)."""
    from cadra.flight.data import FitDataError

    out = Path(out or DEFAULT_OUT)
    truth = truth_model()
    lin_truth = linear_truth(truth)
    pulls6 = {n: [] for n in FREE}
    # the same pulls with the fit's other sigmas (docs/fitting.md, "Uncertainties")
    pulls_alt = {"scaled": {n: [] for n in FREE}, "coloured": {n: [] for n in FREE}}
    pulls_lin = {n: [] for n in LINEAR}
    sig6 = {n: [] for n in FREE}
    t_meas = t_fit = 0.0
    failures = []
    say = print if verbose else (lambda *a, **k: None)
    for k in range(draws):
        try:
            shots, dt = measure_draw(k, out, keep_images, reuse)
        except FitDataError as exc:       # stage one wrote what the fit refuses to read
            failures.append(f"draw {k}: {exc}")
            say(f"draw {k}: {exc}")
            continue
        t_meas += dt
        lin = [linear_theory(s) for s in shots]
        for v, s, _ in lin:
            for n in LINEAR:
                pulls_lin[n].append((v[n] - lin_truth[n]) / s[n])
        t = time.perf_counter()
        res = six_dof(shots, start_from_linear(lin), truth)
        t_fit += time.perf_counter() - t
        if not res.converged:
            failures.append(f"draw {k}: {res.status}")
            say(f"draw {k}: 6-DOF fit {res.status}")
            continue
        row = []
        for n, v, s, s_sc, s_co in zip(res.aero_names, res.aero_values, res.aero_sigma,
                                       res.aero_sigma_scaled, res.aero_sigma_coloured,
                                       strict=True):
            dv = v - truth.parameter(n).value
            pulls6[n].append(float(dv / s))
            pulls_alt["scaled"][n].append(float(dv / s_sc))
            pulls_alt["coloured"][n].append(float(dv / s_co))
            sig6[n].append(float(s))
            row.append(f"{n} {v:.5g} ± {s:.2g} ({pulls6[n][-1]:+.2f})")
        say(f"draw {k}: chi2/nu {res.reduced_chi2:.3f}, " + ", ".join(row))
    all6 = np.array([p for n in FREE for p in pulls6[n]])
    all_lin = np.array([p for n in LINEAR for p in pulls_lin[n]])
    summary = {
        "draws": draws, "rounds": list(SPECS),
        "spin_from_twist_rad_s": round(muzzle_spin_rad_s(), 1),
        "conditions": conditions(),
        "m80_within_2sigma_frac": (round(float(np.mean(np.abs(all6) <= 2)), 4)
                                   if all6.size else None),
        "m80_linear_within_2sigma_frac": (round(float(np.mean(np.abs(all_lin) <= 2)), 4)
                                          if all_lin.size else None),
        "m80_within_2sigma_frac_scaled": _frac(pulls_alt["scaled"]),
        "m80_within_2sigma_frac_coloured": _frac(pulls_alt["coloured"]),
        "n_pulls": int(all6.size),
        "six_dof": {n: {"truth": truth.parameter(n).value,
                        "pull_mean": _r(np.mean(pulls6[n])), "pull_std": _r(np.std(pulls6[n])),
                        "max_abs_pull": _r(np.max(np.abs(pulls6[n]))),
                        "sigma_mean": float(f"{np.mean(sig6[n]):.3g}"),
                        "pulls": [round(p, 3) for p in pulls6[n]]}
                    for n in FREE if pulls6[n]},
        "linear_theory": {n: {"truth": round(lin_truth[n], 6),
                              "pull_mean": _r(np.mean(pulls_lin[n])),
                              "pull_std": _r(np.std(pulls_lin[n])),
                              "max_abs_pull": _r(np.max(np.abs(pulls_lin[n])))}
                          for n in LINEAR},
        "failures": failures, "stage1_s": round(t_meas, 1), "fit_s": round(t_fit, 1),
    }
    if film:
        f = film_sigma(np.random.default_rng(seed))
        summary["film_noise_one_round"] = f
        summary["cmq_sigma_film_per_round"] = float(f"{f['sigma']['CMQ']:.3g}")
        summary["cmq_brl_table_ii_spread"] = list(BRL_TABLE_II["CMQ"])
    return summary


def _r(x) -> float:
    return round(float(x), 3)


def _frac(pulls: dict) -> float | None:
    a = np.array([p for v in pulls.values() for p in v])
    return round(float(np.mean(np.abs(a) <= 2)), 4) if a.size else None
