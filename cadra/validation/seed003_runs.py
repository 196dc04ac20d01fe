"""Seed 003's global segmented roll fit against its own Table 2: the simulated runs and the
draws of ``tools/validate_roll_seed003.py`` (docs/segmented_roll.md).

Two simulated air-bearing runs of a Basic Finner at alpha = 57 deg in seed 003's tunnel
(V 117 ft/s, q 16.3 lb/ft^2), flown by CADRA's roll-bearing dynamics with Eq. 5 and Table 2
as truth (``cadra/aero/models/seed003_romof.toml``), measured at 100 frames/s with 0.25 deg of
white noise (:func:`simulate_run`, :func:`measured_record`); each noise draw is segmented as
the paper segments (:mod:`cadra.studies.segmented_roll`) and fitted globally for all 14
coefficients (:func:`fit_draw`). :func:`run` makes the Table-2-like and Table-3-like tables
over the draws and returns the figures: the pull spread, our signal/noise over the paper's,
the steady spins of the fitted coefficients against +0.0280 / -0.0212, the C10-C11 and
C10-C30 correlations.

The case: d = 2 in, a uniform aluminium Basic Finner (cadra.body.finner), pivot at the cg,
run 1 released at rest at phi = 41.16 deg (breaks out positive), run 2 at 42.16 deg (breaks
out negative).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cadra.aero import resolve_model
from cadra.body.finner import finner_mass_properties, finner_preset
from cadra.dynamics.modes import TestMode
from cadra.dynamics.observe import air_angles
from cadra.dynamics.setup import RigidBody, propagate_states
from cadra.dynamics.trajectory import Launch

__all__ = ["ALPHA", "ALUMINIUM", "D_M", "DEFAULT_DRAWS", "FPS", "MODEL", "Q_INF", "RUNS",
           "SIGMA_DEG", "TrueRun", "V_STREAM", "fit_draw", "measured_record", "run",
           "seed003_body", "simulate_run"]

FT = 0.3048
PSF = 47.880259                     # Pa per lb/ft^2
V_STREAM = 117.0 * FT               # m/s
Q_INF = 16.3 * PSF                  # Pa
ALPHA = math.radians(57.0)
D_M = 2.0 * 0.0254                  # 2 in
ALUMINIUM = 2700.0                  # kg/m^3
FPS = 100.0
SIGMA_DEG = 0.25
#: the two runs: release angle (aircraft roll = aerodynamic roll here), rate, record length
RUNS = {"run1": dict(phi0_deg=41.16, p0_rad_s=0.0, duration_s=11.0),
        "run2": dict(phi0_deg=42.16, p0_rad_s=0.0, duration_s=17.0)}
MODEL = "seed003_romof"
#: the default number of noise draws (what was measured to fit in the time budget)
DEFAULT_DRAWS = 50            # 1547 s on the shared 2-core machine (docs/segmented_roll.md)


def seed003_body() -> RigidBody:
    """The Basic Finner on its roll bearing in seed 003's stream (SI)."""
    fb = finner_preset("basic_finner", d_m=D_M)
    mp = finner_mass_properties(fb, ALUMINIUM)
    rho = 2.0 * Q_INF / V_STREAM**2
    return RigidBody(mass_kg=mp.mass_kg, inertia_body_kg_m2=mp.inertia_kg_m2, d_m=D_M,
                     cg_from_ref_body_m=np.zeros(3), density_kg_m3=rho,
                     speed_of_sound_m_s=340.3, viscosity_pa_s=1.81e-5, gravity_m_s2=0.0,
                     mode=TestMode(kind="roll_bearing", stream_m_s=V_STREAM))


@dataclass(frozen=True)
class TrueRun:
    name: str
    t_s: np.ndarray
    phi_rad: np.ndarray        # continuous (unwrapped) roll angle
    p_rad_s: np.ndarray


def simulate_run(name: str, body: RigidBody | None = None, model=None, *, fps: float = FPS,
                 phi0_deg: float | None = None, p0_rad_s: float | None = None,
                 duration_s: float | None = None) -> TrueRun:
    """One run's exact roll history, CADRA's roll-bearing dynamics (RK4, 0.5 ms steps)."""
    body = body or seed003_body()
    model = model or resolve_model(MODEL)
    run = RUNS.get(name, {})
    phi0 = math.radians(run["phi0_deg"] if phi0_deg is None else phi0_deg)
    p0 = run["p0_rad_s"] if p0_rad_s is None else p0_rad_s
    T = run["duration_s"] if duration_s is None else duration_s
    t = np.arange(int(round(T * fps)) + 1) / fps
    y0 = Launch(speed_m_s=0.0, theta_rad=ALPHA, roll_rad=phi0, p_rad_s=p0).state(body)
    states = propagate_states(y0, 0.0, t, body.phys(), model.compile(), model.values(),
                              dt_max=5e-4)
    phi = np.unwrap(air_angles(states, body)["phi_rad"])
    return TrueRun(name, t, phi, states[:, 10].copy())


