"""Configuration of the synthetic shadowgraph renderer (:mod:`cadra.synthetic.render`).

One frozen dataclass, :class:`RenderConfig`, whose defaults are "default realism" for a scanned
HFFAF shadowgraph (seed 004, DESIGN §5). Every knob is documented in ``docs/renderer.md``; the
TOML form is flat (one key per field), optionally inside a named table of a larger run file::

    seed = 3
    optics_blur_sigma_px = 0.9
    psf_shape = "airy_like"

Intensities are fractions of full scale (0 = black, 1 = the largest quantized value); lengths
are in pixels of the output image (``docs/conventions.md``, "Images and pixels").
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import tomli_w

from cadra.atomic import atomic_write_text


class PsfShape(StrEnum):
    """Optical point-spread function of the camera (all rotationally symmetric, normalized).

    ``GAUSSIAN`` is what measurement code may assume; the others exist so that measurement code
    can be tested without the "inverse crime" of fitting the model that made the data. All three
    share the width parameter ``optics_blur_sigma_px``: the Airy-like pattern has the FWHM of the
    Gaussian of that sigma, the disk has the Gaussian's per-axis variance (radius 2 sigma).
    """

    GAUSSIAN = "gaussian"
    AIRY_LIKE = "airy_like"
    DISK = "disk"


@dataclass(frozen=True)
class RenderConfig:
    """Every knob of the image model; defaults give a realistic scanned shadowgraph.

    Image model (``docs/renderer.md``)::

        I = B(u, v) * [1 - (1 - shadow_level) * O + F] * clutter,   O = coverage (*) PSF (*) motion
        I_noisy = quantize(I * (1 + grain) + sqrt(read^2 + shot^2 * I) * N(0, 1))

    Fields are grouped as: fixed pattern (seed), sampling, illumination, optics, fringe, noise,
    quantization and clutter. See ``docs/renderer.md`` for each field's meaning and default.
    """

    # --- seed of the fixed pattern (illumination, clutter) and default noise stream
    seed: int = 0
    # --- sampling: fine-grid factor for the optics around bodies (coverage itself is exact)
    supersample: int = 8
    # --- illumination (fractions of full scale)
    background_level: float = 0.85
    illumination_variation: float = 0.06
    illumination_order: int = 3
    illumination_mottle: float = 0.012
    illumination_mottle_scale_px: float = 60.0
    shadow_level: float = 0.08
    # --- optics
    optics_blur_sigma_px: float = 0.7
    psf_shape: PsfShape = PsfShape.GAUSSIAN
    motion_blur: bool = True
    # --- diffraction fringe (Laplacian-of-Gaussian edge ringing)
    diffraction_fringe: float = 0.10
    fringe_width_px: float = 0.5
    # --- noise (fractions of full scale; grain relative to the local intensity)
    read_noise_sigma: float = 0.010
    shot_noise_sigma: float = 0.010
    film_grain_sigma: float = 0.012
    film_grain_length_px: float = 1.2
    # --- quantization
    bit_depth: int = 8
    # --- clutter: flow features (need Scene.body_hint) and film defects
    bow_shock: bool = True
    bow_shock_contrast: float = 0.10
    bow_shock_mach: float = 1.25
    wake: bool = True
    wake_contrast: float = 0.04
    scratches: int = 2
    dust: int = 12
    clutter_clearance_px: float = 4.0

    def __post_init__(self) -> None:
        # accept the enum's string value (from TOML or a caller)
        if not isinstance(self.psf_shape, PsfShape):
            try:
                object.__setattr__(self, "psf_shape", PsfShape(self.psf_shape))
            except ValueError:
                valid = ", ".join(repr(p.value) for p in PsfShape)
                raise ValueError(f"psf_shape = {self.psf_shape!r} is not one of {valid}") from None
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            kind = _FIELD_KIND[f.name]
            if kind is bool and not isinstance(value, bool):
                raise TypeError(f"RenderConfig.{f.name} must be a bool, got {value!r}")
            if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
                raise TypeError(f"RenderConfig.{f.name} must be an int, got {value!r}")
            if kind is float:
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise TypeError(f"RenderConfig.{f.name} must be a number, got {value!r}")
                if not math.isfinite(value):
                    raise ValueError(f"RenderConfig.{f.name} must be finite, got {value!r}")
                object.__setattr__(self, f.name, float(value))
        if self.bit_depth not in (8, 16):
            raise ValueError(f"RenderConfig.bit_depth must be 8 or 16, got {self.bit_depth}")
        for name, (lo, hi) in _RANGES.items():
            _check_range(self, name, lo, hi, low_open=name in _LOW_OPEN)

    # ------------------------------------------------------------------ dict / TOML forms

    def to_dict(self) -> dict[str, Any]:
        """Plain ``{field: value}`` dict of TOML-able scalars (the enum as its string)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            out[f.name] = value.value if isinstance(value, PsfShape) else value
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RenderConfig:
        """Build from a (possibly partial) dict; missing keys take defaults.

        Raises
        ------
        ValueError
            If ``data`` holds a key that is not a field, naming the key(s).
        """
        unknown = sorted(set(data) - set(_FIELD_KIND))
        if unknown:
            raise ValueError("unknown RenderConfig key(s): " + ", ".join(repr(k) for k in unknown))
        return cls(**data)

    def replace(self, **changes: Any) -> RenderConfig:
        """Copy with some fields changed (``dataclasses.replace`` with key checking)."""
        return RenderConfig.from_dict({**self.to_dict(), **changes})


