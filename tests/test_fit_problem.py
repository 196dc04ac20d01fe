"""One fit problem behind every prediction (cadra.fitting.problem).

Truth: M2-2429 simulated WITH a lateral cg offset (0.2 mm, body z) and measured exactly
(sigmas 0.28 um, 0.0012 deg as weights). Fitted from the true state with the offset made free
(as ``cadra2 diagnose`` adds it), the solver's final predictions carry the offset; the
report's fitted histories, the gap's where-tests and score columns must predict with the same
physics. With the nominal physics (the offset left out) the reference point moves by the
offset rotated into F, ~0.2 mm = ~700 sigma, so any consumer that re-integrates the nominal
model fails by far.
"""

from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest

from cadra.dynamics.layout import P_CG_OFFSET, P_RHO_GRAD
from cadra.fitting.extras import Extra, phys_direction
from cadra.fitting.solver import fit

CG_Z = 2e-4                          # m, body z: the cg_offset_shot fixture's, and its
SIGMA_POS = 2.8e-7                   # m    sigmas
SIGMA_ANG = np.radians(0.0012)       # rad
CHANNEL_ORDER = ("x", "y", "z", "theta", "psi")


@pytest.fixture(scope="module")
def fitted(cg_offset_shot):
    sim, sd, y0 = cg_offset_shot.sim, cg_offset_shot.data, cg_offset_shot.y0
    extras = [Extra("cg_y", phys_direction=phys_direction(P_CG_OFFSET + 1)),
              Extra("cg_z", phys_direction=phys_direction(P_CG_OFFSET + 2)),
              # held: part of the physics, not fitted (a profile point); 0 changes nothing
              # numerically but must travel with the problem
              Extra("rho_grad", phys_direction=phys_direction(P_RHO_GRAD), held=True)]
    res = fit([sd], sim.model.with_values({}), [y0], extras=extras)
    assert res.converged, res.message
    assert res.value("cg_z") == pytest.approx(CG_Z, rel=1e-4)
    return res, sd


def _solver_fitted(res, channel):
    r = res.residuals
    sel = r[r["channel"] == channel].sort_values("t_s")
    return sel["t_s"].to_numpy(float), sel["fitted"].to_numpy(float)


def test_report_histories_use_the_fitted_physics(fitted):
    """The report's fitted histories at the station times are the solver's predictions."""
    from cadra.report.fit import fitted_histories

    res, sd = fitted
    h = fitted_histories(res, [sd])["M2-2429"]
    # the dense grid runs from the first to the last station: its ends are station times
    t, fx = _solver_fitted(res, "z")
    assert h["t_s"].iloc[0] == t[0] and h["t_s"].iloc[-1] == t[-1]
    for ch, col, scale, sig in (("x", "x_m", 1.0, SIGMA_POS), ("y", "y_m", 1.0, SIGMA_POS),
                                ("z", "z_m", 1.0, SIGMA_POS),
                                ("theta", "theta_deg", np.pi / 180, SIGMA_ANG),
                                ("psi", "psi_deg", np.pi / 180, SIGMA_ANG)):
        _, f = _solver_fitted(res, ch)
        ends = h[col].to_numpy(float)[[0, -1]] * scale
        # another output grid: the adaptive integrator's steps differ (its floor, ~1e-2 sigma)
        assert np.abs(ends - f[[0, -1]]).max() < 0.02 * sig, ch


def test_report_histories_at_station_times_equal_solver_predictions(fitted):
    from cadra.report.fit import fitted_histories

    res, sd = fitted
    h = fitted_histories(res, [sd], times=sd.t_s)["M2-2429"]
    for ch, col, scale in (("x", "x_m", 1.0), ("y", "y_m", 1.0), ("z", "z_m", 1.0),
                           ("theta", "theta_deg", np.pi / 180),
                           ("psi", "psi_deg", np.pi / 180)):
        t, f = _solver_fitted(res, ch)
        np.testing.assert_array_equal(h["t_s"].to_numpy(), t)
        # same integration, float run vs the real part of the complex-step run: rounding
        np.testing.assert_allclose(h[col].to_numpy(float) * scale, f, rtol=0,
                                   atol=1e-11 if scale == 1.0 else 1e-12, err_msg=ch)


def test_where_tests_predict_with_the_fitted_physics(fitted):
    from cadra.gap.where import fitted_channels

    res, sd = fitted
    pred = fitted_channels(res, [sd], times=sd.t_s)["M2-2429"]
    for j, ch in enumerate(CHANNEL_ORDER):
        _, f = _solver_fitted(res, ch)
        np.testing.assert_allclose(pred[:, j], f, rtol=0, atol=1e-11, err_msg=ch)


