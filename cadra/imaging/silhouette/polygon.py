"""The blurred-edge model of a whole polygon, corners included: the image a shadow's outline
makes through the edge model of stage A (a Gaussian edge of width ``s`` with the diffraction
fringe ``a h``), exact near the corners (Owen's T for the Gaussian's mass in a wedge, the
fringe's line integral), for the finned body's roll (:mod:`cadra.imaging.roll`) and its tests.
Lengths in pixels (docs/stage1.md, "Roll of a finned body").
"""

from __future__ import annotations

import math

import cv2
import numba
import numpy as np
import shapely
from scipy.special import ndtr, owens_t

from cadra.imaging.silhouette.edge_model import PHI1, SQRT2PI
from cadra.imaging.silhouette.edges import outline_geometry

#: :func:`blurred_polygon`: beyond this many edge widths from both ends of an edge, its
#: Gaussian mass is the straight edge's
END_CLEAR = 9.0
#: :func:`blurred_polygon`'s simplification of the outline, px
SIMPLIFY_PX = 1e-4


@numba.njit(cache=True)
def _polygon_pairs(p0, dv, ell, nrm, reach, u_lo, v_lo, H, W, fill, pix, edge, d_out, t_out):
    """The (pixel, edge) pairs of ROI pixels within ``reach`` px of an edge segment: the pixel's
    linear ROI index, the edge, its signed distance from the edge's line along the outward
    normal ``nrm`` (``d``, + outside) and the foot's position along the edge from its start
    (``t``, px). With ``fill`` False only counts them (the arrays are not touched); returns the
    count."""
    n = 0
    r2 = reach * reach
    for e in range(p0.shape[0]):
        ax, ay = p0[e, 0], p0[e, 1]
        L = ell[e]
        tx, ty = dv[e, 0] / L, dv[e, 1] / L
        bx, by = ax + dv[e, 0], ay + dv[e, 1]
        u0 = max(int(math.floor(min(ax, bx) - reach)) - u_lo, 0)
        u1 = min(int(math.ceil(max(ax, bx) + reach)) - u_lo, W - 1)
        v0 = max(int(math.floor(min(ay, by) - reach)) - v_lo, 0)
        v1 = min(int(math.ceil(max(ay, by) + reach)) - v_lo, H - 1)
        for r in range(v0, v1 + 1):
            wy = float(r + v_lo) - ay
            for c in range(u0, u1 + 1):
                wx = float(c + u_lo) - ax
                t = wx * tx + wy * ty
                d = wx * nrm[e, 0] + wy * nrm[e, 1]
                tc = min(max(t, 0.0), L)
                if (t - tc) * (t - tc) + d * d > r2:
                    continue
                if fill:
                    pix[n] = r * W + c
                    edge[n] = e
                    d_out[n] = d
                    t_out[n] = t
                n += 1
    return n


def pixel_centres_inside(poly: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(rows, cols) bool: the pixel centres (pixel (r, c) at (u, v) = (c, r)) inside the
    polygon ``poly`` (N, 2), by cv2's fill with the vertices rounded to 1/256 px."""
    mask = np.zeros((int(shape[0]), int(shape[1])), np.uint8)
    pts = np.round(np.asarray(poly, float) * 256.0).astype(np.int32).reshape(-1, 1, 2)
    cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=8)
    return mask.astype(bool)


