"""Linear theory's damped-sine fit (cadra.flight.estimates._damped_sine) against exact sines.

Truth: v(t) = quadratic trend + e^(lambda t) (A cos(omega t) + B sin(omega t)), sampled as a
spark range samples a shot (uneven spacing), with and without noise."""

import math

import numpy as np
import pytest

from cadra.flight.estimates import _damped_sine


def _record(rng, omega, lam, n=24, noise=0.0):
    t = np.sort(rng.uniform(0.0, 0.06, n))
    tc = t - t.mean()
    v = (0.01 + 0.2 * tc - 3.0 * tc * tc
         + np.exp(lam * tc) * (0.03 * np.cos(omega * tc) - 0.02 * np.sin(omega * tc)))
    return t, v + noise * rng.standard_normal(n)


@pytest.mark.parametrize("omega,lam", [(160.0, -4.0), (310.0, 6.0), (95.0, 0.0)])
def test_an_exact_damped_sine_is_recovered(omega, lam):
    """To the Nelder-Mead stop's scale (xatol 1e-4; 95 rad/s is less than a period in the
    record, 1.2e-5 off)."""
    t, v = _record(np.random.default_rng(1), omega, lam)
    w, la, rel = _damped_sine(t, v)
    assert w == pytest.approx(omega, rel=3e-5)
    assert la == pytest.approx(lam, abs=2e-3)
    assert rel < 1e-5


def test_noise_leaves_the_frequency_within_its_scatter_and_a_flat_record_has_none():
    rng = np.random.default_rng(2)
    ws = [_damped_sine(*_record(rng, 200.0, -2.0, noise=1e-3))[0] for _ in range(20)]
    assert abs(np.mean(ws) - 200.0) < 3 * np.std(ws) / math.sqrt(len(ws)) + 0.5
    assert np.std(ws) < 5.0
    t = np.linspace(0.0, 0.06, 20)
    assert all(math.isnan(x) for x in _damped_sine(t, np.full(20, 0.3)))
    w, _, rel = _damped_sine(t, 0.1 + 0.5 * t + rng.normal(0.0, 1e-4, 20))   # trend + noise
    assert math.isnan(w) and rel > 0.7
