"""A view's optics as a protocol: facility point <-> image point <-> facility ray.

Every consumer of a view's geometry (the renderer's scene building, the wire fit, the
silhouette fit, the two-view combination) talks to a :class:`Projection` and never to a 2x3
affine directly, so that a new optical model (the next one: a point-source, i.e. conical,
shadowgraph) is one new class implementing this protocol (docs/conventions.md, "Projections").

Frames and units (docs/conventions.md): facility points ``r_F`` in metres, shape ``(..., 3)``;
image points ``uv`` = (column, row) in pixels, origin at the centre of the top-left pixel,
shape ``(..., 2)``. Each view also has a **view plane**: the plane through the range axis
spanned by the two orthonormal facility directions ``plane_basis`` (2, 3) (top view: x, y;
side view: x, z), with coordinates ``ab = plane_basis @ r_F`` (metres). The view-plane point of
a facility point is where the ray through it meets the view plane; the image and the view
plane are related one-to-one (the film's map), which is what the measurement fits in.

:class:`ParallelProjection` (collimated light, the only implementation now): rays are
parallel to the view plane's normal ``plane_basis[0] x plane_basis[1]``; the view-plane point
of ``r_F`` is ``plane_basis @ r_F``, and the image follows by the inverse of the view's 2x3
``image_to_plane`` affine (docs/conventions.md, "Images and pixels"). Every map is affine, so
the Jacobians are constants.

:class:`PointSourceProjection` (a direct shadowgraph: a point-source spark throws the shadow
onto a film): the view plane is the film's plane, rays run from the spark S through the point,
and a point P lands at P' = S + λ (P − S), λ = n·(O − S) / n·(P − S) (O a point of the film, n
its normal; λ is the magnification, typically 1.0–1.3): a conical projection, whose Jacobians
depend on the point. The renderer draws through it (:meth:`PointSourceProjection.outline`, the
exact shadow of a body) and stage one measures through it (docs/stage1.md, "Point-source
stations").

:func:`intersect_rays` is the weighted least-squares intersection of several views' rays, the
combination step of stage one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from cadra.geometry import affine_inverse, apply_affine

__all__ = ["ParallelProjection", "PointSourceProjection", "Projection", "RayIntersection",
           "intersect_rays"]


@runtime_checkable
class Projection(Protocol):
    """What stage one and the renderer need to know about a view's optics.

    Shapes broadcast over leading axes: ``r_F (..., 3)``, ``uv (..., 2)``, ``ab (..., 2)``.
    Jacobians are ``(..., 2, 3)`` (facility -> image or plane) and ``(..., 2, 2)`` (image <->
    plane). A ray is ``(origin (..., 3), unit direction (..., 3))``; its sense is a convention
    of the implementation (a ray is used as a line).
    """

    plane_basis: np.ndarray   # (2, 3) orthonormal rows: the view plane's axes in F

    def to_image(self, r_F) -> np.ndarray:
        """Image points (px) of facility points (m)."""

    def to_image_jacobian(self, r_F) -> np.ndarray:
        """``d uv / d r_F`` at ``r_F``: (..., 2, 3), px per m."""

    def plane_point(self, r_F) -> np.ndarray:
        """View-plane point (m) of the ray through each facility point."""

    def plane_point_jacobian(self, r_F) -> np.ndarray:
        """``d ab / d r_F`` at ``r_F``: (..., 2, 3); zero along the ray."""

    def magnification(self, r_F) -> np.ndarray:
        """The view plane's scale over the facility's at each point (...,): 1 for parallel
        light, |P' − S| / |P − S| under a point source."""

    def ray(self, uv) -> tuple[np.ndarray, np.ndarray]:
        """The facility ray seen at image points: origin on the view plane, unit direction."""

    def plane_ray(self, ab) -> tuple[np.ndarray, np.ndarray]:
        """The facility ray through view-plane points: origin there, unit direction."""

    def to_plane(self, uv) -> np.ndarray:
        """View-plane points (m) of image points (px)."""

    def from_plane(self, ab) -> np.ndarray:
        """Image points (px) of view-plane points (m): the inverse of :meth:`to_plane`."""

    def to_plane_jacobian(self, uv) -> np.ndarray:
        """``d ab / d uv`` at ``uv``: (..., 2, 2), m per px."""

    def from_plane_jacobian(self, ab) -> np.ndarray:
        """``d uv / d ab`` at ``ab``: (..., 2, 2), px per m."""

    def outline(self, body, R_FB, r_ref_F, n_points: int = 4096) -> np.ndarray:
        """The exact outline (N, 2) of ``body`` at attitude ``R_FB`` and reference point
        ``r_ref_F`` (m) in the view plane (m), counter-clockwise: what the view's light
        draws on it (docs/bodies.md)."""


