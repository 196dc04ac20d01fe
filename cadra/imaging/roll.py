"""Roll of a finned body from its fin silhouettes (stage one; docs/stage1.md, "Roll of a finned
body").

A body of revolution's outline does not depend on its roll; a cruciform finned body's does,
through the fins (docs/bodies.md, "Roll convention"). With stage one's pose of each view held
(the reference point, the in-plane axis angle, the out-of-plane tilt the other view measures),
the roll ``gamma`` (``conventions.quat_from_axis_roll``'s: about the nose axis, 0 = z_b
vertical and down) is fitted in one dimension:

1. **Model** (:class:`ViewRollModel`). The exact outline at trial roll
   (:func:`view_outline_px`: :func:`cadra.body.outline_polygon` at the view's pose) is turned
   into the blurred-edge image of the silhouette fit (:mod:`cadra.imaging.silhouette.edges`):
   ``I = L (1 - g + a h) + D g`` with ``g`` the outline's indicator blurred by a Gaussian of
   the view's fitted edge width ``s = s0 + s4 cos 4 theta`` and ``h`` the fringe (amplitude
   ``a = a0 + a4 cos 4 theta``), both of the whole polygon, corners included
   (:func:`~cadra.imaging.silhouette.polygon.blurred_polygon`: beside a straight edge they are the
   edge model's ``Phi(-d / s)`` and fringe; at the fin tips' and roots' corners, which carry
   the roll near a mirror fold, the nearest side's profile was the estimator's main error).
   The bright level is a
   plane ``L = l0 + l1 du + l2 dv``, the dark level ``D`` a constant: four linear parameters,
   solved at every trial roll (variable projection). The pixels are fixed, those near where
   any roll changes the coverage (wire pixels masked), so residual sums compare across rolls.
   The refinement (step 2) multiplies both levels by the beam's local level
   (:meth:`ViewRollModel.background`).
2. **Scan and refine** (:func:`measure_station_roll`). The cruciform repeats every 90 deg, so
   each view's residual sum is scanned over one period; the two views' curves, each divided by
   its residual variance, are added, and every local minimum of the sum is a candidate. At
   zero incidence a silhouette cannot tell gamma from -gamma (a parallel projection does not
   see depth: the mirror image of the body through a plane parallel to the view casts the same
   shadow), so the candidates come in mirror pairs; the axis' tilt out of each view's plane
   (which moves near and far fins differently) separates them by some chi^2. Each candidate is
   refined per view by Gauss-Newton in gamma with the linear levels projected out, and the two
   views are combined by inverse variance.
3. **Sigma.** The Gauss-Newton curvature ``J^T J`` (J the projected derivative image) with a
   heteroscedasticity- and autocorrelation-consistent score variance (Bartlett-weighted
   products of ``J r`` over pixel lags up to :data:`HAC_LAG_PX`, r the residual), so the film
   grain's pixel-to-pixel correlation shows in the sigma), never below the formal
   ``s^2 / J^T J``, which is kept for comparison.
4. **Continuity** (:func:`resolve_roll_track`). A station's roll is known modulo 90 deg and up
   to the mirror; along the shot the branch is chosen by continuity: from each candidate of
   the first station a track is followed, at every station taking the candidate (and multiple
   of 90 deg) that minimises its chi^2 excess plus the squared miss of a prediction from the
   two previous stations (constant roll rate) in units of :data:`TRACK_SIGMA_RAD`; the track
   with the smallest total wins. The first station's value is taken in [-45, 45) deg: which
   fin is "fin 0" cannot be seen, so the roll is defined up to a multiple of 90 deg.

Everything is a pure function of arrays and frozen dataclasses.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from cadra.body import outline_polygon
from cadra.conventions import body_to_facility_matrix, quat_from_axis_roll
from cadra.facility.reference import VIEW_AXES
from cadra.imaging.silhouette.polygon import blurred_polygon, pixel_centres_inside

__all__ = ["HAC_LAG_PX", "PERIOD_RAD", "TRACK_SIGMA_RAD", "RollCandidate", "StationRoll",
           "ViewRoll", "ViewRollModel", "conical_outline_px", "measure_roll",
           "measure_station_roll", "resolve_roll_track", "view_outline_px", "wrap_period"]

#: The cruciform's roll period, rad.
PERIOD_RAD = 0.5 * math.pi
#: The mirror folds: gamma and -gamma (mod 90 deg) cast the same shadow at zero incidence, so
#: 0 and 45 deg are fold points of the residual curve.
FOLD_RAD = 0.25 * math.pi
#: Scan step over one period, rad.
SCAN_STEP_RAD = math.radians(1.5)
#: Largest pixel lag of the score variance (film grain correlation ~1.2 px, blur ~0.7 px).
HAC_LAG_PX = 3
#: Prediction sigma of the continuity tracking, rad.
TRACK_SIGMA_RAD = math.radians(10.0)
#: Band (px) about the outline where the edge profile is evaluated; beyond it g is 0 or 1.
BAND_PX = 5.0
#: The local background (``ViewRollModel.background``): unshadowed pixels farther than this
#: outside the outline (px), smoothed by a normalized Gaussian of this sigma (px), from a
#: window this much wider than the model's box (px).
BACKGROUND_CLEAR_PX = 4.0
BACKGROUND_SIGMA_PX = 10.0
BACKGROUND_PAD_PX = 40
#: Margin (px) of the pixel box around the fins at every roll.
ROI_MARGIN_PX = 6.0


def view_outline_px(body, projection, view_name: str, pose, tilt_rad: float, roll_rad: float,
                    n_points: int = 1024) -> np.ndarray:
    """The exact outline (px, (N, 2)) of ``body`` in a view at stage one's view pose.

    ``pose = (a_m, b_m, phi_rad)`` (the reference point's view-plane coordinates and the
    in-plane axis angle, :mod:`cadra.imaging.silhouette.template`), ``tilt_rad`` the axis'
    angle out of the view plane (top view: asin a_z; side view: asin a_y), ``roll_rad`` the
    roll about the nose axis of ``quat_from_axis_roll`` for that 3-D axis.
    """
    i, j = VIEW_AXES[view_name]
    P = np.asarray(projection.plane_basis, dtype=float)
    e_out = np.zeros(3)
    e_out[3 - i - j] = 1.0
    a, b, phi = (float(x) for x in pose)
    axis = (math.cos(tilt_rad) * (math.cos(phi) * P[0] + math.sin(phi) * P[1])
            + math.sin(tilt_rad) * e_out)
    R_FB = body_to_facility_matrix(quat_from_axis_roll(axis, roll_rad))
    plane = outline_polygon(body, R_FB, a * P[0] + b * P[1], P, n_points=n_points)
    return projection.from_plane(plane)


def _local_linear_level(img: np.ndarray, w: np.ndarray, sigma: float) -> np.ndarray:
    """At every pixel the value at that pixel of the plane fitted to ``img`` over the pixels of
    weight ``w``, weighted by a Gaussian of ``sigma`` px about it (first-order normalized
    convolution): unlike a weighted mean it is not pulled toward the side its pixels lie on,
    so a gradient of the beam does not bias the level at an edge. Where the weights are too
    few (deep in a shadow) the weighted mean, and the overall mean beyond that."""
    r = int(math.ceil(3.0 * sigma))
    x = np.arange(-r, r + 1, dtype=float)
    g = np.exp(-0.5 * (x / sigma) ** 2)
    g1 = x * g
    g2 = x * x * g

    def corr(a, kx, ky):     # sum_d kx(du) ky(dv) a(x + d): cv2 correlates
        return cv2.sepFilter2D(a, cv2.CV_64F, kx, ky, borderType=cv2.BORDER_CONSTANT)

    iw = img * w
    m00, m10, m01 = corr(w, g, g), corr(w, g1, g), corr(w, g, g1)
    m20, m11, m02 = corr(w, g2, g), corr(w, g1, g1), corr(w, g, g2)
    r0, r1, r2 = corr(iw, g, g), corr(iw, g1, g), corr(iw, g, g1)
    A = np.stack([np.stack([m00, m10, m01], -1), np.stack([m10, m20, m11], -1),
                  np.stack([m01, m11, m02], -1)], -2)
    b = np.stack([r0, r1, r2], -1)
    scale = g.sum() ** 2
    det = np.linalg.det(A / scale)
    good = (m00 > 0.01 * scale) & (np.abs(det) > 1e-6 * sigma ** 4)
    level = np.full(img.shape, np.nan)
    if np.any(good):
        level[good] = np.linalg.solve(A[good], b[good][..., None])[:, 0, 0]
    mean_ok = ~good & (m00 > 1e-3 * scale)
    level[mean_ok] = r0[mean_ok] / m00[mean_ok]
    fill = np.nanmean(level) if np.any(np.isfinite(level)) else 1.0
    return np.where(np.isfinite(level), level, fill)


class ViewRollModel:
    """The roll model of one view (module docstring, step 1).

    Parameters
    ----------
    img : (H, W) image, fraction of full scale.
    outline_fn : ``roll_rad -> (N, 2)`` pixel outline at the view's pose.
    exclude : (H, W) bool, pixels not to use (the wires), or None.
    edge_profile : ``(s0, a0, s4, a4)``: the silhouette fit's edge width and fringe.
    fringe_width_ratio : fringe width / edge width of that profile (``FitSettings``).
    """

    def __init__(self, img, outline_fn, exclude, edge_profile, fringe_width_ratio: float = 1.2):
        self.outline_fn = outline_fn
        self.s0, self.a0, self.s4, self.a4 = (float(x) for x in edge_profile)
        self.ratio = float(fringe_width_ratio)
        H, W = img.shape
        outlines = [outline_fn(g) for g in np.arange(16) * PERIOD_RAD / 16]
        pts = np.concatenate(outlines)
        lo = np.maximum(np.floor(pts.min(axis=0) - ROI_MARGIN_PX).astype(int), 0)
        hi = np.minimum(np.ceil(pts.max(axis=0) + ROI_MARGIN_PX).astype(int), [W - 1, H - 1])
        shape = (int(hi[1] - lo[1] + 1), int(hi[0] - lo[0] + 1))
        # the pixels whose coverage changes with the roll (the fins' sweep), dilated by the
        # margin: the nose and most of the body drop out
        masks = [pixel_centres_inside(p - lo, shape) for p in outlines]
        changing = np.zeros(shape, bool)
        for m in masks[1:]:
            changing |= m != masks[0]
        k = 2 * int(math.ceil(ROI_MARGIN_PX)) + 1
        near = cv2.dilate(changing.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool)
        rows = np.flatnonzero(near.any(axis=1))
        cols = np.flatnonzero(near.any(axis=0))
        if len(rows) == 0:          # nothing depends on the roll (no fins in view)
            rows, cols = np.arange(shape[0]), np.arange(shape[1])
            near[:] = True
        near = near[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        self.u0, self.v0 = int(lo[0] + cols[0]), int(lo[1] + rows[0])
        self.shape = near.shape
        self.I = np.asarray(img, dtype=float)[self.v0:self.v0 + self.shape[0],
                                              self.u0:self.u0 + self.shape[1]]
        use = near.copy()
        if exclude is not None:
            use &= ~np.asarray(exclude, bool)[self.v0:self.v0 + self.shape[0],
                                              self.u0:self.u0 + self.shape[1]]
        self.use = use
        # a window BACKGROUND_PAD_PX wider, for the local background (:meth:`background`)
        pad = BACKGROUND_PAD_PX
        self.pu0, self.pv0 = max(self.u0 - pad, 0), max(self.v0 - pad, 0)
        pu1 = min(self.u0 + self.shape[1] + pad, W)
        pv1 = min(self.v0 + self.shape[0] + pad, H)
        self.I_pad = np.asarray(img, dtype=float)[self.pv0:pv1, self.pu0:pu1]
        self.ok_pad = (np.ones(self.I_pad.shape, bool) if exclude is None else
                       ~np.asarray(exclude, bool)[self.pv0:pv1, self.pu0:pu1])
        self.B = np.ones(self.shape)
        vv, uu = np.indices(self.shape)
        cu, cv = 0.5 * (self.shape[1] - 1), 0.5 * (self.shape[0] - 1)
        self.du = (uu - cu) / max(cu, 1.0)
        self.dv = (vv - cv) / max(cv, 1.0)
        self.n = int(use.sum())

    def basis(self, roll_rad: float) -> tuple[np.ndarray, np.ndarray]:
        """``(1 - g + a h, g)`` on the ROI at ``roll_rad``: the blurred-edge model of the whole
        outline, its corners included (:func:`~cadra.imaging.silhouette.polygon.blurred_polygon`),
        with the view's edge profile ``x0 + x4 cos 4 theta`` per edge."""
        poly = self.outline_fn(roll_rad) - np.array([self.u0, self.v0], dtype=float)

        def c4(nrm):
            return 1.0 - 8.0 * nrm[:, 0] ** 2 * nrm[:, 1] ** 2

        g, h = blurred_polygon(poly, self.shape, lambda n: self.s0 + self.s4 * c4(n),
                               lambda n: self.a0 + self.a4 * c4(n), self.ratio, reach=BAND_PX)
        return 1.0 - g + h, g

    def design(self, roll_rad: float, use=None) -> np.ndarray:
        """(n_used, 4) design matrix of the linear levels ``(l0, l1, l2, D)`` on the pixels
        ``use`` (default: all of the model's), times the local background ``self.B``."""
        bright, dark = self.basis(roll_rad)
        bright, dark = bright * self.B, dark * self.B
        u = self.use if use is None else use
        return np.column_stack([bright[u], (bright * self.du)[u], (bright * self.dv)[u],
                                dark[u]])

    def background(self, roll_rad: float) -> np.ndarray:
        """The beam's local level on the model's pixels, relative (mean 1): the image's
        unshadowed pixels (farther than :data:`BACKGROUND_CLEAR_PX` outside the outline at
        ``roll_rad``, wires masked) fitted by a Gaussian-weighted local plane (sigma
        :data:`BACKGROUND_SIGMA_PX`, :func:`_local_linear_level`), which carries the level
        into the shadow from its surroundings. A plane over the fins' box is not enough: the
        beam's mottle (~1 % over ~60 px) moved a fin edge by ~0.005 px, 0.05 deg of roll near a
        mirror fold; a local mean (no plane) still ~0.001 px at the edge, 0.1 deg at 1-2 deg
        of roll (docs/stage1.md)."""
        shape = self.I_pad.shape
        poly = self.outline_fn(roll_rad) - np.array([self.pu0, self.pv0], dtype=float)
        shadow = pixel_centres_inside(poly, shape).astype(np.uint8)
        k = 2 * int(math.ceil(BACKGROUND_CLEAR_PX)) + 1
        shadow = cv2.dilate(shadow, np.ones((k, k), np.uint8)).astype(bool)
        w = (~shadow & self.ok_pad).astype(float)
        level = _local_linear_level(self.I_pad, w, BACKGROUND_SIGMA_PX)
        ru, rv = self.u0 - self.pu0, self.v0 - self.pv0
        B = level[rv:rv + self.shape[0], ru:ru + self.shape[1]]
        return B / float(np.mean(B))

    def solve(self, roll_rad: float, use=None):
        """Linear levels, residual vector and residual sum of squares at ``roll_rad``."""
        X = self.design(roll_rad, use)
        y = self.I[self.use if use is None else use]
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ coef
        return coef, r, float(r @ r), X

    def rss(self, roll_rad: float) -> float:
        return self.solve(roll_rad)[2]

    def refine(self, roll0: float, iterations: int = 6, step_rad: float = math.radians(0.02),
               max_move_rad: float = math.radians(3.0), passes: int = 2) -> ViewRoll:
        """Gauss-Newton in roll from ``roll0`` with the linear levels projected out and the
        beam's local level (:meth:`background`, re-estimated at the start of each of
        ``passes``); the sigma by the HAC score variance (module docstring, step 3). ``rss`` is
        that of the scan's model (a plane for the beam), comparable between candidates.

        Every pixel of the model is used, the outline's corners included: with the exact
        corner model (:meth:`basis`) no pixel needs leaving out (docs/stage1.md)."""
        # stay on roll0's side of the mirror folds at multiples of 45 deg (module docstring)
        lo = math.floor(roll0 / FOLD_RAD) * FOLD_RAD + step_rad
        hi = lo - step_rad + FOLD_RAD - step_rad
        g = min(max(float(roll0), lo), hi)
        for _ in range(passes):
            use = self.use
            self.B = self.background(g)
            for _ in range(iterations):
                coef, r, rss, X = self.solve(g, use)
                J = self._projected_derivative(g, coef, X, step_rad, use)
                jj = float(J @ J)
                if jj <= 0.0:
                    break
                move = float(J @ r) / jj
                move = max(-max_move_rad, min(max_move_rad, move))
                g_new = min(max(g + move, lo), hi)
                if abs(g_new - g) < 1e-7:
                    g = g_new
                    break
                g = g_new
        coef, r, rss, X = self.solve(g, use)
        J = self._projected_derivative(g, coef, X, step_rad, use)
        jj = float(J @ J)
        n = int(use.sum())
        s2 = rss / max(n - 5, 1)
        sigma_formal = math.sqrt(s2 / jj) if jj > 0 else math.inf
        # the HAC sigma, never below the formal one: with few pixels carrying the roll's
        # signal its Bartlett sum can come out near zero (one station of the sample shot:
        # 0.0002 deg for a 0.01 deg error)
        sigma = (max(math.sqrt(self._hac(J * r, use)) / jj, sigma_formal) if jj > 0
                 else math.inf)
        self.B = np.ones(self.shape)           # the scan's and the candidates' model
        rss_all = self.rss(g)
        return ViewRoll(roll_rad=g, sigma_rad=sigma, sigma_formal_rad=sigma_formal,
                        rss=rss_all, s2=rss_all / max(self.n - 5, 1), n_pixels=n)

    def _projected_derivative(self, g, coef, X, h, use=None):
        """d(model)/d(roll) at fixed levels, with the levels' directions projected out."""
        dp = self.design(g + h, use) @ coef
        dm = self.design(g - h, use) @ coef
        J = (dp - dm) / (2.0 * h)
        beta, *_ = np.linalg.lstsq(X, J, rcond=None)
        return J - X @ beta

    def _hac(self, q_used: np.ndarray, use) -> float:
        """Bartlett-weighted sum over pixel lags of ``q(x) q(x + lag)`` (q = J r on the
        pixels ``use``)."""
        q = np.zeros(self.shape)
        q[use] = q_used
        L = HAC_LAG_PX
        total = 0.0
        H, W = self.shape
        for dv in range(-L, L + 1):
            for du in range(-L, L + 1):
                w = (1.0 - abs(du) / (L + 1.0)) * (1.0 - abs(dv) / (L + 1.0))
                a = q[max(dv, 0):H + min(dv, 0), max(du, 0):W + min(du, 0)]
                b = q[max(-dv, 0):H + min(-dv, 0), max(-du, 0):W + min(-du, 0)]
                total += w * float(np.sum(a * b))
        return max(total, 0.0)


