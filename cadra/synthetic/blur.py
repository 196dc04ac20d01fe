"""The renderer's optics: PSF kernels, motion blur and the opacity of each layer.

Bodies are covered exactly on a fine grid around each (:mod:`cadra.synthetic.raster`), swept
over the exposure, blurred by the PSF and binned to pixels; wires and the scanner mark are
blurred on the pixel grid; the diffraction fringe is a Laplacian of the blurred opacity; the
layers are composed into the clean image by :func:`_compose` (docs/renderer.md, "Image model").
"""

from __future__ import annotations

import math

import cv2
import numba
import numpy as np
from scipy.special import j1

from cadra.synthetic.raster import (
    _accumulate_polygon,
    _filter_bin_cols,
    _integrate_rows,
    _integrate_rows_filter_bin,
    coverage,
)
from cadra.synthetic.render_config import PsfShape, RenderConfig
from cadra.synthetic.scene import Scene, reference_mark_polygon, wire_polygon

#: Largest fine grid (fine pixels) of one body patch; bigger patches lower the supersampling.
_MAX_FINE_PIXELS = 16_000_000


# =============================================================================== PSF kernels


def _box_around(points: np.ndarray, pad: float, W: int, H: int):
    """Inclusive pixel box ``(u0, v0, u1, v1)`` around points, clipped; None if off-image."""
    u0 = max(int(math.floor(points[:, 0].min() - pad)), 0)
    u1 = min(int(math.ceil(points[:, 0].max() + pad)), W - 1)
    v0 = max(int(math.floor(points[:, 1].min() - pad)), 0)
    v1 = min(int(math.ceil(points[:, 1].max() + pad)), H - 1)
    if u1 < u0 or v1 < v0:
        return None
    return u0, v0, u1, v1


def _psf_radius_px(config: RenderConfig) -> float:
    """Support radius of the PSF kernel, px."""
    sigma = config.optics_blur_sigma_px
    if sigma == 0.0:
        return 0.0
    return {PsfShape.GAUSSIAN: 4.0, PsfShape.AIRY_LIKE: 8.0, PsfShape.DISK: 2.0}[
        config.psf_shape
    ] * sigma


def _gaussian_kernel_1d(sigma: float, step: float) -> np.ndarray:
    """Normalized Gaussian sampled at multiples of ``step`` (px), odd length, symmetric."""
    if sigma == 0.0:
        return np.ones(1)
    half = int(math.ceil(4.0 * sigma / step))
    x = np.arange(-half, half + 1) * step
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def _psf_kernel_2d(config: RenderConfig, step: float) -> np.ndarray:
    """Normalized 2-D PSF sampled at multiples of ``step`` px (odd size, point-symmetric)."""
    sigma = config.optics_blur_sigma_px
    shape = config.psf_shape
    if sigma == 0.0:
        return np.ones((1, 1))
    if shape is PsfShape.GAUSSIAN:
        k = _gaussian_kernel_1d(sigma, step)
        return np.outer(k, k)
    half = int(math.ceil(_psf_radius_px(config) / step)) + 1
    x = np.arange(-half, half + 1) * step
    if shape is PsfShape.AIRY_LIKE:
        # (2 J1(z) / z)^2 with the FWHM of the Gaussian (half maximum at z = 1.61634)
        r = np.hypot(x[:, None], x[None, :])
        z = 1.616340 * r / (1.177410 * sigma)
        k = np.ones_like(z)
        nz = z > 0
        k[nz] = (2.0 * j1(z[nz]) / z[nz]) ** 2
        k[r > _psf_radius_px(config)] = 0.0
    else:  # DISK of radius 2 sigma (the Gaussian's per-axis variance), exact-area antialiased
        t = np.linspace(0.0, 2.0 * np.pi, 1024, endpoint=False)
        rad = 2.0 * sigma / step
        circle = np.column_stack([half + rad * np.cos(t), half + rad * np.sin(t)])
        k = coverage(circle, 2 * half + 1, 2 * half + 1)
        k = 0.5 * (k + k[::-1, ::-1])  # exact point symmetry despite the vertex phase
    return k / k.sum()


def _binned_kernel(k: np.ndarray, s: int) -> np.ndarray:
    """Fine kernel ``k`` (2J + 1 taps, symmetric) convolved with an s-cell box / s: 2J + s taps.

    Symmetric about its middle, which sits at the centre of the s fine cells of one pixel.
    """
    return np.convolve(k, np.full(s, 1.0 / s))


# =============================================================================== opacity


