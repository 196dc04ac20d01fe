"""Round trips and sign facts of docs/conventions.md (cadra.conventions)."""

import numpy as np
import pytest

from cadra import conventions as cv

RNG = np.random.default_rng(20261122)


def random_quats(n):
    q = RNG.normal(size=(n, 4))
    return [cv.quat_normalize(x) for x in q]


def test_quaternion_matrix_round_trip():
    for q in random_quats(200):
        R = cv.quat_to_matrix(q)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
        assert np.allclose(cv.matrix_to_quat(R), q, atol=1e-13)


def test_euler_round_trip_and_meaning():
    for _ in range(200):
        yaw, pitch, roll = RNG.uniform(-3.1, 3.1), RNG.uniform(-1.5, 1.5), RNG.uniform(-3.1, 3.1)
        q = cv.euler_to_quat(yaw, pitch, roll)
        assert np.allclose(cv.quat_to_euler(q), (yaw, pitch, roll), atol=1e-12)
    # pure pitch up by 10 deg: nose axis rises in the facility frame (z up)
    a = cv.axis_from_quat(cv.euler_to_quat(0.0, np.radians(10), 0.0))
    assert a[2] == pytest.approx(np.sin(np.radians(10)))
    # aircraft yaw to the right (starboard) swings the nose to -y_F (starboard)
    a = cv.axis_from_quat(cv.euler_to_quat(np.radians(5), 0.0, 0.0))
    assert a[1] < 0


def test_identity_attitude_is_upright_level():
    R = cv.body_to_facility_matrix(np.array([1.0, 0, 0, 0]))
    # x_b downrange, y_b starboard (-y_F), z_b down (-z_F)
    assert np.allclose(R, np.diag([1.0, -1.0, -1.0]))


def test_inclinations_round_trip():
    for _ in range(500):
        theta, psi = RNG.uniform(-0.7, 0.7, size=2)
        a = cv.axis_from_inclinations(theta, psi)
        assert np.linalg.norm(a) == pytest.approx(1.0)
        assert np.allclose(cv.inclinations_from_axis(a), (theta, psi), atol=1e-14)
        tp, pp = cv.projected_angles_from_axis(a)
        assert np.allclose(cv.axis_from_projected_angles(tp, pp), a, atol=1e-14)


def test_quat_from_axis_roll_round_trip():
    for _ in range(200):
        theta, psi, roll = RNG.uniform(-0.6, 0.6), RNG.uniform(-0.6, 0.6), RNG.uniform(-3, 3)
        a = cv.axis_from_inclinations(theta, psi)
        q = cv.quat_from_axis_roll(a, roll)
        assert np.allclose(cv.axis_from_quat(q), a, atol=1e-14)
        assert cv.quat_to_euler(q)[2] == pytest.approx(roll, abs=1e-12)


def test_inclination_signs_follow_seed_004():
    # nose up -> theta > 0; nose to port (+y_F) -> psi > 0
    assert cv.inclinations_from_axis([1.0, 0.0, 0.1])[0] > 0
    assert cv.inclinations_from_axis([1.0, 0.1, 0.0])[1] > 0


def test_aero_angles_round_trip_and_signs():
    for _ in range(300):
        V = RNG.uniform(50, 500)
        alpha, beta = RNG.uniform(-1.2, 1.2), RNG.uniform(-1.2, 1.2)
        v = cv.velocity_from_aero_angles(V, alpha, beta)
        a, b, s = cv.aero_angles(v)
        assert (a, b) == (pytest.approx(alpha, abs=1e-12), pytest.approx(beta, abs=1e-12))
        assert np.cos(s) == pytest.approx(np.cos(alpha) * np.cos(beta), abs=1e-12)
    # model pitched nose-up 5 deg flying level along +x_F: alpha = +5 deg
    q = cv.euler_to_quat(0.0, np.radians(5), 0.0)
    v_body = cv.quat_to_matrix(q).T @ (cv.FLIP @ np.array([100.0, 0, 0]))
    assert np.degrees(cv.aero_angles(v_body)[0]) == pytest.approx(5.0)
    # nose yawed to port (psi > 0) flying along +x_F: beta > 0 (same sense as psi)
    q = cv.quat_from_axis_roll(cv.axis_from_inclinations(0.0, np.radians(4)))
    v_body = cv.quat_to_matrix(q).T @ (cv.FLIP @ np.array([100.0, 0, 0]))
    assert np.degrees(cv.aero_angles(v_body)[1]) == pytest.approx(4.0)


def test_model_axes_to_body():
    I_model = np.array([[10.0, 0.3, -0.2], [0.3, 8.0, 0.1], [-0.2, 0.1, 8.5]])
    I_body = cv.model_to_body_inertia(I_model)
    assert I_body[0, 1] == -0.3 and I_body[0, 2] == 0.2 and I_body[1, 2] == 0.1
    # cg below the axis in model axes (z up) is +z_b (down)
    assert cv.model_to_body_vector([0.0, 0.0, -0.173])[2] == pytest.approx(0.173)
    assert np.allclose(cv.model_to_body_inertia(I_body), I_model)
