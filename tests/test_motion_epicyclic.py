"""cadra.motion epicyclic/tricyclic fits and linear-theory coefficients.

Truths: the analytic epicycle (noise-free recovery to 1e-6), Gaussian noise draws (pulls),
and scipy's solve_ivp of the linear angular equation (seed 000 eq. 2, seed 001 eq. 32) and of
free flight with lift, whose exact root relations the coefficient formulas invert.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cadra.motion import FlightConditions, fit_epicyclic, lift_from_swerve, linear_coefficients
from cadra.numfmt import pm
from cadra.report.motion import coefficients_report, fit_report

ARMS = [(0.10, 0.3, -0.5, 12.0), (0.05, -1.0, -0.8, 3.0)]   # K (rad), phase, λ (1/s), ω (rad/s)
TRIM = (0.01, 0.2, 30.0)                                     # K_t, phase, p


def epicycle(t, arms=ARMS, trim=TRIM, omega_dot=(0.0, 0.0)):
    xi = sum(K * np.exp(1j * ph) * np.exp((lam + 1j * om) * t + 0.5j * od * t * t)
             for (K, ph, lam, om), od in zip(arms, omega_dot, strict=True))
    if trim is not None:
        xi = xi + trim[0] * np.exp(1j * (trim[2] * t + trim[1]))
    return xi


def check_arms(fit, arms, rtol):
    for j, (K, ph, lam, om) in enumerate(arms, start=1):
        a = fit.arm(j)
        assert a.K == pytest.approx(K, rel=rtol)
        assert a.phase == pytest.approx(ph, rel=rtol, abs=rtol)
        assert a.lam == pytest.approx(lam, rel=rtol)
        assert a.omega == pytest.approx(om, rel=rtol)


def test_noise_free_tricyclic_10_constant_recovered_to_1e6():
    t = np.linspace(0.0, 2.0, 200)
    xi = epicycle(t)
    fit = fit_epicyclic(t, xi.imag, xi.real, trim_rate=TRIM[2])
    assert len(fit.names) == 10
    check_arms(fit, ARMS, 1e-6)
    trim = fit.arm(0)
    assert trim.K == pytest.approx(TRIM[0], rel=1e-6)
    assert trim.phase == pytest.approx(TRIM[1], rel=1e-6)
    assert fit.rms < 1e-9


def test_noise_free_12_constant_and_uneven_sampling_recovered_to_1e6():
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 2.0, 150))
    xi = epicycle(t, omega_dot=(0.8, -0.3))
    fit = fit_epicyclic(t, xi.imag, xi.real, trim_rate=TRIM[2], curvature=True, s_ref=0.0)
    assert len(fit.names) == 12
    check_arms(fit, ARMS, 1e-6)
    assert fit.arm(1).omega_dot == pytest.approx(0.8, rel=1e-6)
    assert fit.arm(2).omega_dot == pytest.approx(-0.3, rel=1e-6)


def test_the_10_constant_form_misses_a_chirp_the_12_constant_form_takes():
    t = np.linspace(0.0, 2.0, 200)
    xi = epicycle(t, omega_dot=(0.8, -0.3))
    ten = fit_epicyclic(t, xi.imag, xi.real, trim_rate=TRIM[2])
    twelve = fit_epicyclic(t, xi.imag, xi.real, trim_rate=TRIM[2], curvature=True)
    assert ten.rms > 1e-3 and twelve.rms < 1e-9


def test_pulls_over_50_noise_draws_are_honest():
    t = np.linspace(0.0, 2.0, 200)
    xi = epicycle(t)
    rng = np.random.default_rng(2026)
    sig = np.radians(0.3)
    truth = {"lambda1": -0.5, "omega1": 12.0, "lambda2": -0.8, "omega2": 3.0}
    pulls = {k: [] for k in truth}
    for _ in range(50):
        n = rng.normal(0.0, sig, (2, t.size))
        fit = fit_epicyclic(t, xi.imag + n[0], xi.real + n[1], trim_rate=TRIM[2])
        assert fit.covariance_scaled
        for k, v in truth.items():
            pulls[k].append((fit.value(k) - v) / fit.sigma(k))
    for k, p in pulls.items():
        assert 0.7 <= np.std(p) <= 1.4, (k, np.std(p))
        assert abs(np.mean(p)) < 0.5, (k, np.mean(p))


def test_correlation_matrix_and_reported_chi2():
    t = np.linspace(0.0, 2.0, 200)
    xi = epicycle(t)
    rng = np.random.default_rng(5)
    sig = 0.002
    n = rng.normal(0.0, sig, (2, t.size))
    fit = fit_epicyclic(t, xi.imag + n[0], xi.real + n[1], sig, sig, trim_rate=TRIM[2])
    assert np.allclose(np.diag(fit.correlation), 1.0)
    assert np.allclose(fit.correlation, fit.correlation.T)
    assert fit.dof == 2 * t.size - 10
    assert 0.8 < fit.chi2_dof < 1.2          # the sigmas given are the noise's
    assert fit.rms == pytest.approx(sig * np.sqrt(2), rel=0.1)


@pytest.mark.parametrize("kwargs, word", [
    (dict(s=np.linspace(0, 1, 4)), "s"),
    (dict(alpha=np.r_[np.nan, np.zeros(39)]), "alpha"),
    (dict(beta=np.zeros(39)), "beta"),
    (dict(sigma_alpha=np.zeros(40)), "sigma_alpha"),
    (dict(s=np.r_[np.linspace(0, 1, 39), 0.5]), "s"),
    (dict(arms=3), "arms"),
    (dict(nonrolling=True, nonrolling_iterations=0), "nonrolling_iterations"),
    (dict(trim_rate=float("nan")), "trim_rate"),
])
def test_bad_input_names_the_argument(kwargs, word):
    args = dict(s=np.linspace(0, 1, 40), alpha=np.zeros(40), beta=np.zeros(40))
    args.update(kwargs)
    with pytest.raises(ValueError, match=rf"^{word}\b"):
        fit_epicyclic(args.pop("s"), args.pop("alpha"), args.pop("beta"), **args)


def test_an_arm_the_data_do_not_determine_gets_an_infinite_sigma():
    """Circular motion fitted with two arms (seed 002's footnote: the tricyclic program
    cannot take it): the empty arm's rate and frequency are reported undetermined."""
    t = np.linspace(0.0, 2.0, 200)
    xi = 0.1 * np.exp(0.3j + (-0.1 + 12j) * t)
    fit = fit_epicyclic(t, xi.imag, xi.real)
    assert fit.arm(1).omega == pytest.approx(12.0, rel=1e-9)
    assert np.isfinite(fit.arm(1).omega_sigma) and np.isfinite(fit.arm(1).lam_sigma)
    assert fit.arm(2).K < 1e-12
    assert np.isinf(fit.arm(2).omega_sigma) and np.isinf(fit.arm(2).lam_sigma)
    one = fit_epicyclic(t, xi.imag, xi.real, arms=1)
    assert one.arm(1).omega == pytest.approx(12.0, rel=1e-9)
    assert np.all(np.isfinite(one.sigmas))


