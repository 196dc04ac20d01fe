"""The optics protocol (cadra.optics.projection) against exact geometry.

Round trips: facility -> image -> ray contains the point; image -> plane -> image; the
Jacobians against central differences; the rays' least-squares intersection against the
inverse-variance mean it must equal for two orthogonal parallel views.
"""

import numpy as np
import pytest

from cadra.facility.reference import VIEW_AXES, nominal_image_to_plane
from cadra.optics.projection import ParallelProjection, Projection, intersect_rays
from cadra.synthetic.simulate import FilmPlacement, film_affine

RNG = np.random.default_rng(20261124)


def _projections():
    """Top and side views at a station 4.6 m downrange with a perturbed film placement."""
    out = []
    for name in ("top", "side"):
        M0 = nominal_image_to_plane(4.572, 1.27e-4, 1600, 1200)
        M = film_affine(M0, FilmPlacement(shift_px=4.0, rotation_deg=0.3, scale_rel=2e-3), RNG,
                        1600, 1200)
        out.append(ParallelProjection.for_axes(VIEW_AXES[name], M))
    return out


def _points(n=50):
    return np.column_stack([RNG.uniform(4.5, 4.65, n), RNG.normal(0, 0.03, n),
                            RNG.normal(0, 0.03, n)])


@pytest.mark.parametrize("proj", _projections(), ids=["top", "side"])
def test_ray_through_the_image_point_contains_the_facility_point(proj):
    assert isinstance(proj, Projection)
    r = _points()
    o, d = proj.ray(proj.to_image(r))
    assert np.allclose(np.linalg.norm(d, axis=-1), 1.0, rtol=0, atol=1e-15)
    # distance of r from its ray: |(r - o) x d|
    dist = np.linalg.norm(np.cross(r - o, d), axis=-1)
    assert dist.max() < 1e-15 * 10
    # the ray is the line of sight: perpendicular to the view plane, origin on it
    assert np.allclose(d @ proj.plane_basis.T, 0.0, atol=1e-15)
    assert np.allclose(proj.plane_point(o), proj.plane_point(r), rtol=0, atol=1e-15)


@pytest.mark.parametrize("proj", _projections(), ids=["top", "side"])
def test_plane_round_trip_and_view_plane_point(proj):
    uv = RNG.uniform(0, 1600, (40, 2))
    assert np.allclose(proj.from_plane(proj.to_plane(uv)), uv, rtol=0, atol=1e-9)
    r = _points()
    # parallel view: the view-plane point is the two coordinates the view sees
    axes = list(np.flatnonzero(proj.plane_basis.any(axis=0)))
    assert np.array_equal(proj.plane_point(r), r[:, axes])


@pytest.mark.parametrize("proj", _projections(), ids=["top", "side"])
def test_jacobians_match_central_differences(proj):
    r = _points(5)
    J = proj.to_image_jacobian(r)
    Jp = proj.plane_point_jacobian(r)
    h = 1e-4   # m; every map is affine, so differences are exact to rounding
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        fd = (proj.to_image(r + e) - proj.to_image(r - e)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-9, atol=1e-6)
        fdp = (proj.plane_point(r + e) - proj.plane_point(r - e)) / (2 * h)
        # (rounding: 4.6 m carries ~1e-15 m, over 2h = 2e-4 m)
        np.testing.assert_allclose(Jp[:, :, k], fdp, rtol=0, atol=1e-10)
    uv = proj.to_image(r)
    Ju = proj.to_plane_jacobian(uv)
    Jab = proj.from_plane_jacobian(proj.plane_point(r))
    for k in range(2):
        e = np.zeros(2)
        e[k] = 0.5
        fd = (proj.to_plane(uv + e) - proj.to_plane(uv - e)) / 1.0
        np.testing.assert_allclose(Ju[:, :, k], fd, rtol=1e-9, atol=1e-14)  # 4.6 m rounding
    np.testing.assert_allclose(np.einsum("nij,njk->nik", Ju, Jab),
                               np.broadcast_to(np.eye(2), (5, 2, 2)), atol=1e-12)
    # no image motion along the line of sight
    assert np.allclose(J @ proj.direction, 0.0, atol=1e-9)


def test_ray_intersection_of_orthogonal_parallel_views_is_the_weighted_mean():
    top, side = _projections()
    for _ in range(200):
        r = _points(1)[0]
        s = RNG.uniform(1e-6, 1e-5, 4)
        a_top = r[0] + RNG.normal(0, s[0])
        a_side = r[0] + RNG.normal(0, s[2])
        hit = intersect_rays([top, side], [(a_top, r[1]), (a_side, r[2])],
                             [np.diag([s[0]**2, s[1]**2]), np.diag([s[2]**2, s[3]**2])])
        w_t, w_s = 1 / s[0]**2, 1 / s[2]**2
        x = (w_t * a_top + w_s * a_side) / (w_t + w_s)
        assert hit.r_F[0] == pytest.approx(x, rel=1e-15, abs=0)
        assert tuple(hit.r_F[1:]) == pytest.approx((r[1], r[2]), rel=1e-15, abs=0)
        np.testing.assert_allclose(np.sqrt(np.diag(hit.cov)),
                                   [1 / np.sqrt(w_t + w_s), s[1], s[3]], rtol=1e-14)
        dx = a_top - a_side
        assert hit.closest[0, 0] - hit.closest[1, 0] == dx
        assert hit.chi2 == pytest.approx(dx**2 / (s[0]**2 + s[2]**2), rel=1e-9)


def test_ray_intersection_of_oblique_views_recovers_the_point():
    """Two views whose planes are not the facility's coordinate planes (a tilted side view):
    exact data -> the point itself, chi-square 0."""
    c, s = np.cos(0.3), np.sin(0.3)
    top = ParallelProjection(np.array([[1.0, 0, 0], [0, 1.0, 0]]), np.eye(2, 3))
    tilted = ParallelProjection(np.array([[1.0, 0, 0], [0, -s, c]]), np.eye(2, 3))
    r = np.array([1.2, 0.02, -0.01])
    hit = intersect_rays([top, tilted], [top.plane_point(r), tilted.plane_point(r)],
                         [np.eye(2) * 1e-12, np.eye(2) * 4e-12])
    np.testing.assert_allclose(hit.r_F, r, rtol=0, atol=1e-15)
    assert hit.chi2 < 1e-18


def test_view_optics_equals_the_view_maps():
    """View.optics() is the view's own plane/pixel maps (the projection is the one source)."""
    from cadra.io.facility_file import load_facility

    view = load_facility("hffaf").view(3, "side")
    proj = view.optics()
    r = _points(10)
    np.testing.assert_array_equal(proj.to_image(r),
                                  view.plane_to_pixels(view.project_points(r)))
    uv = RNG.uniform(0, 1200, (10, 2))
    np.testing.assert_array_equal(proj.to_plane(uv), view.pixels_to_plane(uv))
