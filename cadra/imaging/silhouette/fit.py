"""Measure the model's pose in one shadowgraph: the silhouette least squares (method a).

Stage one's main method (seed 004, "Data Reduction and Analysis"; docs/stage1.md):

(a) **Least squares** (:func:`fit_silhouette`): the body's exact outline (:mod:`cadra.body`) is
    placed at a trial pose; pixels in a band around it are grouped into short contour
    *segments*; in each segment a blurred-edge model ``I = L (1 - g) + D g + a L h``,
    ``g = Phi((delta - d) / s)`` (d = the pixel centre's signed distance from the outline,
    + outside; L the local bright level, D the dark level, tied to it image-wide as
    ``D = r L + c`` by default (``FitSettings.dark_level``: a free D per segment costs each
    offset ~12 % of its sigma); s the edge width) gives the segment's edge offset ``delta``
    along the outward normal, with its variance (stage A, :mod:`cadra.imaging.silhouette.edges`).
    ``a L h`` is the diffraction fringe: a bright band outside the edge and a dark one inside,
    the second derivative of a blurred step. The edge width and the fringe amplitude are
    fitted per image, each as ``x0 + x4 cos(4 theta)`` (theta the normal's
    angle to the pixel grid): the profile across an edge depends on that angle at fourth
    order (a square pixel projects onto the normal as a box along an axis, a triangle along a
    diagonal).
    The pose correction then follows from all offsets by weighted least squares (stage B)::

        delta_k = n_k . (dr + dphi x (x_k - r_ref)) - c kappa_k

    The last term is the curvature bias of a blurred edge: the half-intensity contour of a
    blurred convex edge lies inside the true outline by ``(blur variance along the tangent)
    kappa / 2`` (Mendonca et al., ECCV 2004); a diffraction fringe adds a term of the same
    form. ``c`` (px^2) is fitted, not assumed, so the correction holds for a PSF shape or a
    fringe the measurement does not model. Wide edges add ``- e``, a uniform offset of every
    edge (``FitSettings.edge_offset``: the outline's apparent size). Iterated to convergence
    (band and segments re-built at each pose). Uncertainty: Newey-West sandwich over the
    contour-ordered segment residuals, so correlated noise (film grain) and misfit show up
    in the sigma.

Method (b), the area centroid, is :mod:`cadra.imaging.silhouette.centroid`; the outline
template :mod:`cadra.imaging.silhouette.template`; stage A (the per-segment edge offsets and
their numba kernels) :mod:`cadra.imaging.silhouette.edges`; the first guess
:mod:`cadra.imaging.silhouette.locate`.

Geometry is in the *view plane* (metres in F, docs/conventions.md) through the view's
:class:`~cadra.optics.projection.Projection` (for a parallel view: the image's wire affine);
the pose of one view is ``(a, b, phi)``: the reference point's view-plane coordinates and the
in-plane axis angle from the first view axis toward the second (top view: psi_p = atan2(a_y,
a_x); side view: theta_p = atan2(a_z, a_x)). The outline depends also on the axis' tilt out
of the view plane (seen by the other view): ``tilt_rad`` (its sign does not matter: the
outline depends on |cos| of the angle to the line of sight).

Everything here is a pure function of plain arrays and frozen dataclasses (picklable).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from cadra.geometry import densify_polygon
from cadra.imaging.silhouette.centroid import centroid_pose
from cadra.imaging.silhouette.edges import outline_geometry, stage_a
from cadra.imaging.silhouette.noise import (
    noise_autocovariance,
    segment_correlation,
    segment_covariance,
)
from cadra.imaging.silhouette.template import Template, outline_px, pose_px
from cadra.optics.distortion import ideal_projection
from cadra.optics.projection import Projection

__all__ = ["FitSettings", "ViewFit", "fit_silhouette"]

#: After two iterations a converging fit moves far less than this (px at the rim).
MAX_LATE_STEP_PX = 0.3
#: A step's direction whose singular value (the step in pixels) is below this fraction of
#: the largest is not taken (truncated SVD): the kept segments do not determine it. Robust
#: rejection can leave only a slender body's parallel sides, and their noise then set a
#: step of 10 mm along the axis (a finned body fitted at a wrong roll).
STEP_RCOND = 1e-2


@dataclass(frozen=True)
class FitSettings:
    """Knobs of the silhouette fit (docs/stage1.md); defaults suit ~1 px blur."""

    band_px: float = 3.5            # half-width of the pixel band about the outline, at least
    #: ... and at least this many fitted edge widths: a wide edge (2 px optics blur) in a
    #: 3.5 px band left its sigma 2-3x too large (docs/stage1.md, "Wide edges")
    band_widths: float = 3.3
    segment_px: float = 8.0         # contour segment length
    #: pixels this close (along the outline) to a sharp corner are not used: 2.6 edge widths
    #: at the default blur (docs/stage1.md, "corners"); fixed in pixels, never the fitted width
    corner_clear_px: float = 2.0
    min_fill: float = 0.6           # a segment needs this fraction of its expected pixels
    max_iter: int = 8               # pose iterations (band rebuilt each time)
    tol_px: float = 2e-4            # stop when the pose moves less than this (px at the rim)
    outlier_sigma: float = 4.0      # segment offsets beyond this many robust sigma are dropped
    hac_lags: int = 3               # Newey-West lags over contour-ordered segments
    #: "predicted" (default): the offsets' covariance predicted from the image's measured
    #: noise (measure.silhouette.noise), scaled up, never down, by their reduced chi^2
    #: about it; "correlated": the formal covariance times the offsets' reduced chi^2, with
    #: the predicted correlation between segments; "scaled": that without the correlation;
    #: "sandwich": Newey-West over the contour-ordered segments (the earlier default sigma)
    covariance: str = "predicted"
    noise_lag_px: int = 5           # pixel-noise correlation measured to this lag
    fit_curvature_bias: bool = True
    #: a uniform offset of every edge (the outline's apparent size) fitted beside the pose:
    #: "wide" (default) for wide edges only, where the band has widened past ``band_px``
    #: (docs/stage1.md, "Wide edges"), "always" or "never"; never for a sphere, whose
    #: curvature bias is already a size change, nor a finned body, whose fits at trial rolls
    #: run wide
    edge_offset: str = "wide"
    fringe_width_ratio: float = 1.2  # fringe profile width / edge width (1.2-1.4 alike)
    #: stage A's joint least squares stops when no segment offset nor the edge width moves
    #: by this much (px) in a step, or after this many steps (docs/stage1.md, step 3)
    stage_a_tol_px: float = 1e-4
    stage_a_max_iter: int = 30
    dark_level: str = "tied"        # "tied": D = r L + c image-wide; "segment": D per segment

    def band_for(self, edge_width_px: float) -> float:
        """The band's half-width (px) for an edge of this fitted width (px)."""
        return max(self.band_px, self.band_widths * edge_width_px)

    def __post_init__(self):
        if self.covariance not in ("predicted", "correlated", "scaled", "sandwich"):
            raise ValueError(f"FitSettings.covariance: expected 'predicted', 'correlated', "
                             f"'scaled' or 'sandwich', got {self.covariance!r}")
        if self.edge_offset not in ("wide", "always", "never"):
            raise ValueError(f"FitSettings.edge_offset: expected 'wide', 'always' or 'never', "
                             f"got {self.edge_offset!r}")
        if self.dark_level not in ("tied", "segment"):
            raise ValueError(f"FitSettings.dark_level: expected 'tied' or 'segment', got "
                             f"{self.dark_level!r}")



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
    #: d(a_m, b_m, phi_rad) / d(tilt): how the pose moves when the template's out-of-plane
    #: tilt changes (m/rad, m/rad, rad/rad); zeros unless fit_silhouette was given a
    #: ``tilt_step``. The tilt comes from the other view's angle, so its error moves this
    #: view's pose; cadra.imaging.combine propagates it (docs/stage1.md, step 5)
    tilt_sensitivity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: False when the last step's kept segments left a direction of the pose undetermined
    #: (:data:`STEP_RCOND`): the pose is not converged and that direction's sigma is huge
    determined: bool = True


