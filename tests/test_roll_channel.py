"""The observed roll angle phi (cadra.channels): its observation model, its wrapped residual,
its file columns, and stage two fitting the roll channel of a roll-bearing record.

Truths: ``conventions.quat_from_axis_roll`` (the attitude built from a nose axis and a roll)
and ``quat_to_euler``; a central difference of the observation for its complex step; the
known coefficients of a simulated roll-bearing record (seed 001 Eq. 27 forms,
:mod:`cadra.validation.roll_bearing`) recovered within their sigmas.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from cadra import channels as C
from cadra.conventions import axis_from_inclinations, quat_from_axis_roll, quat_to_euler
from cadra.dynamics.observe import observe


def _state(q):
    y = np.zeros(13)
    y[6:10] = q
    return y


def test_phi_round_trips_the_attitude_it_was_built_from():
    rng = np.random.default_rng(3)
    for _ in range(300):
        th, ps = rng.uniform(-1.0, 1.0), rng.uniform(-0.5, 0.5)
        roll = rng.uniform(-math.pi, math.pi)
        q = quat_from_axis_roll(axis_from_inclinations(th, ps), roll)
        o = observe(_state(q)[None, :], np.zeros(3))
        assert o["theta_rad"][0] == pytest.approx(th, abs=1e-12)
        assert o["psi_rad"][0] == pytest.approx(ps, abs=1e-12)
        assert o["phi_rad"][0] == pytest.approx(roll, abs=1e-12)
        assert o["phi_rad"][0] == pytest.approx(quat_to_euler(q)[2], abs=1e-12)


def test_phi_complex_step_matches_a_central_difference():
    q0 = quat_from_axis_roll(axis_from_inclinations(0.3, -0.2), 2.9)     # near the +-pi cut
    rng = np.random.default_rng(8)
    for _ in range(5):
        dq = rng.normal(size=4)
        h = 1e-20
        yc = _state(q0).astype(complex)
        yc[6:10] += 1j * h * dq
        d_cs = observe(yc[None, :], np.zeros(3))["phi_rad"][0].imag / h
        e = 1e-6
        hi = observe(_state(q0 + e * dq)[None, :], np.zeros(3))["phi_rad"][0]
        lo = observe(_state(q0 - e * dq)[None, :], np.zeros(3))["phi_rad"][0]
        assert d_cs == pytest.approx((hi - lo) / (2 * e), rel=1e-6, abs=1e-9)


def test_residual_wraps_only_the_roll():
    meas = np.array([[1.0, 0.0, 0.0, 0.1, 0.0, math.radians(179.0)],
                     [1.0, 0.0, 0.0, 0.1, 0.0, math.radians(719.0)]])
    pred = np.array([[0.5, 0.0, 0.0, 0.1 - 2 * math.pi, 0.0, math.radians(-179.0)],
                     [0.5, 0.0, 0.0, 0.1, 0.0, math.radians(-2.0)]])
    r = C.residual(meas, pred)
    assert r[0, 0] == 0.5 and r[0, 3] == pytest.approx(2 * math.pi)     # theta not wrapped
    assert math.degrees(r[0, 5]) == pytest.approx(-2.0)
    assert math.degrees(r[1, 5]) == pytest.approx(1.0)
    assert np.isnan(C.residual(np.full((1, 6), np.nan), pred[:1])).all()


def test_trajectory_file_reads_phi_when_there_and_not_measured_when_absent(tmp_path):
    from cadra.io.trajectory import COLUMNS, load_trajectory, trajectory_to_csv

    row = dict.fromkeys(COLUMNS, np.nan)
    row.update(station=3, t_s=0.01, status="ok", x_m=1.5, y_m=0.0, z_m=0.0, theta_deg=1.0,
               psi_deg=-1.0, phi_deg=1440.5, sigma_x_m=1e-4, sigma_y_m=1e-4, sigma_z_m=1e-4,
               sigma_theta_deg=0.1, sigma_psi_deg=0.1, sigma_phi_deg=0.2, reason="",
               warnings="")
    p = tmp_path / "t.csv"
    p.write_text(trajectory_to_csv(pd.DataFrame([row]), {"shot_id": "S"}))
    t = load_trajectory(p).table
    assert t["phi_rad"].iloc[0] == pytest.approx(math.radians(1440.5))   # four turns on
    assert t["sigma_phi_rad"].iloc[0] == pytest.approx(math.radians(0.2))
    # a table without a roll (a body of revolution) writes the file as it was before the
    # roll channel, without the phi columns; reading it gives "not measured"
    old = pd.DataFrame([{k: v for k, v in row.items() if "phi" not in k}])
    text = trajectory_to_csv(old, {"shot_id": "S"})
    assert "phi" not in text
    p.write_text(text)
    t = load_trajectory(p).table
    assert np.isnan(t["phi_rad"].iloc[0]) and t["theta_deg"].iloc[0] == 1.0


# --- stage two fits a roll-bearing record's roll channel ---------------------------------

def _roll_record(rng, *, phi0_deg=70.0, n=400, rate_hz=200.0, sigma_deg=0.05):
    """A roll-bearing record of seed 001 Eq. 27's lock-in (the slow-damping finner of
    :mod:`cadra.validation.roll_bearing` and its forms) measured in theta, psi and phi with
    white noise."""
    from cadra.dynamics.trajectory import truth_table
    from cadra.flight.data import shot_data_from_truth
    from cadra.validation.roll_bearing import (
        SLOW_FINNER,
        SLOW_SPEED_M_S,
        bearing,
        lockin_model,
        roll_history,
    )

    model = lockin_model()
    t = np.arange(n) / rate_hz
    body = bearing(SLOW_FINNER, SLOW_SPEED_M_S)
    _, states = roll_history(model, phi0_deg, t, body)
    truth = truth_table(t, states, body)
    sd = shot_data_from_truth(truth, body, "roll-1", "finner",
                              sigma_position_m=1e-4, sigma_angle_rad=math.radians(sigma_deg),
                              rng=rng, positions=False)
    return sd, model, states


def test_roll_record_measures_phi_and_frees_roll_and_p():
    from cadra.fitting.problem import LOCAL_NAMES, default_local_free

    sd, model, _ = _roll_record(np.random.default_rng(1))
    assert sd.has_roll and sd.has_angles
    assert not np.isfinite(sd.meas[:, C.POSITION]).any()
    free = [LOCAL_NAMES[k] for k in default_local_free(sd, model)]
    assert free == ["rot_x_rad", "rot_y_rad", "rot_z_rad", "p_rad_s"]


def test_fit_of_a_roll_bearing_record_recovers_the_roll_coefficients():
    """Seed 001 Table IV's lock-in from 70 deg at 0.05 deg noise in all three angles: the
    fit, started 20-40 % off, recovers C_l(alpha), C_lp0 and C_lp2 within 3 sigma and the
    noise level (chi^2 / nu near 1)."""
    from cadra.fitting import fit_shots

    sd, truth, _ = _roll_record(np.random.default_rng(4))
    start = truth.with_values({"Cla": 0.4, "Clp0": -1.5, "Clp2": 10.0})
    res, _ = fit_shots([sd], start, auto_start=False)
    assert res.converged, res.message
    want = {"Cla": 0.5, "Clp0": -2.0, "Clp2": 15.0}
    for name, v in want.items():
        assert abs(res.value(name) - v) < 3 * res.sigma(name), (name, res.value(name),
                                                                 res.sigma(name))
    assert 0.8 < res.reduced_chi2 < 1.2
    # noise-free, the same start: the fit lands on the truth (what seed 001's MDC misses by
    # 1-4 %, Table IV)
    exact, _, _ = _roll_record(None)
    res, _ = fit_shots([exact], start, auto_start=False)
    assert res.converged, res.message
    for name, v in want.items():
        assert res.value(name) == pytest.approx(v, rel=1e-4), name


def test_roll_only_record_without_the_axis_asks_for_a_starting_state():
    from dataclasses import replace

    from cadra.fitting.start import state_candidates
    from cadra.flight.data import FitDataError

    sd, _, states = _roll_record(np.random.default_rng(2), n=50)
    meas = sd.meas.copy()
    meas[:, C.AXIS] = np.nan
    roll_only = replace(sd, meas=meas)
    with pytest.raises(FitDataError, match="theta and psi"):
        state_candidates(roll_only)
    # with the axis measured the start takes the measured roll and its rate
    y0 = state_candidates(sd)[0]
    k = sd.epoch_index
    assert observe(y0[None, :], np.zeros(3))["phi_rad"][0] == pytest.approx(
        sd.meas[k, C.ROLL[0]], abs=math.radians(0.2))
    assert y0[10] == pytest.approx(states[k, 10], abs=0.05 * abs(states[k, 10]) + 0.1)


def test_finned_range_shot_fits_its_roll_coefficients_and_plots_the_roll():
    """FINNER-1 (canted fins roll the model up from rest) measured in all six channels at
    stage-one-like precision (20 um, 0.03 deg, roll 0.3 deg): the roll drive and damping come
    back within 3 sigma; the angle-history figure gets a roll panel whose measured points,
    moved by whole turns onto the fitted branch, sit on the fitted line."""
    import matplotlib

    matplotlib.use("Agg")
    from cadra.fitting import fit_shots
    from cadra.flight import shot_data_from_truth
    from cadra.report.fit_plots import plot_angle_histories
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    sim = simulate_shot(load_shot_spec("sample_shots/specs/finner_1.toml"))
    assert np.ptp(np.unwrap(np.radians(sim.truth["phi_deg"]))) > math.radians(270)
    sd = shot_data_from_truth(sim.truth, sim.rigid, sim.spec.shot_id, sim.body.kind,
                              sigma_position_m=20e-6, sigma_angle_rad=math.radians(0.03),
                              sigma_roll_rad=math.radians(0.3), rng=np.random.default_rng(3))
    assert sd.has_roll
    res, _ = fit_shots([sd], sim.model)
    assert res.converged, res.message
    for name in ("Cl_delta", "Clp_0"):
        truth = sim.model.parameter(name).value
        assert abs(res.value(name) - truth) < 3 * res.sigma(name), name
        assert res.sigma(name) < 0.1 * abs(truth)
    fig = plot_angle_histories(res, [sd])
    ax = fig.axes[3]
    assert ax.get_title().startswith("FINNER-1: φ")
    x_fit, y_fit = ax.lines[0].get_data()
    pts = [c for c in ax.containers]
    x_m, y_m = pts[0].lines[0].get_data()
    assert np.all(np.abs(np.interp(x_m, x_fit, y_fit) - y_m) < 3 * 0.3)


# --- stage one's sigma beside a faint outline ----------------------------------------------

def test_noise_autocovariance_that_is_no_covariance_is_not_used():
    """Stage one's correlated-noise sigma fits the noise's autocovariance as alpha + beta m^2
    through the levels on the two sides of an outline. Where the two are close (a faint
    shadow, as a thin fin's can be) and their noise differs, that line's slope is mostly
    noise, and extrapolated to darker intensities it exceeded the noise's own variance: a
    correlation beyond 1, which gave a Basic Finner view a negative segment variance, a pose
    sigma of 1e140 m and a singular covariance in the two views' combination. Here: a disc at
    0.7 in a beam of 0.8, grain-like correlated noise inside it only; the line would imply a
    correlation of 1.9 at black. Such an estimate is not used (None: white noise)."""
    import cv2

    from cadra.imaging.silhouette.edges import outline_geometry
    from cadra.imaging.silhouette.noise import noise_autocovariance

    n, white = 400, 0.01
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    r = np.hypot(xx - 200.3, yy - 199.6)
    clean = 0.7 + 0.1 * 0.5 * (1 + np.tanh((r - 100.0) / 0.8))
    rng = np.random.default_rng(3)
    k = cv2.getGaussianKernel(9, 1.5)[:, 0]
    g = cv2.sepFilter2D(rng.standard_normal((n, n)), -1, k, k,
                        borderType=cv2.BORDER_REFLECT_101) / np.sqrt(np.sum(np.outer(k, k)**2))
    img = clean + white * rng.standard_normal((n, n)) + np.where(r < 100, 0.01, 0.0) * g
    t = np.linspace(0, 2 * np.pi, 1024, endpoint=False)
    poly = np.column_stack([200.3 + 100 * np.cos(t), 199.6 + 100 * np.sin(t)])
    coef = np.array([white**2 + 0.5e-4, 0.0, 0.0])
    assert noise_autocovariance(img, outline_geometry(poly), None, coef, 5) is None
