"""Two-view combination against exact geometry (cadra.imaging.combine)."""

import numpy as np
import pytest

from cadra.conventions import axis_from_inclinations, projected_angles_from_axis
from cadra.imaging.combine import ViewPose, combine_views

RNG = np.random.default_rng(7)


def _assert_scatter(draws, sigmas, rel=0.06):
    """Each column of the Monte Carlo ``draws`` scatters by its propagated sigma (4000 draws:
    the standard deviation's own error is 1.1 %)."""
    draws = np.array(draws)
    for j, sigma in enumerate(sigmas):
        assert np.std(draws[:, j]) == pytest.approx(sigma, rel=rel), j


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
    _assert_scatter(draws, (st.sigma_x_m, st.sigma_theta_rad, st.sigma_psi_rad))
    # x mean is inverse-variance weighted
    assert st.sigma_x_m == pytest.approx(1 / np.sqrt(1 / 3e-6**2 + 1 / 5e-6**2))


def test_ray_intersection_gives_the_weighted_mean_of_x():
    """Combining through the projections' rays gives, for the two orthogonal parallel views,
    the numbers of the inverse-variance mean of x (y from the top view, z from the side)."""
    for _ in range(300):
        s = RNG.uniform(1e-6, 1e-5, 4)
        x_top, x_side = RNG.uniform(0, 22) + RNG.normal(0, 1e-5, 2)
        top = ViewPose(x_top, RNG.normal(0, 0.03), 0.1, s[0], s[1], 1e-4)
        side = ViewPose(x_side, RNG.normal(0, 0.03), -0.2, s[2], s[3], 1e-4)
        st = combine_views(top, side)
        w_t, w_s = 1 / s[0]**2, 1 / s[2]**2
        assert st.x_m == pytest.approx((w_t * x_top + w_s * x_side) / (w_t + w_s), rel=1e-15)
        assert (st.y_m, st.z_m) == pytest.approx((top.b_m, side.b_m), rel=1e-15)  # (b w) / w
        assert st.sigma_x_m == pytest.approx(1 / np.sqrt(w_t + w_s), rel=1e-15)
        assert (st.sigma_y_m, st.sigma_z_m) == pytest.approx((s[1], s[3]), rel=1e-15)
        assert st.x_top_minus_side_m == x_top - x_side
        assert st.x_consistency_sigma == pytest.approx(
            abs(x_top - x_side) / np.hypot(s[0], s[2]), rel=1e-9)


def test_views_with_their_own_projections_recover_an_exact_pose():
    """Through each view's projection: the facility's top view and a side view whose plane is
    turned 20 deg about x (not a coordinate plane) recover position and attitude exactly."""
    from cadra.optics.projection import ParallelProjection

    c, s = np.cos(0.35), np.sin(0.35)
    views = {"top": ParallelProjection(np.array([[1.0, 0, 0], [0, 1.0, 0]]), np.eye(2, 3)),
             "side": ParallelProjection(np.array([[1.0, 0, 0], [0, -s, c]]), np.eye(2, 3))}
    for _ in range(50):
        r = RNG.normal(0, 0.03, 3) + [RNG.uniform(0, 22), 0, 0]
        theta, psi = RNG.uniform(-0.5, 0.5, 2)
        a = axis_from_inclinations(theta, psi)
        poses = {}
        for name, proj in views.items():
            ab = proj.plane_point(r)
            pa = proj.plane_basis @ a
            poses[name] = ViewPose(ab[0], ab[1], np.arctan2(pa[1], pa[0]), 2e-6, 2e-6, 1e-4,
                                   projection=proj)
        st = combine_views(poses["top"], poses["side"])
        assert (st.x_m, st.y_m, st.z_m) == pytest.approx(tuple(r), abs=1e-12)
        assert (st.theta_rad, st.psi_rad) == pytest.approx((theta, psi), abs=1e-13)
        assert st.x_consistency_sigma < 1e-6


def test_tilt_error_propagation_matches_monte_carlo():
    """A view's template tilt comes from the other view's angle: its error moves the view's
    reference point by tilt_sensitivity x (tilt error). Simulated here as the measurement
    does it: the true tilts from the true angles, each view's position shifted by its
    sensitivity times the error of the tilt the measured angles give (view_tilts)."""
    from cadra.imaging.combine import view_tilts

    theta, psi = 0.5, -0.1
    theta_p, psi_p = projected_angles_from_axis(axis_from_inclinations(theta, psi))
    s_a, s_b, s_ang = 2e-7, 2e-7, 2.6e-5
    sens_top, sens_side = (-7e-3, -8e-4, 0.0), (1e-3, 2e-4, 0.0)
    true_tilts = view_tilts(theta_p, psi_p)
    st = combine_views(ViewPose(1.0, 0.01, psi_p, s_a, s_b, s_ang, tilt_sensitivity=sens_top),
                       ViewPose(1.0, -0.02, theta_p, s_a, s_b, s_ang,
                                tilt_sensitivity=sens_side))
    plain = combine_views(ViewPose(1.0, 0.01, psi_p, s_a, s_b, s_ang),
                          ViewPose(1.0, -0.02, theta_p, s_a, s_b, s_ang))
    assert st.sigma_x_m > 1.1 * plain.sigma_x_m      # the term matters at these sizes
    draws = []
    for _ in range(4000):
        e_t, e_s = RNG.normal(0, s_ang, 2)
        tilts = view_tilts(theta_p + e_s, psi_p + e_t)
        d_top = np.array(sens_top) * (tilts[0] - true_tilts[0])
        d_side = np.array(sens_side) * (tilts[1] - true_tilts[1])
        t = ViewPose(1.0 + d_top[0] + RNG.normal(0, s_a), 0.01 + d_top[1] + RNG.normal(0, s_b),
                     psi_p + e_t, s_a, s_b, s_ang, tilt_sensitivity=sens_top)
        s = ViewPose(1.0 + d_side[0] + RNG.normal(0, s_a),
                     -0.02 + d_side[1] + RNG.normal(0, s_b), theta_p + e_s, s_a, s_b, s_ang,
                     tilt_sensitivity=sens_side)
        c = combine_views(t, s)
        draws.append((c.x_m, c.y_m, c.z_m))
    _assert_scatter(draws, (st.sigma_x_m, st.sigma_y_m, st.sigma_z_m))
