"""Exact polygon coverage of pixels: the renderer's silhouette truth (docs/renderer.md).

:func:`coverage` integrates every polygon edge analytically over the pixels it crosses (signed
trapezoid areas accumulated along scanlines, as in font rasterizers, numba-compiled), so the
sum of the coverage map is the polygon's area to rounding. The accumulation kernels are also
used on the renderer's fine grids (:mod:`cadra.synthetic.blur`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cadra.synthetic.scene import _as_polygon

__all__ = ["coverage"]


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
