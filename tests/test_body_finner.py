"""cadra.body.finner: the Basic Finner (seed 001), its roll-dependent outline and mass properties.

Truth used here, independent of the code under test:
* the side- and top-view outline of a finned cone-cylinder with its axis in the view plane,
  written out by hand: the cone's triangle a * L_n, the cylinder's rectangle d * (L - L_n),
  and per side the fins' strip chord * (h(gamma) - a) beyond the cylinder, where a fin at
  angle psi to the view's cross axis reaches h = (a + b)|cos psi| + (t/2)|sin psi| and the
  farthest of the four sets the edge: h(gamma) = (a + b) max(|cos|, |sin|) + (t/2) min(...);
* a ray cast per view-plane point against the 3-D solid (the cone-cylinder by a vectorised
  golden-section minimum of the convex rho - R(s) along the ray, the fin boxes by the slab
  test), not through any projection;
* hand formulas of a cone, a cylinder and a box (m (l_j^2 + l_k^2) / 12) and the
  parallel-axis theorem, in scalar form, for the mass properties.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
import shapely
from scipy.spatial.transform import Rotation

from cadra.body import (
    BASIC_FINNER_CAL,
    KINDS,
    FinnedBody,
    body_from_spec,
    cone,
    finner,
    finner_mass_properties,
    finner_preset,
    finner_silhouette,
    finner_silhouette_area_m2,
    outline_polygon,
    silhouette,
)
from cadra.body.finner import box_inertia, fin_corners, fin_frames
from cadra.conventions import FLIP, quat_from_axis_roll, quat_to_matrix
from cadra.geometry import polygon_moments

SIDE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
TOP = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
FB = finner_preset()
D = FB.diameter_m
A, B, C, T = 0.5 * D, FB.fin_span_m, FB.fin_chord_m, FB.fin_thickness_m
L = FB.length_m
L_NOSE = A / np.tan(np.radians(10.0))


def attitude(axis=(1.0, 0.0, 0.0), roll_deg=0.0) -> np.ndarray:
    """R_FB for a nose axis in F and an aircraft roll (conventions.quat_from_axis_roll)."""
    return FLIP @ quat_to_matrix(quat_from_axis_roll(np.asarray(axis, float),
                                                     np.radians(roll_deg)))


def fin_reach(gamma_rad: float) -> float:
    """Farthest reach of the four fins across the axis in a side or top view at roll gamma."""
    c, s = abs(np.cos(gamma_rad)), abs(np.sin(gamma_rad))
    return (A + B) * max(c, s) + 0.5 * T * min(c, s)


def hand_area(gamma_rad: float) -> float:
    return A * L_NOSE + D * (L - L_NOSE) + 2.0 * C * (fin_reach(gamma_rad) - A)


def shoelace(poly: np.ndarray) -> float:
    x, y = poly.T
    return 0.5 * float(np.sum(x * np.roll(y, -1) - y * np.roll(x, -1)))


# --------------------------------------------------------------------------- geometry


def test_preset_dimensions_in_calibres():
    assert BASIC_FINNER_CAL == {"length": 10.0, "half_angle_deg": 10.0, "fin_chord": 1.0,
                                "fin_span": 1.0, "fin_thickness": 0.08}
    assert D == pytest.approx(0.030) and L == pytest.approx(10 * D)
    assert (C, B, T) == pytest.approx((D, D, 0.08 * D))
    assert FB.base_s_m == 0.0 and FB.nose_s_m == pytest.approx(L)
    assert FB.fin_tip_radius_m == pytest.approx(1.5 * D)          # 3 d tip to tip
    s, r = FB.body.s_m, FB.body.r_m
    assert np.interp(L - L_NOSE, s, r) == pytest.approx(A, abs=1e-12)  # shoulder
    mid = (s > 0.01 * L) & (s < L - L_NOSE - 0.01 * L)
    assert np.allclose(r[mid], A)                                  # the cylinder
    cone_part = (s > L - L_NOSE + 1e-6) & (s < L)
    assert np.allclose(r[cone_part], (L - s[cone_part]) * np.tan(np.radians(10.0)),
                       atol=1e-14)
    assert 2.8355 < L_NOSE / D < 2.8357


@pytest.mark.parametrize("view", ["side", "top"])
@pytest.mark.parametrize("roll_deg", [0.0, 45.0, 15.0, 30.0, 60.0, 137.0, -20.0])
def test_outline_at_zero_incidence_matches_hand_area_and_span(view, roll_deg):
    """Axis in the view plane: the outline is a triangle, a rectangle and two fin strips."""
    P = SIDE if view == "side" else TOP
    R = attitude(roll_deg=roll_deg)
    g = np.radians(roll_deg)
    poly = finner_silhouette(FB, R, np.zeros(3), P)
    assert shoelace(poly) == pytest.approx(hand_area(g), rel=1e-13)
    assert finner_silhouette_area_m2(FB, R, P) == pytest.approx(hand_area(g), rel=1e-13)
    # the span seen across the axis: 2 h(gamma), (a + b) cos gamma + (t/2) sin gamma at
    # |gamma| <= 45 deg, on both sides
    assert poly[:, 1].max() == pytest.approx(fin_reach(g), rel=1e-14)
    assert poly[:, 1].min() == pytest.approx(-fin_reach(g), rel=1e-14)
    assert poly[:, 0].min() == pytest.approx(0.0, abs=1e-15)
    assert poly[:, 0].max() == pytest.approx(L, rel=1e-14)


@pytest.mark.parametrize("roll_deg", [0.0, 20.0, 45.0])
def test_end_on_view_is_a_circle_and_a_cross(roll_deg):
    """Looking along the axis: the base disc plus four t-wide fin strips from the circle to
    r = a + b, i.e. pi a^2 + 4 [t (a + b) - the strip |w| <= t/2 of the half disc], whatever
    the roll; the strips' edges run along the fin directions."""
    end = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    w = 0.5 * T
    strip_in_disc = w * np.sqrt(A**2 - w**2) + A**2 * np.arcsin(w / A)
    exact = np.pi * A**2 + 4 * (T * (A + B) - strip_in_disc)
    area = finner_silhouette_area_m2(FB, attitude(roll_deg=roll_deg), end)
    # the disc's polygon is inscribed: short by ~ (2 pi / n)^2 / 6 = 4e-7 at n = 4096 vertices
    assert exact * (1 - 1e-6) < area < exact
    poly = finner_silhouette(FB, attitude(roll_deg=roll_deg), np.zeros(3), end)
    assert np.hypot(*poly.T).max() == pytest.approx(np.hypot(A + B, w), rel=1e-14)


