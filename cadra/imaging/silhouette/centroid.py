"""Method (b) of stage one: the model's pose from the area moments of its shadow.

:func:`centroid_pose`: area moments with subpixel thresholding: pixels in the edge band weigh
by their opacity ``(L - I) / (L - D)`` from the local levels of the silhouette fit's stage A
(:mod:`cadra.imaging.silhouette.edges`), pixels inside weigh 1. The reference point is the
centroid minus the exact silhouette's centroid offset; the angle is the principal axis of the
same moments. A consistency figure beside the silhouette least squares (docs/stage1.md).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy.special import ndtr

from cadra.imaging.silhouette.edges import EdgeSegments
from cadra.imaging.silhouette.template import Template, outline_px, pose_px, rot
from cadra.optics.distortion import ideal_projection
from cadra.optics.projection import Projection

__all__ = ["centroid_pose"]


def centroid_pose(img, template: Template, projection: Projection, pose, seg: EdgeSegments,
                  exclude=None):
    """Area-moment pose (method b) with subpixel thresholding; see the module docstring.

    ``pose`` is the silhouette fit's (it places the outline and picks the nose direction),
    ``seg`` its last stage A (:func:`cadra.imaging.silhouette.edges.stage_a`).

    Returns ``((u, v) ref px, axis angle px rad, (a, b, phi) plane)``. Band pixels weigh by
    their opacity from their segment's local levels; interior pixels weigh 1; pixels of
    unusable segments (corners, wires) are filled with the opacity of the fitted outline.
    """
    H, W = img.shape
    px = seg.pixels
    lin, d, k_all = px["lin"], px["d"], px["seg_all"]
    L, D = px["L"], px["D"]
    band = np.abs(d) <= 4.0
    lin_b, d_b, k_b = lin[band], d[band], k_all[band]
    I = img.ravel()[lin_b]
    have = k_b >= 0
    if exclude is not None:
        have &= ~exclude.ravel()[lin_b]
    op = np.empty(len(lin_b))
    op[have] = (L[k_b[have]] - I[have]) / (L[k_b[have]] - D[k_b[have]])
    # no usable level: the fitted edge model's opacity
    s = seg.edge_sigma_px
    op[~have] = ndtr(-d_b[~have] / s)
    uu, vv = (lin_b % W).astype(float), (lin_b // W).astype(float)
    # interior: pixels inside the outline but not in the band
    poly = outline_px(template, pose, projection)
    u_lo = int(max(math.floor(poly[:, 0].min()) - 1, 0))
    v_lo = int(max(math.floor(poly[:, 1].min()) - 1, 0))
    u_hi = int(min(math.ceil(poly[:, 0].max()) + 1, W - 1))
    v_hi = int(min(math.ceil(poly[:, 1].max()) + 1, H - 1))
    Wr = u_hi - u_lo + 1
    mask = np.zeros((v_hi - v_lo + 1, Wr), np.uint8)
    shift = 4
    pts = np.rint((poly - [u_lo, v_lo]) * (1 << shift)).astype(np.int32)
    cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=shift)
    ub, vb = lin_b % W - u_lo, lin_b // W - v_lo
    inb = (ub >= 0) & (ub < Wr) & (vb >= 0) & (vb < mask.shape[0])
    mask[vb[inb], ub[inb]] = 0
    vi, ui = np.nonzero(mask)
    ui = ui.astype(float) + u_lo
    vi = vi.astype(float) + v_lo
    w = np.concatenate([op, np.ones(len(ui))])
    u = np.concatenate([uu, ui])
    v = np.concatenate([vv, vi])
    A = w.sum()
    cu, cv = (w * u).sum() / A, (w * v).sum() / A
    du, dv = u - cu, v - cv
    muu, mvv, muv = (w * du * du).sum() / A, (w * dv * dv).sum() / A, (w * du * dv).sum() / A
    if template.axisymmetric_point:
        phi_img = math.nan
        c_plane = projection.to_plane(np.array([cu, cv]))
        ref_plane = c_plane - template.centroid_m
        ref_px = ideal_projection(projection).from_plane(ref_plane)
        return (float(ref_px[0]), float(ref_px[1])), phi_img, (float(ref_plane[0]),
                                                               float(ref_plane[1]), math.nan)
    # principal axis in the image, then the nose direction closest to the fitted one
    ev, evec = np.linalg.eigh(np.array([[muu, muv], [muv, mvv]]))
    ax = evec[:, 1] if template.principal_is_axis else evec[:, 0]
    _, ang_fit = pose_px(pose, projection)
    if ax @ np.array([math.cos(ang_fit), math.sin(ang_fit)]) < 0:
        ax = -ax
    # to the plane: angle of the mapped direction
    c_uv = np.array([cu, cv])
    dirp = projection.to_plane_jacobian(c_uv) @ ax
    phi = math.atan2(dirp[1], dirp[0])
    c_plane = projection.to_plane(c_uv)
    ref_plane = c_plane - rot(phi) @ template.centroid_m
    ideal = ideal_projection(projection)
    ref_px = ideal.from_plane(ref_plane)
    ang = (math.atan2(ax[1], ax[0]) if ideal is projection     # (the ideal image's angle)
           else pose_px((*ref_plane, phi), ideal)[1])
    return ((float(ref_px[0]), float(ref_px[1])), float(ang),
            (float(ref_plane[0]), float(ref_plane[1]), float(phi)))
