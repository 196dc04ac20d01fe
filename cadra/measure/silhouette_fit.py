"""Measure the model's pose in one shadowgraph: silhouette least squares and area centroid.

Stage one's two methods (seed 004, "Data Reduction and Analysis"; docs/stage1.md):

(a) **Least squares** (:func:`fit_silhouette`): the body's exact outline (:mod:`cadra.body`) is
    placed at a trial pose; pixels in a band around it are grouped into short contour
    *segments*; in each segment a blurred-edge model ``I = L (1 - g) + D g + a L h``,
    ``g = Phi((delta - d) / s)`` (d = the pixel centre's signed distance from the outline,
    + outside; L the local bright level, D the dark level, tied to it image-wide as
    ``D = r L + c`` by default (``FitSettings.dark_level``: a free D per segment costs each
    offset ~12 % of its sigma); s the edge width) gives the segment's
    edge offset ``delta`` along the outward normal, with its variance (stage A). ``a L h`` is
    the diffraction fringe (:func:`_edge_profile`): a bright band outside the edge and a dark
    one inside, the second derivative of a blurred step. The edge width and the fringe
    amplitude are fitted per image, each as ``x0 + x4 cos(4 theta)`` (theta the normal's
    angle to the pixel grid): the profile across an edge depends on that angle at fourth
    order (a square pixel projects onto the normal as a box along an axis, a triangle along a
    diagonal).
    The pose correction then follows from all offsets by weighted least squares (stage B)::

        delta_k = n_k . (dr + dphi x (x_k - r_ref)) - c kappa_k

    The last term is the curvature bias of a blurred edge: the half-intensity contour of a
    blurred convex edge lies inside the true outline by ``(blur variance along the tangent)
    kappa / 2`` (Mendonca et al., ECCV 2004); a diffraction fringe adds a term of the same
    form. ``c`` (px^2) is fitted, not assumed, so the correction holds for a PSF shape or a
    fringe the measurement does not model. Iterated to convergence (band and segments re-built
    at each pose). Uncertainty: Newey-West sandwich over the contour-ordered segment residuals,
    so correlated noise (film grain) and misfit show up in the sigma.

(b) **Centroid** (:func:`centroid_pose`): area moments of the shadow with subpixel thresholding:
    pixels in the edge band weigh by their opacity ``(L - I) / (L - D)`` from the local levels
    of (a), pixels inside weigh 1. The reference point is the centroid minus the exact
    silhouette's centroid offset; the angle is the principal axis of the same moments.

Geometry is in the *view plane* (metres in F, docs/conventions.md) through the image's wire
affine ``image_to_plane`` (2x3); the pose of one view is ``(a, b, phi)``: the reference point's
view-plane coordinates and the in-plane axis angle from the first view axis toward the second
(top view: psi_p = atan2(a_y, a_x); side view: theta_p = atan2(a_z, a_x)). The outline depends
also on the axis' tilt out of the view plane (seen by the other view): ``tilt_rad`` (its sign
does not matter: the outline depends on |cos| of the angle to the line of sight).

Everything here is a pure function of plain arrays and frozen dataclasses (picklable).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numba
import numpy as np
from scipy.special import ndtr

from cadra.body import Body, silhouette
from cadra.conventions import FLIP, quat_from_axis_roll, quat_to_matrix
from cadra.facility.reference import VIEW_AXES, affine_inverse, apply_affine

SQRT2PI = math.sqrt(2.0 * math.pi)

#: Turning angle above which an outline vertex is a sharp corner (excluded from the fit).
CORNER_TURN_RAD = 0.3
#: Outline curvature (1/px) above which the edge model's linear curvature bias no longer
#: holds (radius < 4 px, a few blur widths): such stretches are treated like corners.
MAX_EDGE_CURVATURE = 0.25
#: After two iterations a converging fit moves far less than this (px at the rim).
MAX_LATE_STEP_PX = 0.3


@dataclass(frozen=True)
class FitSettings:
    """Knobs of the silhouette fit (docs/stage1.md); defaults suit ~1 px blur."""

    band_px: float = 3.5            # half-width of the pixel band about the outline
    segment_px: float = 8.0         # contour segment length
    corner_clear_px: float = 3.0    # segments this close to a sharp corner are not used
    min_fill: float = 0.6           # a segment needs this fraction of its expected pixels
    max_iter: int = 8               # pose iterations (band rebuilt each time)
    tol_px: float = 2e-4            # stop when the pose moves less than this (px at the rim)
    outlier_sigma: float = 4.0      # segment offsets beyond this many robust sigma are dropped
    hac_lags: int = 3               # Newey-West lags over contour-ordered segments
    fit_curvature_bias: bool = True
    fringe_width_ratio: float = 1.2  # fringe profile width / edge width (1.2-1.4 alike)
    cold_rounds: int = 8            # stage-A outer rounds from a cold start (no noise model)
    warm_rounds: int = 2            # stage-A outer rounds warm-started from the last pose
    dark_level: str = "tied"        # "tied": D = r L + c image-wide; "segment": D per segment

    def __post_init__(self):
        if self.dark_level not in ("tied", "segment"):
            raise ValueError(f"FitSettings.dark_level: expected 'tied' or 'segment', got "
                             f"{self.dark_level!r}")


@dataclass(frozen=True, eq=False)
class Template:
    """The body's outline in one view at zero pose: reference point at the origin, projected
    axis along the first view axis; view-plane metres, counter-clockwise."""

    outline_m: np.ndarray
    centroid_m: np.ndarray        # area centroid relative to the reference point
    area_m2: float
    tilt_rad: float
    axisymmetric_point: bool      # a sphere: the in-plane angle is not observable
    principal_is_axis: bool       # the body axis is the major (True) or minor principal axis


def make_template(body: Body, view_name: str, tilt_rad: float = 0.0,
                  n_points: int = 1024) -> Template:
    """Outline template of ``body`` for a view (``"top"``/``"side"``) at out-of-plane tilt."""
    axes = VIEW_AXES[view_name]
    P = np.zeros((2, 3))
    P[0, axes[0]] = 1.0
    P[1, axes[1]] = 1.0
    out_axis = 3 - axes[0] - axes[1]
    a = np.zeros(3)
    a[axes[0]] = math.cos(tilt_rad)
    a[out_axis] = math.sin(tilt_rad)
    R_FB = FLIP @ quat_to_matrix(quat_from_axis_roll(a))
    poly = silhouette(body, R_FB, np.zeros(3), P, n_points=n_points)
    area, centroid, m2 = _polygon_moments(poly)
    # principal axes of the outline: is the body axis (the first view axis) the major one?
    principal_is_axis = bool(m2[0, 0] >= m2[1, 1])
    return Template(outline_m=poly, centroid_m=centroid, area_m2=area, tilt_rad=float(tilt_rad),
                    axisymmetric_point=body.kind == "sphere",
                    principal_is_axis=principal_is_axis)


def _polygon_moments(poly: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Area, centroid and central second-moment matrix (per unit area) of a simple polygon."""
    ref = poly.mean(axis=0)
    x, y = poly[:, 0] - ref[0], poly[:, 1] - ref[1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    a = 0.5 * cr.sum()
    cx = ((x + xn) * cr).sum() / (6 * a)
    cy = ((y + yn) * cr).sum() / (6 * a)
    ixx = ((x * x + x * xn + xn * xn) * cr).sum() / (12 * a) - cx * cx
    iyy = ((y * y + y * yn + yn * yn) * cr).sum() / (12 * a) - cy * cy
    ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cr).sum() / (24 * a) - cx * cy
    return abs(a), np.array([cx, cy]) + ref, np.array([[ixx, ixy], [ixy, iyy]])