@dataclass(frozen=True)
class ViewRoll:
    """One view's refined roll: the value (rad, any branch), the HAC and the formal sigma
    (rad), the residual sum of squares, its variance per pixel and the pixels used."""

    roll_rad: float
    sigma_rad: float
    sigma_formal_rad: float
    rss: float
    s2: float
    n_pixels: int


@dataclass(frozen=True)
class RollCandidate:
    """One local minimum of the two views' chi^2 over a roll period: the combined roll (rad,
    in [0, pi/2)), its sigma, its chi^2 excess over the best candidate, and per view the
    refined :class:`ViewRoll` (on the combined value's branch)."""

    roll_rad: float
    sigma_rad: float
    chi2_excess: float
    views: dict


@dataclass(frozen=True)
class StationRoll:
    """A station's roll measurement: candidates best first (module docstring, step 2), and the
    scan (grid, rad; combined chi^2 at each grid roll)."""

    candidates: tuple[RollCandidate, ...]
    grid_rad: np.ndarray
    chi2: np.ndarray

    @property
    def best(self) -> RollCandidate:
        return self.candidates[0]


def _wrap(x: float, period: float = PERIOD_RAD) -> float:
    """``x`` brought into [-period/2, period/2)."""
    return (x + 0.5 * period) % period - 0.5 * period


