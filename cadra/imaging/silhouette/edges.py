"""Stage A of the silhouette least squares: per-segment edge offsets about a trial outline.

The outline (:func:`outline_geometry`: per-edge normals, curvature, sharp corners) is placed
at a trial pose; pixels within a band of it (:func:`band_pixels`, exact signed distances) are
grouped into short contour segments, and in each segment a blurred-edge model
``I = L (1 - g) + D g + a L h``, ``g = Phi((delta - d) / s)`` (d the pixel centre's signed
distance from the outline, + outside; L the local bright level, D the dark level, tied to it
image-wide as ``D = r L + c`` by default; s the edge width; ``a L h`` the diffraction fringe,
:func:`_edge_profile`) gives the segment's edge offset ``delta`` along the outward normal with
its variance (:func:`stage_a`). The edge width and the fringe amplitude are fitted per image,
each as ``x0 + x4 cos(4 theta)`` (theta the normal's angle to the pixel grid). The method is
described in :mod:`cadra.imaging.silhouette.fit` and docs/stage1.md; all lengths in pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

SQRT2PI = math.sqrt(2.0 * math.pi)

#: Turning angle above which an outline vertex is a sharp corner (excluded from the fit).
CORNER_TURN_RAD = 0.3
#: Outline curvature (1/px) above which the edge model's linear curvature bias no longer
#: holds (radius < 4 px, a few blur widths): such stretches are treated like corners.
MAX_EDGE_CURVATURE = 0.25
#: Largest edge width (the profile's sigma, px) stage A fits. A fit that ends there is not
#: following edges (a template far from the outline, a finned body at a wrong roll): real
#: optics at this scale blur to about 1 px.
MAX_EDGE_SIGMA_PX = 5.0


@dataclass(frozen=True, eq=False)
class Outline:
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


def outline_geometry(poly: np.ndarray) -> Outline:
    """Per-edge geometry of the pixel outline ``poly`` (N, 2): normals, vertex curvature,
    flats, arc length and the sharp corners (turn > :data:`CORNER_TURN_RAD`, or curvature
    > :data:`MAX_EDGE_CURVATURE`) that stage A keeps clear of."""
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
    return Outline(p0=poly, d=d, ell=ell, normal=nrm, kv=kv, straight=straight, s0=s0,
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


def band_pixels(geo: Outline, band: float, shape: tuple[int, int]):
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
def gn_workspace(n, K, tied):
    """The arrays :func:`_gn_accumulate` fills: per-segment normal equations ``A, b``, the
    global profile's ``Hg, bg`` (6 unknowns with a tied dark level, else 4) and the pixels'
    profile values ``G, P, Hh, Hp``."""
    ng = 6 if tied else 4
    return (np.empty((K, 3, 3)), np.empty((K, 3)), np.empty((ng, ng)), np.empty(ng),
            np.empty(n), np.empty(n), np.empty(n), np.empty(n))


@numba.njit(cache=True)
def pixel_terms(Lk, Dk, g, p, h, hp, a, s, ratio, tied, r):
    """One pixel's edge model ``m = L (1 - g) + D g + a L h`` and its derivatives
    ``(c0, c1, c2)`` by the segment's L, D and offset (``tied``: D = r L + c is no unknown,
    ``c1 = 0``); ``g, p, h, hp`` from :func:`_edge_profile` at width ``s``."""
    c0 = 1.0 - g + a * h
    c1 = g
    if tied:
        c0 += r * g
        c1 = 0.0
    c2 = ((Dk - Lk) * p + a * Lk * hp / ratio) / s
    return Lk * (1.0 - g) + Dk * g + a * Lk * h, c0, c1, c2


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
        mj, c0, c1, c2 = pixel_terms(Lk, D[kk], g, p, h, hp, a, s, ratio, tied, rc[0])
        r = I[j] - mj
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


#: Bounds on the profile's cos(4 theta) terms (the pixel's footprint: a box or a triangle of
#: one variance, so small): |s4| <= S4_MAX s0, |a4| <= max(|a0|, A4_FLOOR). Looser, sharp
#: optics fell into a false minimum (docs/stage1.md, "Sharp optics").
S4_MAX = 0.05
A4_FLOOR = 0.02


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
    prof[0] = min(max(s + 0.5 * st[0], max(0.8 * s, 0.2)), min(1.25 * s, MAX_EDGE_SIGMA_PX))
    prof[1] = min(max(prof[1] + 0.5 * st[1], -0.5), 0.5)
    prof[2] = min(max(prof[2] + 0.5 * st[2], -S4_MAX * prof[0]), S4_MAX * prof[0])
    a4 = max(abs(prof[1]), A4_FLOOR)
    prof[3] = min(max(prof[3] + 0.5 * st[3], -a4), a4)


@numba.njit(cache=True)
def _segment_fit(I, d, k, K, c4, prof0, ratio, coef_in, has_coef, n_outer, L0, D0, tied):
    """Stage A's iterations in one compiled loop (see :func:`stage_a`): per-segment levels
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
        # warm start: floored at a fifth of the model's mean variance, as in the noise pass
        # (its quadratic can dip below 0 mid-range: docs/stage1.md, "A strong fringe")
        vbar = 0.0
        for j in range(n):
            m0 = min(max(I[j], 0.0), 1.0)
            w[j] = coef[0] + coef[1] * m0 + coef[2] * m0 * m0
            vbar += w[j] / n
        for j in range(n):
            w[j] = 1.0 / max(w[j], 0.2 * vbar, 1e-12)
    A, b, Hg, bg, G, P, Hh, Hp = gn_workspace(n, K, tied)
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
    return L, D, delta, var_delta, prof, coef, w, chi2, rc