def _rot(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s], [s, c]])


def outline_px(template: Template, pose: tuple[float, float, float],
               image_to_plane: np.ndarray) -> np.ndarray:
    """The template at ``pose = (a_m, b_m, phi_rad)`` in pixels ``(N, 2)`` (u, v)."""
    a, b, phi = pose
    plane = template.outline_m @ _rot(phi).T + np.array([a, b])
    return apply_affine(affine_inverse(image_to_plane), plane)


# =============================================================================== outline geometry


@dataclass(frozen=True, eq=False)
class _Outline:
    """Per-edge geometry of the pixel-space outline polygon."""

    p0: np.ndarray        # (N, 2) edge start, px
    d: np.ndarray         # (N, 2) edge vector, px
    ell: np.ndarray       # (N,) edge length
    normal: np.ndarray    # (N, 2) outward unit normal
    kv: np.ndarray        # (N,) curvature at the edge's start vertex, 1/px
    straight: np.ndarray  # (N,) a flat (single long edge): curvature 0 along it
    s0: np.ndarray        # (N,) arc length at the edge start
    corner_s: np.ndarray  # arc lengths of the sharp corners
    perimeter: float


def _outline_geometry(poly: np.ndarray, corner_clear_px: float) -> _Outline:
    d = np.roll(poly, -1, axis=0) - poly
    ell = np.hypot(d[:, 0], d[:, 1])
    keep = ell > 1e-9
    poly, d, ell = poly[keep], d[keep], ell[keep]
    n = len(poly)
    area2 = np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    t = d / ell[:, None]
    # outward normal: for a counter-clockwise polygon (positive shoelace in (u, v) axes),
    # outward is the tangent turned clockwise, (t_v, -t_u)
    sgn = 1.0 if area2 > 0 else -1.0
    nrm = sgn * np.column_stack([t[:, 1], -t[:, 0]])
    ang = np.arctan2(t[:, 1], t[:, 0])
    turn = np.abs(np.angle(np.exp(1j * (ang - np.roll(ang, 1)))))  # at vertex i (edges i-1, i)
    straight = ell > 1.5  # arc chords are sub-pixel; flats are single long edges
    prev_len, next_len = np.roll(ell, 1), ell
    prev_st, next_st = np.roll(straight, 1), straight
    kv = np.zeros(n)
    both = ~prev_st & ~next_st
    kv[both] = turn[both] / (0.5 * (prev_len[both] + next_len[both]))
    one = prev_st ^ next_st
    arc_len = np.where(prev_st, next_len, prev_len)
    kv[one] = 2.0 * turn[one] / arc_len[one]
    corner_v = ((turn > CORNER_TURN_RAD) | (prev_st & next_st & (turn > 1e-6))
                | (kv > MAX_EDGE_CURVATURE))
    s0 = np.concatenate([[0.0], np.cumsum(ell)[:-1]])
    perim = float(ell.sum())
    return _Outline(p0=poly, d=d, ell=ell, normal=nrm, kv=kv, straight=straight, s0=s0,
                    corner_s=s0[corner_v], perimeter=perim)


@numba.njit(cache=True)
def _band_kernel(p0, dv, ell, nrm, band, u_lo, v_lo, best, sd, edge, tt):
    """For every ROI pixel within ``band`` px of the polygon: the signed distance to the
    polygon (+ outside), the nearest edge and the foot's fraction along it. Exact (brute
    force over each edge's neighbourhood); ROI arrays are (rows, cols), ``best`` starts at inf.
    """
    H, W = best.shape
    # a pixel within ``band`` of the polygon is within ``band`` of its nearest edge, so that
    # edge's box (+-band) holds it: every kept pixel sees the same nearest edge
    reach = band
    for e in range(p0.shape[0]):
        ax, ay = p0[e, 0], p0[e, 1]
        bx, by = ax + dv[e, 0], ay + dv[e, 1]
        L2 = ell[e] * ell[e]
        u0 = max(int(math.floor(min(ax, bx) - reach)) - u_lo, 0)
        u1 = min(int(math.ceil(max(ax, bx) + reach)) - u_lo, W - 1)
        v0 = max(int(math.floor(min(ay, by) - reach)) - v_lo, 0)
        v1 = min(int(math.ceil(max(ay, by) + reach)) - v_lo, H - 1)
        for r in range(v0, v1 + 1):
            y = float(r + v_lo)
            for c in range(u0, u1 + 1):
                x = float(c + u_lo)
                t = ((x - ax) * dv[e, 0] + (y - ay) * dv[e, 1]) / L2
                if t < 0.0:
                    t = 0.0
                elif t > 1.0:
                    t = 1.0
                fx = ax + t * dv[e, 0]
                fy = ay + t * dv[e, 1]
                rx, ry = x - fx, y - fy
                dd = rx * rx + ry * ry
                if dd < best[r, c]:
                    best[r, c] = dd
                    s = rx * nrm[e, 0] + ry * nrm[e, 1]
                    sd[r, c] = math.sqrt(dd) if s >= 0.0 else -math.sqrt(dd)
                    edge[r, c] = e
                    tt[r, c] = t