def measure_station_roll(models: dict, max_candidates: int = 3,
                         previous: StationRoll | None = None) -> StationRoll:
    """Scan, refine and combine the views' roll models (``view name -> ViewRollModel``).

    ``previous``: the same station's roll from a previous round (poses refitted since): its
    candidates are refined again without a new scan.
    """
    s2 = {}
    if previous is None:
        grid = (np.arange(int(round(PERIOD_RAD / SCAN_STEP_RAD))) + 0.5) * SCAN_STEP_RAD
        curves = {}
        for name, m in models.items():
            c = np.array([m.rss(g) for g in grid])
            curves[name] = c
            s2[name] = c.min() / max(m.n - 5, 1)
        chi2 = sum(curves[n] / s2[n] for n in models)
        n = len(grid)
        minima = [k for k in range(n)
                  if chi2[k] <= chi2[k - 1] and chi2[k] < chi2[(k + 1) % n]]
        minima = sorted(minima, key=lambda k: chi2[k])[:max_candidates]
        starts = [float(grid[k]) for k in minima]
        for g0 in list(starts):          # each minimum's mirror, refined on its own branch
            mirror = (-g0) % PERIOD_RAD
            if all(abs(_wrap(mirror - g)) > 0.5 * SCAN_STEP_RAD for g in starts):
                starts.append(mirror)
    else:
        grid, chi2 = previous.grid_rad, previous.chi2
        starts = [c.roll_rad for c in previous.candidates]
    cands = []
    for g0 in starts:
        views = {}
        for name, m in models.items():
            vr = m.refine(g0)
            # the same branch as the scan's minimum
            views[name] = ViewRoll(**{**vr.__dict__,
                                      "roll_rad": g0 + _wrap(vr.roll_rad - g0)})
        w = {nm: 1.0 / v.sigma_rad ** 2 for nm, v in views.items()
             if math.isfinite(v.sigma_rad) and v.sigma_rad > 0}
        if w:
            val = sum(w[nm] * views[nm].roll_rad for nm in w) / sum(w.values())
            sig = 1.0 / math.sqrt(sum(w.values()))
        else:
            val, sig = g0, math.inf
        cands.append([0.0, val % PERIOD_RAD, sig, views])
    for name in models:
        if name not in s2:       # no scan this time: the best refined residual's variance
            s2[name] = min(c[3][name].s2 for c in cands)
    for c in cands:
        c[0] = sum(c[3][nm].rss / s2[nm] for nm in models)
    # merge candidates that refined onto the same minimum
    cands.sort(key=lambda c: c[0])
    merged = []
    for c in cands:
        if all(abs(_wrap(c[1] - m[1])) > math.radians(0.5) for m in merged):
            merged.append(c)
    best = merged[0][0]
    out = tuple(RollCandidate(roll_rad=c[1], sigma_rad=c[2], chi2_excess=c[0] - best,
                              views=c[3]) for c in merged)
    return StationRoll(candidates=out, grid_rad=grid, chi2=chi2)