@dataclass(frozen=True, eq=False)
class StageAState:
    """Stage A's final state, what the offsets' covariance is computed from
    (:func:`cadra.imaging.silhouette.noise.segment_covariance`): the band's pixels (their
    linear index ``lin`` into the image, intensity ``I``, signed distance ``d`` to the outline,
    segment ``k``, weight ``w``), each segment's levels ``L``, ``D`` and offset ``delta``,
    the edge profile ``prof`` and its cos 4θ factors ``c4``, the fringe width ratio, whether
    the dark level is tied, and the ring coefficients ``rc``."""

    lin: np.ndarray
    I: np.ndarray
    d: np.ndarray
    k: np.ndarray
    w: np.ndarray
    L: np.ndarray
    D: np.ndarray
    delta: np.ndarray
    prof: np.ndarray
    c4: np.ndarray
    fringe_ratio: float
    tied: bool
    rc: np.ndarray

    def kernel_args(self) -> tuple:
        """The arguments of the compiled influence kernel after ``lin``, in its order."""
        return (self.I, self.d, self.k, len(self.delta), self.w, self.L, self.D, self.delta,
                self.prof, self.c4, self.fringe_ratio, self.tied, self.rc)


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
    #: per-pixel arrays for the centroid method, and (``FitSettings.covariance`` =
    #: "correlated" or "predicted") ``state``, stage A's final :class:`StageAState`
    pixels: dict = field(default_factory=dict)


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


def stage_a(img, geo: Outline, settings, exclude, profile0: np.ndarray,
            noise_coef=None, band_px: float | None = None) -> EdgeSegments | None:
    """Stage A at one trial outline: every usable segment's edge offset with its variance.

    ``img`` float (H, W); ``geo`` the outline (:func:`outline_geometry`); ``settings`` the
    :class:`cadra.imaging.silhouette.fit.FitSettings`; ``exclude`` True on pixels not to use;
    ``profile0`` the starting edge profile ``(s0, a0, s4, a4)``; ``noise_coef`` a previous
    noise model (a warm start: fewer rounds); ``band_px`` overrides ``settings.band_px``
    (``FitSettings.band_for``; None: the settings' own). None when fewer than 8 segments
    are usable."""
    band = settings.band_px if band_px is None else float(band_px)
    if not band > 0:
        raise ValueError(f"band_px: the pixel band's half-width must be positive, got {band}")
    lin, d, e, t = band_pixels(geo, band, img.shape)
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
    I_u = np.ascontiguousarray(I_u, dtype=np.float64)
    d_u = np.ascontiguousarray(d_u)
    # a cold start (no noise model yet) needs more rounds for the global profile to settle
    L, D, delta, var_delta, prof, coef, w, chi2, rc = _segment_fit(
        I_u, d_u, k, K, c4,
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
    if settings.covariance in ("correlated", "predicted"):
        # the final state, for measure.silhouette.noise (the final pose's sigma only)
        pixels["state"] = StageAState(lin[use], I_u, d_u, k, w, L, D, delta, prof, c4,
                                      float(settings.fringe_width_ratio),
                                      settings.dark_level == "tied", rc)
    return EdgeSegments(delta_px=delta, var_px2=var_delta, normal=np.column_stack([nx / nn,
                                                                                  ny / nn]),
                        foot_px=np.column_stack([fx, fy]), kappa=kap, bright=L, dark=D,
                        index=segs, edge_sigma_px=s, resid_rms=float(math.sqrt(chi2 / npix)),
                        noise_coef=np.asarray(coef), profile=prof, pixels=pixels)
