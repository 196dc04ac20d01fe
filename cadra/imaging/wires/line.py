"""One fiducial wire in one shadowgraph: its profiles across it along its predicted path
(straight, or its image through the recorded image's distortion), each profile's centre, and
the wire's straight line from them (steps 1-6 of :mod:`cadra.imaging.wires.fit`, which
runs them for every wire of a view and solves the image->plane map from the lines).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cadra.imaging.wires.profile import WireProfiles
from cadra.imaging.wires.straightness import BLOCK_SYS_PX, drop_bent_stretches, tls_line

__all__ = ["MAX_DEPTH_REL", "MAX_LINE_RMS_PX", "MIN_DEPTH_REL", "MIN_PROFILES",
           "MIN_USED_FRACTION", "WireFit", "measure_one_wire", "not_found"]

#: Fewest clean profiles for a wire to count as found.
MIN_PROFILES = 10
#: ... and at least this fraction of its usable profiles (inside the image, not excluded).
MIN_USED_FRACTION = 0.2
#: A found wire's centres scatter about its line by less than this (px).
MAX_LINE_RMS_PX = 0.3
#: Depth of a wire's dip relative to the local background: accepted range (an opaque wire
#: of the default facility gives ~0.9; dust, scratches, gaps and noise far less).
MIN_DEPTH_REL, MAX_DEPTH_REL = 0.35, 1.4
#: Coarse detector: half-distance (samples) to the two comparison points either side.
_DETECT_ARM = 4


@dataclass(frozen=True, eq=False)
class WireFit:
    """One wire of one image: found or not (with the reason) and its fitted image line.

    Attributes
    ----------
    name : the wire's name (facility file).
    found : whether a straight dark line was found along the predicted path.
    reason : why not (empty if found).
    point_px : (u, v) of a point on the fitted line: the centroid of the centres used.
    direction_px : unit direction (du, dv) of the line.
    ends_px : the line's points at the first and last centre used ((u0, v0), (u1, v1)).
    centres_px : (N, 2) the profile centres used (u, v).
    n_used, n_rejected : profiles used / rejected (inside the image; excluded ones count as
        rejected).
    rms_px : rms of the centres' perpendicular residuals about the line.
    sigma_offset_px : estimated 1-sigma of the line's perpendicular offset at ``point_px``.
    residual_m, residual_px : mean signed distance of the line's mapped points from the
        surveyed wire line (view plane, m; and in px at the image scale), after the affine.
    profile_axis : image axis the profiles ran along (0: rows, sampling u; 1: columns).
    sigma_sys_px : 1-sigma of the line's offset at ``point_px`` from the centroid's
        sub-pixel phase bias (step 7 of the module docstring; 0 until the affine is solved).
        The offset's total 1-sigma is ``hypot(sigma_offset_px, sigma_sys_px)``.
    dropped_px : length (px) of the stretches left out because the centres there stray from
        the straight line as a whole (step 5: a shock or flow line along the wire).
    clean_px : (M, 2) every clean profile centre (u, v; ideal pixels: the recorded ones
        when no distortion is declared), before the line's clipping and the bent stretches'
        drop: what the bow of an undeclared image distortion is measured from
        (:func:`cadra.imaging.wires.distortion.radial_from_centres`).
    """

    name: str
    found: bool
    reason: str = ""
    point_px: tuple[float, float] = (math.nan, math.nan)
    direction_px: tuple[float, float] = (math.nan, math.nan)
    ends_px: tuple = ()
    centres_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    n_used: int = 0
    n_rejected: int = 0
    rms_px: float = math.nan
    sigma_offset_px: float = math.nan
    residual_m: float = math.nan
    residual_px: float = math.nan
    profile_axis: int = -1
    sigma_sys_px: float = 0.0
    dropped_px: float = 0.0
    clean_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    def distance_px(self, uv) -> np.ndarray:
        """Signed perpendicular distance (px) of points ``(N, 2)`` from the fitted line."""
        p = np.asarray(self.point_px, float)
        t = np.asarray(self.direction_px, float)
        n = np.array([-t[1], t[0]])
        return (np.atleast_2d(np.asarray(uv, float)) - p) @ n


def _centroids(P: np.ndarray, S: np.ndarray, c0: np.ndarray, half_core: float,
               n_iter: int = 4):
    """Darkness-weighted centroid of the dip in each row of ``P``, on a linear background.

    ``P`` (n, k) intensities at integer positions ``S`` (n, k); ``c0`` (n,) start values
    (within ~1/2 px). A straight background is fitted to the samples farther than
    ``half_core + 1`` from ``c0``; the darkness is ``d = 1 - I / bg``. Then, iteratively, ``c``
    moves to the centroid of ``d`` in a window of half-width ``half_core`` about ``c`` (its
    end samples weighted by their fractional overlap, so the window stays symmetric about the
    line). Any normalized symmetric blur, continuous or discrete, leaves the centroid of the
    absorbed light unchanged, so the estimate needs no model of the line's profile.

    Returns
    -------
    c : centres (n,).
    area : sum of ``d`` in the window (px; about depth x the wire's section width).
    width : rms half-width of ``d`` about ``c`` (px).
    bg : background at ``c0`` (n,).
    bg_rms : rms of the background samples about their line, relative to it (n,).
    """
    P = P.astype(np.float64)
    x = S - c0[:, None]
    wb = (np.abs(x) >= half_core + 1.0).astype(np.float64)
    sw = wb.sum(axis=1)
    xw = wb * x
    sx = xw.sum(axis=1)
    sxx = (xw * x).sum(axis=1)
    sy = (wb * P).sum(axis=1)
    sxy = (xw * P).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        b1 = (sw * sxy - sx * sy) / (sw * sxx - sx * sx)
        b0 = (sy - b1 * sx) / sw
        bgx = b0[:, None] + b1[:, None] * x
        d = 1.0 - P / bgx
        bg_rms = np.sqrt((wb * d * d).sum(axis=1) / np.maximum(sw - 2.0, 1.0))
        c = c0.astype(np.float64).copy()
        for _ in range(n_iter):
            x = S - c[:, None]
            wd = np.clip(half_core + 0.5 - np.abs(x), 0.0, 1.0) * d
            area = wd.sum(axis=1)
            c += np.clip(np.nan_to_num((x * wd).sum(axis=1) / area), -1.0, 1.0)
        x = S - c[:, None]
        wd = np.clip(half_core + 0.5 - np.abs(x), 0.0, 1.0) * d
        area = wd.sum(axis=1)
        width = np.sqrt(np.abs((x * x * wd).sum(axis=1) / area))
    return c, area, width, b0, bg_rms


def not_found(name: str, why: str, n_rejected: int = 0) -> WireFit:
    return WireFit(name, False, f"wire {name!r} not found: {why}", n_rejected=n_rejected)


def _recorded_path(p0: np.ndarray, p1: np.ndarray, ax: int, distortion):
    """The wire's predicted path in the recorded image: (its ``1 - ax`` coordinate's range,
    a function of that coordinate giving the ``ax`` one). Straight from ``p0`` to ``p1``, or
    that line's image through ``distortion`` (curved; sampled every pixel)."""
    other = 1 - ax
    d = p1 - p0
    if distortion is None:
        return ((min(p0[other], p1[other]), max(p0[other], p1[other])),
                lambda o: p0[ax] + (o - p0[other]) * (d[ax] / d[other]))
    curve = distortion.distort(p0 + np.linspace(0.0, 1.0, int(math.hypot(*d)) + 2)[:, None] * d)
    curve = curve[np.argsort(curve[:, other])]
    return (curve[0, other], curve[-1, other]), lambda o: np.interp(o, curve[:, other],
                                                                    curve[:, ax])