def fit_silhouette(img: np.ndarray, template: Template, projection: Projection,
                   pose0: tuple[float, float, float], *, exclude: np.ndarray | None = None,
                   settings: FitSettings | None = None, edge_sigma0: float = 0.9,
                   noise_coef: np.ndarray | None = None,
                   edge_profile0: tuple[float, float, float, float] | None = None,
                   centroid: bool = True,
                   tilt_step: tuple[Template, Template, float] | None = None) -> ViewFit:
    """Least-squares silhouette fit (method a) from ``pose0``; see the module docstring.

    ``img`` float (H, W) in [0, 1]; ``projection`` the view's optics (for a parallel view
    :class:`~cadra.optics.projection.ParallelProjection` with the image's wire affine);
    ``exclude`` True on pixels not to use (wires, other
    clutter known in advance); ``edge_sigma0`` (or the whole edge profile ``edge_profile0``,
    :attr:`ViewFit.edge_profile`) and ``noise_coef`` (the image's noise model,
    :attr:`ViewFit.noise_coef`) warm-start a refit; ``centroid=False`` skips method (b)
    (an intermediate fit). ``tilt_step = (template at tilt + h, template at tilt - h, h)``
    gives :attr:`ViewFit.tilt_sensitivity` (:func:`_tilt_sensitivity`). Never raises for
    bad data: ``ok`` False with a reason.
    """
    settings = FitSettings() if settings is None else settings
    Jrot = np.array([[0.0, -1.0], [1.0, 0.0]])
    pose = np.array(pose0, float)
    fit_phi = not template.axisymmetric_point
    # (for a sphere the curvature is the same all round and the term is a radius change: it
    # does not move the centre, but leaving it out lets an uneven set of rejected segments
    # turn the edges' common offset into a centre shift)
    fit_c = settings.fit_curvature_bias
    # the uniform edge offset (docs/stage1.md, "Wide edges"): for which bodies, and when
    e0_body = fit_c and not template.axisymmetric_point and not template.finned
    e0 = 0.0
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
    determined = True
    band = settings.band_for(float(profile[0]))
    A_lin = projection.from_plane_jacobian(pose[:2])   # plane (m) -> pixel displacement
    for it in range(1, settings.max_iter + 1):  # noqa: B007 (it is reported)
        A_lin = projection.from_plane_jacobian(pose[:2])
        poly = outline_px(template, pose, projection)
        b0 = settings.band_px
        inside = ((poly[:, 0] >= b0) & (poly[:, 0] <= W - 1 - b0)
                  & (poly[:, 1] >= b0) & (poly[:, 1] <= H - 1 - b0))
        outside = 1.0 - float(inside.mean())
        if outside > 0.5:
            return _failed(f"model mostly out of frame ({outside:.0%} of its outline)", pose,
                           outside)
        # the band follows the fitted edge width, trusted only with the whole outline in frame
        # (cut by the frame's edge, a fit's width can be anything); a band widened for a wider
        # edge than the start's: stage A cold again (its noise model and profile settle on the
        # new band's pixels), and not converged on this pass
        band_prev, band = band, (settings.band_for(float(profile[0])) if outside == 0.0
                                 else b0)
        widened = band > 1.1 * band_prev
        geo = outline_geometry(poly)
        seg = stage_a(img, geo, settings, exclude, profile, None if widened else noise_coef,
                      band_px=band)
        if seg is None:
            return _failed("too few usable edge segments", pose, outside)
        profile = seg.profile
        noise_coef = seg.noise_coef
        ref_px = projection.from_plane(pose[:2])
        scale = math.sqrt(abs(np.linalg.det(projection.to_plane_jacobian(ref_px))))  # m/px
        rim = 0.5 * math.sqrt(template.area_m2 / math.pi) / scale                  # px
        lever = projection.to_plane(seg.foot_px) - pose[:2]        # plane, m
        cols = [seg.normal @ A_lin[:, 0], seg.normal @ A_lin[:, 1]]
        if fit_phi:
            cols.append(np.einsum("ij,ij->i", seg.normal, (lever @ Jrot.T) @ A_lin.T))
        if fit_c:
            cols.append(-seg.kappa)
        fit_e0 = e0_body and (settings.edge_offset == "always"
                              or (settings.edge_offset == "wide" and band > settings.band_px))
        if fit_e0:
            cols.append(-np.ones(len(seg.kappa)))
        X = np.column_stack(cols)
        y = seg.delta_px
        wts = 1.0 / seg.var_px2
        keep = np.isfinite(y) & np.isfinite(wts) & (wts > 0)
        npar = X.shape[1]
        px_unit = np.full(npar, np.nan)   # each column's parameter per px of the outline's
        px_unit[:2] = scale                # move (a rotation's at the rim); the curvature's
        if fit_phi:                        # a nuisance (NaN)
            px_unit[2] = 1.0 / rim
        beta, keep, determined = _robust_step(X, y, wts, keep, px_unit, settings.outlier_sigma)
        n_rej = int((~keep).sum())
        if keep.sum() < npar + 5:
            return _failed("too few consistent edge segments", pose, outside)
        # covariance on the kept segments (docs/stage1.md, "Sigma"): the formal one scaled by
        # the offsets' reduced chi^2 (their variance runs ~1.5x the formal one: the grain's
        # correlation within a segment), or the Newey-West sandwich
        Xw = X[keep] * np.sqrt(wts[keep])[:, None]
        ew = (y[keep] - X[keep] @ beta) * np.sqrt(wts[keep])
        bread = np.linalg.pinv(Xw.T @ Xw)
        n_k = int(keep.sum())
        if settings.covariance != "sandwich":
            # ("correlated" and "predicted" are computed after the last iteration)
            cov_b = bread * float(ew @ ew) / max(n_k - npar, 1)
        else:
            meat = _newey_west(Xw, ew, settings.hac_lags)
            cov_b = bread @ meat @ bread * n_k / max(n_k - npar, 1)
        dpose = np.zeros(3)
        dpose[0], dpose[1] = beta[0], beta[1]
        if fit_phi:
            dpose[2] = beta[2]
        if it > 3:   # damp late iterations: re-banding noise can make full steps oscillate
            dpose *= 0.5
        move = np.hypot(*(A_lin @ dpose[:2])) + (abs(dpose[2]) * rim if fit_phi else 0.0)
        if it > 2 and move > MAX_LATE_STEP_PX:
            # a converging fit does not jump late: a stage-A failure (a strong fringe, a
            # clutter feature) produced this step; keep the last pose and say so
            diverged = True
            break
        c_bias = float(beta[npar - 1 - int(fit_e0)]) if fit_c else 0.0
        e0 = float(beta[-1]) if fit_e0 else 0.0
        pose = pose + dpose
        cov = np.full((3, 3), 0.0)
        idx = [0, 1, 2] if fit_phi else [0, 1]
        cov[np.ix_(idx, idx)] = cov_b[: len(idx), : len(idx)]
        if not fit_phi:
            cov[2, 2] = np.inf
        # converged: the step is below the tolerance or a small fraction of the pose's own
        # sigma (re-banding at a new pose re-draws the noise; steps below that are jitter)
        sig_px = math.sqrt(max(np.trace(A_lin @ cov[:2, :2] @ A_lin.T), 0.0))
        if move < max(settings.tol_px, 0.5 * sig_px) and not widened and determined:
            converged = True
            break
    if settings.covariance in ("correlated", "predicted") and not diverged:
        # the last iteration's offsets are correlated through the image's correlated noise
        # (film grain): the same scaled covariance, with that correlation between segments
        acov = noise_autocovariance(img, geo, exclude, seg.noise_coef, settings.noise_lag_px)
        if settings.covariance == "correlated":
            R = segment_correlation(seg, W, acov)[np.ix_(keep, keep)]
            cov_b = bread @ (Xw.T @ R @ Xw) @ bread * float(ew @ ew) / max(n_k - npar, 1)
        else:
            # the offsets' covariance predicted from the image's noise (variances and
            # correlations), scaled up, never down, by the offsets' reduced chi^2 about it
            C = segment_covariance(seg, W, acov)[np.ix_(keep, keep)]
            XV = X[keep] * wts[keep][:, None]
            e_k = y[keep] - X[keep] @ beta
            chi2p = float(np.sum(e_k ** 2 / np.maximum(np.diag(C), 1e-300)))
            cov_b = bread @ (XV.T @ C @ XV) @ bread * max(1.0, chi2p / max(n_k - npar, 1))
        idx = [0, 1, 2] if fit_phi else [0, 1]
        cov[np.ix_(idx, idx)] = cov_b[: len(idx), : len(idx)]
    # the pixel pose and its sigmas in the ideal image (a distorted view's recorded image is
    # only where the offsets are measured)
    ideal = ideal_projection(projection)
    ref_px, ang_px = pose_px(pose, ideal)
    # pixel-space sigmas by linear propagation
    Jp = np.zeros((3, 3))
    Jp[:2, :2] = ideal.from_plane_jacobian(pose[:2])
    h = 1e-7
    _, a_plus = pose_px(pose + [0, 0, h], ideal)
    Jp[2, 2] = (a_plus - ang_px) / h
    cov_fin = np.where(np.isfinite(cov), cov, 0.0)
    cov_px = Jp @ cov_fin @ Jp.T
    # offsets about the fitted outline (a sphere: about its mean, the radius change)
    resid = seg.delta_px + c_bias * seg.kappa + e0
    nan2 = (math.nan, math.nan)
    cen = (centroid_pose(img, template, projection, pose, seg, exclude) if centroid
           else (nan2, math.nan, (math.nan,) * 3))
    tilt_sens = (0.0, 0.0, 0.0)
    if tilt_step is not None and fit_phi:
        tilt_sens = _tilt_sensitivity(tilt_step, pose, projection, seg, X, wts, keep, fit_phi)
    warnings = []
    if diverged:
        warnings.append(f"silhouette fit: a late step of > {MAX_LATE_STEP_PX} px was rejected "
                        f"(edge model failing in part of the outline); last pose kept")
    elif not determined:
        warnings.append(f"silhouette fit: the {n_k} edge segments kept ({n_rej} rejected) do "
                        f"not determine the pose (a template far from the outline?); not "
                        f"converged")
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
        edge_profile=tuple(float(x) for x in seg.profile), tilt_sensitivity=tilt_sens,
        determined=determined)


