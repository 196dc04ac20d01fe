"""A view's image distortion: the Brown–Conrady model of a lens or mirror train, in pixels.

An ideal image point ``(u, v)`` (the one the view's projection gives: straight wires, the
facility file's ``image_to_plane``) is recorded at ``D(u, v)``. With ``x = (u - u_c) / R``,
``y = (v - v_c) / R`` (``(u_c, v_c)`` the distortion centre, ``R`` a normalising radius, both
px) and ``r^2 = x^2 + y^2``::

    x_d = x (1 + k1 r^2 + k2 r^4) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4) + p1 (r^2 + 2 y^2) + 2 p2 x y
    D(u, v) = (u_c + R x_d, v_c + R y_d)

Brown (1966), in the form OpenCV's camera model uses (``k1, k2, p1, p2``; its ``k3`` is not
carried: a seed-002-size distortion needs no sixth-order term). The model is linear in its
four coefficients, so a calibration from points is a linear least squares
(:mod:`cadra.calibration.distortion`) and its covariance propagates exactly to the
displacement of any point (:meth:`Distortion.basis`).

Seed 002's biplanar tunnel calibrated its distortion "up to 0.3° in angle" from a grid. A
line's angle changes by the distortion Jacobian's skew part: for the radial term that is
``k1 r^2`` radians for a line at 45° to the radius (:meth:`Distortion.max_angle_change_rad`),
so ``k1 = 5.2e-3`` with ``R`` the image's half-diagonal is 0.3° at the corners.

The renderer draws a distorted view by mapping every outline's vertices through ``D`` (edges
first cut to :data:`DENSIFY_PX`); stage one removes it by resampling the recorded image at
``D`` of each ideal pixel (:meth:`Distortion.undistort_image`), so everything downstream sees
the ideal image. Pure numpy and OpenCV; depends on nothing else in CADRA.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from cadra.geometry import densify_polygon

__all__ = ["COEFFICIENTS", "DENSIFY_PX", "DistortedProjection", "Distortion", "distorted",
           "ideal_projection", "radial_undistorter"]

#: the model's coefficients, in the order of its covariance
COEFFICIENTS = ("k1", "k2", "p1", "p2")
#: an outline's edges are cut to at most this length (px) before they are distorted: a
#: distorted straight edge bows by ~ s^2 kappa / 8 between vertices s apart, kappa the image
#: of a line's curvature (~3e-5 /px for 0.3 deg at the corners of a 1600 x 1200 image):
#: 4e-6 px at 1 px
DENSIFY_PX = 1.0
#: Newton steps of the inverse map (each squares the error; 1e-12 px in four for any
#: distortion the facility file accepts)
_NEWTON_STEPS = 8


@dataclass(frozen=True, eq=False)
class Distortion:
    """Brown–Conrady distortion of one view's image (module doc).

    Attributes
    ----------
    k1, k2 : radial coefficients (dimensionless, ``r`` in units of ``radius_px``).
    p1, p2 : tangential (decentring) coefficients.
    centre_px : ``(u_c, v_c)``, px.
    radius_px : the normalising radius ``R``, px (the image's half-diagonal by convention).
    covariance : (4, 4) covariance of ``(k1, k2, p1, p2)`` from its calibration, or None
        (a distortion taken as exact).
    """

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    centre_px: tuple[float, float] = (0.0, 0.0)
    radius_px: float = 1.0
    covariance: np.ndarray | None = None

    def __post_init__(self):
        for k in COEFFICIENTS:
            object.__setattr__(self, k, float(getattr(self, k)))
        c = tuple(float(x) for x in self.centre_px)
        if len(c) != 2 or not all(map(math.isfinite, c)):
            raise ValueError(f"Distortion.centre_px must be (u, v) px, got {self.centre_px!r}")
        object.__setattr__(self, "centre_px", c)
        if not (math.isfinite(self.radius_px) and self.radius_px > 0):
            raise ValueError(f"Distortion.radius_px must be > 0, got {self.radius_px!r}")
        object.__setattr__(self, "radius_px", float(self.radius_px))
        if not all(math.isfinite(getattr(self, k)) for k in COEFFICIENTS):
            raise ValueError("Distortion coefficients must be finite")
        if self.covariance is not None:
            cov = np.array(self.covariance, dtype=float)
            if cov.shape != (4, 4) or not np.all(np.isfinite(cov)):
                raise ValueError("the covariance must be a finite 4 x 4 (k1, k2, p1, p2)")
            scale = float(np.max(np.abs(np.diag(cov))))
            if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-12 * scale):
                raise ValueError("the covariance is not symmetric")
            if np.min(np.linalg.eigvalsh(cov)) < -1e-12 * max(scale, 1e-300):
                raise ValueError("the covariance is not positive semi-definite")
            cov.setflags(write=False)
            object.__setattr__(self, "covariance", cov)

    @classmethod
    def for_image(cls, width_px: int, height_px: int, **coefficients) -> Distortion:
        """A distortion centred on a ``width_px`` x ``height_px`` image, ``R`` its
        half-diagonal (the convention of the facility file's defaults)."""
        return cls(centre_px=((width_px - 1) / 2.0, (height_px - 1) / 2.0),
                   radius_px=0.5 * math.hypot(width_px, height_px), **coefficients)

    @property
    def coefficients(self) -> np.ndarray:
        """``(k1, k2, p1, p2)``."""
        return np.array([getattr(self, k) for k in COEFFICIENTS])

    def with_coefficients(self, values, covariance=None) -> Distortion:
        """The same centre and radius with other coefficients (and their covariance)."""
        return Distortion(*(float(x) for x in values), centre_px=self.centre_px,
                          radius_px=self.radius_px, covariance=covariance)

    def _normalised(self, uv):
        uv = np.asarray(uv, dtype=float)
        return (uv[..., 0] - self.centre_px[0]) / self.radius_px, \
               (uv[..., 1] - self.centre_px[1]) / self.radius_px

    def basis(self, uv) -> np.ndarray:
        """``(..., 2, 4)``: the displacement ``D(uv) - uv`` (px) per unit of each coefficient
        (the model is linear in them)."""
        x, y = self._normalised(uv)
        r2 = x * x + y * y
        R = self.radius_px
        out = np.empty(np.shape(x) + (2, 4))
        out[..., 0, 0], out[..., 1, 0] = R * x * r2, R * y * r2
        out[..., 0, 1], out[..., 1, 1] = R * x * r2 * r2, R * y * r2 * r2
        out[..., 0, 2], out[..., 1, 2] = R * 2 * x * y, R * (r2 + 2 * y * y)
        out[..., 0, 3], out[..., 1, 3] = R * (r2 + 2 * x * x), R * 2 * x * y
        return out

    def distort(self, uv) -> np.ndarray:
        """Ideal image points ``(..., 2)`` px -> where the distorted image records them:
        ``uv + basis(uv) @ coefficients``, summed here without the ``(..., 2, 4)`` basis (a
        whole image's map is 2 million points)."""
        uv = np.asarray(uv, dtype=float)
        x, y = self._normalised(uv)
        k1, k2, p1, p2 = self.coefficients
        R = self.radius_px
        r2 = x * x + y * y
        radial = k1 * r2 + k2 * r2 * r2
        xy2 = 2.0 * x * y
        out = np.empty(np.shape(x) + (2,))
        out[..., 0] = uv[..., 0] + R * (x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x))
        out[..., 1] = uv[..., 1] + R * (y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2)
        return out

    def jacobian(self, uv) -> np.ndarray:
        """``(..., 2, 2)``: d D / d (u, v) at ideal points ``uv``."""
        x, y = self._normalised(uv)
        k1, k2, p1, p2 = self.coefficients
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        dr = 2 * k1 + 4 * k2 * r2          # d radial / d (r^2) times 2
        J = np.empty(np.shape(x) + (2, 2))
        J[..., 0, 0] = radial + x * dr * x + 2 * p1 * y + 6 * p2 * x
        J[..., 0, 1] = x * dr * y + 2 * p1 * x + 2 * p2 * y
        J[..., 1, 0] = y * dr * x + 2 * p1 * x + 2 * p2 * y
        J[..., 1, 1] = radial + y * dr * y + 6 * p1 * y + 2 * p2 * x
        return J

    def undistort(self, uv_recorded) -> np.ndarray:
        """Recorded image points ``(..., 2)`` px -> the ideal points (Newton on ``D``)."""
        target = np.asarray(uv_recorded, dtype=float)
        uv = target.copy()
        for _ in range(_NEWTON_STEPS):
            r = self.distort(uv) - target
            if not np.any(np.abs(r) > 1e-13 * self.radius_px):
                break
            uv = uv - np.linalg.solve(self.jacobian(uv), r[..., None])[..., 0]
        return uv

    def max_displacement_px(self, width_px: int, height_px: int, n: int = 65) -> float:
        """The largest ``|D(uv) - uv|`` over the image (an ``n`` x ``n`` grid, corners in)."""
        uv = _grid(width_px, height_px, n)
        return float(np.max(np.hypot(*np.moveaxis(self.distort(uv) - uv, -1, 0))))

    def max_angle_change_rad(self, width_px: int, height_px: int, n: int = 65) -> float:
        """The largest change of a short line's direction over the image: the largest
        half-difference of the Jacobian's rotations of two perpendicular directions, i.e.
        ``max |angle(J t) - angle(t)|`` over the directions t, on an ``n`` x ``n`` grid."""
        J = self.jacobian(_grid(width_px, height_px, n)).reshape(-1, 2, 2)
        th = np.linspace(0.0, math.pi, 181)
        t = np.stack([np.cos(th), np.sin(th)])
        Jt = J @ t
        d = np.arctan2(Jt[:, 1], Jt[:, 0]) - th
        return float(np.max(np.abs((d + math.pi) % (2 * math.pi) - math.pi)))

    def is_invertible_on(self, width_px: int, height_px: int, n: int = 65) -> bool:
        """Does ``D`` keep its orientation (Jacobian determinant > 0) over the image?"""
        J = self.jacobian(_grid(width_px, height_px, n))
        return bool(np.all(np.linalg.det(J) > 0.0))

    def undistort_image(self, image: np.ndarray) -> np.ndarray:
        """The ideal image of a recorded one: each ideal pixel sampled at ``D`` of its
        centre, by OpenCV's Lanczos (8 x 8) interpolation, float32; pixels whose ``D`` falls
        off the record take the nearest edge pixel's value."""
        H, W = image.shape
        return _remap(image, self.distort(_pixel_grid(W, H)))

    def to_dict(self) -> dict:
        """The facility file's table (``docs/facility_file.md``, "Distortion")."""
        out = {k: float(getattr(self, k)) for k in COEFFICIENTS}
        out["centre_px"] = [float(c) for c in self.centre_px]
        out["radius_px"] = float(self.radius_px)
        if self.covariance is not None:
            out["covariance"] = [[float(c) for c in row] for row in self.covariance]
        return out


def radial_undistorter(width_px: int, height_px: int):
    """``f(image, k1)``: :meth:`Distortion.undistort_image` of
    ``Distortion.for_image(width_px, height_px, k1=k1)``, for many ``k1`` on images of that
    size (a search over ``k1``): the pixel grid and its radial term are computed once, each
    call only scales and adds them (``D(uv) = uv + k1 R x r^2``, the map to within 1e-12 px
    of the distortion's own)."""
    d = Distortion.for_image(width_px, height_px, k1=1.0)
    uv = _pixel_grid(width_px, height_px)
    per_k1 = d.distort(uv) - uv

    def undistort(image: np.ndarray, k1: float) -> np.ndarray:
        if image.shape != (height_px, width_px):
            raise ValueError(f"an image of {image.shape[1]}x{image.shape[0]} px, not the "
                             f"{width_px}x{height_px} px this undistorter is for")
        return _remap(image, uv + float(k1) * per_k1)

    return undistort


def _remap(image: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``image`` sampled at the points ``m`` (H, W, 2) px, Lanczos, edge pixels replicated."""
    m = m.astype(np.float32)
    return cv2.remap(np.asarray(image, dtype=np.float32), m[..., 0], m[..., 1],
                     interpolation=cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_REPLICATE)


class DistortedProjection:
    """A view's projection as its distorted image records it: the ideal projection
    (``ideal``, any :class:`~cadra.optics.projection.Projection`) followed by the
    :class:`Distortion` ``distortion``. Image <-> plane maps and their Jacobians are chained
    through ``D``; everything else (the view plane, rays, magnification, outlines in the
    plane) is the ideal projection's. Stage one's silhouette fit measures the recorded image
    through it, so the image is never resampled (docs/stage1.md, "Distorted images")."""

    def __init__(self, ideal, distortion: Distortion):
        self.ideal = ideal
        self.distortion = distortion
        self.plane_basis = ideal.plane_basis

    def __getattr__(self, name):       # rays, magnification, outline: the ideal optics'
        return getattr(self.ideal, name)

    def from_plane(self, ab) -> np.ndarray:
        return self.distortion.distort(self.ideal.from_plane(ab))

    def to_plane(self, uv) -> np.ndarray:
        return self.ideal.to_plane(self.distortion.undistort(uv))

    def to_image(self, r_F) -> np.ndarray:
        return self.distortion.distort(self.ideal.to_image(r_F))

    def ray(self, uv):
        return self.ideal.ray(self.distortion.undistort(uv))

    def from_plane_jacobian(self, ab) -> np.ndarray:
        return self.distortion.jacobian(self.ideal.from_plane(ab)) @ \
            self.ideal.from_plane_jacobian(ab)

    def to_plane_jacobian(self, uv) -> np.ndarray:
        q = self.distortion.undistort(uv)
        return self.ideal.to_plane_jacobian(q) @ np.linalg.inv(self.distortion.jacobian(q))

    def to_image_jacobian(self, r_F) -> np.ndarray:
        return self.distortion.jacobian(self.ideal.to_image(r_F)) @ \
            self.ideal.to_image_jacobian(r_F)

    def polygon_from_plane(self, ab_poly) -> np.ndarray:
        """A closed view-plane polygon (N, 2) in the recorded image: its edges cut to
        :data:`DENSIFY_PX` in the ideal image first, so a straight flank comes out curved
        as the distortion draws it."""
        return self.distortion.distort(densify_polygon(self.ideal.from_plane(ab_poly), DENSIFY_PX))


def distorted(projection, distortion: Distortion | None):
    """``projection`` as the distorted image records it (:class:`DistortedProjection`);
    ``projection`` itself without a distortion."""
    return projection if distortion is None else DistortedProjection(projection, distortion)


def ideal_projection(projection):
    """The ideal projection under a :class:`DistortedProjection` (else ``projection``)."""
    return projection.ideal if isinstance(projection, DistortedProjection) else projection


def _grid(width_px: int, height_px: int, n: int) -> np.ndarray:
    u = np.linspace(-0.5, width_px - 0.5, n)
    v = np.linspace(-0.5, height_px - 0.5, n)
    return np.stack(np.meshgrid(u, v), axis=-1)


def _pixel_grid(width_px: int, height_px: int) -> np.ndarray:
    u, v = np.meshgrid(np.arange(width_px, dtype=float), np.arange(height_px, dtype=float))
    return np.stack([u, v], axis=-1)
