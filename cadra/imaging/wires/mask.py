"""The pixels near a view's wires, which the silhouette fit leaves out (docs/stage1.md,
"Wires")."""

from __future__ import annotations

import math

import cv2
import numpy as np

from cadra.facility.reference import View
from cadra.geometry import densify_polygon

__all__ = ["wire_mask"]


def wire_mask(view: View, affine: np.ndarray | None, shape: tuple[int, int],
              half_width_px: float = 4.0, distortion=None) -> np.ndarray:
    """True on pixels within ``half_width_px`` of any wire's image edge.

    Parameters
    ----------
    view : the view whose wires to draw.
    affine : image->plane map (2x3) to place them with (e.g. ``WireMeasurement.affine``);
        None for the nominal one.
    shape : (H, W) of the mask.
    half_width_px : distance (px) beyond each wire's edge (its half-diameter) to mark.
    distortion : the recorded image's :class:`~cadra.optics.distortion.Distortion` (the
        mask is of the recorded image, its wires curved), or None.
    """
    H, W = shape
    mask = np.zeros((H, W), np.uint8)
    for seg, w in zip(view.wire_lines_px(affine=affine, margin_px=10.0), view.wires,
                      strict=True):
        if seg is None:
            continue
        half = half_width_px + 0.5 * view.wire_width_px(w)
        p0, p1 = np.array(seg[0]), np.array(seg[1])
        t = (p1 - p0) / math.hypot(*(p1 - p0))
        n = np.array([-t[1], t[0]]) * half
        poly = np.array([p0 + n, p1 + n, p1 - n, p0 - n])
        # sub-pixel vertices (4 fractional bits); pixel centres inside are marked
        if distortion is None:
            cv2.fillConvexPoly(mask, np.rint(poly * 16).astype(np.int32), 1, cv2.LINE_8, 4)
        else:
            curved = distortion.distort(densify_polygon(poly, 4.0))
            cv2.fillPoly(mask, [np.rint(curved * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    return mask.astype(bool)