def _band_pixels(geo: _Outline, band: float, shape: tuple[int, int]):
    """Pixels within ``band`` px of the outline: linear index, signed distance, edge, t."""
    H, W = shape
    lo = np.floor(geo.p0.min(axis=0) - band - 2).astype(int)
    hi = np.ceil(geo.p0.max(axis=0) + band + 2).astype(int)
    u_lo, v_lo = max(lo[0], 0), max(lo[1], 0)
    u_hi, v_hi = min(hi[0], W - 1), min(hi[1], H - 1)
    if u_hi < u_lo or v_hi < v_lo:
        z = np.zeros(0)
        return z.astype(np.int64), z, z.astype(np.int64), z
    shp = (v_hi - v_lo + 1, u_hi - u_lo + 1)
    best = np.full(shp, np.inf)
    sd = np.zeros(shp)
    edge = np.zeros(shp, np.int64)
    tt = np.zeros(shp)
    _band_kernel(geo.p0, geo.d, geo.ell, geo.normal, float(band), int(u_lo), int(v_lo),
                 best, sd, edge, tt)
    return _band_collect(best, sd, edge, tt, float(band * band), int(u_lo), int(v_lo), int(W))


@numba.njit(cache=True)
def _band_collect(best, sd, edge, tt, band2, u_lo, v_lo, W):
    """The ROI pixels with ``best <= band2``, row-major: linear index, sd, edge, t."""
    H_r, W_r = best.shape
    n = 0
    for r in range(H_r):
        for c in range(W_r):
            if best[r, c] <= band2:
                n += 1
    lin = np.empty(n, np.int64)
    sd_o = np.empty(n)
    e_o = np.empty(n, np.int64)
    t_o = np.empty(n)
    j = 0
    for r in range(H_r):
        for c in range(W_r):
            if best[r, c] <= band2:
                lin[j] = (r + v_lo) * W + (c + u_lo)
                sd_o[j] = sd[r, c]
                e_o[j] = edge[r, c]
                t_o[j] = tt[r, c]
                j += 1
    return lin, sd_o, e_o, t_o


# =============================================================================== stage A


#: Normalization of the fringe profile: ``h`` peaks at +-1 (at one fringe width from the edge).
PHI1 = math.exp(-0.5) / SQRT2PI


@numba.njit(cache=True)
def _edge_profile(x, s, ratio):
    """The edge model's shape at ``x = delta - d`` (px) for edge width ``s``: the step
    ``g = Phi(x / s)``, its derivative ``p = phi(x / s)`` (per unit x / s), the fringe
    ``h = -z_f phi(z_f) / phi(1)`` with ``z_f = x / (ratio s)`` (+1 at one fringe width
    outside the edge, -1 inside: the second derivative of a blurred step, scaled), and
    ``hp = dh / dz_f``."""
    z = x / s
    g = 0.5 * math.erfc(-z / math.sqrt(2.0))
    p = math.exp(-0.5 * z * z) / SQRT2PI
    zf = z / ratio
    pf = math.exp(-0.5 * zf * zf) / SQRT2PI
    return g, p, -zf * pf / PHI1, -(1.0 - zf * zf) * pf / PHI1


@numba.njit(cache=True)
def _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, Hg, bg, G, P, Hh, Hp,
                   reuse, want_global, tied, rc):
    """Gauss-Newton normal equations per segment for (L, D, delta), and for the image's
    global edge profile ``prof = (s0, a0, s4, a4)`` (segment q's width ``s0 + s4 c4[q]``, its
    fringe amplitude ``a0 + a4 c4[q]``) into ``Hg`` (4x4) and ``bg``. Returns sum w r^2.
    ``reuse``: take each pixel's profile values from ``G, P, Hh, Hp`` (filled by the
    noise-model pass at the same state) instead of computing them; ``want_global``: fill
    ``Hg, bg`` too (only the profile step needs them). ``tied``: the dark level is not a
    segment's own unknown but ``D = rc[0] L + rc[1]`` (image-wide ``rc``, two more global
    unknowns: ``Hg`` is then 6x6); the D row of each segment's system is left empty."""
    A[:] = 0.0
    b[:] = 0.0
    Hg[:] = 0.0
    bg[:] = 0.0
    chi2 = 0.0
    for j in range(I.shape[0]):
        kk = k[j]
        s = prof[0] + prof[2] * c4[kk]
        a = prof[1] + prof[3] * c4[kk]
        x = delta[kk] - d[j]
        if reuse:
            g, p, h, hp = G[j], P[j], Hh[j], Hp[j]
        else:
            g, p, h, hp = _edge_profile(x, s, ratio)
        Lk = L[kk]
        Dk = D[kk]
        r = I[j] - (Lk * (1.0 - g) + Dk * g + a * Lk * h)
        c0 = 1.0 - g + a * h
        c1 = g
        if tied:
            c0 += rc[0] * g
            c1 = 0.0
        c2 = ((Dk - Lk) * p + a * Lk * hp / ratio) / s
        ww = w[j]
        A[kk, 0, 0] += ww * c0 * c0
        A[kk, 0, 1] += ww * c0 * c1
        A[kk, 0, 2] += ww * c0 * c2
        A[kk, 1, 1] += ww * c1 * c1
        A[kk, 1, 2] += ww * c1 * c2
        A[kk, 2, 2] += ww * c2 * c2
        b[kk, 0] += ww * c0 * r
        b[kk, 1] += ww * c1 * r
        b[kk, 2] += ww * c2 * r
        chi2 += ww * r * r
        if not want_global:
            continue
        # global profile: d/ds = -c2 x / s, d/da = L h; the cos(4 theta) parts times c4
        js = -c2 * x / s
        ja = Lk * h
        jv = (js, ja, js * c4[kk], ja * c4[kk], Lk * g, g)
        ng = Hg.shape[0]
        for i0 in range(ng):
            bg[i0] += ww * jv[i0] * r
            for i1 in range(i0, ng):
                Hg[i0, i1] += ww * jv[i0] * jv[i1]
    for i0 in range(Hg.shape[0]):
        for i1 in range(i0):
            Hg[i0, i1] = Hg[i1, i0]
    for kk in range(A.shape[0]):
        if tied:
            A[kk, 1, 1] = 1.0   # D is no segment unknown: its step solves to 0
        A[kk, 1, 0] = A[kk, 0, 1]
        A[kk, 2, 0] = A[kk, 0, 2]
        A[kk, 2, 1] = A[kk, 1, 2]
    return chi2


