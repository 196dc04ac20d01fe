"""Observation model: what stage one measures, predicted from the 6-DOF state.

Stage one measures the position of the body's geometric reference point (documented per body
in ``docs/bodies.md``) and the inclinations theta, psi of its nose axis (docs/conventions.md).
The state carries the cg, so the reference point is ``r_cg + R_FB @ ref_from_cg_body``.
Vectorised numpy; complex-step safe (no branches, arcsin of complex is defined).
"""

from __future__ import annotations

import numpy as np

from cadra.conventions import aero_angles, aero_roll_angle
from cadra.dynamics.layout import P_D, P_SOUND, P_WIND, P_WIND_GRAD, S_POS, S_QUAT, S_VEL


def rotation_fb_batch(quats: np.ndarray) -> np.ndarray:
    """(n, 3, 3) body->facility rotation matrices from (n, 4) quaternions (B->E)."""
    w, x, y, z = (quats[:, i] for i in range(4))
    s = 2.0 / (w * w + x * x + y * y + z * z)
    R = np.empty(quats.shape[:1] + (3, 3), dtype=quats.dtype)
    R[:, 0, 0] = 1.0 - s * (y * y + z * z)
    R[:, 0, 1] = s * (x * y - w * z)
    R[:, 0, 2] = s * (x * z + w * y)
    R[:, 1, 0] = -(s * (x * y + w * z))
    R[:, 1, 1] = -(1.0 - s * (x * x + z * z))
    R[:, 1, 2] = -(s * (y * z - w * x))
    R[:, 2, 0] = -(s * (x * z - w * y))
    R[:, 2, 1] = -(s * (y * z + w * x))
    R[:, 2, 2] = -(1.0 - s * (x * x + y * y))
    return R


def _atan2(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``arctan2(y, x)``, also for complex-step arguments (numpy's has no complex form): the
    real part is the real angle, the imaginary part its first-order change."""
    if not (np.iscomplexobj(y) or np.iscomplexobj(x)):
        return np.arctan2(y, x)
    yr, xr = np.real(y), np.real(x)
    return np.arctan2(yr, xr) + 1j * (xr * np.imag(y) - yr * np.imag(x)) / (xr * xr + yr * yr)


def observe(states: np.ndarray, ref_from_cg_body_m: np.ndarray) -> dict[str, np.ndarray]:
    """Predicted measurements at each state.

    Parameters
    ----------
    states : (n, 13) 6-DOF states.
    ref_from_cg_body_m : (3,) body reference point minus the (true) cg, body axes, m.

    Returns
    -------
    dict with ``x_m, y_m, z_m`` (reference point in F), ``theta_rad``, ``psi_rad``
    (inclinations of the nose axis), ``phi_rad`` (the roll angle about the nose axis in
    (-pi, pi]: the aircraft 3-2-1 roll of the attitude, 0 with body z in the vertical plane
    pointing down, as :func:`cadra.conventions.quat_from_axis_roll` takes it) and ``axis``
    (n, 3) unit nose axis in F.
    """
    states = np.atleast_2d(states)
    R = rotation_fb_batch(states[:, S_QUAT])
    ref = states[:, S_POS] + R @ np.asarray(ref_from_cg_body_m)
    axis = R[:, :, 0]
    return {
        "x_m": ref[:, 0],
        "y_m": ref[:, 1],
        "z_m": ref[:, 2],
        "theta_rad": np.arcsin(axis[:, 2]),
        "psi_rad": np.arcsin(axis[:, 1]),
        # E = diag(1, -1, -1) F: the Euler roll atan2(R_E[2, 1], R_E[2, 2]) from R_FB's rows
        "phi_rad": _atan2(-R[:, 2, 1], -R[:, 2, 2]),
        "axis": axis,
    }


def complex_yaw(states: np.ndarray) -> np.ndarray:
    """Linear theory's complex yaw at each state: the nose axis minus the velocity's direction,
    their (y, z) components in F as y + i z (the sines of the yaw angles; still air)."""
    states = np.atleast_2d(states)
    axis = rotation_fb_batch(states[:, S_QUAT])[:, :, 0]
    v = states[:, S_VEL]
    speed = np.linalg.norm(v, axis=1)
    return axis[:, 1] + 1j * axis[:, 2] - (v[:, 1] + 1j * v[:, 2]) / speed


def air_angles(states: np.ndarray, rigid, phys: np.ndarray | None = None
               ) -> dict[str, np.ndarray]:
    """Aerodynamic angles, Mach number and non-dimensional rates along (n, 13) states, as the
    dynamics computes them (air velocity: cg velocity minus the wind and its x gradient of
    ``rigid.effects`` and a tunnel's stream; angles by :func:`cadra.conventions.aero_angles`).

    ``phys``: the ``phys`` vector the states were integrated with
    (:mod:`cadra.dynamics.layout`; a fit's, with its wind extras on), whose wind, wind
    gradient, reference length and speed of sound then replace ``rigid``'s.

    Returns a dict of (n,) arrays ``alpha_rad``, ``beta_rad``, ``sigma_rad`` (classical: 0 =
    nose into the wind; docs/conventions.md), ``phi_rad`` (the aerodynamic roll angle),
    ``airspeed_m_s``, ``mach``, ``p_hat``,
    ``q_hat``, ``r_hat`` (rate d / 2V) and ``air_dir_F`` (n, 3), the unit air-relative
    velocity in F.
    """
    states = np.atleast_2d(np.asarray(states, dtype=float))
    # the body's own phys: its effects' wind and a tunnel's stream (cadra.dynamics.modes)
    phys = np.asarray(rigid.phys() if phys is None else phys, dtype=float)
    w0, dw = phys[P_WIND:P_WIND + 3], phys[P_WIND_GRAD:P_WIND_GRAD + 3]
    d_m, sound = float(phys[P_D]), float(phys[P_SOUND])
    wind = (np.asarray(w0, dtype=float)[None, :]
            + states[:, 0:1] * np.asarray(dw, dtype=float)[None, :])
    v_air = states[:, 3:6] - wind
    R = rotation_fb_batch(states[:, S_QUAT])
    v_b = np.einsum("nji,nj->ni", R, v_air)          # R^T v
    n = len(states)
    alpha, beta, sigma, phi = (np.empty(n) for _ in range(4))
    for i in range(n):
        alpha[i], beta[i], sigma[i] = aero_angles(v_b[i])
        phi[i] = aero_roll_angle(v_b[i])
    V = np.linalg.norm(v_air, axis=1)
    k = d_m / (2.0 * V)
    return {"alpha_rad": alpha, "beta_rad": beta, "sigma_rad": sigma, "phi_rad": phi,
            "airspeed_m_s": V,
            "mach": V / sound, "p_hat": states[:, 10] * k,
            "q_hat": states[:, 11] * k, "r_hat": states[:, 12] * k,
            "air_dir_F": v_air / V[:, None]}