def test_roll_0_and_45_figures():
    """The two cases written out: roll 0 shows two fins at full span (+ 2 c b), roll 45 all
    four at cos 45 (the near and far fins of each side coincide in projection)."""
    body_area = A * L_NOSE + D * (L - L_NOSE)                      # 8.5822 d^2
    a0 = finner_silhouette_area_m2(FB, attitude(roll_deg=0.0), SIDE)
    a45 = finner_silhouette_area_m2(FB, attitude(roll_deg=45.0), SIDE)
    assert a0 == pytest.approx(body_area + 2 * C * B, rel=1e-13)
    assert a45 == pytest.approx(body_area + 2 * C * ((A + B + 0.5 * T) / np.sqrt(2) - A),
                                rel=1e-13)
    assert a0 / D**2 == pytest.approx(10.58218, abs=1e-5)
    assert a45 / D**2 == pytest.approx(9.76007, abs=1e-5)


def test_span_follows_cos_and_sin_in_two_orthogonal_views():
    """Side and top views see the fin span change with roll, each as the larger of |cos|,
    |sin| (the cruciform): equal at 45 deg, full span at 0 and 90."""
    for roll_deg in np.linspace(0.0, 90.0, 19):
        R = attitude(roll_deg=roll_deg)
        side = finner_silhouette(FB, R, np.zeros(3), SIDE)
        top = finner_silhouette(FB, R, np.zeros(3), TOP)
        h = fin_reach(np.radians(roll_deg))
        assert np.ptp(side[:, 1]) == pytest.approx(2 * h, rel=1e-14)
        assert np.ptp(top[:, 1]) == pytest.approx(2 * h, rel=1e-14)


def _random_attitudes(n, seed):
    rng = np.random.default_rng(seed)
    return [Rotation.random(random_state=rng).as_matrix() for _ in range(n)]


