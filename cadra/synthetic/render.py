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
:func:`reference_mark_polygon`, :func:`write_image`, :func:`read_image`. This module is the
composition and the image files; the parts live beside it: the scene
(:mod:`cadra.synthetic.scene`), exact coverage (:mod:`cadra.synthetic.raster`), PSF, motion
blur, opacity layers and the fringe (:mod:`cadra.synthetic.blur`), illumination, clutter,
defects, grain and noise (:mod:`cadra.synthetic.realism`); polygon moments are
:mod:`cadra.geometry`'s.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from cadra.atomic import atomic_write_bytes
from cadra.geometry import polygon_area_centroid
from cadra.synthetic.blur import (
    _add_mark,
    _body_opacity,
    _compose,
    _fringe,
    _union_f32,
    _wire_opacity,
)
from cadra.synthetic.raster import coverage
from cadra.synthetic.realism import (
    _KEY_CLUTTER,
    _apply_keepout,
    _defects,
    _film_grain,
    _fixed_rng,
    _flow_clutter,
    _illumination32,
    _noise_quantize,
    illumination_field,
)
from cadra.synthetic.render_config import (
    PsfShape,
    RenderConfig,
    load_render_config,
    save_render_config,
)
from cadra.synthetic.scene import Scene, reference_mark_polygon, wire_polygon

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

    Encoded in memory, then written by :func:`cadra.atomic.atomic_write_bytes` (temporary
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
