"""Sphere calibration: station biases from sphere shots, applied to a capsule fit.

Truth: the simulator's exact trajectories (three sphere sample shots at 450, 800 and 1200 m/s)
with known station biases injected into the measurements (position: measured = truth + b;
timing: the spark fires dt late, so measured = truth + v dt), and stage-one-like noise.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cadra.calibration.sphere import (
    CalibrationError,
    apply_bias_table,
    estimate_station_biases,
)
from cadra.fitting import fit_shots
from cadra.synthetic.simulate import load_shot_spec, simulate_shot
from cadra.validation.calibration_trials import biased_shot_data

SPECS = "sample_shots/specs"
SIGMA = 1e-6      # m, position noise (stage one measures spheres to ~0.2 um)


def injected() -> np.ndarray:
    """(16, 4) biases: y and z of 0.2-0.8 mm at four stations, 1 us timing at one."""
    b = np.zeros((16, 4))
    b[3, 1], b[8, 1] = 5e-4, -3e-4
    b[5, 2], b[12, 2] = 8e-4, -2e-4
    b[10, 3] = 1e-6
    return b


def _biased(sim, bias, rng, kind=None):
    return biased_shot_data(sim, bias, SIGMA, rng, kind)


@pytest.fixture(scope="module")
def spheres():
    return [simulate_shot(load_shot_spec(f"{SPECS}/sphere_{k}.toml")) for k in (1, 2, 3)]


@pytest.fixture(scope="module")
def estimate(spheres):
    rng = np.random.default_rng(7)
    shots = [_biased(s, injected(), rng) for s in spheres]
    return estimate_station_biases(shots, facility="hffaf"), spheres[0].truth["x_m"].to_numpy()


def test_injected_biases_recovered_within_two_sigma(estimate):
    """In the robust gauge the estimate compares with the injected biases themselves."""
    est, xs = estimate
    truth = injected()
    z = (est.bias - truth) / est.sigma
    assert est.timing_estimated
    assert np.all(np.isfinite(z))
    assert np.mean(np.abs(z) <= 2) >= 0.95
    # the injected ones, each: y, z biases and the 1 us timing bias
    for k, c in ((3, 1), (8, 1), (5, 2), (12, 2), (10, 3)):
        assert abs(z[k, c]) <= 2.5, (k, c, est.bias[k, c], truth[k, c], est.sigma[k, c])
    # clearly detected, and the unbiased stations are not flagged
    assert abs(est.bias[10, 3]) / est.sigma[10, 3] > 50
    assert abs(est.bias[5, 2]) / est.sigma[5, 2] > 50
    flagged = np.abs(est.bias / est.sigma) > 3
    assert set(map(tuple, np.argwhere(flagged))) == {(3, 1), (8, 1), (5, 2), (12, 2), (10, 3)}


def test_unobservable_patterns_are_not_reported(spheres):
    """A common y offset, a linear y trend and a quadratic x pattern along the range look like
    changes of each shot's initial state and drag law: the estimate must show none of them."""
    xs = spheres[0].truth["x_m"].to_numpy()
    b = np.zeros((16, 4))
    b[:, 1] = 2e-4 + 1e-5 * xs
    b[:, 0] = 3e-7 * (xs - 11.0) ** 2
    rng = np.random.default_rng(3)
    est = estimate_station_biases([_biased(s, b, rng) for s in spheres], facility="hffaf")
    assert np.all(np.abs(est.bias[:, :3]) <= 3 * est.sigma[:, :3])


def test_applying_the_table_restores_a_capsule_fit(estimate):
    """A capsule shot measured through the same biased stations: after the recovered table is
    applied, its residual rms is within 10 % of the same shot's fit without biases."""
    est, _ = estimate
    table = est.to_table()
    sim = simulate_shot(load_shot_spec(f"{SPECS}/m2_2429.toml"))
    rng = np.random.default_rng(11)
    clean = _biased(sim, np.zeros((16, 4)), np.random.default_rng(11))
    biased = _biased(sim, injected(), rng)
    r_clean, _ = fit_shots([clean], sim.model)
    r_biased, _ = fit_shots([biased], sim.model)
    r_fixed, _ = fit_shots([apply_bias_table(biased, table)], sim.model)

    def rms(r):
        return np.sqrt(np.mean([r.rms()[c] ** 2 for c in "xyz"]))

    assert rms(r_biased) > 3 * rms(r_clean)
    assert rms(r_fixed) <= 1.10 * rms(r_clean)


def test_refusals(spheres):
    rng = np.random.default_rng(1)
    capsule = simulate_shot(load_shot_spec(f"{SPECS}/m2_2429.toml"))
    with pytest.raises(CalibrationError, match="capsule"):
        estimate_station_biases([_biased(capsule, np.zeros((16, 4)), rng)])
    short = spheres[0]
    sd = _biased(short, np.zeros((16, 4)), rng)
    sd = replace(sd, stations=sd.stations[:4], t_s=sd.t_s[:4], meas=sd.meas[:4],
                 sigma=sd.sigma[:4])
    with pytest.raises(CalibrationError, match="at least"):
        estimate_station_biases([sd])
    with pytest.raises(CalibrationError, match="no sphere shots"):
        estimate_station_biases([])


def test_one_speed_does_not_pretend_to_separate_timing(spheres):
    rng = np.random.default_rng(2)
    est = estimate_station_biases([_biased(spheres[0], injected(), rng)], facility="hffaf")
    assert not est.timing_estimated
    assert np.all(np.isnan(est.sigma[:, 3]))
    assert any("timing" in w for w in est.warnings)
