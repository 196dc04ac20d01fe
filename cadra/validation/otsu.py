"""The classic pixel-level baseline that stage one is compared with: Otsu + image moments.

:func:`otsu_moments` thresholds the image (Otsu), keeps the largest dark connected component
and returns its area centroid and principal-axis angle from second moments. It is deliberately
simple (no subpixel refinement): the reference a silhouette fit must beat.

The area centroid of a silhouette is generally **not** the body's reference point (for a
capsule it lies behind the centre of the maximum-diameter circle). The caller converts it with
the exact silhouette's centroid offset: :func:`polygon_centroid_offset` gives that offset in
body-aligned axes and :func:`reference_from_centroid` applies it to a measurement.
Pixel convention (``docs/conventions.md``): ``(u, v) = (column, row)``, origin at the centre
of the top-left pixel, ``image[v, u]``; angles are ``atan2(dv, du)`` in pixel axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from cadra.geometry import polygon_area_centroid

__all__ = [
    "BaselinePose",
    "baseline_error",
    "otsu_moments",
    "polygon_centroid_offset",
    "reference_from_centroid",
]


@dataclass(frozen=True)
class BaselinePose:
    """Result of :func:`otsu_moments` (full-image pixel coordinates).

    Attributes
    ----------
    u_px, v_px
        Area centroid of the dark component (pixel centres weighted equally).
    angle_rad
        Angle of the principal (major) axis, ``0.5 atan2(2 mu11, mu20 - mu02)`` in
        ``(-pi/2, pi/2]``: a line, so the nose direction (``+ pi``) is not resolved. For a body
        wider than long (the M2 capsule: d / L = 1.52) the major axis is *across* the symmetry
        axis: add ``pi / 2``.
    area_px
        Pixel count of the component (after the opening).
    threshold
        Otsu threshold, fraction of full scale (pixels at or below it are dark).
    mu20_px2, mu11_px2, mu02_px2
        Central second moments divided by the area (px²), so the caller can judge elongation.
    """

    u_px: float
    v_px: float
    angle_rad: float
    area_px: float
    threshold: float
    mu20_px2: float
    mu11_px2: float
    mu02_px2: float


def _to_uint8(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"image must be 2-D, got shape {img.shape}")
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    if img.dtype == np.uint16:
        return np.round(img / 257.0).astype(np.uint8)
    if np.issubdtype(img.dtype, np.floating):
        return np.round(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8)
    raise ValueError(f"image must be uint8, uint16 or float in [0, 1], got {img.dtype}")


def otsu_moments(image, roi=None, opening_px: int = 5) -> BaselinePose:
    """Otsu threshold, largest dark connected component, area centroid and axis angle.

    Parameters
    ----------
    image
        Grey image: ``uint8``, ``uint16`` (scaled to 8 bits) or float in ``[0, 1]``; (H, W).
    roi
        ``(u0, v0, width, height)`` sub-image to work on (threshold included), or ``None`` for
        the whole image. Results are in full-image coordinates either way.
    opening_px
        Diameter of the elliptical structuring element of a morphological opening of the dark
        mask, which cuts thin fiducial wires and specks from the body; ``0`` or ``1``: none.

    Returns
    -------
    BaselinePose

    Raises
    ------
    ValueError
        Bad image or ROI, or no dark component.

    Notes
    -----
    The threshold is ``cv2.threshold(..., THRESH_BINARY_INV | THRESH_OTSU)`` on the 8-bit
    image; components use 8-connectivity. The centroid is that of the area, not the body's
    reference point (module docstring).
    """
    img8 = _to_uint8(image)
    u0 = v0 = 0
    if roi is not None:
        u0, v0, w, h = (int(x) for x in roi)
        if u0 < 0 or v0 < 0 or w < 1 or h < 1 or u0 + w > img8.shape[1] or v0 + h > img8.shape[0]:
            raise ValueError(f"roi {roi} is not inside the image {img8.shape[::-1]}")
        img8 = np.ascontiguousarray(img8[v0 : v0 + h, u0 : u0 + w])
    thr, mask = cv2.threshold(img8, 0, 1, cv2.THRESH_BINARY_INV | cv2.THRESH_OTSU)
    if opening_px > 1:
        se = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (int(opening_px), int(opening_px)))
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, se)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n < 2:
        raise ValueError("no dark component below the Otsu threshold")
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    comp = (labels == best).astype(np.uint8)
    m = cv2.moments(comp, binaryImage=True)
    area = m["m00"]
    mu20, mu11, mu02 = m["mu20"] / area, m["mu11"] / area, m["mu02"] / area
    angle = 0.5 * math.atan2(2.0 * mu11, mu20 - mu02)
    if angle <= -0.5 * math.pi:
        angle += math.pi
    return BaselinePose(
        u_px=float(m["m10"] / area + u0),
        v_px=float(m["m01"] / area + v0),
        angle_rad=float(angle),
        area_px=float(area),
        threshold=float(thr) / 255.0,
        mu20_px2=float(mu20),
        mu11_px2=float(mu11),
        mu02_px2=float(mu02),
    )


def polygon_centroid_offset(polygon_px, ref_px, angle_rad: float) -> tuple[float, float]:
    """Offset of the silhouette's area centroid from the reference point, in body axes.

    Parameters
    ----------
    polygon_px
        Exact silhouette ``(N, 2)`` px at a known pose.
    ref_px
        Its reference point ``(u, v)`` px.
    angle_rad
        Its axis angle ``atan2(dv, du)`` (px axes) at that pose.

    Returns
    -------
    (along, across) : tuple of float
        ``centroid - ref`` rotated by ``-angle_rad``: px along the axis (+ toward the angle's
        direction) and across it (+ toward the axis turned by +90° in pixel axes). The offset
        is the same at any pose with the same silhouette shape (same out-of-plane attitude).
    """
    _, (cu, cv) = polygon_area_centroid(polygon_px)
    du, dv = cu - float(ref_px[0]), cv - float(ref_px[1])
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return c * du + s * dv, -s * du + c * dv


def reference_from_centroid(
    u_px: float, v_px: float, angle_rad: float, offset: tuple[float, float]
) -> tuple[float, float]:
    """Reference point from a measured area centroid, axis angle and the silhouette offset.

    ``offset`` is from :func:`polygon_centroid_offset`; ``angle_rad`` must be the axis
    direction (nose ambiguity and major/minor choice resolved by the caller).
    """
    along, across = offset
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return u_px - (c * along - s * across), v_px - (s * along + c * across)


def baseline_error(image, polygon_px, ref_px, axis_angle_rad: float, sphere: bool
                   ) -> list[float]:
    """The baseline's error on one rendered view whose exact outline ``polygon_px``,
    reference point ``ref_px`` and image axis angle are known: u, v px (and, unless
    ``sphere``, the axis angle, deg). It is given every help: the exact outline's centroid
    offset, and of the nose directions along the blob's major and minor axes the one closest
    to the truth (a capsule's major axis runs across the body, a bullet's along it)."""
    b = otsu_moments(image)
    u_ref, v_ref = float(ref_px[0]), float(ref_px[1])
    if sphere:
        return [b.u_px - u_ref, b.v_px - v_ref]
    ang = min((b.angle_rad + k * math.pi / 2 for k in range(4)),
              key=lambda g: abs(math.remainder(g - axis_angle_rad, 2 * math.pi)))
    off = polygon_centroid_offset(polygon_px, (u_ref, v_ref), axis_angle_rad)
    u, v = reference_from_centroid(b.u_px, b.v_px, ang, off)
    return [u - u_ref, v - v_ref, math.degrees(math.remainder(ang - axis_angle_rad, 2 * math.pi))]