def test_gap_scores_start_from_the_solver_residual(fitted):
    """The gap's score columns are taken at the fit's point: its weighted residual is the
    result's normalized residual and its fit Jacobian the result's (columns: locals, then
    the shared unknowns)."""
    from cadra.fitting.sensitivity import Integration
    from cadra.gap.score import _columns

    res, sd = fitted
    per = _columns(res, [sd], [], Integration())
    np.testing.assert_allclose(per[0]["r"], res.residuals["normalized"].to_numpy(float),
                               rtol=0, atol=1e-6)
    nl = per[0]["local"]
    J = res.jacobian.toarray()
    ns = len(res.param_names) - nl
    np.testing.assert_allclose(per[0]["J"][:, nl:], J[:, :ns], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(per[0]["J"][:, :nl], J[:, ns:], rtol=1e-6, atol=1e-6)


def test_problem_reproduces_the_fit_and_pickles(fitted):
    res, sd = fitted
    prob = res.problem
    assert prob.param_names == res.param_names
    assert [e.name for e in prob.held_extras] == ["rho_grad"]
    pred = prob.predict()[0]
    r = res.residuals
    for j, ch in enumerate(CHANNEL_ORDER):
        _, f = _solver_fitted(res, ch)
        np.testing.assert_allclose(pred[:, j], f, rtol=0, atol=1e-11, err_msg=ch)
    # the weighted Jacobian in theta's order is the result's
    jac = prob.jacobian()[0][sd.mask] / sd.sigma[sd.mask][:, None]
    cols = prob.shot_columns(0)
    dense = np.zeros((jac.shape[0], prob.n_params))
    dense[:, cols] = jac
    np.testing.assert_allclose(dense, res.jacobian.toarray(), rtol=1e-9, atol=1e-9)
    # theta moves the prediction: the cg offset back to 0 moves z by ~the offset
    theta = prob.theta0
    theta[prob.param_names.index("cg_z")] = 0.0
    nominal = prob.predict(theta)[0]
    assert np.abs(nominal[:, :3] - pred[:, :3]).max() > 100 * SIGMA_POS
    # states at arbitrary times pass through the stations' states (another output grid:
    # the adaptive steps differ, tolerance 1e-8 per step; rates to ~1e-7 rad/s of ~5)
    st = prob.states(times=[sd.t_s[0], sd.t_s[-1]])[0]
    np.testing.assert_allclose(st, prob.states()[0][[0, -1]], rtol=1e-7, atol=1e-8)
    back = pickle.loads(pickle.dumps(prob))
    np.testing.assert_array_equal(back.predict()[0], pred)
    assert len(r) == pred[sd.mask].size


def test_station_terms_are_in_the_prediction_not_in_the_trajectory(fitted):
    """A held station bias (a measurement term) moves the predicted y at its station by
    exactly its value and nothing else; the trajectory (histories) does not see it."""
    res, sd = fitted
    prob = res.problem
    biased = replace(prob, extras=prob.extras + (
        Extra("st6_y", station=6, measure="position_y", value=1e-5, held=True),))
    d = biased.predict()[0] - prob.predict()[0]
    i6 = int(np.flatnonzero(sd.stations == 6)[0])
    expected = np.zeros_like(d)
    expected[i6, CHANNEL_ORDER.index("y")] = 1e-5
    np.testing.assert_allclose(d, expected, rtol=0, atol=1e-15)
    h0 = prob.histories(times=sd.t_s)[0]["channels"]
    h1 = biased.histories(times=sd.t_s)[0]["channels"]
    np.testing.assert_array_equal(h0, h1)
    # layout: the free extras sit between the aero parameters and the locals
    lay = prob.layout()
    names = prob.param_names
    assert [names[i] for i in range(lay["extras"].start, lay["extras"].stop)] == ["cg_y", "cg_z"]
    assert names[lay["locals"]["M2-2429"].start] == "M2-2429:x_cg_m"


def test_one_core_gives_the_same_jacobian_without_the_thread_pool(fitted, monkeypatch):
    """Under ``cores.limit(1)`` (a campaign task: Dask gives it one core) the complex-step
    runs stay in the calling thread, and the Jacobian is the threaded one, bit for bit."""
    from cadra import cores
    from cadra.fitting import sensitivity

    res, _ = fitted
    threaded = res.problem.jacobian()[0]

    def no_pool():
        raise AssertionError("the propagation used the thread pool under cores.limit(1)")

    monkeypatch.setattr(sensitivity, "_pool", no_pool)
    monkeypatch.setattr(sensitivity.os, "cpu_count", lambda: 2)   # a pool would be used
    with cores.limit(1):
        assert cores.available() == 1
        one = res.problem.jacobian()[0]
    np.testing.assert_array_equal(one, threaded)
    assert cores.available() == 2
    with pytest.raises(ValueError, match="at least 1 core"):
        with cores.limit(0):
            pass
