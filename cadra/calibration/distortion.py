"""A view's image distortion calibrated from the image of a dot grid (docs/calibration.md,
"Distortion from a grid").

Seed 002 calibrated its biplanar system "point by point" from the image of an accurate grid.
Here a plate of dots at a known pitch is recorded in the view's window
(:func:`cadra.synthetic.scene.dot_grid_scene` draws one for the renderer);
:func:`find_dots` finds the dots' centres in the image (a moment centroid of each dot's
darkness above its local background); and
:func:`fit_distortion` fits the Brown–Conrady coefficients
(:class:`~cadra.optics.distortion.Distortion`) together with the plate's placement (an
affine from plate millimetres to ideal pixels: its position, scale, rotation and tilt are not
known to the pixel), by Gauss–Newton on ``recorded = D(A g)``. The coefficients' covariance
comes from the fit (its residuals' scatter, the affine marginalized) and goes into the
facility file, from where stage one carries it into the stations' sigmas
(:func:`cadra.imaging.distorted.distortion_pose_sigma`).

A dot's centroid in the recorded image is ``D`` of its centre to second order in the dot's
size: ~ r^2 |D''| ~ 1e-3 px for 5 px dots under a seed-002-size distortion, below the centroid's
own noise. Pixels throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from cadra.optics.distortion import Distortion

__all__ = ["MIN_DOT_DARKNESS", "DistortionFit", "calibrate_from_grids", "find_dots",
           "fit_distortion", "grid_points"]

#: a dot counts as found when its darkness ``1 - I / b`` sums to at least this fraction of
#: its area (a rendered or printed dot: 0.6-0.9)
MIN_DOT_DARKNESS = 0.25


def grid_points(width_px: int, height_px: int, pitch_px: float, margin_px: float
                ) -> np.ndarray:
    """The ideal image points (N, 2) of a square grid of ``pitch_px`` centred on the image,
    at least ``margin_px`` inside its border."""
    cu, cv = (width_px - 1) / 2.0, (height_px - 1) / 2.0
    nu = int((cu - margin_px) // pitch_px)
    nv = int((cv - margin_px) // pitch_px)
    u = cu + pitch_px * np.arange(-nu, nu + 1)
    v = cv + pitch_px * np.arange(-nv, nv + 1)
    return np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)


def find_dots(image: np.ndarray, approx_px: np.ndarray, dot_radius_px: float,
              search_px: float = 12.0) -> tuple[np.ndarray, np.ndarray]:
    """The recorded centres (N, 2) of the dots expected near ``approx_px`` (N, 2), and which
    were found (N,) bool, in ``image`` (integer, or float in [0, 1]). Each: the darkest
    point within ``search_px``, then a centroid of the darkness ``1 - I / b`` in a disc of
    1.4 dot radii re-centred on it twice, ``b`` the local background: a plane fitted to
    a ring beyond the dot (:func:`_background_plane`)."""
    image = np.asarray(image)
    img = image.astype(np.float64)
    if image.dtype.kind in "ui":            # an integer image: its full scale is 1
        img /= float(np.iinfo(image.dtype).max)
    H, W = img.shape
    smooth = cv2.GaussianBlur(img, (0, 0), max(dot_radius_px / 2.0, 0.8))
    r_in, r_bg0, r_bg1 = 1.4 * dot_radius_px, 2.0 * dot_radius_px, 3.0 * dot_radius_px
    half = int(math.ceil(max(search_px, r_bg1))) + 2
    yy, xx = np.mgrid[-half:half + 1, -half:half + 1]
    out = np.full((len(approx_px), 2), np.nan)
    ok = np.zeros(len(approx_px), bool)
    for i, (u0, v0) in enumerate(np.asarray(approx_px, dtype=float)):
        iu, iv = int(round(u0)), int(round(v0))
        if not (half <= iu < W - half and half <= iv < H - half):
            continue
        s = int(math.ceil(search_px))
        win = smooth[iv - s:iv + s + 1, iu - s:iu + s + 1]
        dv, du = np.unravel_index(np.argmin(win), win.shape)
        c = np.array([iu - s + du, iv - s + dv], dtype=float)
        # three passes, each window centred on the last centroid: the dot lies whole inside
        # the disc from the first (its edge 1.4 radii out) and the background beyond it
        # averages to zero, so the passes only take out the start's offset
        for p in range(3):
            ju, jv = int(round(c[0])), int(round(c[1]))
            if not (half <= ju < W - half and half <= jv < H - half):
                break
            patch = img[jv - half:jv + half + 1, ju - half:ju + half + 1]
            uu, vv = xx + ju, yy + jv
            rr = np.hypot(uu - c[0], vv - c[1])
            bg = _background_plane(patch, uu - c[0], vv - c[1], (rr >= r_bg0) & (rr <= r_bg1))
            # unclipped: the background's noise and its residual slope average out instead
            # of pulling the centroid toward the darker side
            w = (1.0 - patch / bg) * (rr <= r_in)
            if not w.sum() > 0:
                break
            c = np.array([(w * uu).sum(), (w * vv).sum()]) / w.sum()
            # a dot: darker than its background by MIN_DOT_DARKNESS over its area at least
            if p == 2 and w.sum() >= MIN_DOT_DARKNESS * math.pi * dot_radius_px ** 2:
                out[i], ok[i] = c, True
    return out, ok


def _background_plane(patch: np.ndarray, du: np.ndarray, dv: np.ndarray,
                      ring: np.ndarray) -> np.ndarray:
    """The local background under a dot: a plane fitted to the ring's pixels (twice, the
    second time without those beyond 3 robust sigmas: dust, a neighbour's edge). An
    illumination gradient under a constant background would move the centroid toward the
    darker side by a few thousandths of a pixel, the same way in neighbouring dots: a smooth
    error the distortion fit would take for a distortion term."""
    A = np.column_stack([np.ones(ring.sum()), du[ring], dv[ring]])
    y = patch[ring]
    keep = np.ones(len(y), bool)
    for _ in range(2):
        coef, *_ = np.linalg.lstsq(A[keep], y[keep], rcond=None)
        r = y - A @ coef
        mad = 1.4826 * np.median(np.abs(r[keep] - np.median(r[keep])))
        keep = np.abs(r) <= 3.0 * max(mad, 1e-12)
    return coef[0] + coef[1] * du + coef[2] * dv


@dataclass(frozen=True, eq=False)
class DistortionFit:
    """A distortion calibrated from a grid: the :class:`Distortion` (its covariance that of
    the fit), the plate's affine (2, 3) plate units -> ideal px, the residuals' rms (px),
    the dots used and the fit's degrees of freedom."""

    distortion: Distortion
    affine: np.ndarray
    rms_px: float
    n_points: int
    dof: int


