"""Stage A of the silhouette least squares: per-segment edge offsets about a trial outline.

The outline (:func:`outline_geometry`: per-edge normals, curvature, sharp corners) is placed
at a trial pose; pixels within a band of it (:func:`band_pixels`, exact signed distances) are
grouped into short contour segments, and in each segment a blurred-edge model
``I = L (1 - g) + D g + a L h``, ``g = Phi((delta - d) / s)`` (d the pixel centre's signed
distance from the outline, + outside; L the local bright level, D the dark level, tied to it
image-wide as ``D = r L + c`` by default; s the edge width; ``a L h`` the diffraction fringe,
:mod:`cadra.imaging.silhouette.edge_model`, which also solves it) gives the segment's edge
offset ``delta`` along the outward normal with its variance (:func:`stage_a`). The edge width
and the fringe amplitude are fitted per image, each as ``x0 + x4 cos(4 theta)`` (theta the
normal's angle to the pixel grid). The method is described in
:mod:`cadra.imaging.silhouette.fit` and docs/stage1.md; all lengths in pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from cadra.imaging.silhouette.edge_model import SQRT2PI, _segment_fit

#: Turning angle above which an outline vertex is a sharp corner (excluded from the fit).
CORNER_TURN_RAD = 0.3
#: Outline curvature (1/px) above which the edge model's linear curvature bias no longer
#: holds (radius < 4 px, a few blur widths): such stretches are treated like corners.
MAX_EDGE_CURVATURE = 0.25


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
    noise model (a warm start: one weighted fit, not three); ``band_px`` overrides
    ``settings.band_px`` (``FitSettings.band_for``; None: the settings' own). None when
    fewer than 8 segments are usable."""
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
    L, D, delta, var_delta, prof, coef, w, chi2, rc = _segment_fit(
        I_u, d_u, k, K, c4,
        np.asarray(profile0, float).copy(), float(settings.fringe_width_ratio), coef_in, has,
        settings.stage_a_max_iter, settings.stage_a_tol_px, L0, D0,
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