def _robust_step(X: np.ndarray, y: np.ndarray, wts: np.ndarray, keep: np.ndarray,
                 px_unit: np.ndarray, outlier_sigma: float):
    """The pose step by weighted least squares ``X beta ~ y`` (weights ``wts``) on the
    segments ``keep``, outlying segments dropped at ``outlier_sigma`` robust sigma (dust,
    wire crossings; at most three passes, and never half of them at once).

    The step is solved in pixels (``px_unit[j]``: column j's parameter per pixel of the
    outline's move; NaN: a nuisance column, scaled to the pose columns' size), and a direction
    whose singular value is below :data:`STEP_RCOND` of the largest is not taken: the least
    pixel move that fits. Returns (beta, the segments kept, determined: no direction of a
    nonzero column was left out)."""
    for _ in range(3):
        sw = np.sqrt(wts[keep])
        norms = np.linalg.norm(X[keep] * sw[:, None], axis=0)
        live = norms > 0    # (a column of zeros, the curvature of straight edges alone, is
        pose = np.isfinite(px_unit)     # no direction to determine)
        unit = np.where(pose, px_unit, 1.0)
        size = np.max(norms[pose] * px_unit[pose], initial=0.0) or 1.0
        nuisance = ~pose & live
        unit[nuisance] = size / norms[nuisance]
        Xs, ys = X[keep] * sw[:, None], y[keep] * sw
        sv = np.linalg.svd(Xs * unit, compute_uv=False)
        rank = int(np.count_nonzero(sv > STEP_RCOND * sv[0])) if sv.size else 0
        if rank >= int(live.sum()):     # determined: the plain step (columns at unit norm)
            colscale = np.where(live, norms, 1.0)
            beta = np.linalg.lstsq(Xs / colscale, ys, rcond=None)[0] / colscale
        else:
            beta = np.linalg.lstsq(Xs * unit, ys, rcond=STEP_RCOND)[0] * unit
        e = (y - X @ beta) * np.sqrt(wts)
        mad = 1.4826 * np.median(np.abs(e[keep] - np.median(e[keep])))
        new_keep = keep & (np.abs(e) <= outlier_sigma * max(mad, 1e-12))
        if new_keep.sum() == keep.sum() or new_keep.sum() < 0.5 * keep.sum():
            break   # nothing more to drop, or a noise-free image (mad ~ 0)
        keep = new_keep
    return beta, keep, rank >= int(live.sum())


