"""Synthetic shadowgraph renderer: pixel-space image synthesis with exact silhouette truth.

Other modules say, in pixel coordinates, what to draw (:class:`Scene`: body silhouettes as
polygons, fiducial wires, the scanner reference mark, motion blur, a hint for flow clutter);
this module turns it into a realistic scanned shadowgraph (seed 004 Fig. 8, DESIGN §5).
Pixel convention (``docs/conventions.md``): ``(u, v) = (column, row)``, origin at the centre of
the top-left pixel, arrays indexed ``image[v, u]``; pixel ``(u, v)`` covers
``[u - 1/2, u + 1/2] x [v - 1/2, v + 1/2]``.

Image model (details and every knob in ``docs/renderer.md``)::

    O_body  = box (*) PSF (*) motion (*) 1[bodies]      on an s-times finer grid, then binned
    O_fixed = PSF_px (*) coverage(wires, mark)          on the pixel grid, no motion
    O = 1 - (1 - O_body)(1 - O_fixed)                   opacity, in [0, 1]
    F = A k Laplacian(G_w (*) O_body+wires)             diffraction fringe (not of the mark)
    T = [1 - (1 - shadow_level) O + F] (1 + c)          transmission; c = clutter (off bodies)
    I_clean = B(u, v) max(T, 0)                         B = illumination field
    I = quantize(I_clean (1 + g_s g) + sqrt(read^2 + shot^2 I_clean) n)   g grain, n white

The truth is exact: :func:`coverage` integrates the polygon edges analytically over each pixel
(signed trapezoid areas accumulated along scanlines, as in font rasterizers), so the sum of the
coverage map is the polygon's area to rounding, and its first moments differ from the polygon's
only by the pixel-centre weighting of edge pixels (about 1e-5 px for a 140 px sphere).
Every blur kernel is normalized and point-symmetric, so it moves no centroid.

Public API: :class:`Scene`, :func:`render`, :func:`render_clean`, :func:`coverage`,
:func:`polygon_area_centroid`, :func:`illumination_field`, :func:`wire_polygon`,
:func:`reference_mark_polygon`, :func:`write_image`, :func:`read_image`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numba
import numpy as np
from scipy.special import j1

from cadra.io.atomic import atomic_write_bytes
from cadra.synthetic.render_config import (
    PsfShape,
    RenderConfig,
    load_render_config,
    save_render_config,
)

__all__ = [
    "PsfShape",
    "RenderConfig",
    "Scene",
    "coverage",
    "illumination_field",
    "load_render_config",
    "polygon_area_centroid",
    "quantize",
    "read_image",
    "reference_mark_polygon",
    "render",
    "render_clean",
    "save_render_config",
    "wire_polygon",
    "write_image",
]

#: Largest fine grid (fine pixels) of one body patch; bigger patches lower the supersampling.
_MAX_FINE_PIXELS = 16_000_000

#: SeedSequence spawn keys of the fixed-pattern streams (the noise uses ``default_rng(seed)``).
_KEY_ILLUMINATION = 1
_KEY_CLUTTER = 2


# =============================================================================== scene


def _as_polygon(poly, what: str) -> np.ndarray:
    arr = np.array(poly, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
        raise ValueError(f"{what} must be an (N, 2) array of (u, v) px with N >= 3")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} has non-finite vertices")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Scene:
    """What to draw, in pixel coordinates (``docs/conventions.md``).

    Attributes
    ----------
    width_px, height_px
        Image size (columns, rows).
    bodies
        Closed polygons, each ``(N, 2)`` of ``(u, v)`` px (either orientation, not
        self-intersecting): the exact outline of each dark object at mid-exposure.
    wires
        Opaque straight fiducial wires ``((u0, v0), (u1, v1), width_px)``: a rectangle of that
        width centred on the segment, square ends (put the ends outside the image for a wire
        that crosses the field).
    reference_mark
        ``(u, v, arm_px, width_px)``: an upright cross centred at ``(u, v)``; each arm reaches
        ``arm_px`` from the centre and is ``width_px`` wide. ``None``: no mark.
    motion_blur_px
        Image displacement ``(du, dv)`` of the bodies over the exposure (velocity x shutter
        time). Bodies are swept from ``-m/2`` to ``+m/2`` about the polygons, so the polygons
        are the truth at mid-exposure. Wires and mark do not move.
    body_hint
        ``(u_centre, v_centre, axis_du, axis_dv, radius_px)``: where to draw bow-shock and wake
        clutter; the axis (normalized here) points in the flight direction. ``None``: no flow
        clutter.
    """

    width_px: int
    height_px: int
    bodies: tuple[np.ndarray, ...] = ()
    wires: tuple[tuple[np.ndarray, np.ndarray, float], ...] = ()
    reference_mark: tuple[float, float, float, float] | None = None
    motion_blur_px: tuple[float, float] = (0.0, 0.0)
    body_hint: tuple[float, float, float, float, float] | None = None

    def __post_init__(self) -> None:
        for name in ("width_px", "height_px"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"Scene.{name} must be a positive int, got {value!r}")
            object.__setattr__(self, name, int(value))
        if isinstance(self.bodies, np.ndarray) and self.bodies.ndim == 2:
            raise ValueError("Scene.bodies is a tuple of polygons; wrap a single one: (poly,)")
        bodies = tuple(_as_polygon(b, f"Scene.bodies[{i}]") for i, b in enumerate(self.bodies))
        object.__setattr__(self, "bodies", bodies)
        wires = []
        for i, wire in enumerate(self.wires):
            try:
                p0, p1, width = wire
            except (TypeError, ValueError):
                raise ValueError(f"Scene.wires[{i}] must be ((u0, v0), (u1, v1), width)") from None
            p0 = np.array(p0, dtype=np.float64).reshape(2)
            p1 = np.array(p1, dtype=np.float64).reshape(2)
            width = float(width)
            ok = np.all(np.isfinite(p0)) and np.all(np.isfinite(p1)) and math.isfinite(width)
            if not ok or width <= 0.0 or np.hypot(*(p1 - p0)) == 0.0:
                raise ValueError(f"Scene.wires[{i}] needs distinct finite ends and width > 0")
            p0.setflags(write=False)
            p1.setflags(write=False)
            wires.append((p0, p1, width))
        object.__setattr__(self, "wires", tuple(wires))
        if self.reference_mark is not None:
            mark = tuple(float(x) for x in self.reference_mark)
            if len(mark) != 4 or not all(map(math.isfinite, mark)):
                raise ValueError("Scene.reference_mark must be (u, v, arm_px, width_px)")
            if not 0.0 < mark[3] / 2 < mark[2]:
                raise ValueError("Scene.reference_mark needs 0 < width_px / 2 < arm_px")
            object.__setattr__(self, "reference_mark", mark)
        blur = tuple(float(x) for x in self.motion_blur_px)
        if len(blur) != 2 or not all(map(math.isfinite, blur)):
            raise ValueError("Scene.motion_blur_px must be (du, dv) px")
        object.__setattr__(self, "motion_blur_px", blur)
        if self.body_hint is not None:
            hint = tuple(float(x) for x in self.body_hint)
            if len(hint) != 5 or not all(map(math.isfinite, hint)) or hint[4] <= 0.0:
                raise ValueError("Scene.body_hint must be (u, v, axis_du, axis_dv, radius_px > 0)")
            norm = math.hypot(hint[2], hint[3])
            if norm == 0.0:
                raise ValueError("Scene.body_hint axis has zero length")
            hint = (hint[0], hint[1], hint[2] / norm, hint[3] / norm, hint[4])
            object.__setattr__(self, "body_hint", hint)


def wire_polygon(p0, p1, width_px: float) -> np.ndarray:
    """Rectangle ``(4, 2)`` of a wire of ``width_px`` centred on segment ``p0 -> p1`` (u, v px)."""
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    d = (p1 - p0) / np.hypot(*(p1 - p0))
    n = np.array([-d[1], d[0]]) * (0.5 * width_px)
    return np.array([p0 + n, p1 + n, p1 - n, p0 - n])


def reference_mark_polygon(u: float, v: float, arm_px: float, width_px: float) -> np.ndarray:
    """Upright cross ("plus") ``(12, 2)`` centred at ``(u, v)``: one polygon, so it is exact."""
    a, h = arm_px, 0.5 * width_px
    off = np.array(
        [(a, -h), (a, h), (h, h), (h, a), (-h, a), (-h, h),
         (-a, h), (-a, -h), (-h, -h), (-h, -a), (h, -a), (h, -h)]
    )  # fmt: skip
    return off + np.array([u, v])


def polygon_area_centroid(poly) -> tuple[float, tuple[float, float]]:
    """Exact area (px², positive) and centroid ``(u_c, v_c)`` of a simple polygon (shoelace).

    Vertices are taken relative to their mean first, so the result keeps full precision far
    from the origin.
    """
    p = _as_polygon(poly, "polygon")
    ref = p.mean(axis=0)
    x = p[:, 0] - ref[0]
    y = p[:, 1] - ref[1]
    xn = np.roll(x, -1)
    yn = np.roll(y, -1)
    cross = x * yn - xn * y
    a2 = cross.sum()
    if a2 == 0.0:
        raise ValueError("polygon has zero area")
    cx = ((x + xn) * cross).sum() / (3.0 * a2)
    cy = ((y + yn) * cross).sum() / (3.0 * a2)
    return abs(0.5 * a2), (float(cx + ref[0]), float(cy + ref[1]))


# =============================================================================== exact coverage
#
# Buffer coordinates: buffer cell (i, j) = row i, column j covers [j, j+1] x [i, i+1]. For the
# image grid x = u + 1/2, y = v + 1/2; for a fine patch x = (u - u0 + 1/2) s, y likewise.
# Each polygon edge deposits, row by row, the signed area of the part of each cell to its right
# into an accumulation buffer of shape (rows, cols + 2); the running sum along a row is then
# the exact covered area of each cell (Levien's font-rs accumulation rasterizer).


@numba.njit(cache=True, inline="always")
def _snap(x, lo, hi):
    """Clip to [lo, hi]; rounding residue of the running sum (|x| or |hi - x| < 1e-12) is
    snapped to 0 or hi, so empty and full pixels are exactly 0 and 1."""
    if abs(x) < 1e-12:
        return 0.0
    if abs(hi - x) < 1e-12:
        return hi
    return min(max(x, lo), hi)


@numba.njit(cache=True)
def _clip_half(xs, ys, axis, bound, keep_ge):
    """Sutherland–Hodgman step: keep the part of a polygon on one side of x or y = bound."""
    n = xs.shape[0]
    ox = np.empty(2 * n + 2)
    oy = np.empty(2 * n + 2)
    k = 0
    if n == 0:
        return ox[:0], oy[:0]
    px = xs[n - 1]
    py = ys[n - 1]
    pc = px if axis == 0 else py
    pin = pc >= bound if keep_ge else pc <= bound
    for i in range(n):
        cx = xs[i]
        cy = ys[i]
        cc = cx if axis == 0 else cy
        cin = cc >= bound if keep_ge else cc <= bound
        if cin != pin:
            t = (bound - pc) / (cc - pc)
            if axis == 0:
                ox[k] = bound
                oy[k] = py + t * (cy - py)
            else:
                ox[k] = px + t * (cx - px)
                oy[k] = bound
            k += 1
        if cin:
            ox[k] = cx
            oy[k] = cy
            k += 1
        px = cx
        py = cy
        pc = cc
        pin = cin
    return ox[:k], oy[:k]


@numba.njit(cache=True)
def _accumulate_line(acc, ax, ay, bx, by, weight):
    """Deposit one edge (inside the buffer rectangle) into the accumulation buffer."""
    if ay == by:
        return
    if ay < by:
        d = weight
        x0, y0, x1, y1 = ax, ay, bx, by
    else:
        d = -weight
        x0, y0, x1, y1 = bx, by, ax, ay
    dxdy = (x1 - x0) / (y1 - y0)
    nrows = acc.shape[0]
    r0 = max(int(math.floor(y0)), 0)
    r1 = min(int(math.ceil(y1)), nrows)
    for row in range(r0, r1):
        top = max(float(row), y0)
        bot = min(float(row + 1), y1)
        dy = bot - top
        if dy <= 0.0:
            continue
        xa = x0 + (top - y0) * dxdy if top > y0 else x0
        xb = x0 + (bot - y0) * dxdy if bot < y1 else x1
        dd = d * dy
        if xa < xb:
            xl, xr = xa, xb
        else:
            xl, xr = xb, xa
        xlf = math.floor(xl)
        il = int(xlf)
        xrc = math.ceil(xr)
        ir = int(xrc)
        if ir <= il + 1:
            xm = 0.5 * (xa + xb) - xlf
            acc[row, il] += dd * (1.0 - xm)
            acc[row, il + 1] += dd * xm
        else:
            s = 1.0 / (xr - xl)
            x0f = xl - xlf
            a0 = 0.5 * s * (1.0 - x0f) * (1.0 - x0f)
            x1f = xr - xrc + 1.0
            am = 0.5 * s * x1f * x1f
            acc[row, il] += dd * a0
            if ir == il + 2:
                acc[row, il + 1] += dd * (1.0 - a0 - am)
            else:
                a1 = s * (1.5 - x0f)
                acc[row, il + 1] += dd * (a1 - a0)
                for xi in range(il + 2, ir - 1):
                    acc[row, xi] += dd * s
                a2 = a1 + (ir - il - 3) * s
                acc[row, ir - 1] += dd * (1.0 - a2 - am)
            acc[row, ir] += dd * am


@numba.njit(cache=True)
def _accumulate_polygon(acc, xs, ys, weight):
    """Deposit a closed polygon (buffer coordinates) with ``weight``; clipped to the buffer.

    The sign is normalized so that the running sum is ``+weight x covered area`` whatever the
    orientation of the polygon.
    """
    nrows = acc.shape[0]
    ncols = acc.shape[1] - 2
    n = xs.shape[0]
    area2 = 0.0
    outside = False
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        area2 += xs[i] * ys[j] - xs[j] * ys[i]
        if xs[i] < 0.0 or xs[i] > ncols or ys[i] < 0.0 or ys[i] > nrows:
            outside = True
    # in (x right, y down) buffer axes a negative shoelace sum gives positive accumulation
    w = -weight if area2 > 0.0 else weight
    if outside:
        xs, ys = _clip_half(xs, ys, 0, 0.0, True)
        xs, ys = _clip_half(xs, ys, 0, float(ncols), False)
        xs, ys = _clip_half(xs, ys, 1, 0.0, True)
        xs, ys = _clip_half(xs, ys, 1, float(nrows), False)
        n = xs.shape[0]
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        _accumulate_line(acc, xs[i], ys[i], xs[j], ys[j], w)


@numba.njit(cache=True)
def _integrate_rows(acc, ncols, lo, hi):
    """Running sum along rows of the accumulation buffer, clipped to [lo, hi]."""
    out = np.empty((acc.shape[0], ncols))
    for r in range(acc.shape[0]):
        run = 0.0
        for c in range(ncols):
            run += acc[r, c]
            out[r, c] = _snap(run, lo, hi)
    return out


@numba.njit(cache=True)
def _integrate_rows_filter_bin(acc, ncols, h, s, out):
    """Row running sum (clipped to [0, 1]) of a fine buffer, then filter + bin along the row.

    ``h`` (odd length 2J + s) is the fine 1-D PSF (2J + 1 taps) convolved with the s-cell box
    and divided by s; ``out[r, i] = sum_q h[q] * row[s i - J + q]`` is then "blur at fine
    resolution, average each s fine cells into one pixel", without storing the fine blurred
    row. Cells beyond the row replicate its end cells.
    """
    nout = out.shape[1]
    nh = h.shape[0]
    half = (nh - s) // 2
    buf = np.empty(ncols + 2 * half)
    for r in range(acc.shape[0]):
        run = 0.0
        for c in range(ncols):
            run += acc[r, c]
            buf[c + half] = _snap(run, 0.0, 1.0)
        for c in range(half):
            buf[c] = buf[half]
            buf[ncols + half + c] = buf[ncols + half - 1]
        for i in range(nout):
            base = s * i
            tot = 0.0
            for q in range(nh):
                tot += h[q] * buf[base + q]
            out[r, i] = tot


@numba.njit(cache=True)
def _filter_bin_cols(a, h, s, out):
    """Same filter + bin as :func:`_integrate_rows_filter_bin`, along axis 0 of ``a``."""
    nrows = a.shape[0]
    ncols = a.shape[1]
    nh = h.shape[0]
    half = (nh - s) // 2
    for i in range(out.shape[0]):
        for c in range(ncols):
            out[i, c] = 0.0
        for q in range(nh):
            m = min(max(s * i - half + q, 0), nrows - 1)
            w = h[q]
            for c in range(ncols):
                out[i, c] += w * a[m, c]


def _polygon_list(polygons) -> list[np.ndarray]:
    if isinstance(polygons, np.ndarray) and polygons.ndim == 2:
        polygons = [polygons]
    return [_as_polygon(p, "polygon") for p in polygons]


def coverage(polygons, width_px: int, height_px: int, supersample: int = 0) -> np.ndarray:
    """Fraction of each pixel covered by the polygon(s): the silhouette truth.

    Parameters
    ----------
    polygons
        One ``(N, 2)`` array of ``(u, v)`` px, or a sequence of them (e.g. ``scene.bodies``).
    width_px, height_px
        Image size.
    supersample
        ``0`` (default): exact area, by integrating the edges over each pixel (error ~1e-15).
        ``s >= 1``: independent, approximate reference: the fraction of the ``s x s`` sub-pixel
        centres inside (point sampling; use only to cross-check, its error is O(1/s) on edge
        pixels).

    Returns
    -------
    ndarray, float64, shape (height_px, width_px)
        Covered fraction in [0, 1]. Overlapping polygons add (clipped at 1), which is exact when
        they do not overlap within a pixel.
    """
    polys = _polygon_list(polygons)
    if supersample:
        return _coverage_sampled(polys, width_px, height_px, int(supersample))
    acc = np.zeros((height_px, width_px + 2))
    for p in polys:
        _accumulate_polygon(acc, p[:, 0] + 0.5, p[:, 1] + 0.5, 1.0)
    return _integrate_rows(acc, width_px, 0.0, 1.0)


def _coverage_sampled(polys, width_px, height_px, s) -> np.ndarray:
    """Point-sampled coverage (even-odd rule per polygon): the slow cross-check reference."""
    from skimage.measure import points_in_poly

    out = np.zeros((height_px, width_px))
    sub = (np.arange(s) + 0.5) / s - 0.5
    for p in polys:
        u0 = max(int(np.floor(p[:, 0].min() - 0.5)), 0)
        u1 = min(int(np.ceil(p[:, 0].max() + 0.5)), width_px - 1)
        v0 = max(int(np.floor(p[:, 1].min() - 0.5)), 0)
        v1 = min(int(np.ceil(p[:, 1].max() + 0.5)), height_px - 1)
        if u1 < u0 or v1 < v0:
            continue
        uu = (np.arange(u0, u1 + 1)[:, None] + sub).ravel()
        vv = (np.arange(v0, v1 + 1)[:, None] + sub).ravel()
        gu, gv = np.meshgrid(uu, vv)
        inside = points_in_poly(np.column_stack([gu.ravel(), gv.ravel()]), p)
        inside = inside.reshape(v1 - v0 + 1, s, u1 - u0 + 1, s).mean(axis=(1, 3))
        out[v0 : v1 + 1, u0 : u1 + 1] += inside
    return np.minimum(out, 1.0)


# =============================================================================== PSF kernels


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
    if not scene.wires:
        return None
    polys = [wire_polygon(p0, p1, w) for p0, p1, w in scene.wires]
    return _blurred_coverage(polys, scene.width_px, scene.height_px, config)


def _add_mark(o_fixed: np.ndarray | None, scene: Scene, config: RenderConfig) -> np.ndarray | None:
    """Union of ``o_fixed`` with the blurred reference mark (computed in a box around it)."""
    if scene.reference_mark is None:
        return o_fixed
    H, W = scene.height_px, scene.width_px
    poly = reference_mark_polygon(*scene.reference_mark)
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


# =============================================================================== illumination


def _fixed_rng(config: RenderConfig, key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(key,)))


def _illumination32(width_px: int, height_px: int, config: RenderConfig) -> np.ndarray:
    """The background field as float32 (see :func:`illumination_field`)."""
    rng = _fixed_rng(config, _KEY_ILLUMINATION)
    W, H = width_px, height_px
    # the field is smooth: evaluate it on a grid 8x coarser and upsample (bicubic) once
    ws, hs = max(4, -(-W // 8)), max(4, -(-H // 8))
    field = np.zeros((hs, ws))
    n = config.illumination_order
    if config.illumination_variation > 0.0 and n > 0:
        # full-resolution positions of the coarse samples, as cv2.resize maps them
        uj = (np.arange(ws) + 0.5) * (W / ws) - 0.5
        vj = (np.arange(hs) + 0.5) * (H / hs) - 0.5
        x = (uj - 0.5 * (W - 1)) / (0.5 * W)
        y = (vj - 0.5 * (H - 1)) / (0.5 * H)
        px = np.polynomial.legendre.legvander(x, n).T  # (n+1, ws)
        py = np.polynomial.legendre.legvander(y, n).T
        c = rng.normal(size=(n + 1, n + 1))
        i, j = np.indices(c.shape)
        c[(i + j > n) | ((i == 0) & (j == 0))] = 0.0
        if n >= 2:  # the spark-lit mirror is brighter in the middle: a vignetting bias
            c[2, 0] -= 1.0
            c[0, 2] -= 1.0
        f = py.T @ c @ px
        f -= f.mean()
        f /= np.abs(f).max()
        field += config.illumination_variation * f
    if config.illumination_mottle > 0.0:
        scale = config.illumination_mottle_scale_px
        gh, gw = int(math.ceil(H / scale)) + 2, int(math.ceil(W / scale)) + 2
        g = cv2.resize(rng.normal(size=(gh, gw)), (ws, hs), interpolation=cv2.INTER_CUBIC)
        g = (g - g.mean()) / g.std()
        field += config.illumination_mottle * g
    low = (config.background_level * (1.0 + field)).astype(np.float32)
    return cv2.resize(low, (W, H), interpolation=cv2.INTER_CUBIC)


def illumination_field(width_px: int, height_px: int, config: RenderConfig) -> np.ndarray:
    """Background level B(u, v) (fraction of full scale, float64 (H, W)): the unobstructed beam.

    ``B = background_level * (1 + illumination_variation * f + illumination_mottle * g)``
    where ``f`` is a random combination of 2-D Legendre polynomials up to total degree
    ``illumination_order`` (with a centre-bright bias), scaled to ``max |f| = 1``, and ``g``
    is smooth unit-variance noise of correlation scale ``illumination_mottle_scale_px``;
    evaluated on a grid 8x coarser and upsampled bicubically. A fixed pattern (a function of
    ``config.seed``); these are exactly the values :func:`render_clean` multiplies by.
    """
    return _illumination32(width_px, height_px, config).astype(np.float64)


# =============================================================================== clutter


def _line_profile(r: np.ndarray, width: float) -> np.ndarray:
    """Shadowgraph line (dark on the + side, bright on the - side), extremes -1/+1 at r = +-w."""
    z = r / width
    return -z * np.exp(0.5 - 0.5 * z * z)


def _box_around(points: np.ndarray, pad: float, W: int, H: int):
    """Inclusive pixel box ``(u0, v0, u1, v1)`` around points, clipped; None if off-image."""
    u0 = max(int(math.floor(points[:, 0].min() - pad)), 0)
    u1 = min(int(math.ceil(points[:, 0].max() + pad)), W - 1)
    v0 = max(int(math.floor(points[:, 1].min() - pad)), 0)
    v1 = min(int(math.ceil(points[:, 1].max() + pad)), H - 1)
    if u1 < u0 or v1 < v0:
        return None
    return u0, v0, u1, v1


def _band(points: np.ndarray, pad: float, W: int, H: int):
    """Pixels ``(v, u)`` within about ``pad`` px of a polyline ``(N, 2)`` of (u, v), or None."""
    box = _box_around(points, pad + 1.0, W, H)
    if box is None:
        return None
    u0, v0, u1, v1 = box
    mask = np.zeros((v1 - v0 + 1, u1 - u0 + 1), np.uint8)
    rel = np.clip(points - (u0, v0), -1e6, 1e6)
    pts = np.round(rel * 16.0).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(mask, [pts], False, 1, thickness=2 * int(math.ceil(pad)) + 1,
                  lineType=cv2.LINE_8, shift=4)  # fmt: skip
    vv, uu = np.nonzero(mask)
    return vv + v0, uu + u0


def _flow_clutter(scene: Scene, config: RenderConfig, rng, out: np.ndarray) -> None:
    """Add the bow shock and wake (relative modulation) into ``out`` (H, W)."""
    H, W = scene.height_px, scene.width_px
    uc, vc, au, av, R = scene.body_hint
    a = np.array([au, av])
    nrm = np.array([-av, au])
    origin = np.array([uc, vc])

    def to_image(x, y):
        return origin + np.multiply.outer(x, a) + np.multiply.outer(y, nrm)

    def to_local(vv, uu):
        du, dv = uu - uc, vv - vc
        return du * au + dv * av, du * nrm[0] + dv * nrm[1]

    line_w = 0.8  # px, half-width of a shock line's dark/bright pair
    pad = 5.0 * line_w
    mach = config.bow_shock_mach
    beta = math.asin(1.0 / mach)  # far from the body the shock tends to the Mach angle
    if config.bow_shock and config.bow_shock_contrast > 0.0:
        # Billig (1967) sphere correlations: standoff, vertex curvature radius, hyperbola
        delta = 0.143 * R * math.exp(3.24 / mach**2)
        expo = min(0.54 / (mach - 1.0) ** 1.2, 10.0)  # rc is capped at 100 R anyway
        rc = min(1.143 * R * math.exp(expo), 100.0 * R)
        x0 = R + delta
        tb = math.tan(beta)
        extent = 3.0 * R  # lateral fade length of the shock's visibility

        def shock_x(y):
            return x0 - rc / tb**2 * (np.sqrt(1.0 + (y * tb / rc) ** 2) - 1.0)

        ys = np.linspace(-2.5 * extent, 2.5 * extent, int(5.0 * extent / 2.0) + 2)
        band = _band(to_image(shock_x(ys), ys), pad, W, H)
        if band is not None:
            x, y = to_local(*band)
            slope = -y / (rc * np.sqrt(1.0 + (y * tb / rc) ** 2))
            r = (x - shock_x(y)) / np.sqrt(1.0 + slope * slope)  # + upstream
            val = _line_profile(r, line_w) * np.exp(-((y / extent) ** 2))
            out[band] += config.bow_shock_contrast * val
    if config.wake and config.wake_contrast > 0.0:
        c = config.wake_contrast
        neck_x, neck_y = -2.0 * R, 0.45 * R
        segments = []  # (start, end) local (x, y), contrast, fade length along the line
        for sgn in (1.0, -1.0):  # shear layers from the shoulders to the wake neck
            segments.append(((-0.1 * R, sgn * 0.98 * R), (neck_x, sgn * neck_y), c, None))
            if config.bow_shock:  # supersonic: recompression shocks from the neck
                end = (neck_x - 5.0 * R * math.cos(beta), sgn * (neck_y + 5.0 * R * math.sin(beta)))
                segments.append(((neck_x, sgn * neck_y), end, 0.8 * c, 2.5 * R))
        for (xa, ya), (xb, yb), contrast, fade_len in segments:
            ends = to_image(np.array([xa, xb]), np.array([ya, yb]))
            band = _band(ends, pad, W, H)
            if band is None:
                continue
            x, y = to_local(*band)
            dx, dy = xb - xa, yb - ya
            length = math.hypot(dx, dy)
            t = ((x - xa) * dx + (y - ya) * dy) / length**2
            r = ((x - xa) * dy - (y - ya) * dx) / length * math.copysign(1.0, ya)
            taper = np.clip(np.minimum(t, 1.0 - t) / 0.1, 0.0, 1.0)
            if fade_len is not None:
                taper = taper * np.exp(-np.clip(t, 0.0, 1.0) * length / fade_len)
            out[band] += contrast * _line_profile(r, line_w) * taper
        # turbulent core: smooth noise in a slowly widening wedge behind the neck, evaluated
        # on a 4-px grid and upsampled (it is smooth at the scale 0.12 R)
        length = 8.0 * R
        spread = math.tan(math.radians(7.0))
        half_end = neck_y + length * spread
        corners = to_image(np.array([neck_x + 0.3 * R] * 2 + [neck_x - length] * 2),
                           np.array([-half_end, half_end] * 2))  # fmt: skip
        box = _box_around(corners, 2.0, W, H)
        if box is not None:
            u0, v0, u1, v1 = box
            bw, bh = u1 - u0 + 1, v1 - v0 + 1
            lw, lh = max(2, -(-bw // 4)), max(2, -(-bh // 4))
            uu = u0 - 0.5 + (np.arange(lw) + 0.5) * (bw / lw)
            vv = v0 - 0.5 + (np.arange(lh) + 0.5) * (bh / lh)
            x, y = to_local(vv[:, None], uu[None, :])
            scale = max(0.12 * R, 3.0)
            g = rng.normal(size=(int(bh / scale) + 3, int(bw / scale) + 3))
            g = cv2.resize(g, (lw, lh), interpolation=cv2.INTER_CUBIC)
            g /= max(g.std(), 1e-12)
            half = neck_y + np.clip(neck_x - x, 0.0, None) * spread
            env = np.exp(-((y / half) ** 4)) * np.clip((neck_x + 0.3 * R - x) / (0.6 * R), 0, 1)
            env *= np.exp(-np.clip(neck_x - x, 0.0, None) / (0.5 * length))
            tex = cv2.resize(0.5 * c * g * env, (bw, bh), interpolation=cv2.INTER_LINEAR)
            out[v0 : v1 + 1, u0 : u1 + 1] += tex


def _ribbon(points: np.ndarray, width: float) -> np.ndarray:
    """Closed polygon of a polyline thickened to ``width`` (for scratches and fibres)."""
    d = np.gradient(points, axis=0)
    d /= np.hypot(d[:, 0], d[:, 1])[:, None]
    n = np.column_stack([-d[:, 1], d[:, 0]]) * (0.5 * width)
    return np.vstack([points + n, (points - n)[::-1]])


def _defects(scene: Scene, config: RenderConfig, rng) -> np.ndarray:
    """Film defects as a relative modulation (H, W): scratches (+-), dust and fibres (-)."""
    H, W = scene.height_px, scene.width_px
    acc = np.zeros((H, W + 2))
    diag = math.hypot(W, H)
    for _ in range(config.scratches):
        start = rng.uniform((0, 0), (W, H))
        ang = rng.uniform(0.0, np.pi)
        length = rng.uniform(0.3, 1.0) * diag
        sag = rng.uniform(-0.04, 0.04) * length
        t = np.linspace(-0.5, 0.5, 96)
        d = np.array([math.cos(ang), math.sin(ang)])
        n = np.array([-d[1], d[0]])
        pts = start + (t * length)[:, None] * d + (sag * (1.0 - 4.0 * t * t))[:, None] * n
        contrast = rng.uniform(0.04, 0.14) * (1.0 if rng.random() < 0.4 else -1.0)
        poly = _ribbon(pts, rng.uniform(0.5, 1.6))
        _accumulate_polygon(acc, poly[:, 0] + 0.5, poly[:, 1] + 0.5, contrast)
    for _ in range(config.dust):
        centre = rng.uniform((0, 0), (W, H))
        opacity = rng.uniform(0.35, 0.95)
        if rng.random() < 0.8:  # speck: an irregular blob
            r = 10.0 ** rng.uniform(math.log10(0.6), math.log10(3.5))
            t = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
            wobble = 1.0 + sum(rng.normal(0, 0.12) * np.cos(k * t + rng.uniform(0, 6.3))
                               for k in (2, 3, 5))  # fmt: skip
            poly = centre + (r * np.clip(wobble, 0.4, None))[:, None] * np.column_stack(
                [np.cos(t), np.sin(t)]
            )
        else:  # fibre: a short curved hair
            length = rng.uniform(6.0, 30.0)
            ang = rng.uniform(0.0, np.pi)
            bend = rng.uniform(-0.5, 0.5)
            phi = ang + bend * np.linspace(-1.0, 1.0, 24)
            steps = np.column_stack([np.cos(phi), np.sin(phi)]) * (length / 23.0)
            pts = centre + np.cumsum(steps, axis=0) - steps.sum(axis=0) / 2
            poly = _ribbon(pts, rng.uniform(0.6, 1.2))
            opacity *= 0.8
        _accumulate_polygon(acc, poly[:, 0] + 0.5, poly[:, 1] + 0.5, -opacity)
    return _integrate_rows(acc, W, -1.0, 1.0)


def _apply_keepout(modulation, o_body, boxes, clearance: float) -> None:
    """Zero the clutter on and near the bodies: exactly 0 within ``clearance`` px of the
    blurred shadow (opacity > 1e-3), fading in over the next ~3 px. Only the region around
    the body patches is touched."""
    r = int(math.ceil(clearance))
    H, W = o_body.shape
    for u0, v0, u1, v1, _ in boxes:
        u0, v0 = max(u0 - r - 8, 0), max(v0 - r - 8, 0)
        u1, v1 = min(u1 + r + 8, W - 1), min(v1 + r + 8, H - 1)
        near = (o_body[v0 : v1 + 1, u0 : u1 + 1] > 1e-3).astype(np.uint8)
        zero = _dilate(near, r)
        keep = 1.0 - cv2.GaussianBlur(_dilate(near, r + 3).astype(np.float32), (0, 0), 1.0)
        keep[zero > 0] = 0.0
        modulation[v0 : v1 + 1, u0 : u1 + 1] *= np.clip(keep, 0.0, 1.0)


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    if radius <= 0:
        return mask
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    return cv2.dilate(mask, kernel)


# =============================================================================== rendering


def render_clean(scene: Scene, config: RenderConfig | None = None) -> np.ndarray:
    """Noise-free image (fraction of full scale, float64, shape (H, W)) before quantization.

    ``B(u, v) * max(T, 0)`` with the transmission ``T`` of the module docstring: bodies blurred
    by PSF and motion (fine grid), wires and mark by the PSF, the fringe and the fixed-pattern
    clutter (a function of ``config.seed``; switch clutter off for moment tests). This is the
    expectation of :func:`render` before quantization (for Cramer–Rao bounds and tests).
    """
    config = RenderConfig() if config is None else config
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
    H, W = scene.height_px, scene.width_px
    empty = np.zeros((0, 0))
    o_body, boxes = _body_opacity(scene, config)
    o_fixed = _wire_opacity(scene, config)
    fringe = empty
    if config.diffraction_fringe > 0.0:  # bodies and wires diffract; the scanner mark doesn't
        total = _union_f32(o_body, o_fixed) if o_fixed is not None else o_body.astype(np.float32)
        fringe = _fringe(total, config)
    o_fixed = _add_mark(o_fixed, scene, config)
    rng = _fixed_rng(config, _KEY_CLUTTER)
    flow = scene.body_hint is not None and (
        (config.bow_shock and config.bow_shock_contrast > 0.0)
        or (config.wake and config.wake_contrast > 0.0)
    )
    modulation = empty
    if config.scratches or config.dust:
        modulation = _defects(scene, config, rng)
    if flow:
        if modulation is empty:
            modulation = np.zeros((H, W))
        _flow_clutter(scene, config, rng, modulation)
    if modulation is not empty:
        _apply_keepout(modulation, o_body, boxes, config.clutter_clearance_px)
    out = np.empty((H, W))
    o_fixed = empty if o_fixed is None else o_fixed
    _compose(o_body, o_fixed, fringe, modulation, _illumination32(W, H, config),
             config.shadow_level, out)  # fmt: skip
    return out


@numba.njit(cache=True)
def _noise_quantize(image, grain, grain_sigma, white, read, shot, full, out):
    """``out = clip(floor(full x (I (1 + g_s g) + sqrt(read^2 + shot^2 I) n) + 1/2))``."""
    has_grain = grain.size > 0
    has_white = white.size > 0
    read2 = read * read
    shot2 = shot * shot
    for v in range(image.shape[0]):
        for u in range(image.shape[1]):
            x0 = image[v, u]
            x = x0
            if has_grain:
                x *= 1.0 + grain_sigma * grain[v, u]
            if has_white:
                x += math.sqrt(read2 + shot2 * max(x0, 0.0)) * white[v, u]
            c = math.floor(x * full + 0.5)
            out[v, u] = min(max(c, 0.0), full)


def _film_grain(shape, config: RenderConfig, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance Gaussian field (float32) with correlation length ``film_grain_length_px``."""
    g = rng.standard_normal(shape, dtype=np.float32)
    sigma = config.film_grain_length_px
    if sigma > 0.0:
        k = _gaussian_kernel_1d(sigma, 1.0)
        g = cv2.sepFilter2D(g, -1, k.astype(np.float32), k.astype(np.float32),
                            borderType=cv2.BORDER_REFLECT_101)  # fmt: skip
        g *= np.float32(1.0 / np.sum(k**2))  # std of white noise filtered by k (x) k
    return g