def blurred_polygon(poly: np.ndarray, shape: tuple[int, int], width, fringe, fringe_ratio,
                    reach: float = 6.0):
    """The blurred-edge image model of a whole polygon, corners included: the dark fraction
    ``g`` (the polygon's indicator convolved with an isotropic Gaussian of sigma ``s``) and
    the fringe ``h`` (``a`` times the Laplacian of the indicator convolved with a Gaussian of
    sigma ``fringe_ratio * s``, normalised as :func:`_edge_profile`'s), both at the pixel
    centres of a ``shape`` (rows, cols) grid whose pixel (r, c) is at (u, v) = (c, r).

    Beside a straight edge they are the edge model's ``Phi(-d / s)`` and fringe; at a corner
    they are what the nearest side's profile gets wrong. Exact, by Green's theorem: the
    Gaussian mass of the polygon seen from a pixel is a signed sum over its edges of the
    masses of the triangles (pixel, edge), each ``angle / 2 pi - [T(rho/s, t_B/rho) - T(rho/s,
    t_A/rho)]`` with Owen's T (``scipy.special.owens_t``), rho the pixel's distance from the
    edge's line and t_A, t_B its ends from the foot; the angles sum to the winding number (the
    pixel inside or not), and the T terms vanish beyond ``reach`` px of the edge. The
    Laplacian is a line integral of the Gaussian's normal derivative over the edges: the
    straight edge's profile times the Gaussian weight of the edge's length, ``Phi(t_B/s_f) -
    Phi(t_A/s_f)``.

    ``width`` and ``fringe`` are the edge width s and fringe amplitude a, each a scalar or a
    function of the (N, 2) outward unit normals giving one value per edge (the fitted profile's
    ``x0 + x4 cos 4 theta``). Returns ``(g, h)``, (rows, cols) float arrays; ``g`` is exact
    0 / 1 beyond ``reach`` px (pixel centres by an exact point-in-polygon test near the edges).
    """
    H, W = (int(x) for x in shape)
    poly = np.asarray(poly, dtype=float)
    if np.any(np.all(np.abs(poly - np.round(poly)) < 1e-9, axis=1)):
        # a vertex on a pixel centre: there the edges' signed sum is ambiguous (the pixel is
        # on both edges' lines); g is continuous, so move the outline by a negligible step
        poly = poly + np.array([6e-8, 8e-8])
    # fewer edges to sum: the outline's points along a straight side as one edge, a gently
    # curved stretch (a body sampled finely along its length) as chords within
    # SIMPLIFY_PX of it (0.033 px chords at 430 px radius near the fins: ~500 edges -> ~30)
    poly = shapely.get_coordinates(shapely.simplify(shapely.Polygon(poly), SIMPLIFY_PX))[:-1]
    geo = outline_geometry(poly)
    s = np.broadcast_to(np.asarray(width(geo.normal) if callable(width) else width, float),
                        geo.ell.shape)
    a = np.broadcast_to(np.asarray(fringe(geo.normal) if callable(fringe) else fringe, float),
                        geo.ell.shape)
    args = (geo.p0, geo.d, geo.ell, geo.normal, float(reach), 0, 0, H, W)
    n = _polygon_pairs(*args, False, np.empty(0, np.int64), np.empty(0, np.int64),
                       np.empty(0), np.empty(0))
    pix, edge = np.empty(n, np.int64), np.empty(n, np.int64)
    d, t = np.empty(n), np.empty(n)
    _polygon_pairs(*args, True, pix, edge, d, t)
    # inside or not: an exact point-in-polygon test on the pixels near the outline, a fill
    # elsewhere
    g = pixel_centres_inside(poly, (H, W)).astype(float).ravel()
    near = np.zeros(H * W, bool)
    near[pix] = True
    near = np.flatnonzero(near)
    shp = shapely.Polygon(poly)
    shapely.prepare(shp)
    r, c = np.divmod(near, W)
    inside_near = shapely.contains_xy(shp, c.astype(float), r.astype(float))
    g[near] = inside_near
    inside_pair = g[pix] > 0.5
    # the pixel's side of the edge: + on the polygon's inner side
    side = np.where(d == 0.0, np.where(inside_pair, 1.0, -1.0), -d)
    rho = np.maximum(np.abs(d), 1e-12)
    se, ae = s[edge], a[edge]
    tA, tB = -t, geo.ell[edge] - t
    # T(h, t / rho) - T(h, -t' / rho) is Phi(-rho / s) to double precision where both ends
    # are more than END_CLEAR widths from the foot (T(h, a) -> Phi(-h) / 2 as h a = t / s
    # grows): Owen's T only for the pixels near an edge's end
    dT = ndtr(-rho / se)
    ends = (np.minimum(-tA, tB) < END_CLEAR * se)
    h_e, r_e = rho[ends] / se[ends], rho[ends]
    dT[ends] = owens_t(h_e, tB[ends] / r_e) - owens_t(h_e, tA[ends] / r_e)
    g -= np.bincount(pix, weights=np.sign(side) * dT, minlength=H * W)
    # the fringe: the edge model's profile in the signed distance d (+ outside) times the
    # edge's Gaussian weight
    sf = fringe_ratio * se
    zf = side / sf                        # = -d / s_f
    prof = -zf * np.exp(-0.5 * zf * zf) / SQRT2PI / PHI1
    h = np.bincount(pix, weights=ae * prof * (ndtr(tB / sf) - ndtr(tA / sf)), minlength=H * W)
    return g.reshape(H, W), h.reshape(H, W)
