"""Shared plane geometry (cadra.geometry) against closed forms."""

import numpy as np
import pytest

from cadra.geometry import (
    affine_inverse,
    apply_affine,
    polygon_area_centroid,
    polygon_moments,
)


def test_rectangle_moments_are_the_closed_form():
    """A w x h rectangle far from the origin, both orientations: area w h, centroid its
    centre, central second moments w^2/12, h^2/12, 0."""
    w, h, c = 3.0, 1.25, np.array([1.0e4, -2.5e3])
    rect = c + np.array([[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]])
    for poly in (rect, rect[::-1]):
        area, cen, m2 = polygon_moments(poly)
        assert area == pytest.approx(w * h, rel=1e-14)
        np.testing.assert_allclose(cen, c, rtol=0, atol=1e-11)
        np.testing.assert_allclose(m2, [[w * w / 12, 0.0], [0.0, h * h / 12]], rtol=1e-12,
                                   atol=1e-12)
        a2, (cu, cv) = polygon_area_centroid(poly)
        assert a2 == area and (cu, cv) == (cen[0], cen[1])


def test_rotated_ellipse_polygon_moments():
    """A 4096-gon inscribed in an ellipse (a, b) turned by 30 deg: its moments against the
    ellipse's (pi a b, a^2/4, b^2/4 rotated), to the polygon's O(n^-2) chord error."""
    a, b, t = 40.0, 15.0, np.radians(30.0)
    s = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    poly = np.column_stack([a * np.cos(s), b * np.sin(s)]) @ R.T + [7.0, -3.0]
    area, cen, m2 = polygon_moments(poly)
    assert area == pytest.approx(np.pi * a * b, rel=1e-5)
    np.testing.assert_allclose(cen, [7.0, -3.0], atol=1e-10)
    np.testing.assert_allclose(m2, R @ np.diag([a * a / 4, b * b / 4]) @ R.T, rtol=1e-5,
                               atol=1e-3)


def test_degenerate_polygons_are_refused():
    with pytest.raises(ValueError, match="zero area"):
        polygon_moments(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]))
    with pytest.raises(ValueError, match="N >= 3"):
        polygon_area_centroid([[0.0, 0.0], [1.0, 0.0]])


def test_affine_inverse_round_trip():
    rng = np.random.default_rng(4)
    M = np.array([[1.27e-4, 3e-7, 4.5], [-2e-7, -1.27e-4, 0.07]])
    pts = rng.uniform(0, 1600, (20, 2))
    np.testing.assert_allclose(apply_affine(affine_inverse(M), apply_affine(M, pts)), pts,
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(affine_inverse(affine_inverse(M)), M, rtol=1e-12, atol=1e-15)