def _ridge(A: np.ndarray) -> None:
    """Tiny ridge on each segment's 3x3 normal matrix: a segment whose pixels all lie on one
    side of the edge keeps its unseen level instead of making the system singular."""
    tr = np.trace(A, axis1=1, axis2=2)[:, None]
    idx = np.arange(3)
    A[:, idx, idx] += 1e-9 * tr + 1e-15


@numba.njit(cache=True)
def _solve3_ridge(A, b):
    """Solve a symmetric 3x3 system (Cramer's rule) with a tiny relative ridge: a one-sided
    segment keeps its unseen level instead of making the system singular."""
    r = 1e-9 * (A[0, 0] + A[1, 1] + A[2, 2]) + 1e-15
    a00, a11, a22 = A[0, 0] + r, A[1, 1] + r, A[2, 2] + r
    a01, a02, a12 = A[0, 1], A[0, 2], A[1, 2]
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    out = np.empty(3)
    out[0] = (c00 * b[0] + c01 * b[1] + c02 * b[2]) / det
    out[1] = (c01 * b[0] + c11 * b[1] + c12 * b[2]) / det
    out[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) / det
    return out


@numba.njit(cache=True)
def _profile_step(prof, Hg, bg, rc):
    """Damped, bounded Gauss-Newton step of the global edge profile ``(s0, a0, s4, a4)``
    and, when ``Hg`` is 6x6, of the tied dark level's ``rc`` (full step: it is linear)."""
    Hr = Hg.copy()
    ng = Hg.shape[0]
    tr = 0.0
    for i in range(ng):
        tr += Hg[i, i]
    for i in range(ng):
        Hr[i, i] += 1e-9 * tr + 1e-15
    st = np.linalg.solve(Hr, bg)
    for i in range(ng):
        if not math.isfinite(st[i]):
            return
    if ng == 6:
        rc[0] = min(max(rc[0] + st[4], -0.5), 0.95)
        rc[1] = min(max(rc[1] + st[5], -0.5), 0.95)
    # damped and bounded: a strong fringe is nearly the shape of a width change, and a full
    # step can throw the width (and every offset) far off
    s = prof[0]
    prof[0] = min(max(s + 0.5 * st[0], max(0.8 * s, 0.2)), min(1.25 * s, 5.0))
    prof[1] = min(max(prof[1] + 0.5 * st[1], -0.5), 0.5)
    prof[2] = min(max(prof[2] + 0.5 * st[2], -0.2 * prof[0]), 0.2 * prof[0])
    prof[3] = min(max(prof[3] + 0.5 * st[3], -0.5), 0.5)