def _body_patches(scene: Scene, margin: float) -> list[tuple[int, int, int, int, list[int]]]:
    """Pixel boxes ``(u0, v0, u1, v1, body indices)`` (inclusive) around the bodies, merged
    where they overlap, clipped to the image."""
    boxes = []
    for i, p in enumerate(scene.bodies):
        u0 = max(int(math.floor(p[:, 0].min() - margin)), 0)
        u1 = min(int(math.ceil(p[:, 0].max() + margin)), scene.width_px - 1)
        v0 = max(int(math.floor(p[:, 1].min() - margin)), 0)
        v1 = min(int(math.ceil(p[:, 1].max() + margin)), scene.height_px - 1)
        if u1 >= u0 and v1 >= v0:
            boxes.append([u0, v0, u1, v1, [i]])
    merged = True
    while merged:
        merged = False
        for a in range(len(boxes)):
            for b in range(a + 1, len(boxes)):
                A, B = boxes[a], boxes[b]
                if A[0] <= B[2] and B[0] <= A[2] and A[1] <= B[3] and B[1] <= A[3]:
                    boxes[a] = [min(A[0], B[0]), min(A[1], B[1]), max(A[2], B[2]),
                                max(A[3], B[3]), A[4] + B[4]]  # fmt: skip
                    del boxes[b]
                    merged = True
                    break
            if merged:
                break
    return [tuple(b) for b in boxes]


def _motion_offsets(scene: Scene, config: RenderConfig, s: int) -> np.ndarray:
    """Centred time samples ``(n, 2)`` of the body displacement over the exposure."""
    m = np.array(scene.motion_blur_px) if config.motion_blur else np.zeros(2)
    length = float(np.hypot(*m))
    if length == 0.0:
        return np.zeros((1, 2))
    n = min(max(2, int(math.ceil(2.0 * s * length))), 4096)
    t = (np.arange(n) + 0.5) / n - 0.5  # symmetric about 0: mid-exposure is the truth
    return t[:, None] * m[None, :]


def _body_opacity(scene: Scene, config: RenderConfig) -> tuple[np.ndarray, list]:
    """Blurred body opacity (H, W): coverage (*) PSF (*) motion on a fine grid, binned.

    Also returns the pixel boxes of the fine patches (from :func:`_body_patches`).
    """
    H, W = scene.height_px, scene.width_px
    out = np.zeros((H, W))
    if not scene.bodies:
        return out, []
    motion = np.hypot(*scene.motion_blur_px) if config.motion_blur else 0.0
    margin = _psf_radius_px(config) + 0.5 * motion + 2.0
    boxes = _body_patches(scene, margin)
    for u0, v0, u1, v1, idx in boxes:
        pw, ph = u1 - u0 + 1, v1 - v0 + 1
        s = config.supersample
        s = max(1, min(s, int(math.sqrt(_MAX_FINE_PIXELS / (pw * ph)))))
        offsets = _motion_offsets(scene, config, s)
        acc = np.zeros((ph * s, pw * s + 2))
        weight = 1.0 / len(offsets)
        for i in idx:
            p = scene.bodies[i]
            for du, dv in offsets:
                xs = (p[:, 0] + du - u0 + 0.5) * s
                ys = (p[:, 1] + dv - v0 + 0.5) * s
                _accumulate_polygon(acc, xs, ys, weight)
        if config.psf_shape is PsfShape.GAUSSIAN or config.optics_blur_sigma_px == 0.0:
            h = _binned_kernel(_gaussian_kernel_1d(config.optics_blur_sigma_px, 1 / s), s)
            rows = np.empty((ph * s, pw))
            _integrate_rows_filter_bin(acc, pw * s, h, s, rows)
            patch = np.empty((ph, pw))
            _filter_bin_cols(rows, h, s, patch)
        else:
            fine = _integrate_rows(acc, pw * s, 0.0, 1.0)
            fine = cv2.filter2D(
                fine, -1, _psf_kernel_2d(config, 1 / s), borderType=cv2.BORDER_REPLICATE
            )
            patch = fine.reshape(ph, s, pw, s).mean(axis=(1, 3))
        view = out[v0 : v1 + 1, u0 : u1 + 1]
        view[...] = 1.0 - (1.0 - view) * (1.0 - np.clip(patch, 0.0, 1.0))
    return out, boxes


