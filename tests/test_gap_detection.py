"""The statistics of the gap diagnosis's detection efficiency (cadra.validation.gap_power and
cadra.validation.gap_detection), each against an independent truth: the normal approximation
of a one-parameter test's power, a known detection curve, and the leverage the fit itself
reports."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from cadra.validation.gap_detection import library_candidate, reference_noncentrality
from cadra.validation.gap_power import (
    M90_GRID,
    detection_probability,
    fit_m90,
    lambda90,
    projected_noncentrality,
)


def test_lambda90_of_one_parameter_is_the_normal_shift():
    """ncx2(1, lambda) is (Z + sqrt(lambda))^2: the test at alpha rejects when |Z +
    sqrt(lambda)| > z_{1-alpha/2}, with power Phi(sqrt(lambda) - z) + Phi(-sqrt(lambda) - z).
    Without the second term sqrt(lambda90) = z_{0.995} + z_{0.9} exactly; that term is
    Phi(-6.44) ~ 6e-11, which lowers sqrt(lambda90) by 6e-11 / phi(z_{0.9}) ~ 3.4e-10, i.e.
    lambda90 by ~2e-10 relative. A tolerance of 1e-8 relative is 50 times that (and far
    above the root finder's 1e-12), and far below any error that would matter (1e-3)."""
    lam = lambda90(1, 0.01, 0.9)
    z = stats.norm.isf(0.005) + stats.norm.isf(0.1)
    assert lam < z * z                      # the neglected tail only adds power
    assert math.isclose(lam, z * z, rel_tol=1e-8)
    # and against scipy's noncentral chi^2 itself, for one and several parameters
    for k in (1, 2, 6):
        lk = lambda90(k, 0.01, 0.9)
        assert abs(stats.ncx2.sf(stats.chi2.isf(0.01, k), k, lk) - 0.9) < 1e-9
    assert lambda90(1) < lambda90(2) < lambda90(6)


def test_ml_fit_recovers_a_known_detection_curve():
    """Outcomes drawn from the model's own curve with m90 = 1.3 (one parameter; and a mix of
    k = 1 and 2) give back m90 within its interval; the 95 % likelihood interval of 20-trial
    scans covers the truth at about its nominal rate."""
    rng = np.random.default_rng(7)
    for k in (1, np.where(np.arange(1500) % 2 == 0, 1, 2)):
        m = np.exp(rng.uniform(math.log(0.6), math.log(2.2), 1500))
        y = rng.random(m.size) < detection_probability(m, k, 1.3)
        f = fit_m90(m, k, y)
        assert not f["censored"]
        assert f["lower"] <= 1.3 <= f["upper"]
        assert abs(f["m90"] - 1.3) < 0.04
        assert f["upper"] - f["lower"] < 0.1
    # the curve is what it says: P = 0.9 at m90, rising with m
    p = detection_probability([0.8, 1.3, 2.0], 2, 1.3)
    assert abs(p[1] - 0.9) < 1e-9 and p[0] < p[1] < p[2]
    # coverage of the interval over 20-trial scans (binomial sd of the rate over 200: 0.015)
    hits = 0
    for _ in range(200):
        m = np.exp(rng.uniform(math.log(0.6), math.log(2.2), 20))
        y = rng.random(20) < detection_probability(m, 1, 1.3)
        f = fit_m90(m, 1, y, n_grid=300)
        hits += f["lower"] <= 1.3 <= f["upper"]
    assert 0.88 <= hits / 200 <= 0.99
    # every trial detected: only an upper bound
    f = fit_m90([1.0, 1.5, 2.0], 1, [True, True, True])
    assert f["censored"] and f["lower"] == M90_GRID[0] and f["upper"] < 2.0


def test_projected_noncentrality_of_one_measurement_is_one_minus_leverage():
    """A bias at one measurement (column e_j) of a linear least-squares fit: its score test's
    noncentrality per unit bias^2 is |P_perp e_j|^2 = 1 - h_jj, h the hat matrix."""
    rng = np.random.default_rng(3)
    J = rng.standard_normal((40, 6))
    H = J @ np.linalg.solve(J.T @ J, J.T)
    for j in (0, 17, 39):
        e = np.zeros(40)
        e[j] = 1.0
        r = projected_noncentrality(J, e[:, None], e)
        assert r["k"] == 1
        assert math.isclose(r["lambda_cand"], 1.0 - H[j, j], rel_tol=1e-10)
        assert math.isclose(r["lambda_full"], 1.0 - H[j, j], rel_tol=1e-10)
    # a signature partly outside the candidate's columns: coverage below 1
    d = rng.standard_normal(40)
    r = projected_noncentrality(J, d[:, None] + 0.3 * rng.standard_normal((40, 1)), d)
    assert 0.0 < r["coverage"] < 1.0


def test_station_bias_reference_equals_the_fits_own_leverage():
    """On a real fit (a sphere shot, noise-free, a 5 sigma y bias at one station, fitted
    without it), the reference through cadra.gap.score's columns and the fit's residual is
    (1 - leverage) / sigma^2 per unit bias^2, with the leverage the fit reports in its
    residual table, and the candidate's column holds all of the residual (coverage 1)."""
    from cadra.dynamics.effects import Effects
    from cadra.fitting import fit_shots
    from cadra.synthetic.simulate import simulate_shot
    from cadra.validation.gap_cases import shot_spec
    from cadra.validation.gap_measure import measure

    spec = shot_spec("sphere_2")
    sim = simulate_shot(spec)
    row, ch = 6, 1                               # station 7, channel y
    sd0 = measure(sim, sim.rigid.with_effects(Effects()), spec, None, None)
    b = 5.0 * sd0.sigma[row, ch]

    def edit(m):
        m[row, ch] += b
        return m

    sd = measure(sim, sim.rigid.with_effects(Effects()), spec, None, edit)
    res, _ = fit_shots([sd], sim.model)
    assert res.converged
    st = int(sd.stations[row])
    cand = library_candidate(f"station {st} y bias", sim.model, [sd])
    ref = reference_noncentrality(res, [sd], cand, size=b)
    rr = res.residuals
    lev = float(rr.loc[(rr["station"] == st) & (rr["channel"] == "y"), "leverage"].iloc[0])
    expected = (1.0 - lev) / sd.sigma[row, ch] ** 2
    assert ref["k"] == 1
    # (they agree to ~1e-12; 1e-6 leaves room for the solver's convergence, while a wrong
    # weight, mask or projection would be off by a large factor)
    assert math.isclose(ref["lambda_cand"], expected, rel_tol=1e-6)
    assert math.isclose(ref["coverage"], 1.0, rel_tol=1e-6)
