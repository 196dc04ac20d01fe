"""cadra.motion: Nonplanar Ratio, Murphy's cubic correlator and seed 002's nonrolling-axis
correction.

Truths: planar and circular motion (NPR 0 and 1 by definition), solve_ivp of a spinning body
with a cubic pitching moment (the correlator's frequency relation), and a numerically
parallel-transported (nonrolling) frame (the sign and value of seed 002 eq. 8).
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cadra.motion import (
    cubic_correlator,
    fit_epicyclic,
    fixed_plane_angles,
    nonplanar_ratio,
    nonplanar_ratio_of_fit,
    nonrolling_angle,
)


def test_npr_is_zero_for_planar_motion():
    t = np.linspace(0.0, 3.0, 3001)
    r = 0.2 * np.exp(-0.3 * t) * np.cos(9.0 * t + 0.3)
    dr = 0.2 * np.exp(-0.3 * t) * (-0.3 * np.cos(9.0 * t + 0.3) - 9.0 * np.sin(9.0 * t + 0.3))
    plane = np.exp(0.7j)
    npr = nonplanar_ratio(t, r * plane, dr * plane)
    assert npr.npr == pytest.approx(0.0, abs=1e-12)
    assert npr.seed_ratio == pytest.approx(0.0, abs=1e-12)


def test_npr_is_one_for_circular_motion():
    t = np.linspace(0.0, 3.0, 3001)
    xi = 0.1 * np.exp(1j * (7.0 * t + 0.2))
    npr = nonplanar_ratio(t, xi, 7.0j * xi)
    assert npr.npr == pytest.approx(1.0, abs=1e-12)
    assert npr.seed_ratio > 1e10          # eq. 18 as printed: coning over a zero pitch rate


def test_npr_of_fitted_planar_and_circular_histories():
    t = np.linspace(0.0, 2.0, 200)
    rng = np.random.default_rng(1)
    planar = 0.15 * np.exp(-0.2 * t) * np.cos(11.0 * t) * np.exp(0.4j)
    fit = fit_epicyclic(t, planar.imag + rng.normal(0, 1e-4, t.size),
                        planar.real + rng.normal(0, 1e-4, t.size))
    fine = np.linspace(0.0, 2.0, 4001)
    npr = nonplanar_ratio(fine, fit.predict(fine), fit.predict(fine, derivative=True)).npr
    assert npr < 0.01
    mixed = 0.1 * np.exp(11j * t) + 0.03 * np.exp(-4j * t)
    fit = fit_epicyclic(t, mixed.imag, mixed.real)
    npr = nonplanar_ratio(fine, fit.predict(fine), fit.predict(fine, derivative=True)).npr
    assert 0.3 < npr < 1.0
    # the trim arm is left out: a planar motion plus a trim arm still reads planar
    trimmed = planar + 0.02 * np.exp(1j * (25.0 * t + 0.5))
    fit = fit_epicyclic(t, trimmed.imag, trimmed.real, trim_rate=25.0)
    assert nonplanar_ratio_of_fit(fit, 0.0, 2.0).npr < 1e-6
    assert nonplanar_ratio(fine, fit.predict(fine), fit.predict(fine, True)).npr > 0.05


def test_npr_bad_input():
    t = np.linspace(0, 1, 10)
    with pytest.raises(ValueError, match="^dxi"):
        nonplanar_ratio(t, np.ones(10, complex), np.ones(9, complex))
    with pytest.raises(ValueError, match="^s"):
        nonplanar_ratio(t[::-1], np.ones(10, complex), np.ones(10, complex))


def test_cubic_correlator_planar_is_three_quarters_amplitude_squared():
    K = 0.3
    c = cubic_correlator(K / 2, K / 2, 10.0, -10.0)
    assert c.delta_e_sq == pytest.approx(0.75 * K * K, rel=1e-14)
    assert c.mean_square == pytest.approx(K * K / 2, rel=1e-14)
    with pytest.raises(ValueError, match="^omega1"):
        cubic_correlator(0.1, 0.1, 3.0, 3.0)


def test_cubic_correlator_reproduces_the_integrated_frequencies():
    """Spinning body, C_m = C α + K α³, no damping: ω_1ω_2 = M_0 + M_2 δ_e² (seed 002 eq. 9),
    while the mean square δ² misses the nonlinear part by tens of per cent."""
    P, M0, M2 = 40.0, -900.0, 2000.0

    def rhs(_, y):
        x, v = y[0] + 1j * y[1], y[2] + 1j * y[3]
        acc = 1j * P * v + (M0 + M2 * abs(x) ** 2) * x
        return [v.real, v.imag, acc.real, acc.imag]

    t = np.linspace(0.0, 0.8, 800)
    sol = solve_ivp(rhs, (0, 0.8), [0.15, 0.0, 0.0, 4.0], t_eval=t, method="DOP853",
                    rtol=1e-11, atol=1e-13)
    xi = sol.y[0] + 1j * sol.y[1]
    fit = fit_epicyclic(t, xi.imag, xi.real)
    a1, a2 = fit.arm(1), fit.arm(2)
    c = cubic_correlator(a1.K, a2.K, a1.omega, a2.omega)
    nonlinear = a1.omega * a2.omega - M0
    assert nonlinear / (M2 * c.delta_e_sq) == pytest.approx(1.0, abs=0.05)
    assert abs(nonlinear / (M2 * c.mean_square) - 1.0) > 0.2


# ------------------------------------------------------------------ nonrolling axes (eq. 8)

def _axes(t):
    psi, psid = 0.25 * np.sin(5.0 * t), 1.25 * np.cos(5.0 * t)
    th, thd = 0.2 * np.cos(3.0 * t) + 0.05, -0.6 * np.sin(3.0 * t)
    n = np.array([np.cos(th) * np.cos(psi), np.cos(th) * np.sin(psi), np.sin(th)])
    nd = np.array([-np.sin(th) * thd * np.cos(psi) - np.cos(th) * np.sin(psi) * psid,
                   -np.sin(th) * thd * np.sin(psi) + np.cos(th) * np.cos(psi) * psid,
                   np.cos(th) * thd])
    e2 = np.array([-np.sin(psi), np.cos(psi), 0.0 * t])
    return n, nd, e2, np.cross(n, e2, axis=0)


def test_eq8_matches_a_parallel_transported_frame():
    t = np.linspace(0.0, 3.0, 3001)
    n0, _, e20, e30 = _axes(np.array([0.0]))

    def rhs(tt, y):           # de/dt = -(e · ṅ) n: no rotation about the axis
        n, nd, _, _ = (a[:, 0] for a in _axes(np.array([tt])))
        e2, e3 = y[:3], y[3:]
        return np.r_[-(e2 @ nd) * n, -(e3 @ nd) * n]

    sol = solve_ivp(rhs, (0, 3), np.r_[e20[:, 0], e30[:, 0]], t_eval=t, method="DOP853",
                    rtol=1e-12, atol=1e-13)
    e2n, e3n = sol.y[:3], sol.y[3:]
    _, _, e2f, e3f = _axes(t)
    zeta_nr = -(e2n[0] + 1j * e3n[0])          # sin β + i sin α of the stream along +x
    zeta_f = -(e2f[0] + 1j * e3f[0])
    xi_f = np.arcsin(zeta_f.real) + 1j * np.arcsin(zeta_f.imag)

    def xf(q):
        _, _, a, b = _axes(q)
        z = -(a[0] + 1j * b[0])
        return np.arcsin(z.real) + 1j * np.arcsin(z.imag)

    def dxf(q, h=1e-6):
        return (xf(q + h) - xf(q - h)) / (2 * h)

    phi = nonrolling_angle(t, xf, dxf)
    assert np.max(np.abs(zeta_nr - np.exp(1j * phi) * zeta_f)) < 1e-6
    assert np.max(np.abs(phi)) > 0.01          # the correction is not trivially small here
    # and the fixed-plane angles from the projected (vertical, horizontal) angles, eqs. 6-7
    n, _, _, _ = _axes(t)
    a_f, b_f = fixed_plane_angles(np.arctan2(n[2], n[0]), np.arctan2(n[1], n[0]))
    assert np.allclose(b_f + 1j * a_f, xi_f, atol=1e-12)


def _fixed_plane_from_nonrolling(t, xi_nr, dxi_nr):
    """Integrate eq. 8 forward: the fixed-plane angles of a motion that is exactly epicyclic
    in nonrolling axes."""
    def z_nr(q):
        x = xi_nr(q)
        return np.sin(x.real) + 1j * np.sin(x.imag)

    def dz_nr(q):
        x, dx = xi_nr(q), dxi_nr(q)
        return np.cos(x.real) * dx.real + 1j * np.cos(x.imag) * dx.imag

    def rhs(q, y):
        e = np.exp(-1j * y[0])
        zf = e * z_nr(q)
        u, v = e * dz_nr(q), -1j * e * z_nr(q)
        k = zf.imag / (1 - zf.real**2)
        return [k * u.real / (1 - k * v.real)]

    sol = solve_ivp(rhs, (t[0], t[-1]), [0.0], t_eval=t, method="DOP853", rtol=1e-12,
                    atol=1e-14)
    zf = np.exp(-1j * sol.y[0]) * z_nr(t)
    return np.arcsin(zf.imag), np.arcsin(zf.real)


def test_nonrolling_correction_in_the_fit_recovers_the_nonrolling_epicycle():
    t = np.linspace(0.0, 1.0, 200)
    arms = [(0.25, 0.0, -0.3, 20.0), (0.15, 1.0, -0.5, -6.0)]

    def xi(q):
        return sum(K * np.exp(1j * ph + (lam + 1j * om) * q) for K, ph, lam, om in arms)

    def dxi(q):
        return sum(K * (lam + 1j * om) * np.exp(1j * ph + (lam + 1j * om) * q)
                   for K, ph, lam, om in arms)

    a_f, b_f = _fixed_plane_from_nonrolling(t, xi, dxi)
    plain = fit_epicyclic(t, a_f, b_f)
    nr = fit_epicyclic(t, a_f, b_f, nonrolling=True, nonrolling_iterations=3)
    exact = fit_epicyclic(t, xi(t).imag, xi(t).real)
    assert plain.rms > 1e-3
    assert nr.rms < 0.02 * plain.rms
    for j, (_, _, lam, om) in enumerate(arms, start=1):
        assert abs(nr.arm(j).omega - om) < 0.05 * abs(plain.arm(j).omega - om) + 1e-6
        assert nr.arm(j).lam == pytest.approx(lam, abs=1e-3)
        assert exact.arm(j).lam == pytest.approx(lam, rel=1e-9)