def _blurred_coverage(polys, width: int, height: int, config: RenderConfig) -> np.ndarray:
    """Exact pixel coverage of ``polys`` blurred by the PSF on the pixel grid (no motion)."""
    cov = coverage(polys, width, height)
    sigma = config.optics_blur_sigma_px
    if sigma == 0.0:
        return cov
    if config.psf_shape is PsfShape.GAUSSIAN:
        k = _gaussian_kernel_1d(sigma, 1.0)
        return cv2.sepFilter2D(cov, -1, k, k, borderType=cv2.BORDER_REPLICATE)
    # other shapes: the PSF averaged over each pixel, from a sampling at 1/9 px (odd, so each
    # pixel holds exactly 9 x 9 samples centred on it)
    s = 9
    kf = _psf_kernel_2d(config, 1.0 / s)
    half_c = (kf.shape[0] // 2 + s // 2) // s + 1
    kf = np.pad(kf, ((2 * half_c + 1) * s - kf.shape[0]) // 2)
    kc = kf.reshape(2 * half_c + 1, s, 2 * half_c + 1, s).sum(axis=(1, 3))
    kc = 0.5 * (kc + kc[::-1, ::-1])
    return cv2.filter2D(cov, -1, kc / kc.sum(), borderType=cv2.BORDER_REPLICATE)


def _wire_opacity(scene: Scene, config: RenderConfig) -> np.ndarray | None:
    """Blurred opacity (H, W) of the fiducial wires (pixel grid, no motion); None if none."""
    if not scene.wires and not scene.wire_outlines:
        return None
    polys = [wire_polygon(p0, p1, w) for p0, p1, w in scene.wires] + list(scene.wire_outlines)
    return _blurred_coverage(polys, scene.width_px, scene.height_px, config)


def _add_mark(o_fixed: np.ndarray | None, scene: Scene, config: RenderConfig) -> np.ndarray | None:
    """Union of ``o_fixed`` with the blurred reference mark (computed in a box around it)."""
    if scene.reference_mark is None and scene.mark_outline is None:
        return o_fixed
    H, W = scene.height_px, scene.width_px
    poly = (scene.mark_outline if scene.reference_mark is None
            else reference_mark_polygon(*scene.reference_mark))
    box = _box_around(poly, _psf_radius_px(config) + 3.0, W, H)
    if box is None:
        return o_fixed
    u0, v0, u1, v1 = box
    mark = _blurred_coverage(poly - (u0, v0), u1 - u0 + 1, v1 - v0 + 1, config)
    out = np.zeros((H, W)) if o_fixed is None else o_fixed
    view = out[v0 : v1 + 1, u0 : u1 + 1]
    view[...] = 1.0 - (1.0 - view) * (1.0 - mark)
    return out


def _fringe(opacity: np.ndarray, config: RenderConfig) -> np.ndarray:
    """Diffraction fringe F (fraction of the local background) from the total opacity.

    ``F = A sigma_t^2 / phi(1) * Laplacian(G_w (*) O)`` with the 5-point Laplacian: a bright
    band just outside every edge and a dark band just inside, of peak ``A`` for a straight
    edge (sigma_t^2 = PSF variance + w^2 + 1/12). A Laplacian has zero sum and zero first
    moments, so F changes neither the area nor the centroid of a shadow measured by image
    moments (away from the image border). float32: it is a nuisance, not truth.
    """
    w = config.fringe_width_px
    k = _gaussian_kernel_1d(w, 1.0).astype(np.float32)
    smooth = cv2.sepFilter2D(opacity, -1, k, k, borderType=cv2.BORDER_REPLICATE)
    lap = cv2.Laplacian(smooth, -1, ksize=1, borderType=cv2.BORDER_REPLICATE)
    sigma_t2 = config.optics_blur_sigma_px**2 + w**2 + 1.0 / 12.0
    phi1 = math.exp(-0.5) / math.sqrt(2.0 * math.pi)
    lap *= np.float32(config.diffraction_fringe * sigma_t2 / phi1)
    return lap


@numba.njit(cache=True)
def _union_f32(a, b):
    """``1 - (1 - a)(1 - b)`` as float32 (opacity of two independent layers)."""
    out = np.empty(a.shape, dtype=np.float32)
    for v in range(a.shape[0]):
        for u in range(a.shape[1]):
            out[v, u] = 1.0 - (1.0 - a[v, u]) * (1.0 - b[v, u])
    return out


@numba.njit(cache=True)
def _compose(o_body, o_fixed, fringe, modulation, illum, shadow, out):
    """``out = B max(0, [shadow + (1 - shadow)(1 - o_b)(1 - o_f) + F](1 + c))``, fused.

    Empty (0-size) ``o_fixed``, ``fringe`` or ``modulation`` stand for "absent".
    """
    has_fixed = o_fixed.size > 0
    has_fringe = fringe.size > 0
    has_mod = modulation.size > 0
    for v in range(out.shape[0]):
        for u in range(out.shape[1]):
            clear = 1.0 - o_body[v, u]
            if has_fixed:
                clear *= 1.0 - o_fixed[v, u]
            t = shadow + (1.0 - shadow) * clear
            if has_fringe:
                t += fringe[v, u]
            if has_mod:
                t *= 1.0 + modulation[v, u]
            out[v, u] = max(t, 0.0) * illum[v, u]