@numba.njit(cache=True)
def _segment_fit(I, d, k, K, c4, prof0, ratio, coef_in, has_coef, n_outer, L0, D0, tied):
    """Stage A's iterations in one compiled loop (see :func:`_stage_a`): per-segment levels
    and offsets by Gauss-Newton, the damped global edge profile (width and fringe), the noise
    model, and each offset's formal variance. ``tied``: each segment's dark level is
    ``D = r L + c`` with image-wide ``(r, c)`` (``FitSettings.dark_level``)."""
    n = I.shape[0]
    L = np.full(K, L0)
    D = np.full(K, D0)
    cntL = np.zeros(K)
    cntD = np.zeros(K)
    sumL = np.zeros(K)
    sumD = np.zeros(K)
    for j in range(n):
        if d[j] > 2.0:
            sumL[k[j]] += I[j]
            cntL[k[j]] += 1.0
        elif d[j] < -2.0:
            sumD[k[j]] += I[j]
            cntD[k[j]] += 1.0
    for q in range(K):
        if cntL[q] > 0:
            L[q] = sumL[q] / cntL[q]
        if cntD[q] > 0:
            D[q] = sumD[q] / cntD[q]
    rc = np.array([D0 / L0 if L0 > 0.0 else 0.0, 0.0])
    if tied:
        for q in range(K):
            D[q] = rc[0] * L[q] + rc[1]
    delta = np.zeros(K)
    prof = prof0.copy()
    w = np.ones(n)
    coef = coef_in.copy()
    if has_coef:
        for j in range(n):
            m0 = min(max(I[j], 0.0), 1.0)
            w[j] = 1.0 / max(coef[0] + coef[1] * m0 + coef[2] * m0 * m0,
                             0.2 * max(coef[0] + 0.5 * coef[1] + 0.25 * coef[2], 1e-12))
    A = np.empty((K, 3, 3))
    b = np.empty((K, 3))
    ng = 6 if tied else 4
    Hg = np.empty((ng, ng))
    bg = np.empty(ng)
    G = np.empty(n)
    P = np.empty(n)
    Hh = np.empty(n)
    Hp = np.empty(n)
    reuse = False   # G, P, Hh, Hp hold the current state's profile (after a noise-model pass)
    chi2 = 0.0
    for outer in range(n_outer):
        for _ in range(2):
            _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, Hg, bg,
                           G, P, Hh, Hp, reuse, False, tied, rc)
            reuse = False
            for q in range(K):
                st = _solve3_ridge(A[q], b[q])
                L[q] += st[0]
                D[q] = rc[0] * L[q] + rc[1] if tied else D[q] + st[1]
                delta[q] += min(max(st[2], -1.5), 1.5)
        _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, Hg, bg,
                       G, P, Hh, Hp, False, True, tied, rc)
        _profile_step(prof, Hg, bg, rc)
        if tied:
            for q in range(K):
                D[q] = rc[0] * L[q] + rc[1]
        if outer == 0 or outer == n_outer - 1:
            # noise model var = v0 + v1 m + v2 m^2 from the residuals (m = model intensity)
            N = np.zeros((3, 3))
            rhs = np.zeros(3)
            mean_r2 = 0.0
            for j in range(n):
                kk = k[j]
                s = prof[0] + prof[2] * c4[kk]
                a = prof[1] + prof[3] * c4[kk]
                g, p, h, hp = _edge_profile(delta[kk] - d[j], s, ratio)
                G[j] = g
                P[j] = p
                Hh[j] = h
                Hp[j] = hp
                m = L[kk] * (1.0 - g) + D[kk] * g + a * L[kk] * h
                r2 = (I[j] - m) ** 2
                mean_r2 += r2
                x0, x1, x2 = 1.0, m, m * m
                N[0, 0] += x0 * x0
                N[0, 1] += x0 * x1
                N[0, 2] += x0 * x2
                N[1, 1] += x1 * x1
                N[1, 2] += x1 * x2
                N[2, 2] += x2 * x2
                rhs[0] += x0 * r2
                rhs[1] += x1 * r2
                rhs[2] += x2 * r2
            N[1, 0] = N[0, 1]
            N[2, 0] = N[0, 2]
            N[2, 1] = N[1, 2]
            coef = _solve3_ridge(N, rhs)
            floor = max(0.2 * mean_r2 / n, 1e-12)   # no pixel weighs > 5x the average
            for j in range(n):
                kk = k[j]
                m = (L[kk] * (1.0 - G[j]) + D[kk] * G[j]
                     + (prof[1] + prof[3] * c4[kk]) * L[kk] * Hh[j])
                w[j] = 1.0 / max(coef[0] + coef[1] * m + coef[2] * m * m, floor)
            reuse = True
    chi2 = _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, Hg, bg,
                          G, P, Hh, Hp, reuse, False, tied, rc)
    scale = chi2 / max(n - (2 * K + 6 if tied else 3 * K), 1)
    var_delta = np.empty(K)
    e3 = np.zeros(3)
    e3[2] = 1.0
    contrast = np.abs(L - D)
    typical = np.median(contrast)
    for q in range(K):
        var_delta[q] = _solve3_ridge(A[q], e3)[2] * scale
        # a segment whose edge ran off or lost its contrast carries no information
        if abs(delta[q]) > 2.0 or contrast[q] < 0.3 * typical or not var_delta[q] > 0.0:
            var_delta[q] = np.inf
    return L, D, delta, var_delta, prof, coef, w, chi2


@dataclass(frozen=True, eq=False)
class EdgeSegments:
    """Per-segment edge offsets of one pose iteration (stage A)."""

    delta_px: np.ndarray      # (K,) edge offset along the outward normal
    var_px2: np.ndarray       # (K,) its variance (formal, from the fitted noise model)
    normal: np.ndarray        # (K, 2) mean outward normal, px
    foot_px: np.ndarray       # (K, 2) mean outline point, px
    kappa: np.ndarray         # (K,) mean curvature, 1/px
    bright: np.ndarray        # (K,) L
    dark: np.ndarray          # (K,) D
    index: np.ndarray         # (K,) segment number along the contour
    edge_sigma_px: float
    resid_rms: float
    noise_coef: np.ndarray    # variance model v0 + v1 m + v2 m^2 (m = model intensity)
    profile: np.ndarray       # global edge profile (s0, a0, s4, a4), see _gn_accumulate
    pixels: dict = field(default_factory=dict)   # per-pixel arrays for the centroid method


@numba.njit(cache=True)
def _segment_geometry(d, k, K, w, L, D, delta, s, e, t, normal, p0, dv, kap_px):
    """Per segment: mean outward normal (x, y), outline point (x, y) and curvature, each
    pixel weighted by its information about the segment's offset."""
    acc = np.zeros((6, K))
    for j in range(d.shape[0]):
        q = k[j]
        z = (delta[q] - d[j]) / s
        p = math.exp(-0.5 * z * z) / SQRT2PI
        c = (D[q] - L[q]) * p / s
        wi = w[j] * (c * c)
        ej = e[j]
        acc[0, q] += wi
        acc[1, q] += wi * normal[ej, 0]
        acc[2, q] += wi * normal[ej, 1]
        acc[3, q] += wi * (p0[ej, 0] + t[j] * dv[ej, 0])
        acc[4, q] += wi * (p0[ej, 1] + t[j] * dv[ej, 1])
        acc[5, q] += wi * kap_px[j]
    return (acc[1] / acc[0], acc[2] / acc[0], acc[3] / acc[0], acc[4] / acc[0],
            acc[5] / acc[0])


