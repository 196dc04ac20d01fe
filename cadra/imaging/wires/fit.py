"""Find and fit the fiducial wires in one shadowgraph; solve the image->plane affine from them.

Method (all lengths in pixels unless a name ends in ``_m``):

1. **Prediction.** Each wire of the view is predicted in the image with the view's nominal
   affine (:meth:`View.wire_lines_px`). The film placement moves it by a few pixels at most.
2. **Profiles.** Intensity profiles across the wire are taken every ``step_px`` along it, *along
   the image axis closest to the wire's normal* (rows for a wire running up the image, columns
   for one running across) and through pixel centres, so no interpolation is needed. This is a
   deliberate choice over bilinear sampling on the exact normal: interpolating a ~2 px wide
   line at a fractional offset reshapes it with the sub-pixel phase (a phase-dependent
   bias), whereas the row (column) section of a straight band through pixel centres is
   exactly symmetric about the point where the band's centre line crosses that row (the band
   and the pixel square are both point-symmetric), whatever the band's tilt; so is any
   point-symmetric blur of it.
3. **Coarse line.** In each profile (``+-search_px`` about the prediction) a "darker than both
   sides" detector ``min(I(s - 4), I(s + 4)) - I_smooth(s)`` marks the wire (a body's edge or a
   broad shadow does not respond). The strongest responses are fitted robustly by a straight
   line (median offset, then iterated 2 px clipping).
4. **Sub-pixel centre.** In a window of ``+-half_window`` samples centred on the coarse line, a
   straight background is fitted to the samples beyond ``h + 3`` px (``h`` the wire's
   half-width along the profile) and the darkness ``1 - I / bg`` is centroided in a window of
   half-width ``h + 2`` re-centred on the estimate (fractional end weights) until it settles,
   all profiles at once (vectorized). Any normalized symmetric blur, continuous or discrete,
   and the diffraction fringe (a Laplacian) leave this centroid unchanged, so no model of the
   line's profile is needed. Its own phase bias, from the pixel-centre weighting of the
   wire's two partly covered pixels, is <= ~0.0075 px for the 1.97 px HFFAF wire and averages
   out along any wire that drifts across the pixel grid, but not along one parallel to the
   grid (step 7). These centroids find the wires (steps 5-6); step 8 then replaces them.
5. **Rejection.** A profile is dropped when its window touches ``exclude`` (the model), another
   wire's predicted crossing or the scanner reference mark; when its depth is not that of an
   opaque wire (gaps, dust, a missing wire); when its centroid does not settle near the coarse
   line, or its depth, width or background scatter are unlike the wire's typical profile
   (clutter, an edge); and
   by iterative 3-sigma clipping (robust MAD scale) of the perpendicular residuals of a total
   least-squares line through the centres. Last, a stretch whose centres stray from the line
   together (a shock wave running close along the wire biases hundreds of centres by a
   fraction of their noise each, which no single profile shows) is found by the mean residual
   of blocks of 12 centres and left out (:mod:`cadra.imaging.wires.straightness`). The
   surviving centres give the wire's line.
6. **Affine.** Each found wire contributes two points on its fitted line, at the centroid of
   its centres +- their rms spread along the line. For a least-squares line these two
   "Gauss points" have uncorrelated noise errors of equal variance ``2 sigma^2 / n``, and they
   carry the same first and second moments along the line as the n centres; the affine
   solved from them by generalized least squares (the equations of
   :func:`~cadra.facility.reference.fit_affine_to_wires`, each wire's two points weighted by
   the inverse of their covariance: the noise plus step 7's correlated term) is therefore
   the solution from all centres, and its residuals measure how well the measured lines
   agree with the survey (not the profile noise). When the found wires
   leave a direction poorly determined (three wires: two parallel ones give one scale, the
   third only an offset), the affine is solved with a prior that the image differs from the
   nominal map by a similarity (film placed with a shift, rotation and uniform scale, no
   shear or anisotropy); ``reason`` then says so (a warning, ``ok`` stays True).
7. **Phase bias (centroids).** The centroid errs by a periodic function of the wire's
   sub-pixel phase (step 4). A line that keeps one phase along its length keeps that error
   whole, ~0.004 px rms, as large as its noise sigma; the affine's sigma without it was
   ~0.87 of its error at the model. :mod:`cadra.imaging.wires.phase` sizes the bias from the
   wires that sweep phases in this image and adds, per wire, the covariance it leaves in the
   two Gauss points (``WireFit.sigma_sys_px`` the offset's share;
   ``WireMeasurement.phase_gain`` the size).
8. **Profile model** (``profile_model=True``, the default). A least-squares fit of a
   blurred-bar model is ~2.7x less noisy than the centroid, but biased by up to +-0.035 px
   with the sub-pixel phase unless the model forms the profile as the image did: blur before
   the pixel integration, the pixel, blur after it (:mod:`cadra.imaging.wires.profile`). The
   image formation is fitted from the clean profiles the centroid lines kept: the view's,
   fitted once over several images of the shot and held (only the wires' widths fitted here,
   unless a score test says this image is formed otherwise), or this image's own
   (:mod:`cadra.imaging.wires.formation`). Every clean profile's centre is then fitted with
   it and steps 5-6 run again on those centres (the straightness test allowing the model's
   ~0.0015 px instead of the centroid's 0.0075 px). The formation's covariance, through each
   wire's centre sensitivity, is added to the affine's covariance; no phase term is. Sharp
   wires (fitted total blur < :data:`MIN_MODEL_BLUR_PX`) keep the centroids, and so does an
   image whose model lines disagree with its centroid lines beyond chance
   (:data:`MODEL_AGREEMENT_P`: a formation the model cannot describe, e.g. a disk PSF; a
   warning says so).
   ``WireMeasurement.formation`` says which (None: centroids).

:func:`measure_wires` is a pure function of plain arrays; its results are frozen dataclasses of
floats, tuples and numpy arrays (picklable, for a process pool). :func:`wire_profiles` gives
an image's clean profiles, for a formation fitted over several images.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2

from cadra.facility.reference import View
from cadra.imaging.wires.affine import corner_sigma_px, formation_cov, solve_affine_gls
from cadra.imaging.wires.formation import SHARED_P, fit_formation, fit_widths
from cadra.imaging.wires.phase import line_phases, phase_gain, systematic_cov
from cadra.imaging.wires.profile import Formation, WireProfiles, fit_centres
from cadra.imaging.wires.straightness import (
    BLOCK_SYS_PX,
    MODEL_BLOCK_SYS_PX,
    drop_bent_stretches,
    tls_line,
)
from cadra.optics.projection import Projection

__all__ = ["WireFit", "WireMeasurement", "measure_wires", "wire_profiles"]

#: Below this total blur (px) of the wires' fitted formation the profile model is not used
#: (the centroid and its phase term are): at 0.4 px optics blur a few per cent error in the
#: fitted blur moved lines by several sigma (docs/stage1.md, "The wires' profile model").
MIN_MODEL_BLUR_PX = 0.55
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
#: Profiles within this distance (px) of another wire's predicted line are not used.
CROSSING_CLEARANCE_PX = 18.0
#: Extra clearance (px) around the scanner reference mark.
MARK_CLEARANCE_PX = 6.0
#: A wire-only solution is "poorly determined" when the propagated 1-sigma position error at
#: an image corner exceeds this (px).
MAX_CORNER_SIGMA_PX = 0.02


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
    clean_px : (M, 2) every clean profile centre (u, v), before the line's clipping and the
        bent stretches' drop: what the bow of an undeclared image distortion is measured
        from (:func:`cadra.imaging.wires.distortion.radial_from_centres`).
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


@dataclass(frozen=True, eq=False)
class WireMeasurement:
    """The wires of one image and the image->plane affine solved from them.

    Attributes
    ----------
    ok : an affine was solved.
    reason : why not (``ok`` False); if ``ok``, a non-empty reason is a warning (e.g. a scale
        taken from the similarity prior because a wire is missing).
    affine : (2, 3) image->plane map ``[a, b] = M @ [u, v, 1]`` (m), or None.
    affine_cov : (6, 6) covariance of the affine's entries (row-major), from the lines' offset
        sigmas, or None.
    wires : one :class:`WireFit` per wire of the view, in the view's order.
    affine_rms_m, affine_rms_px : rms distance of the found lines' points from their
        surveyed lines after the fit (m; px at the image scale).
    n_found : number of wires found.
    projection : the view's optics with the solved affine (:meth:`View.optics`; what the
        silhouette fit and the combination use), or None.
    phase_gain : (g_hat, sigma_g, mean g^2): how much of the sharp wire's pixel-sampling
        bias the image shows (step 7 of the module docstring); NaNs if no affine.
    formation : the wires' image formation fitted with ``profile_model`` (None: centroids
        used; ``phase_gain`` is then set, else NaNs).
    """

    ok: bool
    reason: str
    affine: np.ndarray | None
    affine_cov: np.ndarray | None
    wires: tuple[WireFit, ...]
    affine_rms_m: float
    affine_rms_px: float
    n_found: int
    projection: Projection | None = None
    phase_gain: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    formation: Formation | None = None

    def position_sigma_m(self, uv) -> np.ndarray:
        """1-sigma (a, b) (m) of the view-plane image of pixel ``uv`` from the affine's
        uncertainty (NaN if no affine)."""
        if self.affine_cov is None:
            return np.full(2, np.nan)
        u, v = float(uv[0]), float(uv[1])
        J = np.zeros((2, 6))
        J[0, :3] = (u, v, 1.0)
        J[1, 3:] = (u, v, 1.0)
        return np.sqrt(np.diag(J @ self.affine_cov @ J.T))


# --------------------------------------------------------------------------- profile fits


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


def _not_found(name: str, why: str, n_rejected: int = 0) -> WireFit:
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


def _measure_one(img: np.ndarray, name: str, seg, half_width_px: float, blocked,
                 exclude, search_px: float, step_px: float, half_window: int,
                 collect=None, distortion=None) -> WireFit:
    """Find one wire near its predicted segment ``seg`` (ideal pixels); see the module
    docstring. ``collect``, if given, receives the found wire's clean profiles
    (:class:`_Profiles`). ``distortion``: the recorded image's, the profiles taken along the
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
        return _not_found(name, f"its predicted path crosses only {hi - lo:.0f} px of the image")
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
        return _not_found(name, f"only {n_usable} usable profiles along its predicted path "
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
        return _not_found(name, f"contrast below threshold along {frac:.0%} of its predicted "
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
        return _not_found(name, f"too few clean profiles ({n_use} < "
                                f"{max(MIN_PROFILES, math.ceil(MIN_USED_FRACTION * n_cand))}; "
                                f"no wire-like dark line along {frac:.0%} of its predicted "
                                f"path)", n_rejected=int(inside.sum()) - n_use)
    fit, keep = _line_from_centres(name, c, fixed, ax, use, step_px, int(inside.sum()),
                                   distortion=distortion)
    if collect is not None and fit.found:
        collect.append(_Profiles(WireProfiles(P[use], widx[use, 0].astype(float), c[use], h,
                                              slope, cos_t), fixed[use], keep[use], ax,
                                 int(inside.sum())))
    return fit


@dataclass(frozen=True, eq=False)
class _Profiles:
    """A found wire's clean profiles from the first pass (for the profile model): the
    profiles, their fixed coordinates, which of them the centroid line kept, the profile
    axis and the number of profiles inside the image."""

    wp: WireProfiles
    fixed: np.ndarray
    kept: np.ndarray
    ax: int
    n_inside: int


def _line_from_centres(name: str, c: np.ndarray, fixed: np.ndarray, ax: int,
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
        return _not_found(name, f"no straight dark line along its predicted path (centres "
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


# --------------------------------------------------------------------------- affine


def _gauss_points(f: WireFit) -> np.ndarray:
    """Two points on ``f``'s line at its centres' centroid +- their rms spread along it."""
    m = np.asarray(f.point_px, float)
    t = np.asarray(f.direction_px, float)
    spread = math.sqrt(float(np.mean(((f.centres_px - m) @ t) ** 2)))
    return np.array([m - spread * t, m + spread * t])


def _centroid_pass(img: np.ndarray, view: View, exclude: np.ndarray | None, search_px: float,
                   step_px: float, half_window: int, collect: bool, distortion=None):
    """Steps 1-6 for every wire of ``view``: the centroid lines (``fits``, one per wire) and,
    if ``collect``, each found wire's clean profiles (wire index -> :class:`_Profiles`);
    ``distortion`` the recorded image's (:func:`measure_wires`)."""
    segs = view.wire_lines_px()
    mark = view.reference_mark
    mark_r = mark.arm_px + MARK_CLEARANCE_PX

    fits: list = [None] * len(view.wires)
    collected = {}
    for i, (w, seg) in enumerate(zip(view.wires, segs, strict=True)):
        if seg is None:
            fits[i] = _not_found(w.name, "its predicted path misses the image")
            continue
        others = []
        for j, sj in enumerate(segs):
            if j == i or sj is None:
                continue
            q0, q1 = np.asarray(sj[0], float), np.asarray(sj[1], float)
            tq = (q1 - q0) / math.hypot(*(q1 - q0))
            others.append((q0, np.array([-tq[1], tq[0]])))

        def blocked(pts, ax, search, others=others):
            """Profiles (through ``pts``, +-search along image axis ``ax``) near another
            wire's predicted line or the reference mark."""
            out = np.zeros(len(pts), bool)
            for q0, nq in others:
                out |= np.abs((pts - q0) @ nq) < CROSSING_CLEARANCE_PX
            d = np.abs(pts - np.array([mark.u_px, mark.v_px]))
            out |= (d[:, ax] < mark_r + search) & (d[:, 1 - ax] < mark_r)
            return out

        got = [] if collect else None
        fits[i] = _measure_one(img, w.name, seg, 0.5 * view.wire_width_px(w),
                               blocked, exclude, search_px, step_px, half_window, collect=got,
                               distortion=distortion)
        if got:
            collected[i] = got[0]
    return fits, collected


def _checked_image(image, exclude):
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"image must be 2-D, got shape {img.shape}")
    if img.dtype not in (np.float32, np.float64):
        img = img.astype(np.float32)
    if exclude is not None:
        exclude = np.asarray(exclude, bool)
        if exclude.shape != img.shape:
            raise ValueError(f"exclude has shape {exclude.shape}, image {img.shape}")
    return img, exclude


def _kept(g: _Profiles) -> WireProfiles:
    """The profiles of a wire its centroid line kept (the formation is fitted from these)."""
    return WireProfiles(g.wp.P[g.kept], g.wp.s0[g.kept], g.wp.c0[g.kept], g.wp.h, g.wp.t,
                        g.wp.cos_t)


def wire_profiles(image: np.ndarray, view: View, exclude: np.ndarray | None = None,
                  search_px: float = 30.0, step_px: float = 4.0,
                  half_window: int = 8, distortion=None) -> list[WireProfiles]:
    """The clean profiles of each wire of ``view`` found in ``image`` (the centroid lines'
    kept profiles; arguments as :func:`measure_wires`): what the image formation is fitted
    from (:func:`cadra.imaging.wires.formation.fit_formation`, over one image or several)."""
    img, exclude = _checked_image(image, exclude)
    _, collected = _centroid_pass(img, view, exclude, search_px, step_px, half_window, True,
                                  distortion)
    return [_kept(g) for g in collected.values()]


def measure_wires(image: np.ndarray, view: View, exclude: np.ndarray | None = None,
                  search_px: float = 30.0, step_px: float = 4.0,
                  half_window: int = 8, profile_model: bool = True,
                  formation: Formation | None = None, distortion=None) -> WireMeasurement:
    """Find every wire of ``view`` in ``image`` and solve the image->plane affine.

    Parameters
    ----------
    image : float (H, W) in [0, 1], indexed ``image[v, u]``.
    view : the view (facility reference file) the image belongs to.
    exclude : optional bool (H, W), True where pixels must not be used (the model's
        silhouette plus margin).
    search_px : half-width of the search about each wire's nominal prediction (px).
    step_px : spacing of the profiles along each wire (px; an integer number of rows or
        columns).
    half_window : half-width (samples) of the window each profile's centre is fitted in.
    profile_model : fit each profile's centre with a model of the image formation
        (:mod:`cadra.imaging.wires.profile`) instead of the centroid (step 8; False: the
        centroids and their phase term, ~3x faster, ~3x less accurate).
    formation : the view's image formation fitted over several of the shot's images
        (:func:`cadra.imaging.wires.formation.fit_formation`); this image then fits only its
        wires' widths with it held, unless its score test rejects it
        (:func:`~cadra.imaging.wires.formation.fit_widths`; the reason says so). None: the
        formation is fitted from this image alone.
    distortion : the recorded image's :class:`~cadra.optics.distortion.Distortion` (None:
        none). Each wire's profiles are then taken along its curved image, and their centres
        mapped to ideal pixels, where the line is fitted: the lines, the affine and every
        pixel coordinate returned are the ideal image's (docs/stage1.md, "Distorted images").

    Returns
    -------
    WireMeasurement
        Never raises for bad data: a wire not found carries its reason; fewer than three
        wires found, or wires that cannot determine the map, give ``ok = False`` and a reason.

    Notes
    -----
    See the module docstring for the method. Profiles touching ``exclude``, another wire's
    crossing or the reference mark count in ``n_rejected``.
    """
    img, exclude = _checked_image(image, exclude)
    fits, collected = _centroid_pass(img, view, exclude, search_px, step_px, half_window,
                                     profile_model, distortion)
    if not (profile_model and collected):
        return _solve_affine(view, fits)
    # the formation from the profiles the centroid lines kept (or the view's, held); then
    # every clean profile's centre with it, and the lines again from those
    wps = [_kept(g) for g in collected.values()]
    own, notes = formation is None, []
    try:
        if formation is not None:
            if _sharp(formation):
                return _solve_affine(view, fits)
            formation, hs, score, p = fit_widths(wps, formation)
            if not p >= SHARED_P:
                notes.append(f"the wires disagree with the view's shared image formation "
                             f"(score {score:.0f}, p = {p:.1g}): this image's own fitted")
                own = True
        if own:
            formation, hs = fit_formation(wps)
    except (ValueError, np.linalg.LinAlgError):
        return _solve_affine(view, fits)
    if _sharp(formation):
        return _solve_affine(view, fits)   # sharp wires: the centres hang on the exact shape
    model = list(fits)
    for k, (i, g) in enumerate(collected.items()):
        c = fit_centres(g.wp, hs[k], formation)
        model[i], _ = _line_from_centres(fits[i].name, c, g.fixed, g.ax, np.isfinite(c),
                                         step_px, g.n_inside, MODEL_BLOCK_SYS_PX, distortion)
    sens = {i: formation.sens[k] for k, i in enumerate(collected)}
    centroid = _solve_affine(view, fits)
    t2, n_lines = _disagreement(model, centroid.wires)
    if t2 <= chi2.ppf(1.0 - MODEL_AGREEMENT_P, max(n_lines, 1)):
        out = _solve_affine(view, model, formation, sens)
    else:   # the formation does not describe these wires (a PSF far from Gaussian?)
        notes.append(f"wire profile model disagrees with the wires' centroids (chi2 {t2:.0f} "
                     f"over {n_lines} lines): centroids used")
        out = centroid
    reason = "; ".join(x for x in (out.reason, *notes) if x)
    return replace(out, reason=reason) if reason != out.reason else out


def _sharp(formation: Formation) -> bool:
    """Sharp wires (total blur below :data:`MIN_MODEL_BLUR_PX`) are left to the centroid."""
    return math.hypot(formation.sigma_c, formation.sigma_d) < MIN_MODEL_BLUR_PX


#: The profile model's lines are used unless their offsets from the centroid lines, in the
#: centroid lines' sigmas (noise and phase term, with the model's noise), sum in squares
#: beyond chi2's upper quantile at this probability (degrees of freedom: the lines).
MODEL_AGREEMENT_P = 1e-3


def _disagreement(model: list[WireFit], centroid) -> tuple[float, int]:
    """Sum over the wires found both ways of the squared offset of the model's line from the
    centroid's (at the model line's point), each in the two lines' combined sigma. The
    centroid needs no model of the image formation; a formation that does not describe the
    wires moves the model's lines by many of those sigmas (a disk PSF: ~0.03 px). Returns
    the sum and the number of lines."""
    t2, n = 0.0, 0
    for m, c in zip(model, centroid, strict=True):
        if not (m.found and c.found):
            continue
        n += 1
        d = float(c.distance_px(np.atleast_2d(m.point_px))[0])
        var = c.sigma_offset_px ** 2 + c.sigma_sys_px ** 2 + m.sigma_offset_px ** 2
        t2 += d * d / max(var, 1e-12)
    return t2, n


def _solve_affine(view: View, fits: list[WireFit], formation: Formation | None = None,
                  sens: dict | None = None) -> WireMeasurement:
    found = [f for f in fits if f.found]
    n_found = len(found)

    def fail(reason):
        return WireMeasurement(False, reason, None, None, tuple(fits), math.nan, math.nan,
                               n_found)

    if n_found < 3:
        missing = ", ".join(repr(f.name) for f in fits if not f.found)
        return fail(f"only {n_found} of {len(fits)} wires found (missing {missing}); at least 3 "
                    f"are needed for the image->plane map")
    scale = view.scale_m_per_px
    lines = [_gauss_points(f) if f.found else None for f in fits]
    # each Gauss point's perpendicular error: sqrt(2) x the line's offset sigma (floored),
    # independent; plus the centroid's phase bias, common to the line's centres (step 7)
    width_px = [view.wire_width_px(w) for w in view.wires]
    # (the profile model's centres carry no phase bias: no phase term, step 8)
    phases = [line_phases(f.centres_px, f.point_px, f.direction_px, f.profile_axis)
              if f.found and formation is None else None for f in fits]
    gain = ((math.nan,) * 3 if formation is not None else
            phase_gain([None if p is None else (*p, f.rms_px)
                        for p, f in zip(phases, fits, strict=True)], width_px))
    cov_px, fits = [], list(fits)
    for i, (f, p) in enumerate(zip(fits, phases, strict=True)):
        if not f.found:
            cov_px.append(None)
            continue
        sys_cov = (np.zeros((2, 2)) if p is None else
                   systematic_cov(p[0], p[1], p[3], width_px[i], gain[2]))
        fits[i] = WireFit(**{**f.__dict__,
                             "sigma_sys_px": 0.5 * math.sqrt(max(float(sys_cov.sum()), 0.0))})
        cov_px.append(2.0 * max(f.sigma_offset_px, 1e-4) ** 2 * np.eye(2) + sys_cov)
    cov_m = [None if c is None else c * scale ** 2 for c in cov_px]
    reason, prior = "", False
    sol = solve_affine_gls(view, lines, cov_m, prior=False)
    if sol is None or corner_sigma_px(view, sol[1], scale) > MAX_CORNER_SIGMA_PX:
        # the wires alone leave a direction poorly determined: the similarity prior
        prior = True
        sol = solve_affine_gls(view, lines, cov_m, prior=True)
        if sol is None:
            return fail(f"wires {[f.name for f in found]} cannot determine the image->plane map")
        if corner_sigma_px(view, sol[1], scale) > 10 * MAX_CORNER_SIGMA_PX:
            return fail(f"wires {[f.name for f in found]} leave the image->plane map "
                        f"undetermined even with the similarity prior")
        missing = ", ".join(repr(f.name) for f in fits if not f.found)
        reason = (f"wire(s) {missing} not found: the image->plane map uses the prior that the "
                  f"film differs from the nominal map by a similarity (no shear/anisotropy)")
    M, cov, res, wire_of = sol
    if formation is not None and formation.cov is not None and sens:
        cov = cov + formation_cov(view, fits, lines, cov_m, prior, M, formation, sens)
    px = math.sqrt(abs(np.linalg.det(M[:, :2])))
    wire_of = np.asarray(wire_of)
    out = []
    for i, f in enumerate(fits):
        if f.found:
            r = float(np.mean(res[wire_of == i]))
            f = WireFit(**{**f.__dict__, "residual_m": r, "residual_px": r / px})
        out.append(f)
    rms_m = float(np.sqrt(np.mean(res ** 2)))
    return WireMeasurement(True, reason, np.array(M, float), cov, tuple(out), rms_m, rms_m / px,
                           n_found, view.optics(M), phase_gain=gain, formation=formation)