def measured_record(run: TrueRun, rng: np.random.Generator | None,
                    sigma_deg: float = SIGMA_DEG):
    """The run as the film measures it: the roll angle in [0, 2 pi) (the paper plots 0-360
    deg) with white noise of ``sigma_deg`` (none without ``rng``)."""
    from cadra.studies.segmented_roll import RollRecord

    sig = math.radians(sigma_deg)
    phi = run.phi_rad + (rng.standard_normal(run.phi_rad.size) * sig if rng is not None else 0.0)
    return RollRecord(run.name, run.t_s, np.mod(phi, 2 * math.pi), sig)


def fit_draw(draw: int, *, seed: int = 2003, stepwise: bool = False, body=None, model=None,
             runs=None):
    """One noise draw of both runs, segmented and fitted (all 14 coefficients; the paper's
    stepwise order with ``stepwise``). Returns the :class:`SegmentedFit`."""
    from cadra.studies.segmented_roll import STEPS, TABLE_ORDER, segmented_fit

    body = body or seed003_body()
    model = model or resolve_model(MODEL)
    runs = runs or [simulate_run(n, body, model) for n in RUNS]
    rng = np.random.default_rng([seed, draw])
    records = [measured_record(r, rng) for r in runs]
    steps = STEPS if stepwise else (TABLE_ORDER,)
    return segmented_fit(records, model, body, ALPHA, steps=steps)


def _nearest_stable(tab, target: float) -> float:
    st = tab[tab["stable"]]
    if st.empty:
        return math.nan
    return float(st["p_hat"].iloc[int(np.argmin(np.abs(st["p_hat"] - target)))])