def measure_one_wire(img: np.ndarray, name: str, seg, half_width_px: float, blocked,
                 exclude, search_px: float, step_px: float, half_window: int,
                 collect=None, distortion=None) -> WireFit:
    """Find one wire near its predicted segment ``seg`` (ideal pixels); see the module
    docstring. ``collect``, if given, receives the found wire's clean profiles
    (:class:`Profiles`). ``distortion``: the recorded image's, the profiles taken along the
    segment's curved image and the centres mapped to ideal pixels before the line fit."""
    H, W = img.shape
    p0, p1 = np.asarray(seg[0], float), np.asarray(seg[1], float)
    d = p1 - p0
    # ax: image axis the profiles run along (0: rows, sampling u; 1: columns, sampling v)
    ax = 0 if abs(d[1]) >= abs(d[0]) else 1
    other = 1 - ax
    slope = d[ax] / d[other]  # d(ax coordinate) / d(other coordinate) along the wire
    cos_t = abs(d[other]) / math.hypot(*d)
    n_lim = (W, H)
    (lo, hi), path = _recorded_path(p0, p1, ax, distortion)
    lo, hi = max(lo, 0.0), min(hi, n_lim[other] - 1.0)
    fixed = np.arange(math.ceil(lo + 2.0), math.floor(hi - 2.0) + 1, step_px).astype(float)
    if len(fixed) < MIN_PROFILES:
        return not_found(name, f"its predicted path crosses only {hi - lo:.0f} px of the image")
    pred = path(fixed)
    S = int(round(search_px)) + _DETECT_ARM + 1
    offs = np.arange(-S, S + 1)
    base = np.rint(pred).astype(int)
    lim = n_lim[ax] - 1
    # every sample of the search window in the image
    inside = (base - S >= 0) & (base + S <= lim)
    # other wires' crossings and the reference mark
    pts_pred = np.empty((len(fixed), 2))
    pts_pred[:, ax] = pred
    pts_pred[:, other] = fixed
    usable = inside & ~blocked(pts_pred, ax, search_px)
    n_usable = int(usable.sum())
    if n_usable < MIN_PROFILES:
        return not_found(name, f"only {n_usable} usable profiles along its predicted path "
                                f"(< {MIN_PROFILES})", n_rejected=int(inside.sum()))
    fixed, pred, base = fixed[usable], pred[usable], base[usable]
    fi = fixed.astype(int)
    idx = np.clip(base[:, None] + offs[None, :], 0, lim)
    prof = img[fi[:, None], idx] if ax == 0 else img[idx, fi[:, None]]
    # coarse: "darker than both sides" response on the lightly smoothed profile
    sm = prof.copy()
    sm[:, 1:-1] = 0.25 * prof[:, :-2] + 0.5 * prof[:, 1:-1] + 0.25 * prof[:, 2:]
    a = _DETECT_ARM
    resp = np.minimum(sm[:, :-2 * a], sm[:, 2 * a:]) - sm[:, a:-a]
    j = np.argmax(resp, axis=1)
    strength = resp[np.arange(len(j)), j]
    coarse = (base + offs[a + j]).astype(float)  # ax coordinate of the dip
    rows = np.arange(len(j))
    sides = np.minimum(sm[rows, j], sm[rows, j + 2 * a])  # the local background
    strong = strength > 0.5 * MIN_DEPTH_REL * np.maximum(sides, 1e-3)
    n_strong = int(strong.sum())
    if n_strong < MIN_PROFILES:
        frac = 1.0 - n_strong / len(fixed)
        return not_found(name, f"contrast below threshold along {frac:.0%} of its predicted "
                                f"path ({n_strong} < {MIN_PROFILES} profiles with a dark line)",
                          n_rejected=int(inside.sum()))
    # robust coarse line: ax coordinate = q0 + q1 * other coordinate
    dev = coarse - pred
    keep = strong & (np.abs(dev - np.median(dev[strong])) < 3.0)
    q = np.array([slope, float(np.median(dev[strong]))])
    for _ in range(4):
        if keep.sum() < 3:
            break
        qq = np.polyfit(fixed[keep], dev[keep], 1)
        new = strong & (np.abs(dev - np.polyval(qq, fixed)) < 2.0)
        q = qq
        if np.array_equal(new, keep):
            break
        keep = new
    c_coarse = pred + np.polyval(q, fixed)
    # fine: window of +-half_window samples centred on the coarse line
    k0 = np.rint(c_coarse).astype(int)
    k0 = np.clip(k0, half_window, lim - half_window)
    widx = k0[:, None] + np.arange(-half_window, half_window + 1)[None, :]
    P = img[fi[:, None], widx] if ax == 0 else img[widx, fi[:, None]]
    h = half_width_px / cos_t  # half-width of the wire's section along the profile
    half_core = h + 2.0
    c, area, width, bg, bg_rms = _centroids(P, widx, c_coarse, half_core)
    depth = area / (2.0 * h)
    ok = (np.isfinite(c) & np.isfinite(area) & np.isfinite(width) & (bg > 0)
          & (np.abs(c - c_coarse) < 2.0))
    depth_ok = ok & (depth > MIN_DEPTH_REL) & (depth < MAX_DEPTH_REL)
    use = depth_ok.copy()
    if exclude is not None:
        wide = np.clip(k0[:, None] + np.arange(-half_window - 2, half_window + 3)[None, :], 0,
                       lim)
        touched = (exclude[fi[:, None], wide] if ax == 0 else exclude[wide, fi[:, None]])
        use &= ~touched.any(axis=1)
    if use.sum() >= MIN_PROFILES:  # unlike the wire's typical profile: clutter, an edge
        dm, wm = np.median(depth[use]), np.median(width[use])
        use &= ((np.abs(depth - dm) < 0.2 * dm) & (np.abs(width - wm) < 0.6 * wm)
                & (bg_rms < 3.0 * np.median(bg_rms[use]) + 0.01))
    n_use = int(use.sum())
    n_cand = len(use)
    if n_use < max(MIN_PROFILES, MIN_USED_FRACTION * n_cand):
        frac = 1.0 - float(depth_ok.sum()) / n_cand
        return not_found(name, f"too few clean profiles ({n_use} < "
                                f"{max(MIN_PROFILES, math.ceil(MIN_USED_FRACTION * n_cand))}; "
                                f"no wire-like dark line along {frac:.0%} of its predicted "
                                f"path)", n_rejected=int(inside.sum()) - n_use)
    fit, keep = line_from_centres(name, c, fixed, ax, use, step_px, int(inside.sum()),
                                   distortion=distortion)
    if collect is not None and fit.found:
        collect.append(Profiles(WireProfiles(P[use], widx[use, 0].astype(float), c[use], h,
                                              slope, cos_t), fixed[use], keep[use], ax,
                                 int(inside.sum())))
    return fit


