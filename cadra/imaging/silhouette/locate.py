"""Coarse location of the model in a shadowgraph: the first guess of the silhouette fit.

:func:`locate_model` finds the dark blob whose area matches the body's silhouette;
:func:`pose_from_coarse` turns it into a view-plane pose ``(a, b, phi)`` (docs/stage1.md,
"Locate").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from cadra.imaging.silhouette.template import Template, rot
from cadra.optics.projection import Projection

__all__ = ["CoarsePose", "locate_model", "pose_from_coarse"]


@dataclass(frozen=True)
class CoarsePose:
    """First guess of the model in an image, or why there is none."""

    ok: bool
    reason: str
    centroid_px: tuple[float, float] = (math.nan, math.nan)
    angle_px_rad: float = math.nan            # principal axis (nose direction toward +u)
    area_px: float = math.nan
    bbox: tuple[int, int, int, int] = (0, 0, 0, 0)   # u0, v0, u1, v1 (inclusive)
    touches_border: bool = False


def locate_model(img: np.ndarray, template: Template, projection: Projection,
                 exclude: np.ndarray | None = None) -> CoarsePose:
    """Find the model: the dark blob whose area matches the body's silhouette.

    On a 4x reduced copy: threshold halfway between the background and shadow levels, cut
    thin features (wires, the reference mark, scratches) with a morphological opening, keep the
    connected component whose area is closest to the expected one (within a factor 2.5); then
    centroid and principal axis of the thresholded blob at full resolution in its box. The nose
    direction is taken toward +u (downrange): ballistic models fly nose first.
    """
    H, W = img.shape
    f = 4
    small = np.ascontiguousarray(img[f // 2::f, f // 2::f], dtype=np.float32)  # no filtering
    small = small[: H // f, : W // f]
    H0, W0 = img.shape
    centre = np.array([(W0 - 1) / 2.0, (H0 - 1) / 2.0])
    scale_px = math.sqrt(abs(np.linalg.det(projection.to_plane_jacobian(centre))))
    expect = template.area_m2 / scale_px**2
    sample = small[::2, ::2].ravel()      # levels from a quarter of the reduced copy
    bg = float(np.percentile(sample, 75))
    dark = float(np.percentile(sample, 0.2))
    if bg - dark < 0.1:
        return CoarsePose(False, f"no model found: image has no dark shadow (background "
                                 f"{bg:.2f}, darkest {dark:.2f} of full scale)")
    thr = 0.5 * (bg + max(dark, 0.0))
    mask = (small < thr).astype(np.uint8)
    if exclude is not None:
        ex = cv2.resize(exclude.astype(np.uint8), (W // f, H // f),
                        interpolation=cv2.INTER_NEAREST)
        mask[ex > 0] = 0
    r = max(1, int(round(0.03 * math.sqrt(expect) / f)))
    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    opened = cv2.morphologyEx(mask, cv2.MORPH_OPEN, ker)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(opened, connectivity=8)
    if n <= 1:
        return CoarsePose(False, f"no model found: no dark blob (expected ~{expect:.0f} px^2)")
    areas = stats[1:, cv2.CC_STAT_AREA].astype(float) * f * f
    ratio = np.abs(np.log(areas / expect))
    best = int(np.argmin(ratio))
    x0, y0, w, h = (int(x) for x in stats[1 + best, :4])
    touches = bool(x0 <= 0 or y0 <= 0 or x0 + w >= W // f or y0 + h >= H // f)
    if ratio[best] > math.log(2.5) and not touches:
        return CoarsePose(False, f"no model found: largest dark blob {areas.max():.0f} px^2, "
                                 f"expected ~{expect:.0f} px^2")
    if touches and areas[best] < 0.25 * expect:
        return CoarsePose(False, f"model mostly out of frame (blob of {areas[best]:.0f} px^2 "
                                 f"at the border, expected ~{expect:.0f} px^2)")
    # full resolution in the blob's box (+ margin): thresholded moments of the biggest part
    u0, v0 = max(f * x0 - 2 * f, 0), max(f * y0 - 2 * f, 0)
    u1, v1 = min(f * (x0 + w) + 2 * f, W - 1), min(f * (y0 + h) + 2 * f, H - 1)
    roi = (img[v0:v1 + 1, u0:u1 + 1] < thr).astype(np.uint8)
    if exclude is not None:
        roi[exclude[v0:v1 + 1, u0:u1 + 1]] = 0
    n2, lab2, st2, _ = cv2.connectedComponentsWithStats(roi, connectivity=8)
    if n2 <= 1:
        return CoarsePose(False, "no model found at full resolution")
    big = 1 + int(np.argmax(st2[1:, cv2.CC_STAT_AREA]))
    m = cv2.moments((lab2 == big).astype(np.uint8), binaryImage=True)
    cu, cv = m["m10"] / m["m00"] + u0, m["m01"] / m["m00"] + v0
    C = np.array([[m["mu20"], m["mu11"]], [m["mu11"], m["mu02"]]]) / m["m00"]
    ev, evec = np.linalg.eigh(C)
    ax = evec[:, 1] if template.principal_is_axis else evec[:, 0]
    if ax[0] < 0:
        ax = -ax
    return CoarsePose(True, "", (float(cu), float(cv)), float(math.atan2(ax[1], ax[0])),
                      float(m["m00"]), (u0, v0, u1, v1), touches)


def pose_from_coarse(coarse: CoarsePose, template: Template,
                     projection: Projection) -> tuple[float, float, float]:
    """Plane pose ``(a, b, phi)`` from a coarse blob: centroid minus the template offset."""
    c_uv = np.array(coarse.centroid_px)
    c_plane = projection.to_plane(c_uv)
    if template.axisymmetric_point:
        ref = c_plane - template.centroid_m
        return float(ref[0]), float(ref[1]), 0.0
    ax = np.array([math.cos(coarse.angle_px_rad), math.sin(coarse.angle_px_rad)])
    dirp = projection.to_plane_jacobian(c_uv) @ ax
    phi = math.atan2(dirp[1], dirp[0])
    ref = c_plane - rot(phi) @ template.centroid_m
    return float(ref[0]), float(ref[1]), float(phi)