def run(draws: int = DEFAULT_DRAWS, seed: int = 2003, stepwise: bool = False,
        out: Path | None = None) -> dict:
    """``draws`` noise draws of both runs (module doc), the first through the paper's stepwise
    order (every one with ``stepwise``); prints the tables (and writes the first draw's fit
    with the tables over the draws to the new folder ``out``: ``cadra.report.roll.write_roll``)
    and returns the figures, a figure one draw cannot give (a spread) as NaN."""
    import pandas as pd

    from cadra.studies.segmented_roll import (
        PAPER_TABLE2,
        TABLE_ORDER,
        paper_correlation,
        seed003_tables,
        steady_spins,
    )

    t0 = time.perf_counter()
    body, model = seed003_body(), resolve_model(MODEL)
    truth = {n: float(model.parameter(n).value) for n in TABLE_ORDER}
    runs = [simulate_run(n, body, model) for n in RUNS]
    vals, sigs, cors, spins, stats = [], [], [], [], []
    first = None
    for k in range(draws):
        sf = fit_draw(k, seed=seed, stepwise=stepwise or k == 0, body=body,
                      model=model, runs=runs)
        res = sf.result
        tabs = seed003_tables(sf)
        first = first or (sf, tabs)
        t2 = tabs["table2"]
        vals.append(t2["value"].reindex(TABLE_ORDER).to_numpy())
        sigs.append(t2["sigma"].reindex(TABLE_ORDER).to_numpy())
        cors.append(tabs["table3"].reindex(index=TABLE_ORDER, columns=TABLE_ORDER).to_numpy())
        sp = steady_spins(res.model)
        spins.append((_nearest_stable(sp, 0.0280), _nearest_stable(sp, -0.0212)))
        seg = tabs["segments"]
        stats.append({"converged": res.converged, "chi2_dof": res.reduced_chi2,
                      "segments": len(sf.segments), "bias_abs_deg": seg["bias_deg"].abs().mean(),
                      "rms_deg": seg["rms_deg"].mean(), "runs_z": seg["runs_z"].mean(),
                      "longest_run_s": seg["longest_run_s"].max(),
                      "iterations": sum(r.iterations for r in [sf.local, *sf.steps])})
        print(f"draw {k}: {res.status}, chi2/dof {res.reduced_chi2:.3f}, "
              f"{len(sf.segments)} segments, {time.perf_counter() - t0:.0f} s", flush=True)
    V, S = np.array(vals), np.array(sigs)
    tv = np.array([truth[n] for n in TABLE_ORDER])
    pulls = (V - tv) / S
    paper = np.array([PAPER_TABLE2[n] for n in TABLE_ORDER])
    snr = np.mean(np.abs(V) / S, axis=0)
    t2 = pd.DataFrame({
        "truth": tv, "fit_mean": V.mean(0), "fit_std": V.std(0, ddof=1) if len(V) > 1 else np.nan,
        "sigma_mean": S.mean(0), "signal_noise": snr, "paper_sigma": paper[:, 1],
        "paper_signal_noise": paper[:, 2],
        "snr_over_paper": snr / np.abs(paper[:, 0] / paper[:, 1]),
        "pull_mean": pulls.mean(0), "pull_std": pulls.std(0, ddof=1) if len(V) > 1 else np.nan,
        "within_2sigma": np.mean(np.abs(pulls) < 2, axis=0)},
        index=pd.Index(TABLE_ORDER, name="coefficient"))
    R = np.mean(cors, axis=0)
    P = paper_correlation().to_numpy()
    iu = np.triu_indices(len(TABLE_ORDER), 1)
    t3 = pd.DataFrame(np.where(np.triu(np.ones_like(R), 1) > 0, R, np.nan),
                      index=list(TABLE_ORDER), columns=list(TABLE_ORDER))
    pd.set_option("display.width", 200)
    pd.set_option("display.max_columns", 20)
    print(f"\nTable 2 over {draws} draws (truth = seed 003 Table 2):")
    print(t2.to_string(float_format=lambda v: f"{v:.5g}"))
    print("\nTable 3, mean correlation over the draws (upper triangle):")
    print(t3.iloc[:-1, 1:].to_string(float_format=lambda v: f"{v:+.3f}", na_rep=""))
    print(f"\nagainst the paper's Table 3: rms difference "
          f"{np.sqrt(np.mean((R[iu] - P[iu]) ** 2)):.3f}, correlation of the 91 entries "
          f"{np.corrcoef(R[iu], P[iu])[0, 1]:.3f}")
    sp = np.array(spins)
    rel = np.abs(sp - np.array([0.0280, -0.0212])) / np.array([0.0280, 0.0212])
    st = pd.DataFrame(stats)
    print(f"steady spins of the fitted coefficients: +{np.nanmean(sp[:, 0]):.5f} "
          f"({np.nanstd(sp[:, 0]):.5f}), {np.nanmean(sp[:, 1]):.5f} ({np.nanstd(sp[:, 1]):.5f})")
    print(f"segments {st['segments'].mean():.1f}, mean |bias| {st['bias_abs_deg'].mean():.4f} "
          f"deg, mean rms {st['rms_deg'].mean():.4f} deg, mean runs z {st['runs_z'].mean():+.3f}"
          f", longest run {st['longest_run_s'].max():.2f} s")
    if out is not None:
        from cadra.report.roll import write_roll

        sf, tabs = first
        write_roll(sf, {**tabs, "table2_draws": t2, "table3_draws": t3}, runs, ALPHA, out)
        print(f"the first draw's fit and the tables over the draws written to {out}")
    return {
        "seed003_pull_std_min": float(np.min(t2["pull_std"])),
        "seed003_pull_std_max": float(np.max(t2["pull_std"])),
        "seed003_pull_mean_absmax": float(np.max(np.abs(t2["pull_mean"]))),
        "seed003_within_2sigma": float(np.mean(np.abs(pulls) < 2)),
        "seed003_snr_over_paper_min": float(np.min(t2["snr_over_paper"])),
        "seed003_snr_over_paper_max": float(np.max(t2["snr_over_paper"])),
        "steady_spin_rel_err_max": float(np.nanmax(rel)),
        "corr_C10_C11": float(R[TABLE_ORDER.index("C10"), TABLE_ORDER.index("C11")]),
        "corr_C10_C30": float(R[TABLE_ORDER.index("C10"), TABLE_ORDER.index("C30")]),
        "converged": int(st["converged"].sum()),
        "chi2_dof_mean": float(st["chi2_dof"].mean()),
        "segments": float(st["segments"].mean()),
        "draws": draws,
    }
