"""The renderer's realism: illumination, flow clutter, film defects, grain and noise.

The illumination and all clutter are a fixed pattern of ``RenderConfig.seed`` (independent
``SeedSequence`` streams); the film grain and the shot/read noise come from the caller's
generator (docs/renderer.md, "Illumination", "Clutter", "Noise and quantization").
"""

from __future__ import annotations

import math

import cv2
import numba
import numpy as np

from cadra.synthetic.blur import _box_around, _gaussian_kernel_1d
from cadra.synthetic.raster import _accumulate_polygon, _integrate_rows
from cadra.synthetic.render_config import RenderConfig
from cadra.synthetic.scene import Scene

__all__ = ["illumination_field"]

#: SeedSequence spawn keys of the fixed-pattern streams (the noise uses ``default_rng(seed)``).
_KEY_ILLUMINATION = 1
_KEY_CLUTTER = 2


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