# ------------------------------------------------------------------ coefficients vs solve_ivp

COND = FlightConditions(mass_kg=1.0, Ix_kg_m2=1.0e-3, I_kg_m2=5.0e-3, d_m=0.05,
                        density_kg_m3=1.2, speed_m_s=50.0, spin_rad_s=150.0)
CM_ALPHA, CMQ, CMAD, CMPA, CLA = -3.0, -12.0, -4.0, 0.8, 2.5


def simulate(cond, t, lift: bool):
    """Axis θ_c, flight path γ_c and lateral position Z (complex, + port + up), ξ = θ_c − γ_c."""
    c = cond
    qsd, d2v = c.q_inf * c.S * c.d_m, c.d_m / (2 * c.speed_m_s)
    a = c.density_kg_m3 * c.S * c.speed_m_s * CLA / (2 * c.mass_kg) if lift else 0.0
    p = c.spin_rad_s

    def rhs(_, y):
        th, thd, ga, _ = (y[0] + 1j * y[1], y[2] + 1j * y[3], y[4] + 1j * y[5], y[6] + 1j * y[7])
        xi = th - ga
        gad = a * xi
        xid = thd - gad
        mom = qsd * (CM_ALPHA * xi + d2v * (CMQ * thd + CMAD * xid) + 1j * p * d2v * CMPA * xi)
        thdd = (mom + 1j * p * c.Ix_kg_m2 * thd) / c.I_kg_m2
        Zd = c.speed_m_s * ga
        out = [thd, thdd, gad, Zd]
        return [v for z in out for v in (z.real, z.imag)]

    y0 = [0.05, 0.02, 0.0, 3.0, 0, 0, 0, 0]
    sol = solve_ivp(rhs, (t[0], t[-1]), y0, t_eval=t, method="DOP853", rtol=1e-12, atol=1e-14)
    th, ga, Z = sol.y[0] + 1j * sol.y[1], sol.y[4] + 1j * sol.y[5], sol.y[6] + 1j * sol.y[7]
    return th - ga, Z


