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
    if view.distortion is None or not isinstance(img, np.ndarray):
        return img
    return view.distortion.undistort_image(img)


def distortion_pose_sigma(view, wires, pose) -> tuple[float, float, float]:
    """The sigmas (m, m, rad) ``view``'s calibrated distortion (its coefficient covariance)
    puts on the view pose ``(a, b, phi)`` measured with ``wires``. A coefficient error
    ``dk`` moves every ideal point by ``F dk = -J^-1 B dk`` (``B`` the recorded displacement
    per coefficient, :meth:`~cadra.optics.distortion.Distortion.basis`): the model's, and the
    wires' too, whose affine (re-solved here from their lines so moved,
    :func:`fit_affine_to_wires`) then takes up the part of the field it can. The pose's
    change per coefficient is the difference; its covariance follows. Zeros without a
    distortion or its covariance."""

    from cadra.facility.reference import fit_affine_to_wires

    distortion = view.distortion
    if distortion is None or distortion.covariance is None or wires.affine is None:
        return 0.0, 0.0, 0.0
    # each found wire as points along the stretch it was measured over: its line is fitted
    # to all its centres, so it moves with the field's mean along it, not its ends'
    by_name = {w.name: w for w in wires.wires if w.found}
    s = np.linspace(0.0, 1.0, 33)[:, None]
    lines = [None if w.name not in by_name else
             (lambda e: e[0] + s * (e[1] - e[0]))(np.asarray(by_name[w.name].ends_px, float))
             for w in view.wires]

    def field(points):                       # (..., 2, 4): ideal px per unit coefficient
        return -np.linalg.solve(distortion.jacobian(points), distortion.basis(points))

    def plane_pose(M, uv, t):                # plane point and direction angle of (uv, t)
        ab = M[:, :2] @ uv + M[:, 2]
        d = M[:, :2] @ t
        return ab, math.atan2(d[1], d[0])

    M0 = fit_affine_to_wires(view, lines).affine
    uv = wires.projection.from_plane(np.array(pose[:2], dtype=float))
    t = np.linalg.solve(M0[:, :2], np.array([math.cos(pose[2]), math.sin(pose[2])]))
    t /= np.linalg.norm(t)
    ab0, ang0 = plane_pose(M0, uv, t)
    h, step = 1e-6, 0.5                      # coefficient step; px along the axis
    F_uv = field(uv)
    dF = (field(uv + step * t) - field(uv - step * t)) / (2 * step)     # d field / d s
    G = np.zeros((3, 4))
    for j in range(4):
        moved = [None if ln is None else ln + h * field(ln)[..., j] for ln in lines]
        M1 = fit_affine_to_wires(view, moved).affine
        ab1, ang1 = plane_pose(M1, uv + h * F_uv[:, j], t + h * dF[:, j])
        G[:2, j] = (ab1 - ab0) / h
        G[2, j] = math.remainder(ang1 - ang0, 2 * math.pi) / h
    C = G @ distortion.covariance @ G.T
    return tuple(float(math.sqrt(max(C[i, i], 0.0))) for i in range(3))