@pytest.mark.parametrize("R", _random_attitudes(4, 20))
def test_quarter_roll_gives_the_same_outline(R):
    """Cruciform symmetry: rolling by 90 deg about the nose axis leaves the outline."""
    quarter = Rotation.from_euler("x", 90.0, degrees=True).as_matrix()
    r0 = np.array([1.0, -0.2, 0.3])
    for P in (SIDE, TOP):
        p0 = shapely.Polygon(finner_silhouette(FB, R, r0, P))
        p90 = shapely.Polygon(finner_silhouette(FB, R @ quarter, r0, P))
        assert p0.symmetric_difference(p90).area < 1e-12 * p0.area
        p30 = shapely.Polygon(finner_silhouette(
            FB, R @ Rotation.from_euler("x", 30.0, degrees=True).as_matrix(), r0, P))
        assert p0.symmetric_difference(p30).area > 1e-3 * p0.area   # but roll does matter


@pytest.mark.parametrize("R", _random_attitudes(3, 21) + [attitude((1.0, 0.3, -0.2), 25.0)])
def test_outline_is_a_simple_ccw_polygon_containing_the_axis(R):
    r0 = np.array([0.5, 0.1, -0.05])
    for P in (SIDE, TOP):
        poly = finner_silhouette(FB, R, r0, P)
        shape = shapely.Polygon(poly)
        assert shape.is_valid and shape.exterior.is_simple and not shape.interiors
        assert not np.array_equal(poly[0], poly[-1])
        area, _, _ = polygon_moments(poly)
        assert shoelace(poly) > 0 and area == pytest.approx(shape.area)
        axis = r0 + np.linspace(0.0, L, 41)[:, None] * R[:, 0]
        assert shape.buffer(1e-12).contains(shapely.MultiPoint(axis @ P.T))
        # the union holds the body's own outline and every fin's projection
        body = shapely.Polygon(silhouette(FB.body, R, r0, P))
        assert body.difference(shape).area < 1e-15
        fins = [shapely.Polygon(c @ P.T).convex_hull for c in fin_corners(FB, R, r0)]
        assert all(f.difference(shape).area < 1e-15 for f in fins)
        assert shape.area <= body.area + sum(f.area for f in fins) + 1e-15


# ----------------------------------------------------------------------------- ray cast


def _inside_cone_cylinder(v0, m):
    """True where the line v0 + lam m (body axes, from the reference point, |m| = 1) meets the
    solid 0 <= s <= L, rho <= R(s). f = rho - R(clip(s)) + K dist(s, [0, L]) is convex in lam
    (rho is; -R is on [0, L]; K = 1e6 beats R's slopes outside), and the line meets the solid
    where its minimum is <= 0 (to a / K = 15 nm in s): golden-section search, vectorised."""
    big = np.linalg.norm(v0, axis=1) + 2.0 * L

    def f(lam):
        p = v0 + lam[:, None] * m
        rho = np.hypot(p[:, 1], p[:, 2])
        s = np.clip(p[:, 0], 0.0, L)
        radius = np.minimum(A, (L - s) * np.tan(np.radians(10.0)))
        return rho - radius + 1e6 * np.abs(p[:, 0] - s)

    g = 0.5 * (np.sqrt(5.0) - 1.0)
    a, b = -big, big.copy()
    for _ in range(120):
        c1, c2 = b - g * (b - a), a + g * (b - a)
        left = f(c1) < f(c2)
        b = np.where(left, c2, b)
        a = np.where(left, a, c1)
    return f(0.5 * (a + b)) <= 0.0


def _inside_boxes(v0, m):
    """True where the line meets a fin box (from the axis): slab test per fin."""
    hit = np.zeros(len(v0), bool)
    lo_b = np.array([0.0, 0.0, -0.5 * T])
    hi_b = np.array([C, A + B, 0.5 * T])
    for frame in fin_frames(FB):              # rows x_b, e_k, w_k
        p, q = v0 @ frame.T, frame @ m        # the line in the fin's axes
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo_b - p) / q, (hi_b - p) / q
        t_lo = np.where(np.abs(q) > 0, np.minimum(t1, t2), -np.inf)
        t_hi = np.where(np.abs(q) > 0, np.maximum(t1, t2), np.inf)
        inside_slab = np.where(np.abs(q) > 0, True, (p >= lo_b) & (p <= hi_b))
        ok = inside_slab.all(axis=1) & (t_lo.max(axis=1) <= t_hi.min(axis=1))
        hit |= ok
    return hit


@pytest.mark.parametrize("R", [attitude((1.0, 0.35, 0.5), 33.0),
                               attitude((0.6, -0.5, 0.62), -71.0),
                               attitude((1.0, 0.0, 0.05), 10.0)])