def render(
    scene: Scene, config: RenderConfig | None = None, rng: np.random.Generator | None = None
) -> np.ndarray:
    """Realistic quantized shadowgraph: ``uint8`` or ``uint16`` (``config.bit_depth``), (H, W).

    Parameters
    ----------
    scene
        What to draw (pixel coordinates).
    config
        Image model; default ``RenderConfig()``.
    rng
        Source of the noise only (grain, then shot + read); the illumination and clutter are a
        fixed pattern of ``config.seed``. Default ``np.random.default_rng(config.seed)``.

    Notes
    -----
    Noise model: ``I (1 + film_grain_sigma g) + sqrt(read^2 + shot^2 I) n`` with ``g`` a
    unit-variance Gaussian field of correlation length ``film_grain_length_px`` and ``n``
    white unit Gaussian; then :func:`quantize`.
    """
    config = RenderConfig() if config is None else config
    rng = np.random.default_rng(config.seed) if rng is None else rng
    image = render_clean(scene, config)
    empty = np.zeros((0, 0), dtype=np.float32)
    grain = empty
    if config.film_grain_sigma > 0.0:
        grain = _film_grain(image.shape, config, rng)
    white = empty
    if config.read_noise_sigma > 0.0 or config.shot_noise_sigma > 0.0:
        white = rng.standard_normal(image.shape, dtype=np.float32)
    full = (1 << config.bit_depth) - 1
    out = np.empty(image.shape, dtype=np.uint8 if config.bit_depth == 8 else np.uint16)
    _noise_quantize(image, grain, config.film_grain_sigma, white, config.read_noise_sigma,
                    config.shot_noise_sigma, float(full), out)  # fmt: skip
    return out