def test_linear_coefficients_recover_the_integrated_gimbal_motion():
    t = np.linspace(0.0, 1.5, 400)
    xi, _ = simulate(COND, t, lift=False)
    fit = fit_epicyclic(t, xi.imag, xi.real)
    lc = linear_coefficients(fit, COND)
    assert lc.Cm_alpha == pytest.approx(CM_ALPHA, rel=1e-6)
    assert lc.Cmq_sum == pytest.approx(CMQ + CMAD, rel=1e-6)
    assert lc.Cm_p_alpha == pytest.approx(CMPA, rel=1e-6)
    assert lc.spin_from_fit == pytest.approx(COND.spin_rad_s, rel=1e-6)


def test_free_flight_lift_from_swerve_and_the_lift_terms():
    t = np.linspace(0.0, 1.5, 400)
    xi, Z = simulate(COND, t, lift=True)
    fit = fit_epicyclic(t, xi.imag, xi.real)
    sw = lift_from_swerve(fit, t, Z.real, Z.imag, conditions=COND)
    assert sw.C_L_alpha == pytest.approx(CLA, rel=1e-5)
    with_lift = linear_coefficients(fit, COND, lift=(sw.C_L_alpha, sw.C_L_alpha_sigma))
    angular_only = linear_coefficients(fit, COND)
    assert with_lift.Cmq_sum == pytest.approx(CMQ + CMAD, rel=1e-4)
    assert with_lift.Cm_p_alpha == pytest.approx(CMPA, rel=1e-4)
    # the neglected M_q a / I term: |C_mq d a/(2V C_mα)| ≈ 1e-3
    assert with_lift.Cm_alpha == pytest.approx(CM_ALPHA, rel=3e-3)
    assert abs(angular_only.Cmq_sum - (CMQ + CMAD)) > 0.5     # lift matters to the damping
    chained = linear_coefficients(fit, COND, swerve=(t, Z.real, Z.imag))
    assert chained.C_L_alpha == sw.C_L_alpha and chained.Cmq_sum == with_lift.Cmq_sum


def test_coefficient_sigmas_are_honest_over_noise_draws():
    t = np.linspace(0.0, 1.5, 300)
    xi, _ = simulate(COND, t, lift=False)
    rng = np.random.default_rng(11)
    pulls = []
    for _ in range(30):
        n = rng.normal(0.0, np.radians(0.2), (2, t.size))
        lc = linear_coefficients(fit_epicyclic(t, xi.imag + n[0], xi.real + n[1]), COND)
        pulls.append([(lc.Cm_alpha - CM_ALPHA) / lc.Cm_alpha_sigma,
                      (lc.Cmq_sum - CMQ - CMAD) / lc.Cmq_sum_sigma,
                      (lc.Cm_p_alpha - CMPA) / lc.Cm_p_alpha_sigma])
    sd = np.std(pulls, axis=0)
    assert np.all((sd > 0.6) & (sd < 1.5)), sd


def test_distance_fits_need_the_drag_coefficient():
    t = np.linspace(0.0, 1.5, 200)
    xi, _ = simulate(COND, t, lift=False)
    fit = fit_epicyclic(t * COND.speed_m_s, xi.imag, xi.real, variable="distance")
    with pytest.raises(ValueError, match="^conditions"):
        linear_coefficients(fit, COND)


