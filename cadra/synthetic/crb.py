"""Cramér–Rao bound of the model pose measured from one shadowgraph.

Stage one measures, per image, the body's reference-point position ``(u, v)`` (px) and its
in-plane axis angle ``phi`` (rad, ``atan2(dv, du)`` in pixel axes) by fitting the known
silhouette. :func:`pose_crb` gives the smallest standard deviations any unbiased estimator of
those three numbers can reach on images made by :func:`cadra.synthetic.render.render`: the
inverse Fisher information of the renderer's own image model.

Model
-----
The expectation is ``I(p) = render_clean(scene(p), config)`` with one body polygon rigidly
moved by the pose ``p = (du, dv, dphi)``: rotated by ``dphi`` about ``ref_px`` and translated by
``(du, dv)``. The scene has no wires, no reference mark and no flow clutter
(``body_hint=None``), and the configuration's film defects are switched off
(``scratches = dust = 0``): clutter is a *nuisance the bound does not include* (it only
removes information, so a real estimator facing clutter does worse than the bound).

The noise of :func:`~cadra.synthetic.render.render` is, to first order,
``I (1 + s_g g) + sqrt(read^2 + shot^2 I) n`` then quantized to steps ``q = 1/(2^b - 1)``, with
``g`` a unit-variance Gaussian field (white noise filtered by ``k (x) k``, ``k`` the Gaussian
kernel of sigma ``L = film_grain_length_px``, scaled by ``1 / sum(k^2)``) and ``n`` white. The
filtered field has variance ``(sum k^2)^2`` per pixel, so the scaling gives exactly unit
variance, and its correlation between pixels ``(du, dv)`` apart is
``a(du) a(dv)`` with ``a = (k * k) / sum(k^2)`` (``a(0) = 1``). The noise covariance is::

    C = diag(read^2 + shot^2 I + q^2 / 12) + s_g^2 diag(I) K diag(I),   K = a (x) a

(quantization as independent uniform noise, good while the noise exceeds ~q). ``C`` is never
formed: ``C x`` is two diagonal products and one separable convolution (zero padding, which is
the exact restriction of the stationary covariance to the region of interest), and
``C X = G`` is solved by Jacobi-preconditioned conjugate gradients (a few dozen iterations:
``C`` is well conditioned because the grain is a fraction of the total variance).

The Fisher information is ``F = G^T C^-1 G`` with ``G = dI/dp`` by central differences. Its
extra term ``(1/2) tr(C^-1 dC C^-1 dC)`` (information in the signal-dependent variance) is
left out: it is tiny here, and an estimator that does not model the variance cannot use it.
Optional nuisance parameters (a global relative gain, ``dI/dgain = I``, and the blur width
``optics_blur_sigma_px``) are estimated jointly, so the pose block of ``F^-1`` accounts for
not knowing them. The "white" bound treats the grain as independent per pixel
(``C_w = diag(C)``), for comparison.

Region of interest
------------------
The expectation is rendered on a small sub-image (the polygon's bounding box plus a margin)
for speed. The body's transmission does not depend on the illumination, so the ROI is
rendered with a flat unit beam and multiplied by the full frame's illumination field cropped
to the ROI when the frame size is given (``width_px``, ``height_px``): that reproduces the
full-frame ``render_clean`` exactly. Without the frame size the beam is taken as flat at
``background_level`` (the field's mean), which changes the bound by the local brightness only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import cv2
import numpy as np

from cadra.synthetic.blur import _gaussian_kernel_1d
from cadra.synthetic.render import RenderConfig, Scene, illumination_field, render_clean

__all__ = [
    "PoseCRB",
    "apply_pose",
    "grain_correlation_kernel",
    "model_image",
    "noise_covariance_operator",
    "pose_crb",
    "solve_cg",
]

_POSE_NAMES = ("u", "v", "phi")


# =============================================================================== result


@dataclass(frozen=True, eq=False)
class PoseCRB:
    """Cramér–Rao bound of the pose from one image (:func:`pose_crb`).

    Attributes
    ----------
    params
        Parameter names, in the order of the matrices: ``"u"``, ``"v"`` (px), ``"phi"`` (rad;
        absent when the angle is not fitted), then the nuisances ``"gain"`` (relative) and
        ``"blur_sigma"`` (px) when included.
    fisher, fisher_white
        Fisher information with the correlated grain, and with the grain treated as white
        (independent per pixel, same per-pixel variance).
    cov, cov_white
        Their inverses: the Cramér–Rao bound of all parameters.
    sigma_u_px, sigma_v_px, sigma_phi_rad
        Bound (standard deviation) of the pose, correlated noise, nuisances marginalized.
        ``sigma_phi_rad`` is ``nan`` when the angle is not fitted.
    sigma_white_u_px, sigma_white_v_px, sigma_white_phi_rad
        The same with the grain treated as white.
    roi
        ``(u0, v0, width, height)`` of the sub-image the bound was computed on (full-frame px).
    expected
        Noise-free expectation ``I`` on the ROI (fraction of full scale).
    jacobian
        ``dI/dp`` on the ROI, shape ``(height, width, n_params)``.
    cinv_jacobian
        ``C^-1 dI/dp`` (same shape): ``cinv_jacobian^T r`` is the efficient linear estimator's
        score for a residual image ``r``.
    pixel_variance
        Diagonal of ``C`` on the ROI.
    cg_iterations, cg_residual
        Conjugate-gradient iterations used and the final largest relative residual.
    runtime_s
        Wall time of the computation.
    """

    params: tuple[str, ...]
    fisher: np.ndarray
    fisher_white: np.ndarray
    cov: np.ndarray
    cov_white: np.ndarray
    sigma_u_px: float
    sigma_v_px: float
    sigma_phi_rad: float
    sigma_white_u_px: float
    sigma_white_v_px: float
    sigma_white_phi_rad: float
    roi: tuple[int, int, int, int]
    expected: np.ndarray
    jacobian: np.ndarray
    cinv_jacobian: np.ndarray
    pixel_variance: np.ndarray
    cg_iterations: int
    cg_residual: float
    runtime_s: float

    @property
    def n_pose(self) -> int:
        """Number of pose parameters (2 or 3) at the front of ``params``."""
        return sum(name in _POSE_NAMES for name in self.params)

    def pose_cov(self, correlated: bool = True, marginalize_nuisance: bool = True) -> np.ndarray:
        """Bound on the pose covariance.

        Parameters
        ----------
        correlated
            Use the correlated grain (``True``) or the white approximation.
        marginalize_nuisance
            ``True``: pose block of the full inverse (nuisances unknown). ``False``: inverse of
            the pose block of the Fisher matrix (nuisances known exactly).

        Returns
        -------
        ndarray, shape (n_pose, n_pose)
        """
        n = self.n_pose
        if marginalize_nuisance:
            cov = self.cov if correlated else self.cov_white
            return cov[:n, :n].copy()
        fisher = self.fisher if correlated else self.fisher_white
        return np.linalg.inv(fisher[:n, :n])

    def pose_sigmas(
        self, correlated: bool = True, marginalize_nuisance: bool = True
    ) -> dict[str, float]:
        """``{name: standard deviation}`` of the pose parameters (see :meth:`pose_cov`)."""
        cov = self.pose_cov(correlated, marginalize_nuisance)
        return {name: float(math.sqrt(cov[i, i])) for i, name in enumerate(self.params[: len(cov)])}


# =============================================================================== model


def apply_pose(polygon_px, ref_px, pose) -> np.ndarray:
    """Polygon rigidly moved by ``pose = (du, dv, dphi)``: rotated about ``ref_px``, translated.

    ``dphi`` turns the axis angle ``atan2(dv, du)`` in pixel axes (u right, v down), i.e.
    clockwise on the screen.
    """
    p = np.asarray(polygon_px, dtype=np.float64)
    ref = np.asarray(ref_px, dtype=np.float64).reshape(2)
    du, dv, dphi = (float(x) for x in pose)
    c, s = math.cos(dphi), math.sin(dphi)
    d = p - ref
    out = np.empty_like(p)
    out[:, 0] = ref[0] + c * d[:, 0] - s * d[:, 1] + du
    out[:, 1] = ref[1] + s * d[:, 0] + c * d[:, 1] + dv
    return out


def _clean_config(config: RenderConfig) -> RenderConfig:
    """``config`` with a flat unit beam and no film defects (the transmission only)."""
    return config.replace(background_level=1.0, illumination_variation=0.0,
                          illumination_mottle=0.0, scratches=0, dust=0)  # fmt: skip


def model_image(
    polygon_px,
    ref_px,
    config: RenderConfig,
    roi: tuple[int, int, int, int],
    *,
    pose=(0.0, 0.0, 0.0),
    motion_blur_px=(0.0, 0.0),
    illumination: np.ndarray | float | None = None,
    blur_sigma_px: float | None = None,
) -> np.ndarray:
    """Noise-free expectation of the posed body on a sub-image (the model :func:`pose_crb` uses).

    Parameters
    ----------
    polygon_px, ref_px
        Body outline ``(N, 2)`` and its reference point, full-frame ``(u, v)`` px.
    config
        Image model; its film defects and illumination pattern are ignored (see
        ``illumination``).
    roi
        ``(u0, v0, width, height)``, full-frame px.
    pose
        ``(du, dv, dphi)`` applied by :func:`apply_pose`.
    motion_blur_px
        Body displacement over the exposure (``Scene.motion_blur_px``).
    illumination
        Beam ``B`` on the ROI: an ``(height, width)`` array, a number, or ``None`` for
        ``config.background_level``.
    blur_sigma_px
        Override of ``config.optics_blur_sigma_px`` (for the blur derivative).

    Returns
    -------
    ndarray, float64, shape (height, width)
        ``B * max(T, 0)`` exactly as :func:`~cadra.synthetic.render.render_clean` composes it.
    """
    u0, v0, w, h = roi
    cfg = _clean_config(config)
    if blur_sigma_px is not None:
        cfg = cfg.replace(optics_blur_sigma_px=float(blur_sigma_px))
    poly = apply_pose(polygon_px, ref_px, pose) - np.array([u0, v0], dtype=np.float64)
    scene = Scene(width_px=int(w), height_px=int(h), bodies=(poly,),
                  motion_blur_px=tuple(motion_blur_px))  # fmt: skip
    t = render_clean(scene, cfg)
    if illumination is None:
        illumination = config.background_level
    return t * illumination


# =============================================================================== noise


def grain_correlation_kernel(length_px: float) -> np.ndarray:
    """1-D factor ``a`` of the film-grain correlation ``K(du, dv) = a(du) a(dv)``.

    ``a = (k * k) / sum(k^2)`` with ``k`` the Gaussian kernel of sigma ``length_px`` that
    :func:`cadra.synthetic.realism._film_grain` filters white noise with; ``a`` is symmetric,
    odd-length, and its middle tap is 1 (unit variance). ``length_px = 0`` gives ``[1]``.
    """
    if length_px <= 0.0:
        return np.ones(1)
    k = _gaussian_kernel_1d(float(length_px), 1.0)
    return np.convolve(k, k) / np.sum(k * k)


def noise_covariance_operator(expected: np.ndarray, config: RenderConfig):
    """The quantized image's noise covariance ``C`` as an operator, and its diagonal.

    Parameters
    ----------
    expected
        Noise-free image ``I`` (fraction of full scale), shape (H, W).
    config
        Noise knobs: ``read_noise_sigma``, ``shot_noise_sigma``, ``film_grain_sigma``,
        ``film_grain_length_px``, ``bit_depth``.

    Returns
    -------
    apply : callable
        ``apply(x)`` for ``x`` of shape (H, W) returns ``C x`` (same shape).
    diag : ndarray, (H, W)
        ``diag(C) = read^2 + shot^2 I + q^2/12 + s_g^2 I^2``.
    white : ndarray, (H, W)
        The independent part ``read^2 + shot^2 I + q^2/12``.
    """
    img = np.asarray(expected, dtype=np.float64)
    q = 1.0 / ((1 << config.bit_depth) - 1)
    white = (config.read_noise_sigma**2 + config.shot_noise_sigma**2 * np.maximum(img, 0.0)
             + q * q / 12.0)  # fmt: skip
    sg2 = config.film_grain_sigma**2
    diag = white + sg2 * img * img
    a = grain_correlation_kernel(config.film_grain_length_px)

    if sg2 == 0.0:

        def apply(x):
            return white * x

    elif a.size == 1:

        def apply(x):
            return diag * x

    else:

        def apply(x):
            y = cv2.sepFilter2D(img * x, cv2.CV_64F, a, a, borderType=cv2.BORDER_CONSTANT)
            return white * x + sg2 * img * y

    return apply, diag, white


def solve_cg(apply, b: np.ndarray, diag: np.ndarray, tol: float = 1e-9, max_iter: int = 500):
    """Solve ``C x_j = b_j`` for each column by Jacobi-preconditioned conjugate gradients.

    Parameters
    ----------
    apply
        ``C`` applied to one (H, W) image (symmetric positive definite).
    b
        Right-hand sides, shape (H, W, n).
    diag
        ``diag(C)``, (H, W): the preconditioner.
    tol, max_iter
        Stop when every column's residual norm is below ``tol`` times its right-hand side's.

    Returns
    -------
    x : ndarray, (H, W, n)
    iterations : int
    residual : float
        Largest relative residual at exit.
    """
    n = b.shape[-1]
    x = np.zeros_like(b)
    r = b.copy()
    minv = 1.0 / diag
    z = r * minv[..., None]
    p = z.copy()
    rz = np.einsum("ijk,ijk->k", r, z)
    bnorm = np.sqrt(np.einsum("ijk,ijk->k", b, b))
    bnorm[bnorm == 0.0] = 1.0
    rel = np.ones(n)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (reported)
        ap = np.stack([apply(p[..., j]) for j in range(n)], axis=-1)
        alpha = rz / np.einsum("ijk,ijk->k", p, ap)
        x += alpha * p
        r -= alpha * ap
        rel = np.sqrt(np.einsum("ijk,ijk->k", r, r)) / bnorm
        if np.all(rel < tol):
            break
        z = r * minv[..., None]
        rz_new = np.einsum("ijk,ijk->k", r, z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, it, float(rel.max())


# =============================================================================== bound


def nuisance_columns(model, expected: np.ndarray, config: RenderConfig,
                     step_blur_px: float) -> tuple[list[str], list[np.ndarray]]:
    """The image's nuisance parameters and their Jacobian columns: its gain (the expected
    image itself) and, for a blurred image, the blur's width (central difference of
    ``model(blur=...)`` with a step of at most half the blur)."""
    names, cols = ["gain"], [expected.copy()]
    sigma = config.optics_blur_sigma_px
    if sigma > 0.0:
        hb = min(step_blur_px, 0.5 * sigma)
        names.append("blur_sigma")
        cols.append((model(blur=sigma + hb) - model(blur=sigma - hb)) / (2.0 * hb))
    return names, cols


def correlated_fisher(jac: np.ndarray, expected: np.ndarray, config: RenderConfig,
                      cg_tol: float):
    """The Fisher information ``J^T C^-1 J`` of the image's correlated noise (``C`` from
    :func:`noise_covariance_operator`, solved by :func:`solve_cg`), symmetrized; with the
    noise's diagonal, ``C^-1 J`` and the solve's iterations and residual."""
    apply, diag, _ = noise_covariance_operator(expected, config)
    x, iters, resid = solve_cg(apply, jac, diag, tol=cg_tol)
    fisher = np.einsum("ijk,ijl->kl", jac, x)
    return 0.5 * (fisher + fisher.T), diag, x, iters, resid


def _roi_box(polygon, margin, width_px, height_px) -> tuple[int, int, int, int]:
    u0 = int(math.floor(polygon[:, 0].min() - margin))
    u1 = int(math.ceil(polygon[:, 0].max() + margin))
    v0 = int(math.floor(polygon[:, 1].min() - margin))
    v1 = int(math.ceil(polygon[:, 1].max() + margin))
    if width_px is not None:
        u0, u1 = max(u0, 0), min(u1, int(width_px) - 1)
    if height_px is not None:
        v0, v1 = max(v0, 0), min(v1, int(height_px) - 1)
    if u1 < u0 or v1 < v0:
        raise ValueError("the polygon is outside the frame")
    return u0, v0, u1 - u0 + 1, v1 - v0 + 1


def pose_crb(
    polygon_px,
    ref_px,
    config: RenderConfig | None = None,
    *,
    motion_blur_px=(0.0, 0.0),
    width_px: int | None = None,
    height_px: int | None = None,
    roi_margin_px: float = 12,
    step_px: float = 1e-3,
    step_rad: float = 1e-5,
    step_blur_px: float = 1e-3,
    include_nuisance: bool = True,
    fit_angle: bool = True,
    cg_tol: float = 1e-9,
) -> PoseCRB:
    """Cramér–Rao bound of the pose ``(u, v, phi)`` of one body from one rendered image.

    Parameters
    ----------
    polygon_px
        Exact body outline at the true pose, ``(N, 2)`` full-frame ``(u, v)`` px.
    ref_px
        The reference point ``(u, v)`` px: the rotation centre of ``phi``.
    config
        Image model (default ``RenderConfig()``). Film defects and flow clutter are not part
        of the bound (module docstring).
    motion_blur_px
        Body displacement over the exposure, px (as ``Scene.motion_blur_px``).
    width_px, height_px
        Full frame size. When given, the ROI is clipped to the frame and the frame's
        illumination field is used; otherwise a flat beam at ``background_level``.
    roi_margin_px
        Margin around the polygon's bounding box (add half the motion blur automatically).
    step_px, step_rad, step_blur_px
        Central-difference steps of ``u, v``, ``phi`` and the blur width.
    include_nuisance
        Estimate a global relative gain and the blur width jointly (the bound then accounts for
        not knowing them). The blur nuisance is skipped when ``optics_blur_sigma_px = 0``.
    fit_angle
        Include ``phi`` (``False`` for a sphere, whose angle is not observable).
    cg_tol
        Relative residual of the conjugate-gradient solve.

    Returns
    -------
    PoseCRB

    Notes
    -----
    Cost: ``3 + 2 * n`` renders of the ROI plus one CG solve; about 1 s for a 280 px body at
    the default 8x supersampling.
    """
    t0 = time.perf_counter()
    config = RenderConfig() if config is None else config
    poly = np.array(polygon_px, dtype=np.float64)
    if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 3:
        raise ValueError("polygon_px must be an (N, 2) array of (u, v) px")
    ref = np.asarray(ref_px, dtype=np.float64).reshape(2)
    motion = tuple(float(x) for x in motion_blur_px)
    margin = float(roi_margin_px)
    if config.motion_blur:
        margin += 0.5 * math.hypot(*motion)
    roi = _roi_box(poly, margin, width_px, height_px)
    u0, v0, w, h = roi
    if width_px is not None and height_px is not None:
        field = illumination_field(int(width_px), int(height_px), config)
        illum = field[v0 : v0 + h, u0 : u0 + w]
    else:
        illum = float(config.background_level)

    def model(pose=(0.0, 0.0, 0.0), blur=None):
        return model_image(poly, ref, config, roi, pose=pose, motion_blur_px=motion,
                           illumination=illum, blur_sigma_px=blur)  # fmt: skip

    expected = model()
    names = ["u", "v"] + (["phi"] if fit_angle else [])
    cols = []
    for i, step in enumerate([step_px, step_px] + ([step_rad] if fit_angle else [])):
        dp = np.zeros(3)
        dp[i] = step
        cols.append((model(dp) - model(-dp)) / (2.0 * step))
    if include_nuisance:
        extra_names, extra_cols = nuisance_columns(model, expected, config, step_blur_px)
        names += extra_names
        cols += extra_cols
    jac = np.stack(cols, axis=-1)

    fisher, diag, x, iters, resid = correlated_fisher(jac, expected, config, cg_tol)
    fisher_w = np.einsum("ijk,ijl->kl", jac, jac / diag[..., None])
    cov = np.linalg.inv(fisher)
    cov_w = np.linalg.inv(fisher_w)

    def sig(variances, name):
        return float(math.sqrt(variances[names.index(name)])) if name in names else math.nan

    d = np.diag(cov)
    dw = np.diag(cov_w)
    return PoseCRB(
        params=tuple(names),
        fisher=fisher,
        fisher_white=fisher_w,
        cov=cov,
        cov_white=cov_w,
        sigma_u_px=sig(d, "u"),
        sigma_v_px=sig(d, "v"),
        sigma_phi_rad=sig(d, "phi"),
        sigma_white_u_px=sig(dw, "u"),
        sigma_white_v_px=sig(dw, "v"),
        sigma_white_phi_rad=sig(dw, "phi"),
        roi=roi,
        expected=expected,
        jacobian=jac,
        cinv_jacobian=x,
        pixel_variance=diag,
        cg_iterations=iters,
        cg_residual=resid,
        runtime_s=time.perf_counter() - t0,
    )