def quantize(image: np.ndarray, bit_depth: int) -> np.ndarray:
    """Fraction of full scale -> ``uint8``/``uint16`` counts: ``floor(x full + 1/2)``, clipped."""
    if bit_depth not in (8, 16):
        raise ValueError(f"bit_depth must be 8 or 16, got {bit_depth}")
    full = (1 << bit_depth) - 1
    counts = np.floor(np.asarray(image, dtype=np.float64) * full + 0.5)
    np.clip(counts, 0, full, out=counts)
    return counts.astype(np.uint8 if bit_depth == 8 else np.uint16)


# =============================================================================== image files


def write_image(path: str | os.PathLike, image: np.ndarray, overwrite: bool = False) -> Path:
    """Write a ``uint8``/``uint16`` grey image as PNG (bit depth kept), atomically.

    Encoded in memory, then written by :func:`cadra.io.atomic.atomic_write_bytes` (temporary
    file in the destination folder, then ``os.replace``).

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``overwrite`` is false.
    ValueError
        Not a 2-D uint8/uint16 array, or not a ``.png`` path.
    """
    path = Path(path)
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"image must be 2-D uint8 or uint16, got {image.dtype} {image.shape}")
    if path.suffix.lower() != ".png":
        raise ValueError(f"{path}: only .png is written")
    ok, encoded = cv2.imencode(".png", np.ascontiguousarray(image))
    if not ok:
        raise OSError(f"cv2 could not encode {path} as PNG")
    atomic_write_bytes(path, encoded.tobytes(), overwrite=overwrite)
    return path


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read a grey PNG written by :func:`write_image` (``uint8`` or ``uint16``, (H, W))."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(path)
    image = cv2.imread(os.fspath(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise OSError(f"cv2 could not read {path}")
    if image.ndim != 2:
        raise ValueError(f"{path}: expected a single-channel image, got shape {image.shape}")
    return image