def test_distance_fit_with_drag_recovers_the_decelerating_flight():
    """No spin, V falling by drag (V̇ = −k_D V², k_D = ρSC_D/2m): the motion is linear with
    constant coefficients in distance, and the reduction must add Murphy's drag term."""
    c = FlightConditions(mass_kg=0.2, Ix_kg_m2=1.0e-4, I_kg_m2=5.0e-4, d_m=0.05,
                         density_kg_m3=1.2, speed_m_s=300.0, drag_coefficient=0.9)
    kD = c.density_kg_m3 * c.S * c.drag_coefficient / (2 * c.mass_kg)
    kL = c.density_kg_m3 * c.S * CLA / (2 * c.mass_kg)

    def rhs(_, y):
        th, thd, ga, V = y[0] + 1j * y[1], y[2] + 1j * y[3], y[4] + 1j * y[5], y[8]
        xi = th - ga
        gad = kL * V * xi
        q = 0.5 * c.density_kg_m3 * V * V * c.S * c.d_m
        mom = q * (CM_ALPHA * xi + c.d_m / (2 * V) * (CMQ * thd + CMAD * (thd - gad)))
        Zd = V * ga
        out = [thd, mom / c.I_kg_m2, gad, Zd]
        return [v for z in out for v in (z.real, z.imag)] + [-kD * V * V, V]

    t = np.linspace(0.0, 0.25, 300)
    y0 = [0.05, 0.02, 0.0, 3.0, 0, 0, 0, 0, c.speed_m_s, 0.0]
    sol = solve_ivp(rhs, (0, t[-1]), y0, t_eval=t, method="DOP853", rtol=1e-12, atol=1e-14)
    x = sol.y[9]
    xi = (sol.y[0] - sol.y[4]) + 1j * (sol.y[1] - sol.y[5])
    assert sol.y[8][-1] < 0.9 * c.speed_m_s                  # a real deceleration
    fit = fit_epicyclic(x, xi.imag, xi.real, variable="distance")
    sw = lift_from_swerve(fit, x, sol.y[6], sol.y[7], conditions=c)
    assert sw.C_L_alpha == pytest.approx(CLA, rel=1e-4)
    lc = linear_coefficients(fit, c, lift=(sw.C_L_alpha, sw.C_L_alpha_sigma))
    assert lc.Cmq_sum == pytest.approx(CMQ + CMAD, rel=1e-3)
    assert lc.Cm_alpha == pytest.approx(CM_ALPHA, rel=3e-3)   # less the M_q a term, as above
    no_drag = FlightConditions(**{**c.__dict__, "drag_coefficient": 0.0})
    assert abs(linear_coefficients(fit, no_drag, lift=(CLA, 0.0)).Cmq_sum - lc.Cmq_sum) > 1.0


def test_reports_show_what_the_fit_stored():
    t = np.linspace(0.0, 1.5, 300)
    xi, _ = simulate(COND, t, lift=False)
    n = np.random.default_rng(8).normal(0.0, 0.003, (2, t.size))
    fit = fit_epicyclic(t, xi.imag + n[0], xi.real + n[1], scale_covariance=False)
    text = fit_report(fit, min_correlation=0.0)
    assert "epicyclic fit in time: 300 points, 8 constants" in text
    assert "formal covariance" in text
    a = fit.arm(2)
    assert f"ω {pm(a.omega, a.omega_sigma, 'rad/s')}" in text
    assert f"A1_re – lambda1: {fit.correlation[0, 2]:+.3f}" in text
    lc = linear_coefficients(fit, COND)
    assert f"C_mα        {pm(lc.Cm_alpha, lc.Cm_alpha_sigma)}" in coefficients_report(lc)


def test_automatic_starts_over_random_epicycles_and_range_like_records():
    """No user starts: 60 random two-arm motions (1-4 fast cycles, 16 to 100 points, even or
    uneven sampling, 0.2° noise) all converge to the truth (|pull| < 5 on both frequencies)."""
    rng = np.random.default_rng(5)
    sig = np.radians(0.2)
    for _ in range(60):
        n = int(rng.choice([16, 32, 100]))
        t = np.sort(rng.uniform(0, 1, n)) if rng.random() < 0.5 else np.linspace(0, 1, n)
        w1 = rng.uniform(2 * np.pi, 8 * np.pi)
        w2 = rng.uniform(-4 * np.pi, w1 - 1.6 * np.pi)
        lam = rng.uniform(-1.0, 0.3, 2)
        ph = rng.uniform(0, 2 * np.pi, 2)
        xi = (rng.uniform(0.05, 0.2) * np.exp(1j * ph[0] + (lam[0] + 1j * w1) * t)
              + rng.uniform(0.02, 0.1) * np.exp(1j * ph[1] + (lam[1] + 1j * w2) * t))
        e = rng.normal(0, sig, (2, n))
        fit = fit_epicyclic(t, xi.imag + e[0], xi.real + e[1], sig, sig)
        for j, w in ((1, w1), (2, w2)):
            assert abs(fit.arm(j).omega - w) < 5 * fit.arm(j).omega_sigma, (n, w1, w2)
