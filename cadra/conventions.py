"""Frames, attitude and angle conversions: the single home of every convention.

See ``docs/conventions.md`` for the definitions. Summary:

* facility frame F: x downrange, y port, z up; earth-aero frame E = diag(1, -1, -1) F;
* body frame B (Etkin): x nose, y starboard, z down; attitude quaternion ``q = (w, x, y, z)``
  rotates B into E (``v_E = R(q) v_B``);
* model axes M (file boundary): x nose, y port, z up with the model upright (seed 004 Table 2);
* measured inclinations theta = asin(a_z), psi = asin(a_y) of the nose axis ``a`` in F.

All functions are pure and work on plain floats / numpy arrays in SI units (radians).
"""

from __future__ import annotations

import numpy as np

#: F <-> E (and M <-> B) axis flip; its own inverse.
FLIP = np.diag([1.0, -1.0, -1.0])

G0 = 9.80665
"""Standard gravity, m/s^2."""


# --------------------------------------------------------------------------- quaternions


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion with non-negative scalar part (a canonical sign)."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n == 0.0:
        raise ValueError(f"quaternion {q!r} has no direction")
    q = q / n
    return -q if q[0] < 0 else q


def quat_mul(a, b):
    """Hamilton product of quaternions (w, x, y, z); complex-safe."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw])


def rotvec_quat(v) -> np.ndarray:
    """Unit quaternion of the rotation vector ``v`` (rad)."""
    v = np.asarray(v, dtype=float)
    a = float(np.linalg.norm(v))
    if a < 1e-300:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(a / 2)], np.sin(a / 2) * v / a])


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix R (3x3) of unit quaternion ``q = (w, x, y, z)``: ``v_E = R v_B``."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (scalar first, w >= 0) of a proper rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"rotation matrix must be 3x3, got {R.shape}")
    tr = np.trace(R)
    cands = np.array([tr, R[0, 0], R[1, 1], R[2, 2]])
    k = int(np.argmax(cands))
    if k == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
             (R[1, 0] - R[0, 1]) / (4 * w)]
    elif k == 1:
        x = 0.5 * np.sqrt(1.0 + 2 * R[0, 0] - tr)
        q = [(R[2, 1] - R[1, 2]) / (4 * x), x, (R[0, 1] + R[1, 0]) / (4 * x),
             (R[0, 2] + R[2, 0]) / (4 * x)]
    elif k == 2:
        y = 0.5 * np.sqrt(1.0 + 2 * R[1, 1] - tr)
        q = [(R[0, 2] - R[2, 0]) / (4 * y), (R[0, 1] + R[1, 0]) / (4 * y), y,
             (R[1, 2] + R[2, 1]) / (4 * y)]
    else:
        z = 0.5 * np.sqrt(1.0 + 2 * R[2, 2] - tr)
        q = [(R[1, 0] - R[0, 1]) / (4 * z), (R[0, 2] + R[2, 0]) / (4 * z),
             (R[1, 2] + R[2, 1]) / (4 * z), z]
    return quat_normalize(np.array(q))


def euler_to_quat(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Quaternion B->E from aircraft Euler angles (3-2-1: yaw about z_E, pitch, roll), rad."""
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    return quat_normalize(
        np.array(
            [
                cr * cp * cy + sr * sp * sy,
                sr * cp * cy - cr * sp * sy,
                cr * sp * cy + sr * cp * sy,
                cr * cp * sy - sr * sp * cy,
            ]
        )
    )