def resolve_roll_track(times_s, station_rolls, sigma_pred_rad: float = TRACK_SIGMA_RAD):
    """The roll along a shot from each station's candidates (module docstring, step 4).

    Parameters
    ----------
    times_s : (n,) spark times, increasing.
    station_rolls : n :class:`StationRoll` or None (a station without a roll).

    Returns
    -------
    roll_rad : (n,) unwrapped roll (nan where None), the first measured station in [-45, 45)
        deg.
    sigma_rad : (n,) the chosen candidates' sigmas.
    chosen : (n,) index of the chosen candidate (-1 where None).
    """
    t = np.asarray(times_s, dtype=float)
    idx = [k for k, s in enumerate(station_rolls) if s is not None]
    n = len(station_rolls)
    roll = np.full(n, np.nan)
    sig = np.full(n, np.nan)
    chosen = np.full(n, -1)
    if not idx:
        return roll, sig, chosen
    best_track, best_cost = None, math.inf
    for j0, c0 in enumerate(station_rolls[idx[0]].candidates):
        track = [(idx[0], j0, _wrap(c0.roll_rad))]
        cost = c0.chi2_excess
        for k in idx[1:]:
            if len(track) >= 2:
                (k1, _, p1), (k2, _, p2) = track[-2], track[-1]
                pred = p2 + (p2 - p1) * (t[k] - t[k2]) / (t[k2] - t[k1])
                s_pred = sigma_pred_rad
            else:
                pred, s_pred = track[-1][2], 3.0 * sigma_pred_rad
            options = []
            for j, c in enumerate(station_rolls[k].candidates):
                val = pred + _wrap(c.roll_rad - pred)
                options.append((c.chi2_excess + ((val - pred) / s_pred) ** 2, j, val))
            step_cost, j, val = min(options)
            cost += step_cost
            track.append((k, j, val))
        if cost < best_cost:
            best_track, best_cost = track, cost
    for k, j, val in best_track:
        roll[k] = val
        sig[k] = station_rolls[k].candidates[j].sigma_rad
        chosen[k] = j
    return roll, sig, chosen


