"""Two-view combination against exact geometry (cadra.measure.combine)."""

import numpy as np
import pytest

from cadra.conventions import axis_from_inclinations, projected_angles_from_axis
from cadra.measure.combine import ViewPose, combine_views

RNG = np.random.default_rng(7)


def test_combination_recovers_exact_pose():
    for _ in range(100):
        r = RNG.normal(0, 0.03, 3) + [RNG.uniform(0, 22), 0, 0]
        theta, psi = RNG.uniform(-0.6, 0.6, 2)
        theta_p, psi_p = projected_angles_from_axis(axis_from_inclinations(theta, psi))
        top = ViewPose(r[0], r[1], psi_p, 2e-6, 2e-6, 1e-4)
        side = ViewPose(r[0], r[2], theta_p, 2e-6, 2e-6, 1e-4)
        st = combine_views(top, side)
        assert (st.x_m, st.y_m, st.z_m) == pytest.approx(tuple(r), abs=1e-12)
        assert (st.theta_rad, st.psi_rad) == pytest.approx((theta, psi), abs=1e-14)
        assert st.x_top_minus_side_m == 0.0


def test_sigma_propagation_matches_monte_carlo():
    theta, psi = 0.4, -0.25
    theta_p, psi_p = projected_angles_from_axis(axis_from_inclinations(theta, psi))
    s_ang = 2e-4
    top = ViewPose(1.0, 0.01, psi_p, 3e-6, 2e-6, s_ang)
    side = ViewPose(1.0, -0.02, theta_p, 5e-6, 2e-6, s_ang)
    st = combine_views(top, side)
    draws = []
    for _ in range(4000):
        t = ViewPose(1.0 + RNG.normal(0, 3e-6), 0.01, psi_p + RNG.normal(0, s_ang), 3e-6, 2e-6,
                     s_ang)
        s = ViewPose(1.0 + RNG.normal(0, 5e-6), -0.02, theta_p + RNG.normal(0, s_ang), 5e-6,
                     2e-6, s_ang)
        c = combine_views(t, s)
        draws.append((c.x_m, c.theta_rad, c.psi_rad))
    draws = np.array(draws)
    assert np.std(draws[:, 0]) == pytest.approx(st.sigma_x_m, rel=0.06)
    assert np.std(draws[:, 1]) == pytest.approx(st.sigma_theta_rad, rel=0.06)
    assert np.std(draws[:, 2]) == pytest.approx(st.sigma_psi_rad, rel=0.06)
    # x mean is inverse-variance weighted
    assert st.sigma_x_m == pytest.approx(1 / np.sqrt(1 / 3e-6**2 + 1 / 5e-6**2))