def test_outline_agrees_with_a_ray_cast_through_the_solid(R):
    """Every view-plane point farther than 0.1 um from the outline is inside the polygon
    exactly when its line of sight meets the cone-cylinder or a fin."""
    rng = np.random.default_rng(7)
    r0 = np.zeros(3)
    for P in (SIDE, TOP):
        poly = finner_silhouette(FB, R, r0, P)
        shape = shapely.Polygon(poly)
        x0, y0, x1, y1 = shape.bounds
        pts = np.column_stack([rng.uniform(x0 - 0.002, x1 + 0.002, 12000),
                               rng.uniform(y0 - 0.002, y1 + 0.002, 12000)])
        n = np.cross(P[0], P[1])
        v0 = (pts @ P) @ R                    # R^T (x P0 + y P1): the points in body axes
        m = R.T @ n
        truth = _inside_cone_cylinder(v0, m) | _inside_boxes(v0, m)
        inside = shapely.contains_xy(shape, pts[:, 0], pts[:, 1])
        far = shapely.distance(shape.exterior, shapely.points(pts)) > 1e-7
        assert far.sum() > 11900 and 0.1 < truth.mean() < 0.9
        assert np.array_equal(inside[far], truth[far])


# ------------------------------------------------------------------------ other bodies


def test_outline_polygon_dispatches_and_silhouette_refuses_a_finned_body():
    R = attitude((1.0, 0.2, 0.1), 20.0)
    c = cone(0.02, np.radians(10.0))
    assert np.array_equal(outline_polygon(c, R, np.zeros(3), SIDE),
                          silhouette(c, R, np.zeros(3), SIDE))
    assert np.array_equal(outline_polygon(FB, R, np.zeros(3), SIDE),
                          finner_silhouette(FB, R, np.zeros(3), SIDE))
    with pytest.raises(AttributeError):       # it would drop the fins: refused, not wrong
        silhouette(FB, R, np.zeros(3), SIDE)


# --------------------------------------------------------------------------- mass


def test_box_inertia_against_a_midpoint_sum():
    lengths = np.array([0.03, 0.02, 0.0024])
    g = [(np.arange(n) + 0.5) / n - 0.5 for n in (60, 40, 8)]
    x, y, z = (np.meshgrid(*g, indexing="ij")[i] * lengths[i] for i in range(3))
    pts = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    m = 2.0 / len(pts)
    I = m * (np.sum(pts**2) * np.eye(3) - pts.T @ pts)
    assert np.allclose(box_inertia(2.0, lengths), I, rtol=1e-3, atol=1e-20)
    # the thin-plate limit: about the normal, the sum of the two in-plane moments
    plate = box_inertia(2.0, (0.03, 0.02, 0.0))
    assert plate[2, 2] == pytest.approx(plate[0, 0] + plate[1, 1])
    assert plate[2, 2] == pytest.approx(2.0 * (0.03**2 + 0.02**2) / 12)


def test_mass_properties_against_hand_formulas():
    rho = 7850.0
    mp = finner_mass_properties(FB, rho)
    # cone-cylinder by hand: cylinder length L_c from the base, cone of height L_n on it
    L_c = L - L_NOSE
    m_cyl = rho * np.pi * A**2 * L_c
    m_cone = rho * np.pi * A**2 * L_NOSE / 3.0
    s_cyl, s_cone = 0.5 * L_c, L_c + 0.25 * L_NOSE
    m_fin = rho * C * B * T
    s_fin, u_fin = 0.5 * C, A + 0.5 * B
    mass = m_cyl + m_cone + 4 * m_fin
    cg = (m_cyl * s_cyl + m_cone * s_cone + 4 * m_fin * s_fin) / mass
    assert mp.mass_kg == pytest.approx(mass, rel=1e-9)
    assert mp.body_volume_m3 == pytest.approx((m_cyl + m_cone) / rho, rel=1e-9)
    assert mp.fin_volume_m3 == pytest.approx(C * B * T, rel=1e-15)
    assert mp.cg_s_m == pytest.approx(cg, rel=1e-9)
    ixx = (0.5 * m_cyl * A**2 + 0.3 * m_cone * A**2
           + 4 * m_fin * ((B**2 + T**2) / 12 + u_fin**2))
    dx = s_fin - cg
    iyy = (m_cyl * ((3 * A**2 + L_c**2) / 12 + (s_cyl - cg) ** 2)
           + m_cone * (3 * A**2 / 20 + 3 * L_NOSE**2 / 80 + (s_cone - cg) ** 2)
           # fins along +-z: about y (their thickness axis) (c^2 + b^2)/12, offset dx, u
           + 2 * m_fin * ((C**2 + B**2) / 12 + dx**2 + u_fin**2)
           # fins along +-y: about y (their span axis) (c^2 + t^2)/12, offset dx only
           + 2 * m_fin * ((C**2 + T**2) / 12 + dx**2))
    I = mp.inertia_kg_m2
    assert I[0, 0] == pytest.approx(ixx, rel=1e-9)
    assert I[1, 1] == pytest.approx(iyy, rel=1e-9) and I[2, 2] == pytest.approx(iyy, rel=1e-9)
    assert np.abs(I - np.diag(np.diag(I))).max() < 1e-15 * I[1, 1]
    # density scales everything and moves nothing
    mp2 = finner_mass_properties(FB, 2.0 * rho)
    assert mp2.mass_kg == pytest.approx(2 * mp.mass_kg) and mp2.cg_s_m == pytest.approx(cg)
    # the fins' share (4 fins = 5.0 % of the volume) and the density-free figures of the docs
    assert 4 * mp.fin_volume_m3 / (mp.body_volume_m3 + 4 * mp.fin_volume_m3) == pytest.approx(
        0.0478, abs=5e-4)
    assert mp.cg_s_m / D == pytest.approx(3.911, abs=1e-3)


