"""The seeds' evaluations of the classic angular-motion reductions as simulated cases: seed
001 Table II (1-DOF nonlinear pitch), seed 000 Table 2 and seed 001 Table V (3-DOF nonlinear
epicyclic motion with spin and Magnus on a wind-tunnel gimbal), for
``tools/validate_motion.py`` (:mod:`cadra.validation.motion_validation` makes its tables).

Each case is simulated by CADRA's 6-DOF dynamics in the matching test mode (``pitch_pivot``,
``gimbal``; :func:`simulate`), reduced by the classic method of ``cadra.motion`` (sectional
fits and the Kryloff-Bogoliuboff reduction; :func:`classic`) and fitted by CADRA's 6-DOF fit
(``cadra.fitting.solver.fit``; :func:`cadra_fit`) with the same forms, quadratic in the angle
(:func:`aero_model`). :func:`noise_free` and :func:`noisy` give the errors per coefficient
and, with noise, the CADRA fit's pulls (fit - truth) / sigma over the draws;
:func:`sensitivity` the classic method's over the record's unstated choices.

The seeds omit mass data and initial conditions: the choices are the constants below
(docs/motion.md, "Validation against the seeds").
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from cadra.aero import model_from_dict
from cadra.dynamics.modes import TestMode
from cadra.dynamics.observe import observe
from cadra.dynamics.setup import RigidBody, propagate_states
from cadra.dynamics.trajectory import Launch
from cadra.fitting.sensitivity import Integration
from cadra.fitting.solver import FitOptions, fit
from cadra.flight.data import ShotData
from cadra.motion import (
    FlightConditions,
    kb_pitch_reduction,
    kb_reduction,
    sectional_epicyclic,
    sectional_pitch,
)

__all__ = ["Case", "KB_NAMES", "Record", "T2_000", "T2_001", "T5_001", "aero_model",
           "cadra_fit", "classic", "noise_free", "noisy", "pct", "sensitivity", "simulate"]

DT_TRUTH = 1e-4        # s, RK4 step of the simulated truth
# a gimbal record lasts 20-30 s: steps up to 5 ms (p h <= 0.15; the step-doubling control
# keeps the local error below 1e-8 rad) so a propagation stays within the integrator's budget
OPTIONS = FitOptions(integration=Integration(h_max_s=5e-3, threads=1))


# --- case definitions ------------------------------------------------------------------------

@dataclass(frozen=True)
class Case:
    """One seed evaluation: body and stream, truth coefficients, record and sectioning."""

    name: str
    kind: str                          # "pitch" (pitch pivot) or "gimbal"
    truth: dict                        # coefficient -> input value (seed's table)
    paper: dict                        # coefficient -> the paper's % error (noise-free)
    cond: FlightConditions
    duration_s: float
    n_points: int
    window: int
    step: int
    launch: dict                       # Launch keyword arguments (angles rad, rates rad/s)
    paper_noise: dict = field(default_factory=dict)   # "0.25" -> {coef: % error}


# seed 001 Table II: 1-DOF, Cm_alpha and (Cmq + Cmalphadot) quadratic in alpha^2, trim moment
# Cm_delta delta_E = 1.0. Body (ours; the seed gives none): 1 kg, I = 5e-3 kg m^2, d = 5 cm,
# air 1.2 kg/m^3 at 50 m/s: pitch frequency 30 rad/s (4.7 Hz), damping rate 0.55 1/s;
# 2.5 s at 800 Hz (2000 points), released at rest at 20 deg.
T2_001 = Case(
    name="seed 001 Table II (1-DOF pitch pivot)", kind="pitch",
    truth={"Cma0": -30.0, "Cma2": 15.0, "Cmq0": -75.0, "Cmq2": -50.0, "Cmt": 1.0},
    paper={"Cma0": 0.18, "Cma2": 0.47, "Cmq0": 0.21, "Cmq2": 11.49, "Cmt": 0.0},
    cond=FlightConditions(mass_kg=1.0, Ix_kg_m2=1.0e-3, I_kg_m2=5.0e-3, d_m=0.05,
                          density_kg_m3=1.2, speed_m_s=50.0),
    duration_s=2.5, n_points=2000, window=320, step=32,
    launch={"theta_rad": np.radians(20.0)})

# seed 000 Table 2 (basic set): restoring, damping and Magnus quadratic in |alpha|^2, in the
# seed's normalisation (QAd; QAd^2/2V; Magnus moment = p C_mpa Q A d^2/2V alpha), which is
# cadra.motion's. Stream 34.88 ft/s (10.63 m/s, the seed's), spin 30 rad/s (the seed's
# experiment: 24-34 rad/s, about 8x the nutation rate); body (ours): d = 3 cm, I = 0.0614 kg m^2,
# I_x = 0.04 I, so that the seed's coefficient magnitudes give a nutation rate of p/8
# (3.75 rad/s) and both arms damped; 12 deg start (8 deg nutation + 4 deg precession arm);
# 30 s at 190 points per nutation cycle; sections of 1.8 nutation cycles (342 points).
_I000 = 0.0614 / 8
T2_000 = Case(
    name="seed 000 Table 2 (3-DOF gimbal, spin + Magnus)", kind="gimbal",
    truth={"Cma0": -400.0, "Cma2": 1000.0, "Cmq0": -10100.0, "Cmq2": -150000.0,
           "Cmpa0": -600.0, "Cmpa2": 6000.0},
    paper={"Cma0": 3, "Cma2": 13, "Cmq0": 3, "Cmq2": 11, "Cmpa0": 3, "Cmpa2": 4},
    paper_noise={
        "0.25": {"Cma0": 3, "Cma2": 11, "Cmq0": 4, "Cmq2": 15, "Cmpa0": 6, "Cmpa2": 40},
        "1": {"Cma0": 2.5, "Cma2": 1.5, "Cmq0": 0.4, "Cmq2": 78, "Cmpa0": 13, "Cmpa2": 112},
        "nofreq": {"Cma0": 3, "Cma2": 15, "Cmq0": 3, "Cmq2": 52, "Cmpa0": 5, "Cmpa2": 45}},
    cond=FlightConditions(mass_kg=1.0, Ix_kg_m2=0.04 * _I000, I_kg_m2=_I000, d_m=0.015,
                          density_kg_m3=1.225, speed_m_s=10.63, spin_rad_s=30.0),
    duration_s=30.0, n_points=3400, window=342, step=34,
    launch={"K1_rad": np.radians(8.0), "K2_rad": np.radians(4.0)})

# seed 001 Table V: the same model, other values (damping and Magnus grow with the angle).
# Low spin keeps the fast arm damped at 10 deg (Magnus T below D omega_1 needs omega_1 > p
# there): p = 2 rad/s, I_x/I = 0.1; q S d / I = 0.319 1/s^2 (omega about 6 rad/s), V = 30 m/s,
# d = 9.3 mm (damping rates about 0.07 1/s); 10 deg start (6 + 4 deg); 20 s at 200 Hz (about
# 200 points per cycle); sections of 400 points (about 1.9 cycles).
_I001 = 0.5 * 1.225 * 30.0**2 * np.pi * 0.0093**3 / 4 / 0.319
T5_001 = Case(
    name="seed 001 Table V (3-DOF gimbal, spin + Magnus)", kind="gimbal",
    truth={"Cma0": -113.0, "Cma2": 1067.0, "Cmq0": -3000.0, "Cmq2": 49249.0,
           "Cmpa0": 1000.0, "Cmpa2": 16416.0},
    paper={"Cma0": 0.0, "Cma2": 0.7, "Cmq0": 0.2, "Cmq2": 2.7, "Cmpa0": 0.3, "Cmpa2": 3.9},
    cond=FlightConditions(mass_kg=1.0, Ix_kg_m2=0.1 * _I001, I_kg_m2=_I001, d_m=0.0093,
                          density_kg_m3=1.225, speed_m_s=30.0, spin_rad_s=2.0),
    duration_s=20.0, n_points=4000, window=400, step=40,
    launch={"K1_rad": np.radians(6.0), "K2_rad": np.radians(4.0)})

KB_NAMES = {"Cma0": "Cm_alpha0", "Cma2": "Cm_alpha2", "Cmq0": "Cmq_sum0", "Cmq2": "Cmq_sum2",
            "Cmpa0": "Cm_p_alpha0", "Cmpa2": "Cm_p_alpha2"}


def aero_model(case: Case, values: dict | None = None):
    """CADRA's model with the seed's forms. 1-DOF: alpha_beta, C_m = Cma0 alpha + Cma2 alpha^3
    + Cmt, C_mq = Cmq0 + Cmq2 alpha^2 (seed 001 eqs. 6, 15). Gimbal: sigma model,
    C_m = (Cma0 + Cma2 sigma^2) sigma, C_mq = Cmq0 + Cmq2 sigma^2, and the Magnus moment
    C_n = (Cmpa0 + Cmpa2 sigma^2) p_hat sigma about e_P. docs/conventions.md writes
    C_n = 2 C_Mpa p_hat sin sigma with McCoy's C_Mpa (p d / V), so Cmpa here is 2 C_Mpa: the
    seeds' and cadra.motion's C_mpa, which multiplies p d / 2V. The moments are linear in
    sigma times the polynomial, as in the seeds' eq. 8 (M_alpha(|alpha|) alpha), not in
    sin(sigma): with sin(sigma) the K-B reduction, whose model has no sine, reads
    C_ma2 - C_ma0 / 6 (+6.7 % on seed 000's C_ma2). No forces matter: the pivot is at the cg.
    """
    vals = dict(case.truth if values is None else values)
    if case.kind == "pitch":
        coef = {"Cm": "Cma0*alpha + Cma2*alpha**3 + Cmt", "Cmq": "Cmq0 + Cmq2*alpha**2"}
        plane = "alpha_beta"
    else:
        coef = {"Cm": "(Cma0 + Cma2*sigma**2)*sigma", "Cmq": "Cmq0 + Cmq2*sigma**2",
                "Cn": "(Cmpa0 + Cmpa2*sigma**2)*p_hat*sigma"}
        plane = "sigma"
    return model_from_dict({
        "format": "cadra.aero/1", "name": case.name, "angle_plane": plane,
        "coefficients": coef, "parameters": {k: {"value": v} for k, v in vals.items()}})


def rigid_body(case: Case) -> RigidBody:
    """The case's body on its mount (pivot at the cg), no gravity."""
    c = case.cond
    kind = "pitch_pivot" if case.kind == "pitch" else "gimbal"
    return RigidBody(mass_kg=c.mass_kg,
                     inertia_body_kg_m2=np.diag([c.Ix_kg_m2, c.I_kg_m2, c.I_kg_m2]),
                     d_m=c.d_m, cg_from_ref_body_m=np.zeros(3), density_kg_m3=c.density_kg_m3,
                     speed_of_sound_m_s=340.0, viscosity_pa_s=1.8e-5, gravity_m_s2=0.0,
                     mode=TestMode(kind=kind, stream_m_s=c.speed_m_s,
                                   pivot_from_cg_body_m=(0.0, 0.0, 0.0)))


def linear_arms(case: Case) -> tuple[float, float]:
    """Linear-theory arm frequencies (rad/s) at zero amplitude: omega^2 - P omega + M = 0."""
    c = case.cond
    s_m, _, ix_i = c.scales()
    P, M = c.spin_rad_s * ix_i, case.truth["Cma0"] / s_m
    r = np.sqrt(P * P / 4 - M)
    return P / 2 + r, P / 2 - r


def launch(case: Case) -> Launch:
    """The release: the pivot's at rest at its angle; the gimbal's with both arms along
    +beta at their linear-theory rates and the case's spin."""
    if case.kind == "pitch":
        return Launch(speed_m_s=0.0, **case.launch)
    # xi = beta + i alpha = K1 e^{i w1 t} + K2 e^{i w2 t}: at t = 0 both arms along +beta
    w1, w2 = linear_arms(case)
    K1, K2 = case.launch["K1_rad"], case.launch["K2_rad"]
    return Launch(speed_m_s=0.0, psi_rad=K1 + K2, q_rad_s=w1 * K1 + w2 * K2,
                  p_rad_s=case.cond.spin_rad_s)


@dataclass
class Record:
    """A simulated record: times, the gimbal's (or pivot's) angles theta and psi (rad), the
    body, the state at t[0] and every state."""

    t: np.ndarray
    theta: np.ndarray
    psi: np.ndarray
    body: RigidBody
    y0: np.ndarray           # state at t[0]
    states: np.ndarray


def simulate(case: Case) -> Record:
    """The case flown by CADRA's 6-DOF dynamics (RK4 at DT_TRUTH)."""
    body = rigid_body(case)
    m = aero_model(case)
    t = np.linspace(0.0, case.duration_s, case.n_points)
    y0 = launch(case).state(body)
    states = propagate_states(y0, 0.0, t, body.phys(), m.compile(), m.values(), DT_TRUTH)
    obs = observe(states, body.ref_from_cg_body_m())
    return Record(t, obs["theta_rad"], obs["psi_rad"], body, y0, states)


# --- the two reductions ----------------------------------------------------------------------

def classic(case: Case, t, theta, psi, sig=None, *, frequency_correction=True) -> dict:
    """The seeds' method: sectional fits and the K-B reduction (cadra.motion). The measured
    angles are taken as alpha = theta, beta = psi (the gimbal's angles)."""
    if case.kind == "pitch":
        sec = sectional_pitch(t, theta, sig, window=case.window, step=case.step, trim=True)
        kb = kb_pitch_reduction(sec, case.cond, frequency_correction=frequency_correction)
        out = {k: getattr(kb, KB_NAMES[k]) for k in ("Cma0", "Cma2", "Cmq0", "Cmq2")}
        # trim moment (seed 001 eq. 19, garbled in the OCR; derived): the moment averaged
        # over a cycle about alpha_T vanishes, Cmt = -[Cma0 aT + Cma2 (aT^3 + 3/2 aT K^2)]
        aT, K = sec.alpha_T, sec.K[:, 0]
        out["Cmt"] = float(np.mean(-(out["Cma0"] * aT + out["Cma2"] * (aT**3 + 1.5 * aT * K**2))))
        return out
    sec = sectional_epicyclic(t, theta, psi, sig, sig, window=case.window, step=case.step)
    kb = kb_reduction(sec, case.cond, frequency_correction=frequency_correction)
    return {k: getattr(kb, v) for k, v in KB_NAMES.items()}


def cadra_fit(case: Case, rec: Record, theta, psi, sig: float, start: dict):
    """CADRA's 6-DOF fit of the angles (positions not measured), all coefficients free, the
    mount's local unknowns at the epoch (default_local_free) started from the truth."""
    n = rec.t.size
    meas = np.full((n, 5), np.nan)
    meas[:, 3], meas[:, 4] = theta, psi
    sg = np.where(np.isfinite(meas), sig, np.nan)
    shot = ShotData("tunnel", rec.body, "cone", np.arange(1, n + 1), rec.t, meas, sg)
    y_epoch = rec.states[shot.epoch_index].copy()
    res = fit([shot], aero_model(case, start), [y_epoch], options=OPTIONS)
    vals = dict(zip(res.aero_names, res.aero_values, strict=True))
    sigs = dict(zip(res.aero_names, res.aero_sigma, strict=True))
    return res, vals, sigs


def pct(values: dict, truth: dict) -> dict:
    """% errors of ``values`` against ``truth`` per coefficient."""
    return {k: 100.0 * abs(values[k] / truth[k] - 1.0) for k in truth}


def start_values(case: Case, classic_values: dict) -> dict:
    """CADRA's start: the classic reduction's values (the intended use of the quick look)."""
    return {k: float(classic_values[k]) for k in case.truth}


# --- runs ------------------------------------------------------------------------------------

NOISE_FREE_SIGMA = 1e-6     # rad: weights of a noise-free fit (tight convergence, chi^2 ~ 0)


def noise_free(case: Case, rec: Record) -> dict:
    """Classic (with and without the frequency-variation correction) and CADRA on the exact
    record; % errors per coefficient."""
    cl = classic(case, rec.t, rec.theta, rec.psi)
    nf = classic(case, rec.t, rec.theta, rec.psi, frequency_correction=False)
    t0 = time.perf_counter()
    res, vals, _ = cadra_fit(case, rec, rec.theta, rec.psi, NOISE_FREE_SIGMA,
                             start_values(case, cl))
    return {"classic": pct(cl, case.truth), "classic_no_freq": pct(nf, case.truth),
            "cadra": pct(vals, case.truth), "cadra_status": res.status,
            "cadra_s": time.perf_counter() - t0, "classic_values": cl, "cadra_values": vals}


def noisy(case: Case, rec: Record, sig_rad: float, draws: int, rng) -> dict:
    """``draws`` noise realisations (white, sig_rad on theta and psi): the classic reduction's
    and CADRA's % errors (mean |error|) and CADRA's pulls (fit - truth) / sigma."""
    errs_c, errs_f, pulls, chi2, failed = [], [], [], [], []
    restarts = 0
    for _ in range(draws):
        th = rec.theta + rng.normal(0.0, sig_rad, rec.t.size)
        ps = rec.psi + rng.normal(0.0, sig_rad, rec.t.size)
        try:
            cl = classic(case, rec.t, th, ps, sig_rad)
            errs_c.append(pct(cl, case.truth))
            start = start_values(case, cl)
        except Exception as exc:          # a sectional fit that does not converge
            failed.append(f"classic: {type(exc).__name__}: {exc}")
            start = dict(case.truth)
        res, vals, sigs = cadra_fit(case, rec, th, ps, sig_rad, start)
        if not res.converged:
            # the classic values can be far off at high noise (a 30 s record then runs into
            # another minimum): one restart, every coefficient 20 % off the truth
            failed.append(f"cadra from the classic values: {res.status}: {res.message}")
            restarts += 1
            res, vals, sigs = cadra_fit(case, rec, th, ps, sig_rad,
                                        {k: 1.2 * v for k, v in case.truth.items()})
            if not res.converged:
                failed.append(f"cadra restarted: {res.status}: {res.message}")
                continue
        errs_f.append(pct(vals, case.truth))
        pulls.append({k: (vals[k] - v) / sigs[k] for k, v in case.truth.items()})
        chi2.append(res.reduced_chi2)
    names = list(case.truth)

    def mean(rows):
        return {k: float(np.mean([r[k] for r in rows])) if rows else float("nan")
                for k in names}

    return {"sigma_deg": float(np.degrees(sig_rad)), "draws": draws,
            "classic": mean(errs_c), "cadra": mean(errs_f),
            "pull_mean": {k: float(np.mean([p[k] for p in pulls])) for k in names},
            "pull_std": {k: (float(np.std([p[k] for p in pulls], ddof=1)) if len(pulls) > 1
                             else float("nan")) for k in names},
            "reduced_chi2_mean": float(np.mean(chi2)), "n_cadra": len(pulls),
            "n_classic": len(errs_c), "restarts": restarts, "failures": failed}


def sensitivity(case: Case) -> dict:
    """The classic reduction's noise-free errors over variants of the record the seeds do not
    give (spin, split of the start between the arms, section length): min and max % error per
    coefficient."""
    import dataclasses

    rows = []
    p0 = case.cond.spin_rad_s
    K = (case.launch["K1_rad"], case.launch["K2_rad"])
    tot = K[0] + K[1]
    for p in (p0, 1.5 * p0):
        for split in (K, (tot / 2, tot / 2), (0.75 * tot, 0.25 * tot)):
            c = dataclasses.replace(case, cond=dataclasses.replace(case.cond, spin_rad_s=p),
                                    launch={"K1_rad": split[0], "K2_rad": split[1]})
            rec = simulate(c)
            for f in (0.5, 1.0, 1.5):
                w = int(round(f * case.window))
                cc = dataclasses.replace(c, window=w, step=max(1, w // 10))
                rows.append(pct(classic(cc, rec.t, rec.theta, rec.psi), case.truth))
    return {k: (min(r[k] for r in rows), max(r[k] for r in rows)) for k in case.truth} | {
        "n_variants": len(rows)}
