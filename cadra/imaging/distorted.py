"""Stage one on a view whose image is distorted (docs/stage1.md, "Distorted images"): the
ideal image its wires are fitted in, and the sigma a calibrated distortion's uncertainty puts
on a view's pose. The silhouette itself is fitted in the recorded image through
:class:`cadra.optics.distortion.DistortedProjection`."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["distortion_pose_sigma", "ideal_image"]


def ideal_image(view, img):
    """``img`` with the view's distortion removed, for the wires' fit: resampled at ``D`` of
    every ideal pixel (:meth:`cadra.optics.distortion.Distortion.undistort_image`), where
    the wires are straight. The silhouette is fitted in the recorded image itself, through
    the distorted projection (docs/stage1.md, "Distorted images"). Unchanged without a
    distortion (or for a loader's failure)."""
    if getattr(view, "distortion", None) is None or not isinstance(img, np.ndarray):
        return img
    return view.distortion.undistort_image(img)


def distortion_pose_sigma(distortion, projection, pose) -> tuple[float, float, float]:
    """The sigmas (m, m, rad) a calibrated distortion's coefficient covariance puts on a
    view pose ``(a, b, phi)``: the recorded point moves by ``B dk`` (``B`` the displacement
    per coefficient, :meth:`~cadra.optics.distortion.Distortion.basis`), so its ideal point
    by ``-J^-1 B dk``, carried to the plane; the direction turns by the displacement's
    derivative along it, across it. Zeros without a distortion or its covariance."""
    if distortion is None or distortion.covariance is None:
        return 0.0, 0.0, 0.0
    ab = np.array(pose[:2], dtype=float)
    uv = projection.from_plane(ab)
    A = projection.to_plane_jacobian(uv) @ np.linalg.inv(distortion.jacobian(uv))
    B = distortion.basis(uv)                             # (2, 4) px per coefficient
    t = projection.from_plane_jacobian(ab) @ np.array([math.cos(pose[2]), math.sin(pose[2])])
    t /= np.linalg.norm(t)
    n = np.array([-t[1], t[0]])
    h = 0.5
    dB = (distortion.basis(uv + h * t) - distortion.basis(uv - h * t)) / (2 * h)
    G = np.vstack([A @ B, n @ dB])                       # (3, 4): a, b (m), angle (rad)
    C = G @ distortion.covariance @ G.T
    return tuple(float(math.sqrt(max(C[i, i], 0.0))) for i in range(3))