_FIELD_KIND: dict[str, type] = {
    f.name: (
        PsfShape
        if f.name == "psf_shape"
        else {"bool": bool, "int": int, "float": float}[str(f.type)]
    )
    for f in dataclasses.fields(RenderConfig)
}


#: Allowed closed range ``[lo, hi]`` of each numeric knob (``(lo, hi]`` for :data:`_LOW_OPEN`).
_RANGES: dict[str, tuple[float, float]] = {
    "supersample": (1, 32),
    "background_level": (0.0, 1.0),
    "illumination_variation": (0.0, 0.5),
    "illumination_order": (0, 8),
    "illumination_mottle": (0.0, 0.5),
    "illumination_mottle_scale_px": (2.0, 1e6),
    "shadow_level": (0.0, 1.0),
    "optics_blur_sigma_px": (0.0, 20.0),
    "diffraction_fringe": (0.0, 0.5),
    "fringe_width_px": (0.1, 10.0),
    "read_noise_sigma": (0.0, 1.0),
    "shot_noise_sigma": (0.0, 1.0),
    "film_grain_sigma": (0.0, 1.0),
    "film_grain_length_px": (0.0, 50.0),
    "bow_shock_contrast": (0.0, 1.0),
    "bow_shock_mach": (1.0, 30.0),
    "wake_contrast": (0.0, 1.0),
    "scratches": (0, 1000),
    "dust": (0, 100000),
    "clutter_clearance_px": (0.0, 1000.0),
}
_LOW_OPEN = ("background_level", "bow_shock_mach")


def _check_range(cfg: RenderConfig, name: str, lo: float, hi: float, low_open=False) -> None:
    value = getattr(cfg, name)
    bad = value <= lo if low_open else value < lo
    if bad or value > hi:
        left = "(" if low_open else "["
        raise ValueError(f"RenderConfig.{name} = {value!r} is outside {left}{lo}, {hi}]")


def load_render_config(path: str | os.PathLike, table: str | None = None) -> RenderConfig:
    """Read a :class:`RenderConfig` from a TOML file.

    Parameters
    ----------
    path
        TOML file.
    table
        Name of the table holding the keys (dotted for nested tables, e.g. ``"sim.render"``);
        ``None`` reads the top level.

    Raises
    ------
    ValueError
        Unknown key (named in the message), bad value, or missing table.
    """
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    if table:
        for part in table.split("."):
            if not isinstance(data.get(part), dict):
                raise ValueError(f"{os.fspath(path)}: no table [{table}]")
            data = data[part]
    try:
        return RenderConfig.from_dict(data)
    except (ValueError, TypeError) as exc:
        raise type(exc)(f"{os.fspath(path)}: {exc}") from None


def save_render_config(
    path: str | os.PathLike, config: RenderConfig, overwrite: bool = False
) -> Path:
    """Write ``config`` as flat TOML (atomic: temp file in the same folder + ``os.replace``).

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    text = "# cadra.imaging RenderConfig (docs/renderer.md)\n" + tomli_w.dumps(config.to_dict())
    atomic_write_text(path, text, overwrite=overwrite)
    return path
