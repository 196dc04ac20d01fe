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
an image's clean profiles, for a formation fitted over several images; the centroid pass they
come from (:func:`centroid_pass`) can be handed to :func:`measure_wires` later, which then
goes on from it instead of making it again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from cadra.facility.reference import View
from cadra.imaging.wires.affine import corner_sigma_px, formation_cov, solve_affine_gls
from cadra.imaging.wires.formation import SHARED_P, fit_formation, fit_widths
from cadra.imaging.wires.line import (
    Profiles,
    WireFit,
    line_from_centres,
    measure_one_wire,
    not_found,
)
from cadra.imaging.wires.phase import line_phases, phase_gain, systematic_cov
from cadra.imaging.wires.profile import Formation, WireProfiles, fit_centres
from cadra.imaging.wires.straightness import MODEL_BLOCK_SYS_PX
from cadra.optics.projection import Projection
from cadra.stats import chi2_quantile

__all__ = ["CENTROIDS", "CentroidPass", "WireFit", "WireMeasurement", "centroid_pass",
           "measure_wires", "wire_profiles"]

#: Below this total blur (px) of the wires' fitted formation the profile model is not used
#: (the centroid and its phase term are): at 0.4 px optics blur a few per cent error in the
#: fitted blur moved lines by several sigma (docs/stage1.md, "The wires' profile model").
MIN_MODEL_BLUR_PX = 0.55
#: Profiles within this distance (px) of another wire's predicted line are not used.
CROSSING_CLEARANCE_PX = 18.0
#: Extra clearance (px) around the scanner reference mark.
MARK_CLEARANCE_PX = 6.0
#: A wire-only solution is "poorly determined" when the propagated 1-sigma position error at
#: an image corner exceeds this (px).
MAX_CORNER_SIGMA_PX = 0.02
#: :func:`measure_wires`' ``formation`` that asks for no profile model: every wire's
#: centres by centroid, with their phase term (step 7)
CENTROIDS = "centroid"


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
    if ``collect``, each found wire's clean profiles (wire index -> :class:`Profiles`);
    ``distortion`` the recorded image's (:func:`measure_wires`)."""
    segs = view.wire_lines_px()
    mark = view.reference_mark
    mark_r = mark.arm_px + MARK_CLEARANCE_PX

    fits: list = [None] * len(view.wires)
    collected = {}
    for i, (w, seg) in enumerate(zip(view.wires, segs, strict=True)):
        if seg is None:
            fits[i] = not_found(w.name, "its predicted path misses the image")
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
        fits[i] = measure_one_wire(img, w.name, seg, 0.5 * view.wire_width_px(w),
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


def _kept(g: Profiles) -> WireProfiles:
    """The profiles of a wire its centroid line kept (the formation is fitted from these)."""
    return WireProfiles(g.wp.P[g.kept], g.wp.s0[g.kept], g.wp.c0[g.kept], g.wp.h, g.wp.t,
                        g.wp.cos_t)


@dataclass(frozen=True, eq=False)
class CentroidPass:
    """Steps 1-6 over one image of a view (:func:`centroid_pass`): each wire's centroid line
    (``fits``) and each found wire's clean profiles (``collected``, wire index ->
    :class:`~cadra.imaging.wires.line.Profiles`), made with the ``exclude`` mask and
    ``settings`` ``(search_px, step_px, half_window, distortion)`` it records."""

    fits: list
    collected: dict
    exclude: np.ndarray | None
    settings: tuple

    def profiles(self) -> list[WireProfiles]:
        """The clean profiles the centroid lines kept, a wire each."""
        return [_kept(g) for g in self.collected.values()]


def centroid_pass(image: np.ndarray, view: View, exclude: np.ndarray | None = None,
                  search_px: float = 30.0, step_px: float = 4.0,
                  half_window: int = 8, distortion=None) -> CentroidPass:
    """Steps 1-6 of :func:`measure_wires` (arguments as there), kept: what the image
    formation is fitted from (:meth:`CentroidPass.profiles`) and where
    :func:`measure_wires` goes on (its ``first_pass``)."""
    img, exclude = _checked_image(image, exclude)
    fits, collected = _centroid_pass(img, view, exclude, search_px, step_px, half_window,
                                     True, distortion)
    return CentroidPass(fits, collected, exclude,
                        (search_px, step_px, half_window, distortion))


def wire_profiles(image: np.ndarray, view: View, exclude: np.ndarray | None = None,
                  search_px: float = 30.0, step_px: float = 4.0,
                  half_window: int = 8, distortion=None) -> list[WireProfiles]:
    """The clean profiles of each wire of ``view`` found in ``image`` (the centroid lines'
    kept profiles; arguments as :func:`measure_wires`): what the image formation is fitted
    from (:func:`cadra.imaging.wires.formation.fit_formation`, over one image or several)."""
    return centroid_pass(image, view, exclude, search_px, step_px, half_window,
                         distortion).profiles()


def measure_wires(image: np.ndarray, view: View, exclude: np.ndarray | None = None,
                  search_px: float = 30.0, step_px: float = 4.0,
                  half_window: int = 8, profile_model: bool = True,
                  formation: Formation | str | None = None, distortion=None,
                  first_pass: CentroidPass | None = None) -> WireMeasurement:
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
        formation is fitted from this image alone. :data:`CENTROIDS`: no profile model
        (as ``profile_model=False``: a shot's quick look, docs/stage1.md).
    distortion : the recorded image's :class:`~cadra.optics.distortion.Distortion` (None:
        none). Each wire's profiles are then taken along its curved image, and their centres
        mapped to ideal pixels, where the line is fitted: the lines, the affine and every
        pixel coordinate returned are the ideal image's (docs/stage1.md, "Distorted images").
    first_pass : :func:`centroid_pass` of this image made already (the shot's formation
        pass); used when its mask and settings are these, else made again.

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
    if isinstance(formation, str):
        if formation != CENTROIDS:
            raise ValueError(f"formation must be a Formation, None or {CENTROIDS!r}, "
                             f"not {formation!r}")
        profile_model, formation = False, None
    img, exclude = _checked_image(image, exclude)
    if (profile_model and first_pass is not None
            and first_pass.settings[:3] == (search_px, step_px, half_window)
            and first_pass.settings[3] is distortion
            and (exclude is None) == (first_pass.exclude is None)
            and (exclude is None or np.array_equal(exclude, first_pass.exclude))):
        fits, collected = list(first_pass.fits), first_pass.collected
    else:
        fits, collected = _centroid_pass(img, view, exclude, search_px, step_px,
                                         half_window, profile_model, distortion)
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
        model[i], _ = line_from_centres(fits[i].name, c, g.fixed, g.ax, np.isfinite(c),
                                         step_px, g.n_inside, MODEL_BLOCK_SYS_PX, distortion)
    sens = {i: formation.sens[k] for k, i in enumerate(collected)}
    # the centroid lines with their errors (the centroids' own affine only if it is used)
    centroid = fits if sum(f.found for f in fits) < 3 else _line_errors(view, fits, None)[0]
    t2, n_lines = _disagreement(model, centroid)
    if t2 <= chi2_quantile(1.0 - MODEL_AGREEMENT_P, max(n_lines, 1)):
        out = _solve_affine(view, model, formation, sens)
    else:   # the formation does not describe these wires (a PSF far from Gaussian?)
        notes.append(f"wire profile model disagrees with the wires' centroids (chi2 {t2:.0f} "
                     f"over {n_lines} lines): centroids used")
        out = _solve_affine(view, fits)
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


def _line_errors(view: View, fits: list[WireFit], formation: Formation | None):
    """Each found line's error: ``fits`` with their phase term's sigma (``sigma_sys_px``),
    each line's (2, 2) covariance of its Gauss points' perpendicular errors (px^2; None for
    a wire not found) and the phase gain: sqrt(2) x the line's offset sigma (floored),
    independent, plus the centroid's phase bias, common to the line's centres (step 7; the
    profile model's centres, ``formation`` given, carry none: step 8)."""
    width_px = [view.wire_width_px(w) for w in view.wires]
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
    return fits, cov_px, gain


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
    fits, cov_px, gain = _line_errors(view, fits, formation)
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
