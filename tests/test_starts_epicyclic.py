"""cadra2 fit's starting values: from an all-zero model, and from the epicyclic fit's arms for a
spinning body (cadra.fitting.start, cadra.flight.starts.start_estimates).

Truth: the simulator's CONE-1 (10 deg cone, bundled ``cone_linear``) with its spin and C_m_alpha
changed, flown by the same dynamics, measured as truth + Gaussian noise (20 um, 0.05 deg)."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cadra.fitting import fit_shots, starting_model
from cadra.fitting.sensitivity import Integration
from cadra.fitting.solver import FitOptions
from cadra.flight import shot_data_from_truth
from cadra.flight.estimates import estimate_motion
from cadra.flight.starts import epicyclic_estimates, start_estimates
from cadra.synthetic.simulate import load_shot_spec, simulate_shot

SPEC = Path(__file__).resolve().parents[1] / "sample_shots" / "specs" / "cone_1.toml"
OPTS = FitOptions(integration=Integration(threads=1))


def _shot(p_rad_s=None, cm_a=None, seed=3):
    spec = load_shot_spec(SPEC)
    if p_rad_s is not None:
        spec = replace(spec, launch=replace(spec.launch, p_rad_s=p_rad_s))
    if cm_a is not None:
        spec = replace(spec, aero_values={**spec.aero_values, "Cm_a": cm_a})
    sim = simulate_shot(spec)
    shot = shot_data_from_truth(sim.truth, sim.rigid, sim.spec.shot_id, sim.body.kind,
                                sigma_position_m=20e-6, sigma_angle_rad=math.radians(0.05),
                                rng=np.random.default_rng(seed))
    return sim, shot


@pytest.fixture(scope="module")
def gyro():
    """Statically unstable (C_m_alpha +0.30), spun at 3800 rad/s: gyroscopic stability
    factor ~2 (a rifle bullet's range)."""
    return _shot(p_rad_s=3800.0, cm_a=0.30)


def _zero(model):
    return model.with_values({n: 0.0 for n in model.free_names()})


def test_start_from_all_zero_model_moves_to_the_targets():
    """A C_D_0 >= 0 started at 0 sat on its bound, and the bounded solver then moved no
    parameter at all: the 'starting values' were the zeros."""
    sim, shot = _shot()
    start = starting_model([shot], _zero(sim.model))
    est = estimate_motion(shot)
    cd = float(start.evaluate(sigma=est.sigma_rms_rad, alpha=est.sigma_rms_rad, beta=0.0,
                              mach=est.mach)["CD"])
    assert cd == pytest.approx(est.cd, rel=0.05)
    assert est.cd == pytest.approx(0.28 + 1.85 * math.sin(est.sigma_rms_rad) ** 2, rel=0.1)
    assert start.parameter("Cm_a").value == pytest.approx(-0.49, rel=0.1)


def test_epicyclic_estimates_give_sign_and_spin_of_a_gyroscopically_stable_body(gyro):
    sim, shot = gyro
    plain = estimate_motion(shot)
    epi = epicyclic_estimates([shot])[0]
    assert epi.cm_alpha == pytest.approx(0.30, rel=0.02)
    assert epi.spin_rad_s == pytest.approx(float(sim.states[0, 10]), rel=0.02)
    assert epi.cmq_sum == pytest.approx(-4.0, abs=1.5)
    # the damped sine's frequency cannot give a positive C_m_alpha
    start_plain = starting_model([shot], _zero(sim.model), [plain])
    start_epi = starting_model([shot], _zero(sim.model), [epi])
    assert start_plain.parameter("Cm_a").value <= 0.0
    assert start_epi.parameter("Cm_a").value == pytest.approx(0.30, rel=0.05)


def test_epicyclic_start_converges_to_the_truth_in_fewer_iterations(gyro):
    sim, shot = gyro
    ref, _ = fit_shots([shot], sim.model, options=OPTS, auto_start=False)
    res, _ = fit_shots([shot], _zero(sim.model), options=OPTS,
                       estimates=start_estimates([shot], "auto"))
    assert res.status == "converged"
    assert res.chi2 <= ref.chi2 * (1 + 3 * math.sqrt(2 / ref.dof))
    assert res.model.parameter("Cm_a").value == pytest.approx(0.30, rel=0.01)
    plain, _ = fit_shots([shot], _zero(sim.model), options=OPTS)
    assert res.iterations < plain.iterations


def test_auto_keeps_the_plain_estimate_without_spin():
    sim, shot = _shot(p_rad_s=0.0)
    est = start_estimates([shot], "auto")[0]
    assert est == estimate_motion(shot)
    assert start_estimates([shot], "linear") is None
    with pytest.raises(ValueError, match="auto, linear or epicyclic"):
        start_estimates([shot], "guess")


def test_tunnel_release_of_a_spinning_model_gives_its_moment_slope_and_spin():
    """A free flight in a wind tunnel (seed 002's kind of test): the epicyclic fit of theta,
    psi against the stream, in time, gives C_m_alpha and the spin for the start, which the
    damped sines cannot (two arms). Truth: the 6-DOF dynamics with the tunnel mode; lift 0
    (the estimate leaves the path's turning by lift out)."""
    from cadra.aero import model_from_dict
    from cadra.dynamics.modes import TestMode
    from cadra.dynamics.observe import observe
    from cadra.dynamics.setup import RigidBody, propagate_states
    from cadra.dynamics.trajectory import Launch
    from cadra.flight.data import ShotData

    body = RigidBody(mass_kg=0.0277, inertia_body_kg_m2=np.diag([1.0, 0.69, 0.69]) * 1e-6,
                     d_m=0.0381, cg_from_ref_body_m=[0.0, 0.0, 0.0], density_kg_m3=0.0372,
                     speed_of_sound_m_s=170.0, viscosity_pa_s=5e-6, gravity_m_s2=0.0,
                     mode=TestMode(kind="tunnel", stream_m_s=677.0))
    truth = model_from_dict({
        "format": "cadra.aero/1", "name": "tunnel-spin", "angle_plane": "sigma",
        "coefficients": {"CD": "CD0", "Cm": "Cma*sin(sigma)", "Cmq": "Cmq0"},
        "parameters": {"CD0": {"value": 1.3}, "Cma": {"value": -0.185},
                       "Cmq0": {"value": -0.8}}})
    p = 2 * math.pi * 28.0
    t = np.arange(180) / 2000.0
    states = propagate_states(Launch(speed_m_s=0.0, theta_rad=math.radians(8.0),
                                     p_rad_s=p, q_rad_s=30.0).state(body), 0.0, t,
                              body.phys(), truth.compile(), truth.values())
    obs = observe(states, body.ref_from_cg_body_m())
    rng = np.random.default_rng(2)
    s = math.radians(0.1)
    meas = np.column_stack([obs["x_m"], obs["y_m"], obs["z_m"],
                            obs["theta_rad"] + s * rng.standard_normal(t.size),
                            obs["psi_rad"] + s * rng.standard_normal(t.size)])
    sig = np.column_stack([np.full((t.size, 3), 1e-4), np.full((t.size, 2), s)])
    shot = ShotData("tunnel-spin", body, "cone", np.arange(1, t.size + 1), t, meas, sig)
    est = epicyclic_estimates([shot])[0]
    assert est.cm_alpha == pytest.approx(-0.185, rel=0.05)
    assert est.spin_rad_s == pytest.approx(p, rel=0.05)
    assert start_estimates([shot], "auto")[0] == est       # it spins: auto takes the arms