def fit_distortion(plate_xy, recorded_px, width_px: int, height_px: int, affine0,
                   iterations: int = 8) -> DistortionFit:
    """Fit ``recorded = D(A g)`` for the distortion's four coefficients (about the image's
    centre, radius its half-diagonal) and the plate's affine ``A`` (2, 3) from plate points
    ``g`` = ``plate_xy`` (N, 2) (any unit) to ideal pixels, starting from ``affine0``; by
    Gauss–Newton. Several images of the plate (moved between them): lists of ``plate_xy``,
    ``recorded_px`` and ``affine0``, one affine each, one distortion for all (``affine``
    then the list of them). The covariance of the coefficients is the fit's, scaled by the
    residuals' reduced chi^2 (the centroids' noise is not assumed)."""
    several = isinstance(plate_xy, list | tuple)
    gs = [np.asarray(g, dtype=float) for g in (plate_xy if several else [plate_xy])]
    ys = [np.asarray(y, dtype=float) for y in (recorded_px if several else [recorded_px])]
    A0 = list(affine0) if several else [affine0]
    if not (len(gs) == len(ys) == len(A0)) or any(
            g.shape != y.shape or g.ndim != 2 or g.shape[1] != 2 for g, y in zip(gs, ys,
                                                                                 strict=True)):
        raise ValueError("plate_xy and recorded_px must both be (N, 2) (or lists of them, "
                         "with an affine0 each)")
    m = len(gs)
    n_unknown = 4 + 6 * m
    n = sum(len(g) for g in gs)
    if 2 * n < n_unknown + 6:
        raise ValueError(f"{n} grid points; the fit has {n_unknown} unknowns and needs at "
                         f"least {(n_unknown + 7) // 2} points")
    base = Distortion.for_image(width_px, height_px)
    A = [np.array(a, dtype=float).reshape(2, 3) for a in A0]
    k = np.zeros(4)
    Gs = [np.column_stack([g, np.ones(len(g))]) for g in gs]    # (n_i, 3)

    def residual_and_design(A, k):
        d = base.with_coefficients(k)
        rs, Xs = [], []
        for i, (G, y) in enumerate(zip(Gs, ys, strict=True)):
            ideal = G @ A[i].T
            rs.append((y - d.distort(ideal)).reshape(-1))
            # d recorded / d A[i][a, j] = J_D[:, :, a] G[:, j]; d recorded / d k: the basis
            JA = np.einsum("nai,nj->naij", d.jacobian(ideal), G).reshape(len(G), 2, 6)
            X = np.zeros((len(G), 2, n_unknown))
            X[:, :, 4 + 6 * i:10 + 6 * i] = JA
            X[:, :, :4] = d.basis(ideal)
            Xs.append(X.reshape(2 * len(G), n_unknown))
        return np.concatenate(rs), np.vstack(Xs)

    for _ in range(iterations):
        r, X = residual_and_design(A, k)
        step, *_ = np.linalg.lstsq(X, r, rcond=None)
        k += step[:4]
        for i in range(m):
            A[i] += step[4 + 6 * i:10 + 6 * i].reshape(2, 3)
        if np.max(np.abs(X @ step)) < 1e-9:
            break
    r, X = residual_and_design(A, k)
    dof = 2 * n - n_unknown
    s2 = float(r @ r) / max(dof, 1)
    cov = np.linalg.pinv(X.T @ X) * s2
    cov = 0.5 * (cov + cov.T)                  # exactly symmetric (pinv's rounding is not)
    return DistortionFit(distortion=base.with_coefficients(k, cov[:4, :4]),
                         affine=A if several else A[0],
                         rms_px=float(math.sqrt(np.mean(r * r))), n_points=n, dof=dof)