def quat_to_euler(q: np.ndarray) -> tuple[float, float, float]:
    """Aircraft Euler angles (yaw, pitch, roll), rad, of quaternion B->E.

    Pitch is in [-pi/2, pi/2].
    """
    R = quat_to_matrix(q)
    pitch = float(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
    yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    roll = float(np.arctan2(R[2, 1], R[2, 2]))
    return yaw, pitch, roll


def body_to_facility_matrix(q: np.ndarray) -> np.ndarray:
    """R_FB: ``v_F = R_FB v_B`` for attitude quaternion ``q`` (B->E)."""
    return FLIP @ quat_to_matrix(q)


# --------------------------------------------------------------------------- model axes


def model_to_body_vector(v_model: np.ndarray) -> np.ndarray:
    """Vector in model axes M (x nose, y port, z up) -> body axes B (x nose, y stbd, z down)."""
    return FLIP @ np.asarray(v_model, dtype=float)


def model_to_body_inertia(I_model: np.ndarray) -> np.ndarray:
    """Inertia tensor in model axes -> body axes (``D I D``)."""
    return FLIP @ np.asarray(I_model, dtype=float) @ FLIP


# --------------------------------------------------------------------------- measured angles


def axis_from_quat(q: np.ndarray) -> np.ndarray:
    """Unit nose axis ``a`` in facility axes F."""
    return body_to_facility_matrix(q)[:, 0]


def inclinations_from_axis(a_F: np.ndarray) -> tuple[float, float]:
    """(theta, psi), rad: inclination of the axis to the x-y plane (+up) and x-z plane (+port)."""
    a = np.asarray(a_F, dtype=float)
    a = a / np.linalg.norm(a)
    return float(np.arcsin(a[2])), float(np.arcsin(a[1]))


def axis_from_inclinations(theta: float, psi: float) -> np.ndarray:
    """Unit nose axis in F (with a_x > 0) from the inclinations (theta, psi), rad."""
    az, ay = np.sin(theta), np.sin(psi)
    ax2 = 1.0 - az * az - ay * ay
    if ax2 <= 0.0:
        raise ValueError(
            f"inclinations theta={np.degrees(theta):.3f} deg, psi={np.degrees(psi):.3f} deg "
            "do not describe a nose-forward axis (sin^2 theta + sin^2 psi >= 1)"
        )
    return np.array([np.sqrt(ax2), ay, az])


def projected_angles_from_axis(a_F: np.ndarray) -> tuple[float, float]:
    """(theta_p, psi_p), rad: the axis angles seen in the side view (x-z) and top view (x-y)."""
    a = np.asarray(a_F, dtype=float)
    return float(np.arctan2(a[2], a[0])), float(np.arctan2(a[1], a[0]))


def axis_from_projected_angles(theta_p: float, psi_p: float) -> np.ndarray:
    """Unit nose axis in F from the side-view and top-view projected angles (a_x > 0)."""
    a = np.array([1.0, np.tan(psi_p), np.tan(theta_p)])
    return a / np.linalg.norm(a)


def quat_from_axis_roll(a_F: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """Attitude quaternion whose nose axis is ``a_F`` with aircraft roll angle ``roll``, rad.

    The yaw and pitch come from the axis (pitch = theta, yaw = -atan2(a_y, a_x) in E);
    roll is about the nose axis, 0 = the model's z_b in the vertical plane, pointing down.
    """
    a = np.asarray(a_F, dtype=float)
    a = a / np.linalg.norm(a)
    a_E = FLIP @ a
    pitch = np.arcsin(np.clip(-a_E[2], -1.0, 1.0))
    yaw = np.arctan2(a_E[1], a_E[0])
    return euler_to_quat(yaw, pitch, roll)


# --------------------------------------------------------------------------- aero angles


def aero_angles(v_body: np.ndarray) -> tuple[float, float, float]:
    """(alpha, beta, sigma), rad, from the air-relative velocity in body axes (u, v, w)."""
    u, v, w = (float(c) for c in v_body)
    V = np.sqrt(u * u + v * v + w * w)
    if V == 0.0:
        raise ValueError("aerodynamic angles are undefined at zero airspeed")
    return (
        float(np.arctan2(w, u)),
        float(np.arcsin(np.clip(v / V, -1.0, 1.0))),
        float(np.arccos(np.clip(u / V, -1.0, 1.0))),
    )


def aero_roll_angle(v_body: np.ndarray) -> float:
    """phi, rad in (-pi, pi]: the aerodynamic roll angle, from body z toward body y to the
    cross-flow (v, w) -- the angle between the body's x-z plane (a fin plane of a cruciform
    body) and the plane of the total angle of attack. 0 at pure positive alpha, +pi/2 at pure
    positive beta; rolling the body by +gamma about x_b raises it by gamma (p = phi'). 0 where the
    cross-flow vanishes (sigma = 0)."""
    _, v, w = (float(c) for c in v_body)
    if v == 0.0 and w == 0.0:
        return 0.0
    return float(np.arctan2(v, w))


def velocity_from_aero_angles(V: float, alpha: float, beta: float) -> np.ndarray:
    """Body-axis air-relative velocity (u, v, w) of speed V at angles (alpha, beta), rad."""
    return V * np.array([np.cos(alpha) * np.cos(beta), np.sin(beta), np.sin(alpha) * np.cos(beta)])


def alpha_cev_deg(alpha: float) -> float:
    """Display-only CEV angle of attack, deg (180 = heat shield forward)."""
    return 180.0 - np.degrees(alpha)
