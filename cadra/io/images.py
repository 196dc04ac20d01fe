"""Station images for stage one, from files or from memory, with a clear reason for every
refusal.

A station image is refused (and that station flagged, never the whole shot) when it is
missing, unreadable or truncated, not greyscale, of another size or bit depth than its view
declares, or holds non-finite values. A file (:func:`load_station_image`) and an array in
memory (:func:`station_image`: what the renderer or a frame grabber hands over) pass the same
checks and become the same float32 image.

A file's size is read from its header before it is decoded (Pillow reads the header only), so
a file whose header claims a huge image (a 1 MB PNG claiming 32000 x 32000 px decodes to
2 GB) is refused without decoding it; a decoder's own error is a refusal too, never an
exception.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np


@dataclass(frozen=True)
class ImageProblem:
    """Why an image cannot be measured (falsy, so it cannot pass for an image)."""

    path: str
    reason: str

    def __bool__(self) -> bool:
        return False


def load_station_image(path: str | Path, width_px: int, height_px: int,
                       bit_depth: int) -> np.ndarray | ImageProblem:
    """The image as float32 in [0, 1] (full scale of its bit depth), or an :class:`ImageProblem`.

    PNG truncation is detected by decoding: OpenCV returns nothing for a damaged file.
    """
    path = Path(path)
    try:
        if not path.is_file():
            if path.is_symlink():
                return ImageProblem(str(path), "a symbolic link to nothing (broken, or a "
                                               "loop), not an image file")
            return ImageProblem(str(path), "missing image file")
        if path.stat().st_size == 0:
            return ImageProblem(str(path), "empty image file")
        size = header_size(path)
        if isinstance(size, ImageProblem):
            return size
        if size is not None and size != (width_px, height_px):
            return ImageProblem(str(path), f"{size[0]}x{size[1]} px, the view declares "
                                           f"{width_px}x{height_px} (from its header; not "
                                           f"decoded)")
        img = cv2.imdecode(np.fromfile(path, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except (OSError, RuntimeError, cv2.error) as exc:  # a link loop, a decoder's refusal
        return ImageProblem(str(path), f"unreadable image file ({type(exc).__name__}: "
                                       f"{' '.join(str(exc).split())[:200]})")
    if img is None:
        return ImageProblem(str(path), "unreadable or truncated image file")
    return station_image(img, width_px, height_px, bit_depth, str(path))


def header_size(path: str | Path) -> tuple[int, int] | ImageProblem | None:
    """``(width, height)`` px from an image file's header, without decoding it; an
    :class:`ImageProblem` if the header claims more pixels than Pillow will open; None if
    Pillow does not know the format (OpenCV may still read it)."""
    import warnings

    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                return tuple(int(v) for v in im.size)
    except Image.DecompressionBombError:
        return ImageProblem(str(path), f"its header claims more than "
                                       f"{2 * Image.MAX_IMAGE_PIXELS:,} px; not decoded")
    except (UnidentifiedImageError, ValueError, SyntaxError):
        return None


def station_image(img: np.ndarray, width_px: int, height_px: int, bit_depth: int,
                  name: str = "image") -> np.ndarray | ImageProblem:
    """A grey ``uint8``/``uint16`` image array as float32 in [0, 1] (full scale of its bit
    depth), or an :class:`ImageProblem` naming ``name``: the checks of a file, on an array."""
    img = np.asarray(img)
    if img.ndim != 2:
        return ImageProblem(name, f"not a greyscale image (shape {img.shape})")
    bits = {np.dtype(np.uint8): 8, np.dtype(np.uint16): 16}.get(img.dtype)
    if bits is None:
        return ImageProblem(name, f"unexpected pixel type {img.dtype}")
    if bits != bit_depth:
        return ImageProblem(name, f"{bits}-bit image, the view declares {bit_depth}-bit")
    if img.shape != (height_px, width_px):
        return ImageProblem(name, f"{img.shape[1]}x{img.shape[0]} px, the view declares "
                                  f"{width_px}x{height_px}")
    # one pass (the cast is exact, the product rounded once, as in astype then multiply)
    return np.multiply(img, np.float32(1.0 / (2**bits - 1)), dtype=np.float32)
