"""The point-source (conical) projection of a direct shadowgraph (cadra.optics), against
geometry computed independently here.

- A point's film point is the intersection of the line from the spark through it with the
  film's plane, solved as a 3x3 linear system (S + t (P - S) = O + a e_a + b e_b): 1e-12 m.
- The ray back from the point's image passes through the point and the spark.
- The magnification is |P' - S| / |P - S|, and the BRL-like layout gives 1.0-1.3.
- The Jacobians equal central differences; the facility Jacobian is zero along the ray.
- A spark far away is the parallel projection.
- Two views' rays intersect at the point (the protocol's :func:`intersect_rays`, which is
  nonlinear here).
- A spark in the film's plane, or film axes that are not orthonormal, are refused.
"""

import numpy as np
import pytest

from cadra.optics import ParallelProjection, PointSourceProjection, intersect_rays

# a BRL-like station's top view (m): the spark 2.5 m above the line of flight, the film
# 0.6 m below it (magnification ~1.24), the film's axes x and y, scanned at 0.1 mm/px
SCALE = 1e-4
IMAGE = np.array([[SCALE, 0.0, -0.08], [0.0, -SCALE, 0.06]])


def top_view(spark_z=2.5, film_z=-0.6):
    return PointSourceProjection(spark_m=[0.05, -0.02, spark_z], film_origin_m=[0.0, 0.0, film_z],
                                 plane_basis=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                 image_to_plane=IMAGE)


def side_view():
    # the spark 2.5 m to port, the film 0.6 m to starboard, film axes x and z
    return PointSourceProjection(spark_m=[-0.03, 2.5, 0.01], film_origin_m=[0.0, -0.6, 0.0],
                                 plane_basis=[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
                                 image_to_plane=IMAGE)


def points(n=50, seed=0):
    return np.random.default_rng(seed).uniform([-0.1, -0.1, -0.1], [0.1, 0.1, 0.1], (n, 3))


def test_the_film_point_is_the_rays_intersection_with_the_film():
    proj = top_view()
    P = points()
    ab = proj.plane_point(P)
    S, O, (ea, eb) = proj.spark_m, proj.film_origin_m, proj.plane_basis
    for p, got in zip(P, ab, strict=True):
        t, a, b = np.linalg.solve(np.column_stack([p - S, -ea, -eb]), O - S)
        np.testing.assert_allclose(got, [a, b], atol=1e-12)
        assert t == pytest.approx(proj.magnification(p), rel=1e-12)
    lam = proj.magnification(P)
    film = O + ab @ proj.plane_basis
    np.testing.assert_allclose(lam, np.linalg.norm(film - S, axis=1)
                               / np.linalg.norm(P - S, axis=1), rtol=1e-12)
    assert 1.15 < lam.min() and lam.max() < 1.35


def test_the_ray_from_an_image_point_passes_through_the_point_and_the_spark():
    proj = top_view()
    P = points()
    o, d = proj.ray(proj.to_image(P))
    for p, oi, di in zip(P, o, d, strict=True):
        for q in (p, proj.spark_m):
            off = (q - oi) - ((q - oi) @ di) * di
            assert np.linalg.norm(off) < 1e-12
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-14)


def test_the_jacobians_are_the_derivatives():
    proj = top_view()
    P = points(5, seed=1)
    J = proj.to_image_jacobian(P)
    Jab = proj.plane_point_jacobian(P)
    h = 1e-6
    for k, p in enumerate(P):
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            fd = (proj.to_image(p + e) - proj.to_image(p - e)) / (2 * h)
            np.testing.assert_allclose(J[k, :, j], fd, rtol=1e-7, atol=1e-6)
        # moving the point along its ray moves nothing on the film
        along = (p - proj.spark_m) / np.linalg.norm(p - proj.spark_m)
        np.testing.assert_allclose(Jab[k] @ along, 0.0, atol=1e-12)


def test_a_spark_far_away_is_the_parallel_projection():
    """At 1e7 m the perspective's share is of order |P| z / 1e7 ~ 1e-9 m, 1e-5 px."""
    far = top_view(spark_z=1e7, film_z=0.0)
    par = ParallelProjection(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), IMAGE)
    P = points()
    np.testing.assert_allclose(far.to_image(P), par.to_image(P), atol=5e-5)
    assert np.abs(far.to_image(P) - par.to_image(P)).max() > 1e-7     # and not identical


def test_two_views_rays_meet_at_the_point():
    top, side = top_view(), side_view()
    cov = np.eye(2) * (1e-5) ** 2
    for p in points(10, seed=2):
        r = intersect_rays([top, side], [top.plane_point(p), side.plane_point(p)], [cov, cov])
        np.testing.assert_allclose(r.r_F, p, atol=1e-10)
        assert r.chi2 < 1e-12


@pytest.mark.parametrize("kwargs, match", [
    ({"spark_m": [0.0, 0.0, -0.6]}, "spark lies in the film"),
    ({"plane_basis": [[1.0, 0.0, 0.0], [0.5, 1.0, 0.0]]}, "orthonormal"),
    ({"image_to_plane": np.zeros((2, 3))}, "invertible"),
])
def test_a_geometry_that_cannot_be_is_refused(kwargs, match):
    base = {"spark_m": [0.0, 0.0, 2.5], "film_origin_m": [0.0, 0.0, -0.6],
            "plane_basis": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], "image_to_plane": IMAGE}
    with pytest.raises(ValueError, match=match):
        PointSourceProjection(**{**base, **kwargs})
