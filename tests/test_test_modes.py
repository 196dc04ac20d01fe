"""Wind-tunnel test modes (cadra.dynamics.modes) against closed forms.

Truths: the drag-only drift of a model released in a stream (w = w0 / (1 + k w0 t)); the
linear pitch oscillation on a pivot ahead of the cg (static and plunging terms by hand); a
compound pendulum on a gimbal (omega^2 = m g l / (I + m l^2)) with its pivot held fixed; the
exponential roll-up on a roll bearing; and a fit of a pitch-pivot record recovering the
model's C_m slope and damping within its sigmas.
"""

import numpy as np
import pytest
from scipy.linalg import expm

from cadra.aero import model_from_dict
from cadra.conventions import body_to_facility_matrix
from cadra.dynamics.modes import TestMode
from cadra.dynamics.observe import observe
from cadra.dynamics.setup import RigidBody, propagate_states
from cadra.dynamics.trajectory import Launch
from cadra.fitting.problem import default_local_free
from cadra.fitting.sensitivity import LOCAL_NAMES
from cadra.fitting.solver import fit
from cadra.flight.data import ShotData

# seed 004 M1 (shot 2384): mass properties; tunnel air at the range's density
M1 = dict(mass_kg=0.096563, inertia_body_kg_m2=np.diag([104.208, 81.024, 81.024]) * 1e-7,
          d_m=0.03556, cg_from_ref_body_m=[-0.0044, 0.0, 0.0], density_kg_m3=1.191,
          speed_of_sound_m_s=345.3, viscosity_pa_s=1.81e-5)
U = 100.0   # stream, m/s


def model(CD=0.0, CLa=0.0, Cma=0.0, Cmq=0.0, Cl0=0.0, Clp=0.0):
    return model_from_dict({
        "format": "cadra.aero/1", "name": "tunnel-test", "angle_plane": "sigma",
        "coefficients": {"CD": "CD0", "CL": "CLa*sin(sigma)", "Cm": "Cma*sin(sigma)",
                         "Cmq": "Cmq0", "Cl": "Cl0", "Clp": "Clp0"},
        "parameters": {k: {"value": v} for k, v in dict(
            CD0=CD, CLa=CLa, Cma=Cma, Cmq0=Cmq, Cl0=Cl0, Clp0=Clp).items()},
    })


def run(body, m, launch, t):
    return propagate_states(launch.state(body), 0.0, t, body.phys(), m.compile(), m.values())


def test_mode_refuses_what_cannot_be():
    with pytest.raises(ValueError, match="not a test mode"):
        TestMode(kind="sting")
    with pytest.raises(ValueError, match="still air"):
        TestMode(kind="range", stream_m_s=50.0)
    with pytest.raises(ValueError, match="needs a stream"):
        TestMode(kind="gimbal")
    with pytest.raises(ValueError, match="has no pivot"):
        TestMode(kind="tunnel", stream_m_s=50.0, pivot_from_cg_body_m=(0.01, 0, 0))
    # the shot file's [test_mode] table (unknown keys, units, model axes): test_shotfile.py


def test_tunnel_release_drifts_as_drag_alone_says():
    """Released at rest in the stream, drag only: the air-relative speed w = U + v_x obeys
    w' = -k w^2, k = rho S C_D / 2m, so w = U / (1 + k U t)."""
    body = RigidBody(**{**M1, "gravity_m_s2": 0.0},
                     mode=TestMode(kind="tunnel", stream_m_s=U))
    CD = 1.2
    t = np.linspace(0.0, 0.5, 11)
    states = run(body, model(CD=CD), Launch(speed_m_s=0.0), t)
    k = body.density_kg_m3 * body.area_m2 * CD / (2 * body.mass_kg)
    w = U / (1 + k * U * t)
    np.testing.assert_allclose(states[:, 3] + U, w, rtol=1e-10)
    x = np.log1p(k * U * t) / k - U * t          # integral of (w - U)
    np.testing.assert_allclose(states[:, 0] - states[0, 0], x, rtol=1e-9, atol=1e-12)


