"""An image distortion the facility file does not declare, found from the wires.

Straight wires recorded through a distorted lens or mirror train come out curved: the
straight-line fit of each keeps the centres near one chord and the affine from the four
wires then misses the survey by tenths of a pixel, which fails the station
(:data:`cadra.imaging.station.WIRE_RMS_MAX_PX`). :func:`radial_from_wires` asks whether a radial
distortion about the image centre explains that: it removes trial distortions
``k1`` (:class:`~cadra.optics.distortion.Distortion`, radius the image's half-diagonal) from
the image and minimizes the wires' affine rms over ``k1``. A ``k1`` that brings the rms down
to the survey's level names the cause (docs/stage1.md, "Distorted images"); it is also a
first calibration from the fiducials, one coefficient only (a grid calibrates all four:
:mod:`cadra.calibration.distortion`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from cadra.optics.distortion import Distortion

__all__ = ["K1_SCAN", "K1_SEARCH", "WireDistortion", "radial_from_wires"]

#: the k1 searched (|k1| up to 0.02, 1.2 deg at the corners): the facility file's bound is
#: 5 % of the radius in displacement
K1_SEARCH = 0.02
#: scan points each side of zero before the search (a step of 0.002)
K1_SCAN = 10


@dataclass(frozen=True)
class WireDistortion:
    """``k1`` (radial, radius the half-diagonal), the wires' affine rms (px) without and with
    it removed, and the largest line-direction change it makes over the image (deg)."""

    k1: float
    rms_before_px: float
    rms_after_px: float
    max_angle_deg: float

    def explains(self, limit_px: float) -> bool:
        """Does removing it bring the wires' affine rms from beyond ``limit_px`` (the
        survey's level, :data:`cadra.imaging.station.WIRE_RMS_MAX_PX`) to within it?"""
        return self.rms_before_px > limit_px >= self.rms_after_px


def radial_from_wires(image: np.ndarray, view, exclude: np.ndarray | None = None
                      ) -> WireDistortion | None:
    """The radial distortion ``k1`` that best straightens ``view``'s wires in ``image`` (the
    recorded float image; ``exclude`` the model's pixels), by a bounded scalar search over
    ``+-``:data:`K1_SEARCH` (a scan, then a bounded search about its best: about 35 fast wire
    fits, a few seconds). None when the wires cannot be fitted."""
    from cadra.imaging.wires.fit import measure_wires

    W, H = view.width_px, view.height_px

    def rms(k1: float) -> float:
        d = Distortion.for_image(W, H, k1=k1)
        m = measure_wires(d.undistort_image(image), view, exclude=exclude,
                          profile_model=False)
        return m.affine_rms_px if m.ok and math.isfinite(m.affine_rms_px) else 1e3

    before = rms(0.0)
    if before >= 1e3:
        return None
    # a scan first (the rms is not smooth in k1 where the line fits drop and keep centres),
    # then a bounded search about its best
    grid = np.linspace(-K1_SEARCH, K1_SEARCH, 2 * K1_SCAN + 1)
    best = grid[int(np.argmin([rms(k) if k != 0.0 else before for k in grid]))]
    h = K1_SEARCH / K1_SCAN
    res = minimize_scalar(rms, bounds=(best - h, best + h), method="bounded",
                          options={"xatol": 1e-5})
    k1 = float(res.x) if res.fun < before else 0.0
    after = float(min(res.fun, before))
    d = Distortion.for_image(W, H, k1=k1)
    return WireDistortion(k1, float(before), after,
                          math.degrees(d.max_angle_change_rad(W, H)))