def _broadcast(mat: np.ndarray, pts) -> np.ndarray:
    """``mat`` (a constant Jacobian) repeated over the leading axes of the points ``pts``."""
    pts = np.asarray(pts, dtype=float)
    return np.broadcast_to(mat, pts.shape[:-1] + mat.shape).copy()


class _ImagePlane:
    """What every view shares: the image <-> view-plane affine (``image_to_plane`` and its
    inverse ``plane_to_image``), and the image and the ray through the view-plane point."""

    image_to_plane: np.ndarray
    plane_to_image: np.ndarray

    def to_image(self, r_F) -> np.ndarray:
        return self.from_plane(self.plane_point(r_F))

    def ray(self, uv) -> tuple[np.ndarray, np.ndarray]:
        return self.plane_ray(self.to_plane(uv))

    def to_plane(self, uv) -> np.ndarray:
        return apply_affine(self.image_to_plane, uv)

    def from_plane(self, ab) -> np.ndarray:
        return apply_affine(self.plane_to_image, ab)

    def to_plane_jacobian(self, uv) -> np.ndarray:
        return _broadcast(self.image_to_plane[:, :2], uv)

    def from_plane_jacobian(self, ab) -> np.ndarray:
        return _broadcast(self.plane_to_image[:, :2], ab)


