"""Extra unknowns of a fit (cadra.fitting.extras): unmodelled effects made free.

Truth: a shot simulated WITH a lateral cg offset and measured with a station's position
bias and a timing bias added exactly; fitted from the true state with the effects' parameters
started at 0, the fit must land on the injected values (noise-free: to rounding of the
integration), and the cg-offset column must carry the observed reference point's shift.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cadra.channels import residual
from cadra.dynamics.layout import N_PHYS, P_CG_OFFSET
from cadra.fitting.extras import Extra, phys_direction
from cadra.fitting.sensitivity import predict, predict_with_jacobian
from cadra.fitting.solver import fit

CG_Z = 2e-4          # m, body z (the cg_offset_shot fixture's)
BIAS_Y = 3e-6        # m, station 6 y
DT = 1e-7            # s, station 10


@pytest.fixture(scope="module")
def case(cg_offset_shot):
    """The shot with a station-6 y bias and a station-10 timing bias added."""
    sim, sd = cg_offset_shot.sim, cg_offset_shot.data
    meas = sd.meas.copy()
    i6 = int(np.flatnonzero(sd.stations == 6)[0])
    i10 = int(np.flatnonzero(sd.stations == 10)[0])
    meas[i6, 1] += BIAS_Y
    meas[i10, :3] += sim.truth[["vx_m_s", "vy_m_s", "vz_m_s"]].to_numpy()[i10] * DT
    return sim, replace(sd, meas=meas), cg_offset_shot.y0


def test_fit_recovers_cg_offset_station_bias_and_timing(case):
    sim, sd, y0 = case
    extras = [Extra("cg_y", phys_direction=phys_direction(P_CG_OFFSET + 1)),
              Extra("cg_z", phys_direction=phys_direction(P_CG_OFFSET + 2)),
              Extra("st6_y", station=6, measure="position_y"),
              Extra("st10_dt", station=10, measure="timing")]
    res = fit([sd], sim.model.with_values({}), [y0], extras=extras)
    assert res.converged, res.message
    assert res.value("cg_y") == pytest.approx(0.0, abs=1e-9)
    assert res.value("cg_z") == pytest.approx(CG_Z, rel=1e-4)
    assert res.value("st6_y") == pytest.approx(BIAS_Y, rel=1e-3)
    assert res.value("st10_dt") == pytest.approx(DT, rel=1e-3)
    # noise-free data, the model that made them: the residual is at the integration floor
    assert res.reduced_chi2 < 1e-4
    # sigmas exist, are finite and positive, and sit in the covariance's order
    for n in ("cg_y", "cg_z", "st6_y", "st10_dt"):
        assert 0 < res.sigma(n) < np.inf
        assert n in res.param_names


def test_cg_offset_column_moves_the_observed_reference_point(case):
    """Complex-step column of a cg-offset direction = central difference of the prediction
    with the offset applied both to the dynamics and to the reference point."""
    sim, sd, y0 = case
    program = sim.model.compile()
    params = sim.model.values()
    phys = sd.rigid.phys()
    ref = sd.rigid.ref_from_cg_body_m()
    d = np.array(phys_direction(P_CG_OFFSET + 1))
    _, J = predict_with_jacobian(y0, sd.t_s[sd.epoch_index], sd.t_s, phys, program, params,
                                 ref, [], [], phys_dirs=d[None, :])
    h = 1e-5            # the offset's effect is smooth: central-difference error ~h^2
    e = np.array([0.0, h, 0.0])
    t0 = sd.t_s[sd.epoch_index]

    def fd(shift_ref):
        up = predict(y0, t0, sd.t_s, phys + h * d, program, params, ref - shift_ref * e)
        dn = predict(y0, t0, sd.t_s, phys - h * d, program, params, ref + shift_ref * e)
        return residual(up, dn) / (2 * h)        # the roll wrapped

    scale = np.abs(J[:, :, 0]).max(axis=0)           # per channel
    # (the adaptive integrator's step choices make the difference quotient noisy at ~5e-4)
    assert np.all(np.abs(J[:, :, 0] - fd(1.0)) <= 2e-3 * scale)
    # without the reference point's shift the positions would be off by ~1 m per m
    assert np.abs(J[:, :3, 0] - fd(0.0)[:, :3]).max() > 0.5


@pytest.mark.parametrize("kwargs", [
    {"phys_direction": phys_direction(0), "station": 3, "measure": "position_x"},   # both kinds
    {},                                                                     # neither
    {"station": 3, "measure": "rotation"},                                 # unknown measure
    {"phys_direction": (0.0,) * N_PHYS},                                   # zero direction
])
def test_bad_extras_refused(kwargs):
    with pytest.raises(ValueError):
        Extra("e", **kwargs)


def test_extra_named_like_a_model_parameter_refused(case):
    sim, sd, y0 = case
    with pytest.raises(ValueError, match="names of their own"):
        fit([sd], sim.model, [y0], extras=[Extra("CD_A1", station=2, measure="position_x")])


def test_fit_shots_carries_extras_through_both_stages(case):
    """From automatic starting values (linear-theory aero start, states from the data, the
    film-sigma first stage and the real-sigma second), the extras still land on the truth."""
    from cadra.fitting import fit_shots

    sim, sd, _ = case
    extras = [Extra("cg_z", phys_direction=phys_direction(P_CG_OFFSET + 2)),
              Extra("st6_y", station=6, measure="position_y"),
              Extra("st10_dt", station=10, measure="timing")]
    res, _ = fit_shots([sd], sim.model, extras=extras)
    assert res.converged, res.message
    assert res.value("cg_z") == pytest.approx(CG_Z, rel=1e-3)
    assert res.value("st6_y") == pytest.approx(BIAS_Y, rel=1e-2)
    assert res.value("st10_dt") == pytest.approx(DT, rel=1e-2)
    assert res.reduced_chi2 < 1e-3


def test_held_extras_act_but_are_not_fitted(case):
    """A held extra acts at its value (here the true cg offset and timing bias: the fit of
    the free station bias is then exact) and is not an unknown: it has no column in the
    covariance, the degrees of freedom count only the free unknowns, and the result lists it.
    Held at a wrong value it leaves a misfit no free unknown can remove."""
    sim, sd, y0 = case
    free = Extra("st6_y", station=6, measure="position_y")
    held = [Extra("cg_z", phys_direction=phys_direction(P_CG_OFFSET + 2), value=CG_Z, held=True),
            Extra("st10_dt", station=10, measure="timing", value=DT, held=True)]
    res = fit([sd], sim.model.with_values({}), [y0], extras=[free, *held])
    assert res.converged, res.message
    assert res.extra_names == ("st6_y",)
    assert {e.name for e in res.held_extras} == {"cg_z", "st10_dt"}
    assert res.value("cg_z") == CG_Z and res.sigma("cg_z") == 0.0
    assert res.value("st6_y") == pytest.approx(BIAS_Y, rel=1e-3)
    assert res.reduced_chi2 < 1e-4
    assert "cg_z" not in res.param_names
    full = fit([sd], sim.model.with_values({}), [y0],
               extras=[free, *(replace(e, held=False) for e in held)])
    assert res.n_free == full.n_free - 2
    wrong = fit([sd], sim.model.with_values({}), [y0],
                extras=[free, replace(held[0], value=0.0), held[1]])
    assert wrong.reduced_chi2 > 1e3 * max(res.reduced_chi2, 1e-6)