def wrap_period(x: float) -> float:
    """``x`` (rad) brought into the cruciform's half period about 0, [-45, 45) deg."""
    return (x + 0.5 * PERIOD_RAD) % PERIOD_RAD - 0.5 * PERIOD_RAD


def conical_outline_px(body, view, projection, pose, tilt_rad: float, pose3d,
                       roll_rad: float, n_points: int = 1024) -> np.ndarray:
    """The exact outline (px, (N, 2)) of ``body`` at roll ``roll_rad`` in a point-source
    ``view`` at stage one's view pose ``pose`` (film-plane ``(a, b, phi)``), the shadow's
    cone made at the station's 3-D pose ``pose3d`` = (reference point, m; unit axis)
    (:func:`cadra.imaging.silhouette.template.make_conical_template`, as the silhouette fit's
    templates are)."""
    from cadra.imaging.silhouette.template import make_conical_template, outline_px

    r_ref, axis = pose3d
    tpl = make_conical_template(body, view.optics(), np.asarray(r_ref, dtype=float),
                                np.asarray(axis, dtype=float), n_points=n_points,
                                roll_rad=float(roll_rad), tilt_rad=float(tilt_rad))
    return outline_px(tpl, pose, projection)


def measure_roll(body, views, images: dict, fits: dict, tilts: dict, masks: dict, settings,
                 previous=None, pose3d=None):
    """The roll of a finned body at one station from both views' fin silhouettes, each view's
    fitted pose held (:func:`measure_station_roll`): ``views`` the station's views, ``fits``
    their :class:`cadra.imaging.view.ViewResult`, ``tilts`` the axis' tilt out of each
    view's plane, ``masks`` the wire masks, ``settings`` the silhouette fit's; ``previous``
    this station's roll of the last round. A point-source view's outline is its shadow's
    (:func:`conical_outline_px`, at ``pose3d``), a parallel view's the body's projection
    (:func:`view_outline_px`)."""
    models = {}
    for name in ("top", "side"):
        r = fits[name]
        f = r.fit
        profile = f.edge_profile or (f.edge_sigma_px, 0.0, 0.0, 0.0)
        if views[name].projection == "point_source":
            outline = functools.partial(conical_outline_px, body, views[name], r.projection,
                                        f.pose, tilts[name], pose3d)
        else:
            outline = functools.partial(view_outline_px, body, r.projection, name, f.pose,
                                        tilts[name])
        models[name] = ViewRollModel(images[name], outline, masks.get(name), profile,
                                     settings.fringe_width_ratio)
    return measure_station_roll(models, previous=previous)