def _along_normal(feet: np.ndarray, normals: np.ndarray, poly: np.ndarray,
                  reach_px: float = 3.0) -> np.ndarray:
    """Signed distance t (px) from each foot along its normal to the closed polyline ``poly``
    (the crossing nearest the foot within ``reach_px``; NaN if none). The polyline is
    densified to 1-px edges and only the edges at a foot's 24 nearest points (a k-d tree)
    are tried."""
    P = densify_polygon(poly)
    E = np.roll(P, -1, axis=0) - P
    k_near = min(24, len(P))
    _, idx = cKDTree(P).query(feet, k=k_near)
    idx = np.concatenate([idx, (idx - 1) % len(P)], axis=1)     # the edges ending there too
    d = P[idx] - feet[:, None, :]                                  # (feet, candidates, 2)
    e = E[idx]
    n = normals[:, None, :]
    # p + t n = P_i + s E_i:  t = cross(P_i - p, E_i) / cross(n, E_i),
    #                         s = cross(P_i - p, n) / cross(n, E_i)
    den = n[..., 0] * e[..., 1] - n[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]) / den
        sp = (d[..., 0] * n[..., 1] - d[..., 1] * n[..., 0]) / den
    ok = (np.abs(den) > 1e-12) & (sp >= 0.0) & (sp <= 1.0) & (np.abs(t) <= reach_px)
    t = np.where(ok, t, np.inf)
    out = t[np.arange(len(feet)), np.argmin(np.abs(t), axis=1)]
    return np.where(np.isfinite(out), out, np.nan)