def test_pitch_pivot_ahead_of_cg_oscillates_as_linear_theory():
    """Pivot l ahead of the cg, gravity off, small amplitude. By hand (body x nose, z down):
    the cg moves at q l along z_b, so alpha = theta + l theta'/U; the lift acts at the cg,
    l behind the pivot. About the pivot, with I_P = I_yy + m l^2:
    I_P theta'' = q S (d Cma - l CLa) (theta + l theta'/U) + q S d^2 Cmq theta' / 2U."""
    l = 0.006
    body = RigidBody(**{**M1, "gravity_m_s2": 0.0},
                     mode=TestMode(kind="pitch_pivot", stream_m_s=U,
                                   pivot_from_cg_body_m=(l, 0.0, 0.0)))
    CLa, Cma, Cmq = 1.5, -0.117, -2.0
    theta0 = 1e-3
    t = np.linspace(0.0, 0.3, 301)
    states = run(body, model(CLa=CLa, Cma=Cma, Cmq=Cmq),
                 Launch(speed_m_s=0.0, theta_rad=theta0, r_rad_s=5.0), t)
    theta = observe(states, body.ref_from_cg_body_m())["theta_rad"]
    qS = 0.5 * body.density_kg_m3 * U**2 * body.area_m2
    d = body.d_m
    I_P = 81.024e-7 + body.mass_kg * l**2
    a = qS * (d * Cma - l * CLa) / I_P
    b = qS * ((d * Cma - l * CLa) * l / U + d**2 * Cmq / (2 * U)) / I_P
    A = np.array([[0.0, 1.0], [a, b]])
    lin = np.array([(expm(A * tk) @ [theta0, 0.0])[0] for tk in t])
    # neglected: sin(sigma) - sigma and the speed change, relative ~theta^2 ~ 1e-6
    assert np.max(np.abs(theta - lin)) < 2e-5 * theta0
    # the mount allowed no yaw or roll rate (r = 5 rad/s at launch was taken away)
    assert np.max(np.abs(states[:, 10])) == 0.0 and np.max(np.abs(states[:, 12])) == 0.0
    # and the pivot stayed put
    piv = states[:, 0:3] + np.einsum("nij,j->ni", _R(states), [l, 0.0, 0.0])
    assert np.max(np.abs(piv - piv[0])) < 1e-12


def _R(states):
    return np.stack([body_to_facility_matrix(s[6:10] / np.linalg.norm(s[6:10]))
                     for s in states])


@pytest.mark.parametrize("axis", ["pitch", "roll"])
def test_gimbal_is_a_compound_pendulum(axis):
    """No aerodynamics, the cg l below the gimbal centre: small swings about body y (x) at
    omega^2 = m g l / (I_yy + m l^2) (I_xx + m l^2), and the gimbal centre never moves."""
    l = 0.01
    body = RigidBody(**M1, mode=TestMode(kind="gimbal", stream_m_s=U,
                                         pivot_from_cg_body_m=(0.0, 0.0, -l)))
    amp = 1e-3
    launch = (Launch(speed_m_s=0.0, theta_rad=amp) if axis == "pitch"
              else Launch(speed_m_s=0.0, roll_rad=amp))
    I = 81.024e-7 if axis == "pitch" else 104.208e-7
    omega = np.sqrt(body.mass_kg * body.gravity_m_s2 * l / (I + body.mass_kg * l**2))
    t = np.linspace(0.0, 4 * 2 * np.pi / omega, 401)
    states = run(body, model(), launch, t)
    R = _R(states)
    if axis == "pitch":
        angle = observe(states, body.ref_from_cg_body_m())["theta_rad"]
    else:   # the roll angle: body y against the horizontal
        angle = np.arcsin(-R[:, 2, 1])
    # pendulum nonlinearity at 1e-3 rad: phase error ~ amp^2 omega t / 16 ~ 1e-6
    assert np.max(np.abs(angle - amp * np.cos(omega * t))) < 1e-4 * amp
    piv = states[:, 0:3] + np.einsum("nij,j->ni", R, [0.0, 0.0, -l])
    assert np.max(np.abs(piv - piv[0])) < 1e-12