@dataclass(frozen=True, eq=False)
class ParallelProjection(_ImagePlane):
    """Parallel (collimated) projection: see the module docstring.

    Parameters
    ----------
    plane_basis : (2, 3) orthonormal rows, the facility directions the view sees (the
        orthonormal view matrix of :func:`cadra.body.outline.silhouette`).
    image_to_plane : (2, 3) affine ``[a, b] = M @ [u, v, 1]`` (m), nominal or fitted to the
        image's wires.
    """

    plane_basis: np.ndarray
    image_to_plane: np.ndarray
    plane_to_image: np.ndarray = field(init=False, repr=False)
    direction: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        P = np.array(self.plane_basis, dtype=float)
        M = np.array(self.image_to_plane, dtype=float)
        if P.shape != (2, 3) or not np.allclose(P @ P.T, np.eye(2), atol=1e-12):
            raise ValueError("plane_basis: expected (2, 3) orthonormal rows")
        if M.shape != (2, 3) or not np.all(np.isfinite(M)) or np.linalg.det(M[:, :2]) == 0.0:
            raise ValueError("image_to_plane: expected a finite, invertible (2, 3) affine")
        Minv = affine_inverse(M)
        d = np.cross(P[0], P[1])
        for name, value in (("plane_basis", P), ("image_to_plane", M), ("plane_to_image", Minv),
                            ("direction", d)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def for_axes(cls, axes: tuple[int, int], image_to_plane) -> ParallelProjection:
        """The projection of a view seeing facility axes ``axes`` (top (0, 1), side (0, 2))."""
        P = np.zeros((2, 3))
        P[0, axes[0]] = 1.0
        P[1, axes[1]] = 1.0
        return cls(P, image_to_plane)

    @classmethod
    def from_view(cls, view, affine=None) -> ParallelProjection:
        """The projection of a :class:`cadra.facility.reference.View` with its nominal affine,
        or ``affine`` (e.g. the one fitted to the image's wires)."""
        return cls.for_axes(view.axes, view.image_to_plane if affine is None else affine)

    # facility -> image
    def plane_point(self, r_F) -> np.ndarray:
        return np.asarray(r_F, dtype=float) @ self.plane_basis.T

    def plane_point_jacobian(self, r_F) -> np.ndarray:
        return _broadcast(self.plane_basis, r_F)

    def magnification(self, r_F) -> np.ndarray:
        return np.ones(np.asarray(r_F, dtype=float).shape[:-1])

    def to_image_jacobian(self, r_F) -> np.ndarray:
        return _broadcast(self.plane_to_image[:, :2] @ self.plane_basis, r_F)

    # image -> facility
    def plane_ray(self, ab) -> tuple[np.ndarray, np.ndarray]:
        ab = np.asarray(ab, dtype=float)
        return ab @ self.plane_basis, _broadcast(self.direction, ab)

    def outline(self, body, R_FB, r_ref_F, n_points: int = 4096) -> np.ndarray:
        """The body's exact parallel silhouette (:func:`cadra.body.outline_polygon`)."""
        from cadra.body import outline_polygon

        return outline_polygon(body, R_FB, r_ref_F, self.plane_basis, n_points=n_points)


@dataclass(frozen=True, eq=False)
class PointSourceProjection(_ImagePlane):
    """Conical projection from a point source onto a film plane: see the module docstring.

    Parameters
    ----------
    spark_m : (3,) the spark's position in F, m.
    film_origin_m : (3,) the film plane's origin (its (a, b) = (0, 0)) in F, m.
    plane_basis : (2, 3) orthonormal rows, the film's in-plane axes in F (its a and b).
    image_to_plane : (2, 3) affine ``[a, b] = M @ [u, v, 1]`` (m, in the film plane): the
        scan's pixels on the film (a similarity or an affine for film shrinkage and tilt).
    """

    spark_m: np.ndarray
    film_origin_m: np.ndarray
    plane_basis: np.ndarray
    image_to_plane: np.ndarray
    plane_to_image: np.ndarray = field(init=False, repr=False)
    normal: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        S = np.array(self.spark_m, dtype=float).reshape(-1)
        O = np.array(self.film_origin_m, dtype=float).reshape(-1)
        P = np.array(self.plane_basis, dtype=float)
        M = np.array(self.image_to_plane, dtype=float)
        if S.shape != (3,) or O.shape != (3,) or not np.all(np.isfinite(np.r_[S, O])):
            raise ValueError("spark_m, film_origin_m: expected finite points (3,) in m")
        if P.shape != (2, 3) or not np.allclose(P @ P.T, np.eye(2), atol=1e-12):
            raise ValueError("plane_basis: expected (2, 3) orthonormal rows")
        if M.shape != (2, 3) or not np.all(np.isfinite(M)) or np.linalg.det(M[:, :2]) == 0.0:
            raise ValueError("image_to_plane: expected a finite, invertible (2, 3) affine")
        n = np.cross(P[0], P[1])
        if abs(n @ (O - S)) < 1e-6:
            raise ValueError("spark_m: the spark lies in the film's plane (it must face it)")
        Minv = affine_inverse(M)
        for name, value in (("spark_m", S), ("film_origin_m", O), ("plane_basis", P),
                            ("image_to_plane", M), ("plane_to_image", Minv), ("normal", n)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def magnification(self, r_F) -> np.ndarray:
        """λ = n·(O − S) / n·(P − S) of each facility point: the shadow's size over the
        point's (NaN for a point level with the spark, whose ray never meets the film)."""
        d = (np.asarray(r_F, dtype=float) - self.spark_m) @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(d != 0.0, (self.normal @ (self.film_origin_m - self.spark_m)) / d,
                            np.nan)

    # facility -> image
    def plane_point(self, r_F) -> np.ndarray:
        r = np.asarray(r_F, dtype=float)
        lam = self.magnification(r)[..., None]
        return (self.spark_m + lam * (r - self.spark_m) - self.film_origin_m) @ self.plane_basis.T

    def plane_point_jacobian(self, r_F) -> np.ndarray:
        """``A (λ E − λ (P − S) nᵀ / n·(P − S))``, A the film's axes: zero along the ray."""
        r = np.asarray(r_F, dtype=float)
        d = r - self.spark_m
        lam = self.magnification(r)
        dn = d @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            dP = lam[..., None, None] * (np.eye(3) - d[..., :, None] * self.normal
                                         / dn[..., None, None])
        return self.plane_basis @ dP

    def to_image_jacobian(self, r_F) -> np.ndarray:
        return self.plane_to_image[:, :2] @ self.plane_point_jacobian(r_F)

    # image -> facility
    def plane_ray(self, ab) -> tuple[np.ndarray, np.ndarray]:
        """The ray from the spark through each film point: origin on the film, unit
        direction from the spark toward it."""
        ab = np.asarray(ab, dtype=float)
        o = self.film_origin_m + ab @ self.plane_basis
        d = o - self.spark_m
        return o, d / np.linalg.norm(d, axis=-1, keepdims=True)

    def outline(self, body, R_FB, r_ref_F, n_points: int = 4096) -> np.ndarray:
        """The film's cut through the cone of rays from the spark tangent to the body
        (:func:`cadra.body.conical_outline_polygon`): exact, the fins of a finned body
        included."""
        from cadra.body import conical_outline_polygon

        return conical_outline_polygon(body, R_FB, r_ref_F, self.spark_m, self.plane_point,
                                       n_points=n_points)


@dataclass(frozen=True)
class RayIntersection:
    """Result of :func:`intersect_rays`: the point (m, F), its covariance, the chi-square of
    the views' view-plane residuals at it, and each ray's point closest to it (k, 3)."""

    r_F: np.ndarray
    cov: np.ndarray
    chi2: float
    closest: np.ndarray


def intersect_rays(projections: Sequence[Projection], plane_points, plane_covs,
                   max_iter: int = 10, tol_m: float = 1e-13) -> RayIntersection:
    """Weighted least-squares intersection of the rays of several views.

    View k measured the view-plane point ``plane_points[k]`` (2,) with covariance
    ``plane_covs[k]`` (2, 2); the point ``r_F`` minimizing
    ``sum_k (plane_point_k(r_F) - ab_k)^T C_k^-1 (plane_point_k(r_F) - ab_k)`` is found by
    Gauss-Newton from the linear intersection of the rays (each ray weighted across itself by
    ``J_k^T C_k^-1 J_k``, ``J_k`` its view's :meth:`Projection.plane_point_jacobian`).
    For parallel projections the problem is linear and the first solve is the answer: two
    orthogonal views give the inverse-variance mean of the coordinate both see and each
    view's own measurement of the other two.
    """
    ab = [np.asarray(p, dtype=float).reshape(2) for p in plane_points]
    W = [np.linalg.inv(np.asarray(c, dtype=float).reshape(2, 2)) for c in plane_covs]
    rays = [proj.plane_ray(a) for proj, a in zip(projections, ab, strict=True)]
    # the rays' linear intersection: each ray weighted across itself at its own origin
    N, g = np.zeros((3, 3)), np.zeros(3)
    for proj, w, (o, _) in zip(projections, W, rays, strict=True):
        J = proj.plane_point_jacobian(o)
        N += J.T @ w @ J
        g += J.T @ w @ (J @ o)
    r = np.linalg.solve(N, g)
    for _ in range(max_iter):   # Gauss-Newton (no step for affine projections)
        N, g = np.zeros((3, 3)), np.zeros(3)
        for proj, a, w in zip(projections, ab, W, strict=True):
            J = proj.plane_point_jacobian(r)
            N += J.T @ w @ J
            g += J.T @ w @ (a - proj.plane_point(r))
        step = np.linalg.solve(N, g)
        if np.max(np.abs(step)) < tol_m:
            break
        r = r + step
    chi2 = 0.0
    closest = []
    for proj, a, w, (o, d) in zip(projections, ab, W, rays, strict=True):
        e = proj.plane_point(r) - a
        chi2 += float(e @ w @ e)
        closest.append(o + ((r - o) @ d) * d)
    return RayIntersection(r_F=r, cov=np.linalg.inv(N), chi2=chi2, closest=np.array(closest))