def _tilt_sensitivity(tilt_step, pose, projection, seg, X, wts, keep, fit_phi):
    """d(pose)/d(tilt) from the segments' own weighted least squares. From the template at
    tilt - h to the one at tilt + h the outline moves each segment's foot by D_k along its
    normal, so the fitted offsets would change by -D_k: to first order the pose moves by the
    weighted least-squares solution for -D (the same design: position, angle and curvature
    bias), over 2h. A central difference: a silhouette depends on |tilt|, so near zero tilt a
    one-sided step sees the curvature of |tilt|, not the derivative. The outline's change of
    curvature (the curvature-bias column) is left out: it changed nothing on the capsules
    and, from the nearest vertex, blew up near a bullet's base corner at small tilt; the
    position part is within 1-30 % of full refits (tests/test_silhouette_fit.py)."""
    template_p, template_m, h = tilt_step
    poly_p = outline_px(template_p, pose, projection)
    poly_m = outline_px(template_m, pose, projection)
    D = (_along_normal(seg.foot_px, seg.normal, poly_p)
         - _along_normal(seg.foot_px, seg.normal, poly_m))
    rhs = -D
    use = keep & np.isfinite(rhs)
    if use.sum() < X.shape[1] + 5:
        return (0.0, 0.0, 0.0)
    sw = np.sqrt(wts[use])
    beta, *_ = np.linalg.lstsq(X[use] * sw[:, None], rhs[use] * sw, rcond=None)
    d = beta / (2.0 * h)
    return (float(d[0]), float(d[1]), float(d[2]) if fit_phi else 0.0)


def _failed(reason: str, pose, outside: float) -> ViewFit:
    """A failed fit; with part of the outline out of frame, the reason says so (the likely
    cause of too few usable segments, a start far off)."""
    nan = math.nan
    if 0.0 < outside <= 0.5:
        reason = f"{reason} (model partly out of frame: {outside:.0%} of its outline)"
    return ViewFit(ok=False, reason=reason, pose=tuple(float(x) for x in pose),
                   cov=np.full((3, 3), np.nan), ref_px=(nan, nan), axis_angle_px_rad=nan,
                   sigma_ref_px=(nan, nan), sigma_axis_px_rad=nan, curvature_bias_px2=nan,
                   edge_sigma_px=nan, resid_rms=nan, offset_rms_px=nan, n_segments=0,
                   n_rejected=0, iterations=0, converged=False,
                   outline_outside_frac=outside, centroid_ref_px=(nan, nan),
                   centroid_axis_px_rad=nan, centroid_pose=(nan, nan, nan))

