"""Observation model: what stage one measures, predicted from the 6-DOF state.

Stage one measures the position of the body's geometric reference point (documented per body
in ``docs/bodies.md``) and the inclinations theta, psi of its nose axis (docs/conventions.md).
The state carries the cg, so the reference point is ``r_cg + R_FB @ ref_from_cg_body``.
Vectorised numpy; complex-step safe (no branches, arcsin of complex is defined).
"""

from __future__ import annotations

import numpy as np

from cadra.dynamics.layout import S_POS, S_QUAT


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


def observe(states: np.ndarray, ref_from_cg_body_m: np.ndarray) -> dict[str, np.ndarray]:
    """Predicted measurements at each state.

    Parameters
    ----------
    states : (n, 13) 6-DOF states.
    ref_from_cg_body_m : (3,) body reference point minus the (true) cg, body axes, m.

    Returns
    -------
    dict with ``x_m, y_m, z_m`` (reference point in F), ``theta_rad``, ``psi_rad``
    (inclinations of the nose axis) and ``axis`` (n, 3) unit nose axis in F.
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
        "axis": axis,
    }
