"""Seed 001 Table IV re-run: pure roll (roll lock-in) about the pi/4 trim, eqs. 27-31
(``tools/validate_roll_seed001.py``, docs/pureroll.md).

A cruciform finner on a roll bearing at alpha = 10 deg (:mod:`cadra.validation.roll_bearing`'s
Table IV finner) is released at 70 deg roll orientation (25 deg above the trim), with seed
001's inputs C_lp0 -2, C_lp2 15, C_l(alpha) 0.5 as aero-model forms, and simulated by CADRA's
6-DOF dynamics in the ``roll_bearing`` test mode. The record of the aerodynamic roll angle
phi = gamma, noise-free and with 0.05 deg of white noise, is reduced by

* the method of differential corrections of :mod:`cadra.motion.pureroll` (whole record, the
  sin 4 gamma pendulum averaged exactly), the seed's own harmonic averaging (eqs. 28-30) with
  and without its frequency-variation amplitude correction, and the sectional estimates that
  start them (:func:`classic`);
* CADRA's 6-DOF fit of the same record with C_l(alpha), C_lp0, C_lp2 free: stage two
  (``fit_shots``) on the ``phi`` channel alone, or a least-squares fallback without it
  (:func:`cadra_fit`).

Then the limit cycle (eq. 31) against the exact energy balance and the simulated one
(:func:`limit_cycles`). The seed gives no conditions: the choices are the constants below.
:func:`run` makes the whole table and returns the figures.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import brentq, least_squares

from cadra.dynamics.observe import air_angles
from cadra.dynamics.setup import RigidBody, propagate_states
from cadra.dynamics.trajectory import Launch
from cadra.motion.pureroll import (
    energy_balance_amplitude,
    limit_cycle_amplitude_eq31,
    mdc_fit,
    pure_roll_coefficients,
    section_estimates,
)
from cadra.validation.roll_bearing import (
    ALPHA,
    DT_TRUTH,
    TABLE_IV_SPEED_M_S,
    bearing,
    lockin_model,
    release_state,
)

__all__ = ["NOISE_DEG", "PAPER", "PHI0_DEG", "RATE_HZ", "RECORD_S", "TRUTH", "cadra_fit",
           "classic", "conditions", "limit_cycles", "run", "simulate"]

# --- the choices (the seed gives none of them; the body: roll_bearing.TABLE_IV_FINNER) ----
SPEED = TABLE_IV_SPEED_M_S        # m/s, a subsonic (Notre Dame-like) tunnel
RECORD_S, RATE_HZ = 4.0, 200.0    # about 20 cycles, 41-46 frames per cycle
NOISE_DEG = 0.05
PHI0_DEG = 70.0                   # seed 001 Table IV: the initial roll angle
TRUTH = {"Clp0": -2.0, "Clp2": 15.0, "Cl_alpha": 0.5}
PAPER = {"Clp0": 1.00, "Clp2": 3.87, "Cl_alpha": 0.04}     # Table IV's % errors
PARAM = {"Cl_alpha": "Cla", "Clp0": "Clp0", "Clp2": "Clp2"}


def body() -> RigidBody:
    """The Table IV finner on its roll bearing."""
    return bearing()


def conditions() -> dict:
    """I_x, q, S, d and V of the record (the pure-roll reduction's conditions)."""
    b = body()
    q = 0.5 * b.density_kg_m3 * SPEED**2
    return dict(Ix=float(b.inertia_body_kg_m2[0, 0]), q=q, S=float(b.area_m2), d=b.d_m,
                V=SPEED)


def launch_state(phi0_rad: float, p0: float = 0.0) -> np.ndarray:
    """The bearing's state at rest in roll (rate ``p0``) with the aerodynamic phi at phi0."""
    return release_state(body(), phi0_rad, p0)


def simulate(t, coeffs: dict, phi0_deg: float = PHI0_DEG):
    """(states, gamma) of the roll bearing; gamma = the aerodynamic roll angle, unwrapped
    (rad)."""
    b = body()
    m = lockin_model(coeffs["Cl_alpha"], coeffs["Clp0"], coeffs["Clp2"])
    states = propagate_states(launch_state(np.radians(phi0_deg)), 0.0, t, b.phys(),
                              m.compile(), m.values(), dt_max=DT_TRUTH)
    return states, np.unwrap(air_angles(states, b)["phi_rad"])


def pct(values: dict) -> dict:
    return {k: 100.0 * abs(values[k] / TRUTH[k] - 1.0) for k in TRUTH}


def pct_sigma(sigmas: dict) -> dict:
    return {k: 100.0 * sigmas[k] / abs(TRUTH[k]) for k in TRUTH}


# --- the classic reductions ------------------------------------------------------------

def classic(t, g, sigma=None) -> dict:
    """The pureroll reductions: whole-record MDC (pendulum; the seed's harmonic averaging
    with and without the frequency correction) and the pendulum sections."""
    c = conditions()
    out = {}
    se = section_estimates(t, g, sigma)
    out["sections"] = pure_roll_coefficients(se, **c)
    for key, kw in (("mdc", {}), ("harmonic", {"model": "harmonic"}),
                    ("harmonic_no_freq", {"model": "harmonic", "frequency_correction": False})):
        t0 = time.perf_counter()
        f = mdc_fit(t, g, sigma, start=se if not kw else None, **kw)
        out[key] = pure_roll_coefficients(f, **c)
        out[key + "_s"] = time.perf_counter() - t0
        out[key + "_fit"] = f
    return out


def values_of(coef) -> dict:
    return {"Clp0": coef.Clp0, "Clp2": coef.Clp2, "Cl_alpha": coef.Cl_alpha}


def sigmas_of(coef) -> dict:
    return {"Clp0": coef.Clp0_sigma, "Clp2": coef.Clp2_sigma, "Cl_alpha": coef.Cl_alpha_sigma}


# --- CADRA's 6-DOF fit -------------------------------------------------------------------

def cadra_fit_least_squares(t, g, sigma: float, start: dict) -> dict:
    """The 6-DOF (1-DOF roll mode) fit of γ: ``least_squares`` (MINPACK LM) around CADRA's
    ``propagate_states`` in the roll_bearing mode, free C_l(α), C_lp0, C_lp2 and the release
    (roll orientation and rate); the prediction is the simulator's own φ."""
    b = body()
    phys = b.phys()
    model = lockin_model(1.0, 1.0, 1.0)
    prog = model.compile()
    order = [k for p in model.names for k, v in PARAM.items() if v == p]

    def predict(x):
        vals = dict(zip(("Cl_alpha", "Clp0", "Clp2"), x[:3], strict=True))
        st = propagate_states(launch_state(x[3], x[4]), 0.0, t, phys, prog,
                              np.array([vals[k] for k in order]), dt_max=DT_TRUTH)
        return np.unwrap(air_angles(st, b)["phi_rad"])

    x0 = np.array([start["Cl_alpha"], start["Clp0"], start["Clp2"], g[0], 0.0])
    t0 = time.perf_counter()
    res = least_squares(lambda x: (predict(x) - g) / sigma, x0, method="lm", x_scale="jac",
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=300)
    J = res.jac
    dof = t.size - x0.size
    chi2 = float(res.fun @ res.fun)
    cov = np.linalg.pinv(J.T @ J) * (chi2 / dof)
    sig = np.sqrt(np.diag(cov))
    keys = ("Cl_alpha", "Clp0", "Clp2")
    return {"values": dict(zip(keys, res.x[:3], strict=True)),
            "sigmas": dict(zip(keys, sig[:3], strict=True)), "status": res.message,
            "chi2_dof": chi2 / dof, "seconds": time.perf_counter() - t0,
            "method": "scipy least_squares around propagate_states (roll_bearing)"}


def phi_channel_available() -> bool:
    """Whether stage two observes the roll angle (the ``phi`` channel of cadra.channels)."""
    from cadra import channels
    return "phi" in channels.NAMES


def cadra_fit_stage_two(t, states, noise, sigma: float, start: dict) -> dict:
    """CADRA's stage-two fit (``cadra.fitting.fit_shots``: the fit problem, its sensitivity
    integration and solver) of the record as a roll-only ShotData: the ``phi`` channel (the
    aircraft roll of the same states, plus the same noise) alone measured; C_l(α), C_lp0,
    C_lp2 free with the mount's local unknowns (roll orientation and rate at the epoch),
    started from the pureroll MDC's coefficients and the record's own roll and rate there."""
    from cadra import channels
    from cadra.dynamics.observe import observe
    from cadra.fitting import FitOptions, Integration, fit_shots
    from cadra.flight import ShotData

    b = body()
    k = channels.NAMES.index("phi")
    n = t.size
    meas = np.full((n, channels.N_CHANNELS), np.nan)
    sg = np.full((n, channels.N_CHANNELS), np.nan)
    phi = observe(states, b.ref_from_cg_body_m())["phi_rad"] + noise
    meas[:, k] = channels.wrap_angle(phi)
    sg[:, k] = sigma
    shot = ShotData(shot_id="LOCKIN-70", rigid=b, body_kind="finner", stations=np.arange(n),
                    t_s=t.copy(), meas=meas, sigma=sg, source={"origin": "simulated"})
    e = shot.epoch_index
    un = np.unwrap(phi)
    rate = (un[e + 1] - un[e - 1]) / (t[e + 1] - t[e - 1])
    y0 = Launch(speed_m_s=0.0, theta_rad=ALPHA, roll_rad=float(un[e]),
                p_rad_s=float(rate)).state(b)
    model = lockin_model(start["Cl_alpha"], start["Clp0"], start["Clp2"])
    opts = FitOptions(integration=Integration(threads=1))
    t0 = time.perf_counter()
    res, _ = fit_shots([shot], model, options=opts, auto_start=False, initial=[y0],
                       continuation=None)
    vals = dict(zip(res.aero_names, res.aero_values, strict=True))
    sigs = dict(zip(res.aero_names, res.aero_sigma, strict=True))
    return {"values": {k2: float(vals[v]) for k2, v in PARAM.items()},
            "sigmas": {k2: float(sigs[v]) for k2, v in PARAM.items()},
            "status": f"{res.status} in {res.iterations} iterations",
            "chi2_dof": float(res.reduced_chi2), "seconds": time.perf_counter() - t0,
            "method": "cadra.fitting.fit_shots, phi channel only (roll_bearing mode)"}


def cadra_fit(t, states, g_true, noise, sigma: float, start: dict) -> dict:
    """CADRA's 6-DOF fit of the record: stage two on the phi channel when it exists, else
    :func:`cadra_fit_least_squares` on the same dynamics path."""
    if phi_channel_available():
        return cadra_fit_stage_two(t, states, noise, sigma, start)
    return cadra_fit_least_squares(t, g_true + noise, sigma, start)


# --- the limit cycle (eq. 31) ------------------------------------------------------------

def amplitude_after(coeffs: dict, K_deg: float, cycles: float) -> tuple[float, float]:
    """Release at 45 + K_deg; the peak |γ − π/4| (deg) over the last cycle of ``cycles``
    cycles (of the small-amplitude period scaled by the pendulum's at K_deg)."""
    from cadra.motion.pureroll import pendulum_frequency
    c = conditions()
    A = c["q"] * c["S"] * c["d"] / c["Ix"] * coeffs["Cl_alpha"]
    period = 2 * np.pi / pendulum_frequency(np.radians(K_deg), A)
    t = np.linspace(0.0, cycles * period, int(60 * cycles) + 1)
    _, g = simulate(t, coeffs, 45.0 + K_deg)
    last = t > (cycles - 1.1) * period
    return float(np.degrees(np.max(np.abs(g[last] - np.pi / 4)))), period


def simulated_limit_cycle(coeffs: dict, lo_deg: float, hi_deg: float,
                          cycles: int = 8) -> float | None:
    """The release amplitude (deg) about the trim at which the simulated oscillation neither
    grows nor decays over ``cycles`` cycles; None without a sign change in [lo, hi]."""
    def growth(K):      # a run that rolls over the separatrix (and blows up) grew
        a = amplitude_after(coeffs, K, cycles)[0]
        return a - K if np.isfinite(a) and a < 45.0 else 45.0
    if growth(lo_deg) * growth(hi_deg) > 0:
        return None
    return brentq(growth, lo_deg, hi_deg, xtol=1e-4)


def limit_cycles() -> dict:
    """Table IV's inputs (eq. 31: 41.8 deg) and the seed's second claim: C_lp2 set by eq. 31
    to the 25 deg initial amplitude (C_lp0 −2), 'damped 0.25 deg after 10 cycles'."""
    out = {}
    k31 = np.degrees(limit_cycle_amplitude_eq31(TRUTH["Clp0"], TRUTH["Clp2"]))
    keb = energy_balance_amplitude(TRUTH["Clp0"], TRUTH["Clp2"])
    a43, _ = amplitude_after(TRUTH, 43.0, 10)
    out["table_iv"] = {"eq31_deg": k31, "energy_balance_deg": None if keb is None
                       else float(np.degrees(keb)),
                       "simulated_deg": simulated_limit_cycle(TRUTH, 30.0, 44.0),
                       "released_43_after_10_cycles_deg": a43}
    K = np.radians(PHI0_DEG - 45.0)
    claim = dict(TRUTH, Clp2=-4.0 * TRUTH["Clp0"] / K**2)
    keb = float(np.degrees(energy_balance_amplitude(claim["Clp0"], claim["Clp2"])))
    ksim = simulated_limit_cycle(claim, 22.0, 28.0)
    a10, _ = amplitude_after(claim, PHI0_DEG - 45.0, 10)
    out["eq31_at_25deg"] = {"Clp2": claim["Clp2"], "eq31_deg": PHI0_DEG - 45.0,
                            "energy_balance_deg": keb, "simulated_deg": ksim,
                            "change_in_10_cycles_deg": a10 - (PHI0_DEG - 45.0)}
    out["rel_err"] = {"simulated_vs_eq31": ksim / (PHI0_DEG - 45.0) - 1.0,
                      "simulated_vs_energy_balance": ksim / keb - 1.0}
    return out


# --- the report --------------------------------------------------------------------------

def table(title: str, rows: list[tuple[str, dict]], fmt: str = "{:>12.4f}") -> None:
    print(f"\n{title}")
    print(f"{'':>26}" + "".join(f"{k:>12}" for k in TRUTH))
    for name, row in rows:
        print(f"{name:>26}" + "".join(fmt.format(row[k]) for k in TRUTH))


def run(noise_seed: int = 1, draws: int = 5) -> dict:
    """The re-run (module doc): prints the tables and returns the figures (without the run
    time): noise-free errors, ``draws`` noise realisations from ``noise_seed``, the limit
    cycle."""
    c = conditions()
    print("Seed 001 Table IV: pure roll about the pi/4 lock-in trim (eqs. 27-31)")
    print(f"  Ix {c['Ix']:.3g} kg m2, q {c['q']:.1f} Pa, S {c['S']:.4g} m2, d {c['d']} m, "
          f"V {c['V']} m/s, alpha {np.degrees(ALPHA):.0f} deg; record {RECORD_S} s at "
          f"{RATE_HZ:.0f} Hz from {PHI0_DEG} deg; noise {NOISE_DEG} deg")
    t = np.arange(0.0, RECORD_S + 0.5 / RATE_HZ, 1.0 / RATE_HZ)
    states, g = simulate(t, TRUTH)
    out: dict = {"conditions": c, "record_s": RECORD_S, "rate_hz": RATE_HZ}

    # noise-free
    cl = classic(t, g)
    nf_sigma = 1e-6
    cf = cadra_fit(t, states, g, np.zeros_like(g), nf_sigma, values_of(cl["mdc"]))
    errs = {k: pct(values_of(cl[k])) for k in ("mdc", "harmonic", "harmonic_no_freq",
                                               "sections")}
    errs["cadra"] = pct(cf["values"])
    table("noise-free: % error (Table IV: paper 1.00 / 3.87 / 0.04)", [
        ("paper (seed 001 Table IV)", PAPER),
        ("MDC, pendulum averaging", errs["mdc"]),
        ("MDC, seed's harmonic + fc", errs["harmonic"]),
        ("MDC, harmonic, no fc", errs["harmonic_no_freq"]),
        ("sections (start values)", errs["sections"]),
        ("CADRA 6-DOF fit", errs["cadra"])], "{:>12.5f}")
    print(f"  CADRA fit: {cf['method']}; {cf['status']}; {cf['seconds']:.1f} s")
    out["noise_free"] = {k: {c2: round(v, 6) for c2, v in e.items()} for k, e in errs.items()}
    out["lockin_mdc_err_pct"] = {k: round(v, 6) for k, v in errs["mdc"].items()}
    out["lockin_mdc_seed_method_err_pct"] = {k: round(v, 6) for k, v in
                                             errs["harmonic"].items()}
    out["lockin_cadra_err_pct"] = {k: float(f"{v:.3g}") for k, v in errs["cadra"].items()}
    ratio = max(errs["cadra"][k] / errs["mdc"][k] for k in TRUTH)
    out["lockin_cadra_over_mdc_error_max"] = float(f"{ratio:.3g}")
    out["lockin_cadra_over_seed_method_error_max"] = float(
        f"{max(errs['cadra'][k] / errs['harmonic'][k] for k in TRUTH):.3g}")
    out["cadra_fit_method"] = cf["method"]

    # noisy
    rng = np.random.default_rng(noise_seed)
    sig = np.radians(NOISE_DEG)
    rows = {"mdc": [], "harmonic": [], "cadra": []}
    pulls = {"mdc": [], "cadra": []}
    sigpct = {"mdc": [], "cadra": []}
    for _ in range(draws):
        noise = rng.normal(0.0, sig, t.size)
        gn = g + noise
        cn = classic(t, gn, sig)
        fn = cadra_fit(t, states, g, noise, sig, values_of(cn["mdc"]))
        rows["mdc"].append(pct(values_of(cn["mdc"])))
        rows["harmonic"].append(pct(values_of(cn["harmonic"])))
        rows["cadra"].append(pct(fn["values"]))
        pulls["mdc"].append({k: (values_of(cn["mdc"])[k] - TRUTH[k]) / sigmas_of(cn["mdc"])[k]
                             for k in TRUTH})
        pulls["cadra"].append({k: (fn["values"][k] - TRUTH[k]) / fn["sigmas"][k]
                               for k in TRUTH})
        sigpct["mdc"].append(pct_sigma(sigmas_of(cn["mdc"])))
        sigpct["cadra"].append(pct_sigma(fn["sigmas"]))
    mean = {k: {c2: float(np.mean([r[c2] for r in v])) for c2 in TRUTH} for k, v in rows.items()}
    table(f"{NOISE_DEG} deg noise: mean |% error| over {draws} draw(s)", [
        ("MDC, pendulum averaging", mean["mdc"]), ("MDC, seed's harmonic + fc", mean["harmonic"]),
        ("CADRA 6-DOF fit", mean["cadra"])])
    msig = {k: {c2: float(np.mean([r[c2] for r in v])) for c2 in TRUTH}
            for k, v in sigpct.items()}
    table("  their quoted sigmas (% of the input), mean over the draws", [
        ("MDC, pendulum averaging", msig["mdc"]), ("CADRA 6-DOF fit", msig["cadra"])])
    table("  pulls (fit - truth)/sigma, last draw", [
        ("MDC, pendulum averaging", pulls["mdc"][-1]), ("CADRA 6-DOF fit", pulls["cadra"][-1])],
        "{:>12.2f}")
    out["noisy"] = {"draws": draws, "mean_err_pct": mean, "mean_sigma_pct": msig,
                    "pulls_last": {k: v[-1] for k, v in pulls.items()}}
    out["lockin_noisy_cadra_over_mdc_error_max"] = float(
        f"{max(mean['cadra'][k] / mean['mdc'][k] for k in TRUTH):.3g}")

    # limit cycle
    lc = limit_cycles()
    ti, c25 = lc["table_iv"], lc["eq31_at_25deg"]
    print("\nlimit cycle (eq. 31, K = 2 sqrt(-Clp0/Clp2))")
    print(f"  Table IV inputs: eq. 31 {ti['eq31_deg']:.2f} deg; exact energy balance: "
          f"{ti['energy_balance_deg']}; simulated: {ti['simulated_deg']} (a release at 43 deg"
          f" is at {ti['released_43_after_10_cycles_deg']:.2f} deg after 10 cycles)")
    print(f"  Clp2 = {c25['Clp2']:.3f} (eq. 31 at 25 deg): energy balance "
          f"{c25['energy_balance_deg']:.3f} deg, simulated {c25['simulated_deg']:.3f} deg; "
          f"from 25 deg the amplitude changes {c25['change_in_10_cycles_deg']:+.3f} deg in 10 "
          "cycles (seed: 0.25 deg)")
    print(f"  simulated cycle vs eq. 31: {100 * lc['rel_err']['simulated_vs_eq31']:+.3f} %, vs "
          f"the energy balance: {100 * lc['rel_err']['simulated_vs_energy_balance']:+.3f} %")
    out["limit_cycle"] = lc
    out["limit_cycle_rel_err"] = {k: float(f"{v:.4g}") for k, v in lc["rel_err"].items()}
    return out