def test_roll_bearing_spins_up_exponentially():
    """Held at 10 deg in the stream, a constant roll driving moment and roll damping:
    I_xx p' = q S d (Cl0 + Clp p d / 2U), so p = p_ss + (p0 - p_ss) exp(-t / tau). The nose
    axis stays where the bearing holds it."""
    body = RigidBody(**M1, mode=TestMode(kind="roll_bearing", stream_m_s=U,
                                         pivot_from_cg_body_m=(0.02, 0.0, 0.0)))
    Cl0, Clp = 0.01, -0.5
    t = np.linspace(0.0, 0.2, 41)
    launch = Launch(speed_m_s=0.0, theta_rad=np.radians(10.0), p_rad_s=20.0, q_rad_s=3.0)
    states = run(body, model(Cl0=Cl0, Clp=Clp, CLa=1.5, Cma=-0.117, CD=1.0), launch, t)
    d = body.d_m
    qSd = 0.5 * body.density_kg_m3 * U**2 * body.area_m2 * d
    p_ss = -Cl0 * 2 * U / (Clp * d)
    tau = -104.208e-7 * 2 * U / (qSd * Clp * d)
    p = p_ss + (20.0 - p_ss) * np.exp(-t / tau)
    np.testing.assert_allclose(states[:, 10], p, rtol=1e-9)
    obs = observe(states, body.ref_from_cg_body_m())
    assert np.max(np.abs(obs["theta_rad"] - np.radians(10.0))) < 1e-12
    assert np.max(np.abs(obs["psi_rad"])) < 1e-12


def test_fit_of_a_pitch_pivot_record_recovers_the_moment_slope_and_damping():
    """Angles only, 0.01 deg noise, 200 frames: the fit frees the attitude (with the pivot
    axis's direction) and q at the epoch, and C_m's slope and C_mq; both come back within
    3 sigma, and chi^2/nu is 1 within its scatter."""
    l = 0.006
    mode = TestMode(kind="pitch_pivot", stream_m_s=U, pivot_from_cg_body_m=(l, 0.0, 0.0))
    body = RigidBody(**M1, mode=mode)
    truth = model(CD=1.0, CLa=1.5, Cma=-0.117, Cmq=-2.0)
    t = np.linspace(0.0, 0.2, 200)
    states = run(body, truth, Launch(speed_m_s=0.0, theta_rad=np.radians(5.0)), t)
    obs = observe(states, body.ref_from_cg_body_m())
    rng = np.random.default_rng(7)
    s = np.radians(0.01)
    meas = np.full((t.size, 5), np.nan)
    meas[:, 3] = obs["theta_rad"] + s * rng.standard_normal(t.size)
    meas[:, 4] = obs["psi_rad"] + s * rng.standard_normal(t.size)
    sig = np.where(np.isfinite(meas), s, np.nan)
    shot = ShotData("tunnel-1", body, "capsule", np.arange(1, t.size + 1), t, meas, sig)
    lf = default_local_free(shot, truth)
    assert [LOCAL_NAMES[k] for k in lf] == ["rot_x_rad", "rot_y_rad", "rot_z_rad", "q_rad_s"]
    start = truth.with_values({"Cma": -0.08, "Cmq0": 0.0}).with_vary(
        {"CD0": False, "CLa": False})
    y_epoch = states[shot.epoch_index].copy()
    result = fit([shot], start, [y_epoch])
    assert result.converged
    for name, true in (("Cma", -0.117), ("Cmq0", -2.0)):
        i = result.aero_names.index(name)
        assert abs(result.aero_values[i] - true) < 3 * result.aero_sigma[i], name
    assert result.aero_sigma[result.aero_names.index("Cmq0")] < 0.2
    assert result.chi2 / (result.n_observations - result.n_free) == pytest.approx(1.0, abs=0.2)