def _stage_a(img, geo: _Outline, settings: FitSettings, exclude, profile0: np.ndarray,
             noise_coef=None):
    lin, d, e, t = _band_pixels(geo, settings.band_px, img.shape)
    if len(lin) == 0:
        return None
    # the true outline bulges beyond each chord of a curved stretch by kappa l^2 t (1 - t) / 2
    nxt = (e + 1) % len(geo.kv)
    kap_all = np.where(geo.straight[e], 0.0, (1 - t) * geo.kv[e] + t * geo.kv[nxt])
    d = d - 0.5 * kap_all * geo.ell[e] ** 2 * t * (1.0 - t)
    fs = geo.s0[e] + t * geo.ell[e]
    bad = np.zeros(len(lin), bool)
    if len(geo.corner_s):
        # stretches of outline near a sharp corner: chunked to bound the temporary's size
        for c0 in range(0, len(geo.corner_s), 64):
            cs = geo.corner_s[c0:c0 + 64]
            dist = np.abs(fs[:, None] - cs[None, :])
            dist = np.minimum(dist, geo.perimeter - dist)
            bad |= dist.min(axis=1) < settings.corner_clear_px
    if exclude is not None:
        bad = bad | exclude.ravel()[lin]
    I = img.ravel()[lin]
    nseg = max(int(round(geo.perimeter / settings.segment_px)), 4)
    seg_len = geo.perimeter / nseg
    seg = np.minimum((fs / seg_len).astype(np.int64), nseg - 1)
    expected = np.bincount(seg, minlength=nseg)
    use = ~bad
    got = np.bincount(seg[use], minlength=nseg)
    good_seg = got >= settings.min_fill * np.median(expected[expected > 0])
    use &= good_seg[seg]
    segs = np.flatnonzero(good_seg)
    K = len(segs)
    if K < 8:
        return None
    remap = -np.ones(nseg, np.int64)
    remap[segs] = np.arange(K)
    d_u, I_u = d[use], I[use]
    k = remap[seg[use]]

    out_m, in_m = d_u > 2.0, d_u < -2.0
    L0 = float(np.median(I_u[out_m])) if out_m.any() else 1.0
    D0 = float(np.median(I_u[in_m])) if in_m.any() else 0.0
    has = noise_coef is not None
    coef_in = np.asarray(noise_coef, float) if has else np.zeros(3)
    # each segment's normal angle to the pixel grid, for the profile's cos(4 theta) terms
    e_u = e[use]
    c4 = np.cos(4.0 * np.arctan2(np.bincount(k, geo.normal[e_u, 1], minlength=K),
                                 np.bincount(k, geo.normal[e_u, 0], minlength=K)))
    # a cold start (no noise model yet) needs more rounds for the global profile to settle
    L, D, delta, var_delta, prof, coef, w, chi2 = _segment_fit(
        np.ascontiguousarray(I_u, dtype=np.float64), np.ascontiguousarray(d_u), k, K, c4,
        np.asarray(profile0, float).copy(), float(settings.fringe_width_ratio), coef_in, has,
        settings.warm_rounds if has else settings.cold_rounds, L0, D0,
        settings.dark_level == "tied")
    s = float(prof[0])
    npix = len(I_u)
    # segment geometry, weighted by the pixels' information about delta
    nx, ny, fx, fy, kap = _segment_geometry(d_u, k, K, w, L, D, delta, s, e[use], t[use],
                                            geo.normal, geo.p0, geo.d, kap_all[use])
    nn = np.hypot(nx, ny)
    pixels = {"lin": lin, "d": d, "seg_all": remap[seg], "L": L, "D": D}
    return EdgeSegments(delta_px=delta, var_px2=var_delta, normal=np.column_stack([nx / nn,
                                                                                  ny / nn]),
                        foot_px=np.column_stack([fx, fy]), kappa=kap, bright=L, dark=D,
                        index=segs, edge_sigma_px=s, resid_rms=float(math.sqrt(chi2 / npix)),
                        noise_coef=np.asarray(coef), profile=prof, pixels=pixels)


# =============================================================================== stage B


def _newey_west(X: np.ndarray, e: np.ndarray, lags: int) -> np.ndarray:
    """Newey-West estimate of Var(X^T e) for contour-ordered rows (circular)."""
    xe = X * e[:, None]
    S = xe.T @ xe
    n = len(e)
    for lag in range(1, min(lags, n - 1) + 1):
        wgt = 1.0 - lag / (lags + 1.0)
        G = xe.T @ np.roll(xe, -lag, axis=0)
        S += wgt * (G + G.T)
    return S


@dataclass(frozen=True)
class ViewFit:
    """One view's silhouette measurement (method a) and centroid measurement (method b).

    ``pose`` = (a_m, b_m, phi_rad) in the view plane; ``cov`` its 3x3 covariance (for a sphere
    phi is not measured: 0 with infinite variance). Pixel-space figures are for diagnostics
    and comparison with renderer truth: ``ref_px`` and ``axis_angle_px_rad`` (atan2(dv, du) of
    the nose direction in the image).
    """

    ok: bool
    reason: str
    pose: tuple[float, float, float]
    cov: np.ndarray
    ref_px: tuple[float, float]
    axis_angle_px_rad: float
    sigma_ref_px: tuple[float, float]
    sigma_axis_px_rad: float
    curvature_bias_px2: float
    edge_sigma_px: float
    resid_rms: float              # intensity residual rms (fraction of full scale)
    offset_rms_px: float          # rms of the segment offsets about the fitted outline
    n_segments: int
    n_rejected: int
    iterations: int
    converged: bool
    outline_outside_frac: float
    centroid_ref_px: tuple[float, float]
    centroid_axis_px_rad: float
    centroid_pose: tuple[float, float, float]
    warnings: tuple[str, ...] = ()
    noise_coef: np.ndarray | None = None
    edge_profile: tuple[float, float, float, float] | None = None  # (s0, a0, s4, a4)


def _pose_px(template: Template, pose, M) -> tuple[np.ndarray, float]:
    Minv = affine_inverse(M)
    ref = apply_affine(Minv, np.array(pose[:2]))
    tip = apply_affine(Minv, np.array(pose[:2]) + 1e-3 * np.array([math.cos(pose[2]),
                                                                   math.sin(pose[2])]))
    return ref, math.atan2(tip[1] - ref[1], tip[0] - ref[0])


