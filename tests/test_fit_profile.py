"""Profile likelihood of one fit parameter (cadra.fitting.profile).

Truth: a station's position bias enters the prediction linearly, so chi^2 is exactly
quadratic in it and its profile interval must be the fit's own value +- 2 sigma (scaled by
sqrt(reduced chi^2) when that exceeds 1). A drag coefficient is nearly linear over its
sigma: the same, to a few per cent.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from cadra.dynamics.effects import Effects
from cadra.fitting import fit_shots
from cadra.fitting.extras import Extra
from cadra.fitting.profile import profile_parameter
from cadra.flight import shot_data_from_truth
from cadra.synthetic.simulate import load_shot_spec, simulate_shot

BIAS_Z = 3e-6        # m, station 9


@pytest.fixture(scope="module")
def case():
    spec = load_shot_spec("sample_shots/specs/m2_2429.toml")
    sim = simulate_shot(spec)
    sd = shot_data_from_truth(sim.truth, sim.rigid.with_effects(Effects()), "M2-2429",
                              "capsule", sigma_position_m=2.8e-7,
                              sigma_angle_rad=np.radians(0.0012),
                              rng=np.random.default_rng(1))
    meas = sd.meas.copy()
    meas[int(np.flatnonzero(sd.stations == 9)[0]), 2] += BIAS_Z
    sd = replace(sd, meas=meas)
    res, _ = fit_shots([sd], sim.model, extras=[Extra("b9z", station=9, measure="position_z")])
    assert res.converged, res.message
    return sd, res


def _two_sigma(res, name):
    v, s = res.value(name), res.sigma(name) * math.sqrt(max(1.0, res.reduced_chi2))
    return v - 2 * s, v + 2 * s


def test_profile_of_a_linear_parameter_is_its_two_sigma_interval(case):
    sd, res = case
    p = profile_parameter(res, [sd], "b9z")
    lo, hi = _two_sigma(res, "b9z")
    assert p.closed
    assert p.lower == pytest.approx(lo, abs=0.01 * (hi - lo))
    assert p.upper == pytest.approx(hi, abs=0.01 * (hi - lo))
    assert p.best_value == pytest.approx(res.value("b9z"))
    # the injected bias lies inside (noise 0.28 um, sigma ~0.3 um)
    assert p.lower < BIAS_Z < p.upper


def test_profile_of_an_aero_parameter(case):
    sd, res = case
    p = profile_parameter(res, [sd], "CD_A1")
    lo, hi = _two_sigma(res, "CD_A1")
    assert p.lower == pytest.approx(lo, abs=0.03 * (hi - lo))
    assert p.upper == pytest.approx(hi, abs=0.03 * (hi - lo))
    # every point refitted the rest: the profile never drops below the fit's minimum
    assert np.all(p.chi2 >= res.chi2 - 1e-6 * res.chi2)


def test_unknown_parameter_refused(case):
    sd, res = case
    with pytest.raises(ValueError, match="not a free parameter"):
        profile_parameter(res, [sd], "no_such")
    with pytest.raises(ValueError, match="no data"):
        profile_parameter(res, [], "b9z")