def test_plain_python_baseline_refuses_a_mount():
    """The reference fitter's plain-Python RHS is free flight only: a mount is refused by
    name, not flown free."""
    from cadra.validation.fit_baseline import python_rhs

    m = model()
    body = RigidBody(**M1, mode=TestMode(kind="gimbal", stream_m_s=U))
    with pytest.raises(ValueError, match="free flight only"):
        python_rhs(body.phys(), m, m.values())


def test_pitch_pivot_record_from_files_through_cadra2_fit(tmp_path):
    """A tunnel record as files -- a shot file with its [test_mode] table (frames as
    stations, no images) and an angles-only trajectory file -- fitted by `cadra2 fit` with
    its automatic start: C_m's slope and C_mq within 3 sigma of the truth."""
    import json

    import pandas as pd

    from cadra.aero import save_model
    from cadra.cli.cadra2 import main
    from cadra.io.shotfile import MassProperties, ShotFile, StationRecord, load_shot, save_shot
    from cadra.io.trajectory import COLUMNS, write_trajectory
    from cadra.units import torr_to_pa

    mode = TestMode(kind="pitch_pivot", stream_m_s=U, pivot_from_cg_body_m=(0.006, 0.0, 0.0))
    t = np.linspace(0.0, 0.2, 120)
    shot = ShotFile(
        shot_id="T-1", model={"kind": "capsule", "preset": "M1", "d_cm": 3.556},
        mass=MassProperties(0.096563, [0.0044, 0.0, 0.0],
                            np.diag([104.208, 81.024, 81.024]) * 1e-7),
        pressure_pa=torr_to_pa(760.0), temperature_k=295.0, facility="hffaf",
        stations=tuple(StationRecord(i + 1, float(tk)) for i, tk in enumerate(t)),
        test_mode=mode)
    save_shot(shot, tmp_path / "shot.toml")
    back = load_shot(tmp_path / "shot.toml")
    assert back.test_mode == mode
    assert "[test_mode]" in (tmp_path / "shot.toml").read_text()

    from cadra.flight.data import rigid_body_from_shot

    body = rigid_body_from_shot(back)
    truth = model(CD=1.0, CLa=1.5, Cma=-0.117, Cmq=-2.0)
    states = run(body, truth, Launch(speed_m_s=0.0, theta_rad=np.radians(4.0)), t)
    obs = observe(states, body.ref_from_cg_body_m())
    rng = np.random.default_rng(3)
    sa = 0.01
    n = t.size
    table = pd.DataFrame({
        "station": np.arange(1, n + 1), "t_s": t, "status": "ok",
        "x_m": np.nan, "y_m": np.nan, "z_m": np.nan,
        "theta_deg": np.degrees(obs["theta_rad"]) + rng.normal(0, sa, n),
        "psi_deg": np.degrees(obs["psi_rad"]) + rng.normal(0, sa, n),
        "sigma_x_m": np.nan, "sigma_y_m": np.nan, "sigma_z_m": np.nan,
        "sigma_theta_deg": sa, "sigma_psi_deg": sa, "x_top_minus_side_m": np.nan,
        "x_consistency": np.nan, "reason": "", "warnings": ""})
    traj = tmp_path / "trajectory.csv"
    write_trajectory(traj, table.loc[:, list(COLUMNS)],
                     {"shot_id": "T-1", "shot_file": str(tmp_path / "shot.toml")})
    start = truth.with_values({"Cma": -0.05, "Cmq0": 0.0}).with_vary(
        {"CD0": False, "CLa": False, "Cl0": False, "Clp0": False})
    save_model(start, tmp_path / "model.toml")
    out = tmp_path / "fit"
    assert main(["fit", str(traj), "--model", str(tmp_path / "model.toml"), "-o", str(out),
                 "--no-plots", "-q"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["converged"]
    # 236 degrees of freedom: chi^2/nu = 1 +- 0.09
    assert abs(res["reduced_chi2"] - 1.0) < 0.3
    par = res["parameters"]
    for name, true in (("Cma", -0.117), ("Cmq0", -2.0)):
        assert abs(par[name]["value"] - true) < 3 * par[name]["sigma"], name