def fit_silhouette(img: np.ndarray, template: Template, image_to_plane: np.ndarray,
                   pose0: tuple[float, float, float], *, exclude: np.ndarray | None = None,
                   settings: FitSettings | None = None, edge_sigma0: float = 0.9,
                   noise_coef: np.ndarray | None = None,
                   edge_profile0: tuple[float, float, float, float] | None = None,
                   centroid: bool = True) -> ViewFit:
    """Least-squares silhouette fit (method a) from ``pose0``; see the module docstring.

    ``img`` float (H, W) in [0, 1]; ``exclude`` True on pixels not to use (wires, other
    clutter known in advance); ``edge_sigma0`` (or the whole edge profile ``edge_profile0``,
    :attr:`ViewFit.edge_profile`) and ``noise_coef`` (the image's noise model,
    :attr:`ViewFit.noise_coef`) warm-start a refit; ``centroid=False`` skips method (b)
    (an intermediate fit). Never raises for bad data: ``ok`` False
    with a reason.
    """
    settings = FitSettings() if settings is None else settings
    M = np.asarray(image_to_plane, float)
    Minv = affine_inverse(M)
    A_lin = Minv[:, :2]              # plane (m) -> pixel displacement
    Jrot = np.array([[0.0, -1.0], [1.0, 0.0]])
    pose = np.array(pose0, float)
    fit_phi = not template.axisymmetric_point
    # (for a sphere the curvature is the same all round and the term is a radius change: it
    # does not move the centre, but leaving it out lets an uneven set of rejected segments
    # turn the edges' common offset into a centre shift)
    fit_c = settings.fit_curvature_bias
    nan3 = np.full((3, 3), np.nan)
    H, W = img.shape
    profile = (np.array(edge_profile0, float) if edge_profile0 is not None
               else np.array([edge_sigma0, 0.0, 0.0, 0.0]))
    converged = False
    seg = None
    cov = nan3
    c_bias = 0.0
    n_rej = 0
    it = 0
    outside = 0.0
    diverged = False
    for it in range(1, settings.max_iter + 1):  # noqa: B007 (it is reported)
        poly = outline_px(template, pose, M)
        inside = ((poly[:, 0] >= settings.band_px) & (poly[:, 0] <= W - 1 - settings.band_px)
                  & (poly[:, 1] >= settings.band_px) & (poly[:, 1] <= H - 1 - settings.band_px))
        outside = 1.0 - float(inside.mean())
        if outside > 0.5:
            return _failed(f"model mostly out of frame ({outside:.0%} of its outline)", pose,
                           outside)
        geo = _outline_geometry(poly, settings.corner_clear_px)
        seg = _stage_a(img, geo, settings, exclude, profile, noise_coef)
        if seg is None:
            return _failed("too few usable edge segments", pose, outside)
        profile = seg.profile
        noise_coef = seg.noise_coef
        ref_px = apply_affine(Minv, pose[:2])
        lever = apply_affine(M, seg.foot_px) - pose[:2]            # plane, m
        cols = [seg.normal @ A_lin[:, 0], seg.normal @ A_lin[:, 1]]
        if fit_phi:
            cols.append(np.einsum("ij,ij->i", seg.normal, (lever @ Jrot.T) @ A_lin.T))
        if fit_c:
            cols.append(-seg.kappa)
        X = np.column_stack(cols)
        y = seg.delta_px
        wts = 1.0 / seg.var_px2
        keep = np.isfinite(y) & np.isfinite(wts) & (wts > 0)
        for _ in range(3):  # robust: drop outlying segments (dust, wire crossings)
            sw = np.sqrt(wts[keep])
            colscale = np.linalg.norm(X[keep] * sw[:, None], axis=0)
            colscale[colscale == 0] = 1.0
            beta, *_ = np.linalg.lstsq(X[keep] * sw[:, None] / colscale, y[keep] * sw,
                                       rcond=None)
            beta = beta / colscale
            e = (y - X @ beta) * np.sqrt(wts)
            mad = 1.4826 * np.median(np.abs(e[keep] - np.median(e[keep])))
            new_keep = keep & (np.abs(e) <= settings.outlier_sigma * max(mad, 1e-12))
            if new_keep.sum() == keep.sum() or new_keep.sum() < 0.5 * keep.sum():
                break   # nothing more to drop, or a noise-free image (mad ~ 0)
            keep = new_keep
        n_rej = int((~keep).sum())
        npar = X.shape[1]
        if keep.sum() < npar + 5:
            return _failed("too few consistent edge segments", pose, outside)
        # covariance: Newey-West sandwich on the kept, contour-ordered segments
        Xw = X[keep] * np.sqrt(wts[keep])[:, None]
        ew = (y[keep] - X[keep] @ beta) * np.sqrt(wts[keep])
        bread = np.linalg.pinv(Xw.T @ Xw)
        meat = _newey_west(Xw, ew, settings.hac_lags)
        n_k = int(keep.sum())
        cov_b = bread @ meat @ bread * n_k / max(n_k - npar, 1)
        dpose = np.zeros(3)
        dpose[0], dpose[1] = beta[0], beta[1]
        if fit_phi:
            dpose[2] = beta[2]
        if it > 3:   # damp late iterations: re-banding noise can make full steps oscillate
            dpose *= 0.5
        rim = 0.5 * math.sqrt(template.area_m2 / math.pi) / math.sqrt(abs(np.linalg.det(M[:, :2])))
        move = np.hypot(*(A_lin @ dpose[:2])) + (abs(dpose[2]) * rim if fit_phi else 0.0)
        if it > 2 and move > MAX_LATE_STEP_PX:
            # a converging fit does not jump late: a stage-A failure (a strong fringe, a
            # clutter feature) produced this step; keep the last pose and say so
            diverged = True
            break
        c_bias = float(beta[-1]) if fit_c else 0.0
        pose = pose + dpose
        cov = np.full((3, 3), 0.0)
        idx = [0, 1, 2] if fit_phi else [0, 1]
        cov[np.ix_(idx, idx)] = cov_b[: len(idx), : len(idx)]
        if not fit_phi:
            cov[2, 2] = np.inf
        # converged: the step is below the tolerance or a small fraction of the pose's own
        # sigma (re-banding at a new pose re-draws the noise; steps below that are jitter)
        sig_px = math.sqrt(max(np.trace(A_lin @ cov[:2, :2] @ A_lin.T), 0.0))
        if move < max(settings.tol_px, 0.5 * sig_px):
            converged = True
            break
    ref_px, ang_px = _pose_px(template, pose, M)
    # pixel-space sigmas by linear propagation
    Jp = np.zeros((3, 3))
    Jp[:2, :2] = A_lin
    h = 1e-7
    _, a_plus = _pose_px(template, pose + [0, 0, h], M)
    Jp[2, 2] = (a_plus - ang_px) / h
    cov_fin = np.where(np.isfinite(cov), cov, 0.0)
    cov_px = Jp @ cov_fin @ Jp.T
    # offsets about the fitted outline (a sphere: about its mean, the radius change)
    resid = seg.delta_px + c_bias * seg.kappa
    nan2 = (math.nan, math.nan)
    cen = (centroid_pose(img, template, M, pose, seg, exclude) if centroid
           else (nan2, math.nan, (math.nan,) * 3))
    warnings = []
    if diverged:
        warnings.append(f"silhouette fit: a late step of > {MAX_LATE_STEP_PX} px was rejected "
                        f"(edge model failing in part of the outline); last pose kept")
    elif not converged:
        warnings.append(f"silhouette fit not converged in {settings.max_iter} iterations")
    if outside > 0.0:
        warnings.append(f"model partly out of frame ({outside:.0%} of its outline)")
    return ViewFit(
        ok=True, reason="", pose=tuple(float(x) for x in pose), cov=cov,
        ref_px=(float(ref_px[0]), float(ref_px[1])), axis_angle_px_rad=float(ang_px),
        sigma_ref_px=(float(math.sqrt(cov_px[0, 0])), float(math.sqrt(cov_px[1, 1]))),
        sigma_axis_px_rad=float(math.sqrt(cov_px[2, 2])) if fit_phi else math.inf,
        curvature_bias_px2=c_bias, edge_sigma_px=seg.edge_sigma_px, resid_rms=seg.resid_rms,
        offset_rms_px=float(np.sqrt(np.mean(resid ** 2))), n_segments=len(seg.delta_px),
        n_rejected=n_rej, iterations=it, converged=converged, outline_outside_frac=outside,
        centroid_ref_px=cen[0], centroid_axis_px_rad=cen[1], centroid_pose=cen[2],
        warnings=tuple(warnings), noise_coef=seg.noise_coef,
        edge_profile=tuple(float(x) for x in seg.profile))