def calibrate_from_grids(images, pitch_px: float, dot_radius_px: float, centres_px=None,
                         margin_px: float = 30.0) -> DistortionFit:
    """A view's distortion from recorded images of a dot plate: the whole method in one call.

    ``images``: one or more grid images of the view (integer, or float in [0, 1]), the plate
    moved between them; its dots on a square grid of ``pitch_px`` (the plate's pitch over the
    view's scale, ``pitch_m / scale_m_per_px``), ``dot_radius_px`` in radius, nominally
    centred on each image (or on ``centres_px[i]``, (u, v) px). The dots are looked for where
    that nominal placement puts them (:func:`find_dots`, 12 px of search), and the
    distortion and each image's placement fitted (:func:`fit_distortion`, the plate in
    pixels of the nominal scale). Returns the :class:`DistortionFit`; its ``distortion``
    (covariance included) is the facility file's ``distortion`` table
    (``Distortion.to_dict``)."""
    images = list(images) if isinstance(images, list | tuple) else [images]
    if not images:
        raise ValueError("no grid image given")
    H, W = np.asarray(images[0]).shape
    centres = ([((W - 1) / 2.0, (H - 1) / 2.0)] * len(images) if centres_px is None
               else [tuple(map(float, c)) for c in centres_px])
    if len(centres) != len(images):
        raise ValueError(f"{len(centres)} centres for {len(images)} images")
    plates, found_all, starts = [], [], []
    for img, c in zip(images, centres, strict=True):
        if np.asarray(img).shape != (H, W):
            raise ValueError("the grid images differ in size")
        pts = grid_points(W, H, pitch_px, margin_px) + (np.array(c) - [(W - 1) / 2.0,
                                                                         (H - 1) / 2.0])
        found, ok = find_dots(img, pts, dot_radius_px)
        if ok.sum() < 8:
            raise ValueError(f"only {int(ok.sum())} dots found where a {pitch_px:g} px grid "
                             f"centred at ({c[0]:.0f}, {c[1]:.0f}) puts them")
        plates.append(pts[ok] - np.array(c))
        found_all.append(found[ok])
        starts.append(np.array([[1.0, 0.0, c[0]], [0.0, 1.0, c[1]]]))
    return fit_distortion(plates, found_all, W, H, starts)
