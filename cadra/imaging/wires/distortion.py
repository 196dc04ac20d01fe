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

from cadra.imaging.wires.straightness import tls_line
from cadra.optics.distortion import Distortion, radial_undistorter
from cadra.stats import chi2_quantile

__all__ = ["BOW_Z", "K1_SCAN", "K1_SEARCH", "WireBow", "WireDistortion", "radial_from_centres",
           "radial_from_wires"]

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
    undistort = radial_undistorter(W, H)

    def rms(k1: float) -> float:
        m = measure_wires(undistort(image, k1), view, exclude=exclude, profile_model=False)
        return m.affine_rms_px if m.ok and math.isfinite(m.affine_rms_px) else 1e3

    before = rms(0.0)
    if before >= 1e3:
        return None
    # a scan first (the rms is not smooth in k1 where the line fits drop and keep centres),
    # then a bounded search about its best
    grid = np.linspace(-K1_SEARCH, K1_SEARCH, 2 * K1_SCAN + 1)
    best = grid[int(np.argmin([rms(k) if k != 0.0 else before for k in grid]))]
    h = K1_SEARCH / K1_SCAN
    from scipy.optimize import minimize_scalar  # here: a process that never searches

    res = minimize_scalar(rms, bounds=(best - h, best + h), method="bounded",
                          options={"xatol": 1e-5})
    k1 = float(res.x) if res.fun < before else 0.0
    after = float(min(res.fun, before))
    d = Distortion.for_image(W, H, k1=k1)
    return WireDistortion(k1, float(before), after,
                          math.degrees(d.max_angle_change_rad(W, H)))


#: a radial bow of the wires is taken as an undeclared distortion when its ``k1`` is this many
#: of its sigmas from zero and every wire's own ``k1`` agrees with it (:data:`BOW_AGREE_P`)
BOW_Z = 6.0
#: the wires' own ``k1`` agree with their common one unless their scatter about it exceeds
#: chi2's upper quantile at this probability (a shock or flow line bends one wire alone)
BOW_AGREE_P = 1e-3


@dataclass(frozen=True)
class WireBow:
    """The radial distortion ``k1`` (:meth:`Distortion.for_image`: about the centre of the
    ``width_px`` x ``height_px`` image, radius the half-diagonal) that straightens a view's
    wires' centres, with its 1-sigma; the wires' own ``k1`` scatter about it (chi2 over
    ``n_wires - 1`` degrees of freedom)."""

    k1: float
    sigma_k1: float
    chi2_wires: float
    n_wires: int
    width_px: int
    height_px: int

    @property
    def max_angle_deg(self) -> float:
        """The largest line-direction change the distortion makes over the image (deg)."""
        W, H = self.width_px, self.height_px
        return math.degrees(Distortion.for_image(W, H, k1=self.k1).max_angle_change_rad(W, H))

    @property
    def z(self) -> float:
        return self.k1 / self.sigma_k1 if self.sigma_k1 > 0 else 0.0

    @property
    def agrees(self) -> bool:
        """Do the wires bow as one radial distortion bows them (not one wire alone)?"""
        dof = self.n_wires - 1
        return dof >= 1 and self.chi2_wires <= chi2_quantile(1.0 - BOW_AGREE_P, dof)

    @property
    def found(self) -> bool:
        """A distortion the wires show: significant (:data:`BOW_Z`) and shared by them."""
        return abs(self.z) >= BOW_Z and self.agrees

    def distortion(self, width_px: int, height_px: int) -> Distortion:
        """The distortion found, with its variance as the covariance of its ``k1``."""
        cov = np.zeros((4, 4))
        cov[0, 0] = self.sigma_k1 ** 2
        return Distortion.for_image(width_px, height_px, k1=self.k1, covariance=cov)


def radial_from_centres(view, wires) -> WireBow | None:
    """The radial distortion ``k1`` that straightens ``view``'s wires, from their clean
    centres (:attr:`cadra.imaging.wires.line.WireFit.clean_px`, the ideal image's pixels).
    Removing ``k1`` moves a recorded centre ``q`` to ``q - k1 b(q)`` to first order (``b``
    the displacement per unit ``k1``, :meth:`Distortion.basis`), so each centre's distance
    from its wire's line changes by ``-k1 n.b``: each wire's ``k1`` is the least-squares
    coefficient of ``n.b`` in its centres' distances from their total-least-squares line,
    with the line's offset and turn (a constant and a slope along it) fitted beside it, and
    its sigma from the residuals' scatter. Their scatter about the weighted common ``k1``
    tells a distortion (every wire bowed as one) from a shock or a flow line along a wire. A
    wire through the image centre is not bowed and carries no weight. First order in
    ``k1``: a bow of pixels is measured again after it is removed (stage one's passes,
    :data:`cadra.imaging.distorted.BOW_PASSES`). A fraction of a millisecond a wire; None
    with fewer than two bowed wires."""
    W, H = view.width_px, view.height_px
    unit = Distortion.for_image(W, H)
    ks, ws = [], []
    for w in wires.wires:
        p = np.asarray(w.clean_px, float) if w.found else np.zeros((0, 2))
        if len(p) < 10:
            continue
        m, t, n, r = tls_line(p)
        g = unit.basis(p)[:, :, 0] @ n                 # n . b: the bow per unit k1
        A = np.column_stack([np.ones(len(p)), (p - m) @ t, g])
        coef, *_ = np.linalg.lstsq(A, r, rcond=None)
        dof = len(p) - 3
        s2 = float(np.sum((r - A @ coef) ** 2)) / dof
        cov = np.linalg.pinv(A.T @ A)
        var = s2 * cov[2, 2]
        if var > 0 and math.isfinite(var):
            ks.append(float(coef[2]))
            ws.append(1.0 / var)
    if len(ks) < 2:
        return None
    ks, ws = np.array(ks), np.array(ws)
    k1 = float(np.sum(ws * ks) / np.sum(ws))
    sigma = float(1.0 / math.sqrt(np.sum(ws)))
    chi2_w = float(np.sum(ws * (ks - k1) ** 2))
    return WireBow(k1, sigma, chi2_w, len(ks), W, H)