def _failed(reason: str, pose, outside: float) -> ViewFit:
    nan = math.nan
    return ViewFit(ok=False, reason=reason, pose=tuple(float(x) for x in pose),
                   cov=np.full((3, 3), np.nan), ref_px=(nan, nan), axis_angle_px_rad=nan,
                   sigma_ref_px=(nan, nan), sigma_axis_px_rad=nan, curvature_bias_px2=nan,
                   edge_sigma_px=nan, resid_rms=nan, offset_rms_px=nan, n_segments=0,
                   n_rejected=0, iterations=0, converged=False,
                   outline_outside_frac=outside, centroid_ref_px=(nan, nan),
                   centroid_axis_px_rad=nan, centroid_pose=(nan, nan, nan))


# =============================================================================== method (b)


def centroid_pose(img, template: Template, M, pose, seg: EdgeSegments, exclude=None):
    """Area-moment pose (method b) with subpixel thresholding; see the module docstring.

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
    poly = outline_px(template, pose, M)
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
    Minv = affine_inverse(M)
    if template.axisymmetric_point:
        phi_img = math.nan
        c_plane = apply_affine(M, np.array([cu, cv]))
        ref_plane = c_plane - template.centroid_m
        ref_px = apply_affine(Minv, ref_plane)
        return (float(ref_px[0]), float(ref_px[1])), phi_img, (float(ref_plane[0]),
                                                               float(ref_plane[1]), math.nan)
    # principal axis in the image, then the nose direction closest to the fitted one
    ev, evec = np.linalg.eigh(np.array([[muu, muv], [muv, mvv]]))
    ax = evec[:, 1] if template.principal_is_axis else evec[:, 0]
    _, ang_fit = _pose_px(template, pose, M)
    if ax @ np.array([math.cos(ang_fit), math.sin(ang_fit)]) < 0:
        ax = -ax
    # to the plane: angle of the mapped direction
    dirp = M[:, :2] @ ax
    phi = math.atan2(dirp[1], dirp[0])
    c_plane = apply_affine(M, np.array([cu, cv]))
    ref_plane = c_plane - _rot(phi) @ template.centroid_m
    ref_px = apply_affine(Minv, ref_plane)
    return ((float(ref_px[0]), float(ref_px[1])), float(math.atan2(ax[1], ax[0])),
            (float(ref_plane[0]), float(ref_plane[1]), float(phi)))


# =============================================================================== locate


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


def locate_model(img: np.ndarray, template: Template, image_to_plane: np.ndarray,
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
    scale_px = math.sqrt(abs(np.linalg.det(np.asarray(image_to_plane)[:, :2])))
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
                     image_to_plane: np.ndarray) -> tuple[float, float, float]:
    """Plane pose ``(a, b, phi)`` from a coarse blob: centroid minus the template offset."""
    M = np.asarray(image_to_plane, float)
    c_plane = apply_affine(M, np.array(coarse.centroid_px))
    if template.axisymmetric_point:
        ref = c_plane - template.centroid_m
        return float(ref[0]), float(ref[1]), 0.0
    ax = np.array([math.cos(coarse.angle_px_rad), math.sin(coarse.angle_px_rad)])
    dirp = M[:, :2] @ ax
    phi = math.atan2(dirp[1], dirp[0])
    ref = c_plane - _rot(phi) @ template.centroid_m
    return float(ref[0]), float(ref[1]), float(phi)