def test_mass_properties_do_not_depend_on_the_fins_roll_positions():
    """A cruciform's transverse inertia is isotropic: turning every fin by any angle leaves
    the tensor (in body axes) unchanged."""
    mp = finner_mass_properties(FB, 2700.0)
    turned = dataclasses.replace(FB, fin_phi_rad=tuple(np.array(FB.fin_phi_rad) + 0.37))
    assert np.allclose(finner_mass_properties(turned, 2700.0).inertia_kg_m2,
                       mp.inertia_kg_m2, rtol=0, atol=1e-14 * mp.itrans_kg_m2)


# --------------------------------------------------------------------------- specs


def test_spec_round_trip_scaling_and_errors():
    assert "finner" in KINDS
    fb = body_from_spec({"kind": "finner", "preset": "basic_finner"})
    assert isinstance(fb, FinnedBody) and fb.to_spec()["d_cm"] == pytest.approx(3.0)
    again = body_from_spec(fb.to_spec())
    assert again.to_spec() == fb.to_spec()
    small = body_from_spec({"kind": "finner", "preset": "basic_finner", "d_cm": 2.0})
    assert small.length_m == pytest.approx(0.2) and small.fin_thickness_m == pytest.approx(
        0.0016)
    thick = body_from_spec({"kind": "finner", "preset": "basic_finner",
                            "fin_thickness_mm": 1.5})
    assert thick.fin_thickness_m == pytest.approx(0.0015) and thick.diameter_m == D
    plain = body_from_spec({"kind": "finner", "d_cm": 3.0, "length_cm": 30.0,
                            "half_angle_deg": 10.0, "fin_chord_cm": 3.0, "fin_span_cm": 3.0})
    assert plain.fin_thickness_m == pytest.approx(0.08 * 0.03)
    assert np.allclose(plain.body.arcs, FB.body.arcs)
    for spec, key in [
        ({"kind": "finner", "preset": "nope"}, "preset"),
        ({"kind": "finner", "preset": "basic_finner", "fin_chord_cm": 25.0}, "fin_chord_cm"),
        ({"kind": "finner", "preset": "basic_finner", "fin_thickness_cm": 1.5},
         "fin_thickness_cm"),
        ({"kind": "finner", "preset": "basic_finner", "length_cm": 1.0}, "length_cm"),
        ({"kind": "finner", "preset": "basic_finner", "fin_span_cm": 0.0}, "fin_span_cm"),
        ({"kind": "finner", "d_cm": 3.0, "length_cm": 30.0, "fin_chord_cm": 3.0,
          "fin_span_cm": 3.0}, "half_angle_deg"),
        ({"kind": "finner", "d_cm": 3.0, "half_angle_deg": 10.0, "fin_chord_cm": 3.0,
          "fin_span_cm": 3.0}, "length_cm"),
        ({"kind": "finner", "preset": "basic_finner", "ogive_length_cm": 1.0},
         "ogive_length_cm"),
    ]:
        with pytest.raises(ValueError, match=f"^{re.escape(key)}: "):
            body_from_spec(spec)
    with pytest.raises(ValueError, match="^half_angle_rad: "):
        finner(0.03, 0.3, 0.0, 0.03, 0.03)
