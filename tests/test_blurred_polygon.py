"""The blurred-edge model of a whole polygon, corners included
(cadra.imaging.silhouette.polygon.blurred_polygon), against independent truths: the Gaussian's
mass over the polygon integrated numerically (shapely's point-in-polygon on a fine grid), the
straight edge's Phi(-d/s), and the Laplacian of the blurred indicator by finite differences."""

import math

import numpy as np
import pytest
import shapely
from scipy.special import ndtr

from cadra.imaging.silhouette.edge_model import PHI1
from cadra.imaging.silhouette.polygon import blurred_polygon

#: a non-convex quadrilateral with a sharp tip (11 deg), a reflex vertex on a pixel centre
#: (24, 20) and edges at odd angles to the grid
POLY = np.array([[10.3, 12.1], [40.7, 15.2], [25.2, 33.9], [24.0, 20.0]])
SHAPE = (48, 56)


def gaussian_mass(poly, x, y, s, n=301, reach=6.0):
    """The mass of an isotropic Gaussian (sigma s) at (x, y) inside ``poly``: the density
    summed on a fine grid (midpoint rule, 0.04 px cells) with an exact point-in-polygon test."""
    P = shapely.Polygon(poly)
    xs = np.linspace(-reach * s, reach * s, n)
    X, Y = np.meshgrid(xs, xs)
    w = np.exp(-(X ** 2 + Y ** 2) / (2 * s * s))
    w /= w.sum()
    return float((w * shapely.contains_xy(P, x + X, y + Y)).sum())


@pytest.mark.parametrize("poly", [POLY, POLY[::-1]], ids=["ccw", "cw"])
def test_dark_fraction_is_the_gaussian_mass_inside_at_corners_and_edges(poly):
    """At the sharp tip, the reflex vertex (a pixel centre on the vertex itself), beside the
    edges and deep inside/outside, either orientation: within the numerical integral's own
    error (~3e-4)."""
    s = 0.8
    g, _ = blurred_polygon(poly, SHAPE, s, 0.0, 1.2)
    for r, c in [(12, 11), (13, 12), (12, 10), (20, 24), (19, 24), (14, 25), (30, 25),
                 (25, 25), (5, 5), (20, 30)]:
        assert g[r, c] == pytest.approx(gaussian_mass(poly, c, r, s), abs=1e-3), (r, c)


def test_beside_a_long_straight_edge_it_is_the_edge_model():
    """Far from the corners of a large square, g is Phi(-d/s) (d + outside) to 1e-12, and the
    fringe is the edge model's profile -z_f phi(z_f) / phi(1), z_f = -d / (ratio s)."""
    sq = np.array([[10.25, 10.4], [90.25, 10.4], [90.25, 90.4], [10.25, 90.4]])
    s, a, ratio = 0.75, 0.1, 1.2
    g, h = blurred_polygon(sq, (100, 100), s, a, ratio)
    row = 50
    d = 10.25 - np.arange(5, 16)                 # distance outside the left edge, px
    assert np.allclose(g[row, 5:16], ndtr(-d / s), atol=1e-12)
    zf = -d / (ratio * s)
    prof = -zf * np.exp(-0.5 * zf * zf) / math.sqrt(2 * math.pi) / PHI1
    assert np.allclose(h[row, 5:16], a * prof, atol=1e-12)
    assert g[50, 50] == 1.0 and g[2, 2] == 0.0 and h[50, 50] == 0.0


def test_fringe_is_the_laplacian_of_the_blurred_indicator():
    """h / a is the Laplacian of the indicator blurred at s_f, times s_f^2 / phi(1): checked
    by a five-point finite difference of the exact g at that width, at the corners too (the
    reflex vertex on a pixel centre included)."""
    s, ratio = 0.8, 1.2
    sf = ratio * s
    _, h = blurred_polygon(POLY, SHAPE, s, 1.0, ratio)
    step = 0.05
    for r, c in [(12, 11), (13, 12), (20, 24), (14, 25), (16, 38)]:
        def gm(dx, dy, r=r, c=c):
            return blurred_polygon(POLY - np.array([dx, dy]), SHAPE, sf, 0.0, 1.0)[0][r, c]
        lap = (gm(step, 0) + gm(-step, 0) + gm(0, step) + gm(0, -step) - 4 * gm(0, 0)) / step ** 2
        assert h[r, c] == pytest.approx(lap * sf ** 2 / PHI1, abs=2e-3), (r, c)


def test_per_edge_widths_follow_the_normals():
    """A width given as a function of the outward normals: a horizontal edge's pixels see its
    own width, a vertical edge's theirs."""
    sq = np.array([[10.0, 10.5], [60.0, 10.5], [60.0, 60.5], [10.0, 60.5]])
    g, _ = blurred_polygon(sq, (70, 70), lambda n: np.where(np.abs(n[:, 0]) > 0.5, 0.5, 1.0),
                           0.0, 1.2)
    assert g[11, 35] == pytest.approx(ndtr(0.5 / 1.0), abs=1e-12)     # top edge, s = 1
    assert g[35, 11] == pytest.approx(ndtr(1.0 / 0.5), abs=1e-12)     # left edge, s = 0.5
