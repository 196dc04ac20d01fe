"""Pure plane geometry shared by the synthetic side and the measurement: polygons and 2x3 affines.

The lowest layer of the package: numpy only, no other :mod:`cadra` import, so the renderer
(:mod:`cadra.synthetic`), stage one (:mod:`cadra.imaging`), the optics (:mod:`cadra.optics`) and
the facility model (:mod:`cadra.facility`) can all use it without importing each other.

Polygons are ``(N, 2)`` vertex arrays, closed implicitly (last vertex not repeated), either
orientation, not self-intersecting. A 2x3 affine ``M`` maps ``y = M @ [x, 1]``.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "affine_inverse",
    "apply_affine",
    "as_polygon",
    "densify_polygon",
    "polygon_area_centroid",
    "polygon_moments",
]


def densify_polygon(poly: np.ndarray, max_edge_px: float = 1.0) -> np.ndarray:
    """``poly`` (N, 2), closed, with points inserted along every edge longer than
    ``max_edge_px``: each edge cut into equal pieces of at most that length, its start
    vertex kept (an outline's flats are single long edges; a distortion bends them)."""
    poly = np.asarray(poly, dtype=float)
    E = np.roll(poly, -1, axis=0) - poly
    n = np.maximum(np.ceil(np.hypot(E[:, 0], E[:, 1]) / max_edge_px).astype(int), 1)
    i = np.repeat(np.arange(len(poly)), n)
    f = (np.arange(i.size) - np.repeat(np.cumsum(n) - n, n)) / n[i]
    return poly[i] + f[:, None] * E[i]


def as_polygon(poly, what: str = "polygon") -> np.ndarray:
    """``poly`` as a read-only float64 ``(N, 2)`` array, N >= 3, finite (ValueError naming
    ``what`` otherwise)."""
    arr = np.array(poly, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
        raise ValueError(f"{what} must be an (N, 2) array of (u, v) px with N >= 3")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} has non-finite vertices")
    arr.setflags(write=False)
    return arr


def polygon_moments(poly) -> tuple[float, np.ndarray, np.ndarray]:
    """Area (positive), centroid ``(2,)`` and central second-moment matrix ``(2, 2)`` (per unit
    area) of a simple polygon (shoelace and its moment analogues).

    Vertices are taken relative to their mean first, so the result keeps full precision far
    from the origin. ValueError for a polygon of zero area.
    """
    p = np.asarray(poly, dtype=np.float64)
    ref = p.mean(axis=0)
    x, y = p[:, 0] - ref[0], p[:, 1] - ref[1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    a = 0.5 * cr.sum()
    if a == 0.0:
        raise ValueError("polygon has zero area")
    cx = ((x + xn) * cr).sum() / (6 * a)
    cy = ((y + yn) * cr).sum() / (6 * a)
    ixx = ((x * x + x * xn + xn * xn) * cr).sum() / (12 * a) - cx * cx
    iyy = ((y * y + y * yn + yn * yn) * cr).sum() / (12 * a) - cy * cy
    ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cr).sum() / (24 * a) - cx * cy
    return abs(a), np.array([cx, cy]) + ref, np.array([[ixx, ixy], [ixy, iyy]])


def polygon_area_centroid(poly) -> tuple[float, tuple[float, float]]:
    """Exact area (px², positive) and centroid ``(u_c, v_c)`` of a simple polygon (shoelace).

    The first two of :func:`polygon_moments`, for a validated polygon (:func:`as_polygon`).
    """
    area, c, _ = polygon_moments(as_polygon(poly, "polygon"))
    return area, (float(c[0]), float(c[1]))


def affine_inverse(M: np.ndarray) -> np.ndarray:
    """Inverse of a 2x3 affine map ``y = M @ [x, 1]``, as a 2x3 map."""
    M = np.asarray(M, dtype=float)
    A_inv = np.linalg.inv(M[:, :2])
    return np.hstack([A_inv, -(A_inv @ M[:, 2])[:, None]])


def apply_affine(M: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Apply a 2x3 affine to points ``(..., 2)``."""
    pts = np.asarray(pts, dtype=float)
    M = np.asarray(M, dtype=float)
    return pts @ M[:, :2].T + M[:, 2]