@dataclass(frozen=True, eq=False)
class Profiles:
    """A found wire's clean profiles from the first pass (for the profile model): the
    profiles, their fixed coordinates, which of them the centroid line kept, the profile
    axis and the number of profiles inside the image."""

    wp: WireProfiles
    fixed: np.ndarray
    kept: np.ndarray
    ax: int
    n_inside: int


def line_from_centres(name: str, c: np.ndarray, fixed: np.ndarray, ax: int,
                       use: np.ndarray, step_px: float, n_inside: int,
                       sys_px: float = BLOCK_SYS_PX, distortion=None):
    """The wire's line from its profile centres ``c`` (profile axis ``ax``; ``use``: the
    clean ones): iterative 3-sigma clipping, the bent stretches left out (step 5; ``sys_px``
    the bias a stretch of centres may share without being bent). With the recorded image's
    ``distortion`` the centres are mapped to ideal pixels first, where the wire is straight.
    Returns (WireFit, the centres kept)."""
    other = 1 - ax
    pts = np.empty((len(c), 2))
    pts[:, ax] = c
    pts[:, other] = fixed
    if distortion is not None:
        ok = np.isfinite(c)
        pts[ok] = distortion.undistort(pts[ok])
    keep = use.copy()
    for _ in range(8):
        m, t, nrm, _ = tls_line(pts[keep])
        res_all = (pts - m) @ nrm
        sig = 1.4826 * float(np.median(np.abs(res_all[keep])))
        new = use & (np.abs(res_all) <= max(3.0 * sig, 1e-3))
        if new.sum() < MIN_PROFILES or np.array_equal(new, keep):
            break
        keep = new
    keep, dropped = drop_bent_stretches(pts, keep, fixed, step_px, sys_px)
    m, t, nrm, res = tls_line(pts[keep])
    n_used = int(keep.sum())
    rms_px = float(np.sqrt(np.sum(res ** 2) / max(n_used - 2, 1)))
    if rms_px > MAX_LINE_RMS_PX:
        return not_found(name, f"no straight dark line along its predicted path (centres "
                                f"scatter {rms_px:.2f} px > {MAX_LINE_RMS_PX} px)",
                          n_rejected=n_inside - n_used), keep
    along = (pts[keep] - m) @ t
    ends = (tuple(map(float, m + along.min() * t)), tuple(map(float, m + along.max() * t)))
    sigma_off = rms_px / math.sqrt(n_used)
    return WireFit(name=name, found=True, reason="", point_px=(float(m[0]), float(m[1])),
                   direction_px=(float(t[0]), float(t[1])), ends_px=ends,
                   centres_px=pts[keep].copy(), n_used=n_used,
                   n_rejected=n_inside - n_used, rms_px=rms_px,
                   sigma_offset_px=sigma_off, profile_axis=ax, dropped_px=dropped,
                   clean_px=pts[use].copy()), keep
