"""cadra.body: shapes, the seed 004 capsule OML, specs, and exact silhouettes.

Truth used here, independent of the code under test:
* seed 004 Table 1 (nominal dimensions) and Table 2 (measured d, h, cg, inertia of solid steel
  M1 models);
* analytic outlines: a sphere's circle, a sharp cone's apex + tangents to its base ellipse, the
  capsule's width/length at zero incidence and its end-on circle;
* the support function of the body computed by brute force from a dense meridian and direct
  3-D vector algebra (no view-plane algebra of cadra.body.outline);
* scipy's ConvexHull of projected surface points.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from cadra.body import (
    TABLE1_CM,
    axial_offset_from_base,
    axial_offset_from_virtual_apex,
    body_from_spec,
    capsule,
    cg_offset_from_table2,
    cone,
    meridian,
    silhouette,
    silhouette_area_m2,
    solid_properties,
    solve_capsule_oml,
    sphere,
    surface_points,
)

TOP = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
SIDE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
UPRIGHT = np.diag([1.0, -1.0, -1.0])          # level, upright model: body axes -> facility
R_PORT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # nose along +y_F


def shoelace(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - y * np.roll(x, -1)))


def edge_normals(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals of the edges of a CCW polygon and each edge's offset u·v."""
    e = np.roll(poly, -1, axis=0) - poly
    u = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.hypot(e[:, 0], e[:, 1])[:, None]
    return u, np.einsum("ij,ij->i", u, poly)


_MERIDIANS: dict = {}


def _dense_meridian(body, n):
    key = (id(body), n)
    if key not in _MERIDIANS:
        _MERIDIANS[key] = meridian(body.arcs, n)
    return _MERIDIANS[key]


class SupportTruth:
    """h(u) = max over the body of u·(P x), from a dense meridian (chords within ~3e-12 m of
    the arcs) and the 3-D normal split into axial and radial parts: independent of the
    silhouette's closed form. The meridian is a convex chain, so the maximising vertex is where
    the chain's segment normals pass the direction's normal angle (a binary search)."""

    def __init__(self, body, R, P, r_ref, n=200_001):
        s, r = _dense_meridian(body, n)
        keep = np.ones(len(s), dtype=bool)
        keep[1:] = np.hypot(np.diff(s), np.diff(r)) > 0
        self.s, self.r = s[keep], r[keep]
        ds, dr = np.diff(self.s), np.diff(self.r)
        self.beta = np.arctan2(ds, -dr)[::-1]           # segment normal angles, ascending
        self.R, self.P, self.r_ref = R, P, np.asarray(r_ref, float)

    def __call__(self, U: np.ndarray) -> np.ndarray:
        nB = (U @ self.P) @ self.R                      # 3-D direction in body axes
        na, nr = nB[:, 0], np.hypot(nB[:, 1], nB[:, 2])
        b = np.arctan2(nr, na)
        n = len(self.s)
        i = (n - 1) - np.searchsorted(self.beta, b)     # vertex index in base -> nose order
        idx = np.clip(i[:, None] + np.arange(-2, 3), 0, n - 1)
        best = np.max(na[:, None] * self.s[idx] + nr[:, None] * self.r[idx], axis=1)
        return best + U @ (self.P @ self.r_ref)


def outline_deviation(body, R, P, r_ref, poly):
    """(max gap between polygon edges and the true outline, max excursion of a vertex outside
    it, max distance of a vertex from the outline), metres."""
    h = SupportTruth(body, R, P, r_ref)
    u, c = edge_normals(poly)
    gap = h(u) - c                                     # >= 0: outline beyond the edge
    # vertex i: minimise h(u) - u·v over normals between its two adjacent edge normals
    a_prev = np.arctan2(*np.roll(u, 1, axis=0)[:, ::-1].T)
    a_next = np.arctan2(*u[:, ::-1].T)
    da = np.angle(np.exp(1j * (a_next - a_prev)))
    frac = np.linspace(0.0, 1.0, 33)
    ang = (a_prev[:, None] + da[:, None] * frac).ravel()
    U = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    V = np.repeat(poly, len(frac), axis=0)
    off = (h(U) - np.einsum("ij,ij->i", U, V)).reshape(len(poly), len(frac)).min(axis=1)
    return float(gap.max()), float(max(-gap.min(), -off.min(), 0.0)), float(np.abs(off).max())


def random_rotations(seed: int, n: int) -> np.ndarray:
    return Rotation.random(n, random_state=np.random.default_rng(seed)).as_matrix()


# ---------------------------------------------------------------------------- Table 1 / OML


@pytest.mark.parametrize("preset", ["M1", "M2", "M3"])
def test_presets_reproduce_table1(preset):
    b = capsule(preset)
    t1 = {k: v * 1e-2 for k, v in TABLE1_CM[preset].items() if v is not None}
    p = b.param
    for k in ("d", "h", "R1", "R2", "l1"):
        assert p[f"{k}_m"] == pytest.approx(t1[k], rel=1e-15)
    # the geometry itself: maximum diameter d, length h, base-to-junction l1 - (s_b from apex)
    assert 2 * b.r_m.max() == pytest.approx(t1["d"], rel=1e-12)
    assert b.nose_s_m - b.base_s_m == pytest.approx(t1["h"], rel=1e-14)
    assert b.diameter_m == t1["d"] and b.length_m == pytest.approx(t1["h"], rel=1e-14)
    oml = b.oml
    assert abs(oml.residual_m) < 1e-14                 # |s_n - s_b - h| (m); Table 1 h ~ 2.3 cm
    assert oml.junction_r_m == pytest.approx(oml.l1_m * np.tan(oml.theta_c_rad), rel=1e-14)
    # the reference point is the maximum-diameter plane
    i = np.argmax(b.r_m)
    assert abs(b.s_m[i]) < 1e-4 * t1["d"] and b.r_m[i] == pytest.approx(t1["d"] / 2, rel=1e-8)


def test_theta_c_from_the_brief_equations():
    """θc from the Fig. 6 tangency equations written out here, Apollo-like (33 deg)."""
    d, h, R1, R2, l1 = (TABLE1_CM["M2"][k] for k in ("d", "h", "R1", "R2", "l1"))
    rho_t = d / 2 - R2

    def length(th):
        s_t = (R2 + rho_t * np.cos(th)) / np.sin(th)
        s_n = s_t - np.sqrt((R1 - R2) ** 2 - rho_t**2) + R1
        s_b = l1 + R2 * np.sin(th) - R2
        return s_n - s_b

    from scipy.optimize import brentq

    th = brentq(lambda t: length(t) - h, 0.3, 1.2, xtol=1e-15)
    assert np.degrees(capsule("M2").oml.theta_c_rad) == pytest.approx(np.degrees(th), abs=1e-10)
    assert 33.0 < np.degrees(th) < 33.6
    assert 33.0 < np.degrees(capsule("M3").oml.theta_c_rad) < 33.6


def test_m3_is_a_427_percent_scale_m2():
    m2, m3 = TABLE1_CM["M2"], TABLE1_CM["M3"]
    for k in ("d", "h", "R1", "R2", "l1", "l2", "d1"):
        assert m3[k] / m2[k] == pytest.approx(0.427, abs=0.0015), k
    b2, b3 = capsule("M2"), capsule("M3")
    assert b3.length_m / b2.length_m == pytest.approx(0.427, abs=0.001)
    assert b3.nose_s_m / b2.nose_s_m == pytest.approx(0.427, abs=0.002)


def test_capsule_meridian_is_tangent_continuous():
    """Every joint of the Fig. 6 OML is a tangency: the dense meridian never turns sharply."""
    for preset in ("M2", "M3"):
        b = capsule(preset)
        s, r = meridian(b.arcs, 40_001)                  # turns by < 1e-3 rad per segment
        seg = np.diff(np.stack([s, r], axis=1), axis=0)
        seg = seg[np.hypot(*seg.T) > 0]
        ang = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
        assert np.max(np.abs(np.diff(ang))) < 2e-3      # a corner would turn by degrees
        assert np.all(np.diff(b.s_m) >= 0)
        assert b.r_m[0] == 0 and b.r_m[-1] == 0


def test_m1_solid_steel_mass_properties_match_table2():
    """M1 is solid steel (seed 004): the resolved OML's centroid and radii of gyration must
    match Table 2's measured x_cg-b and I/m (density-free), and its density must be steel's."""
    rows = [  # Table 2, M1: d, h, m, x_cg-b, Ixx, Iyy (2366 and 2365 excluded: Iyy outliers)
        (3.556, 2.339, 96.300, 1.387, 103.679, 80.549), (3.556, 2.344, 97.013, 1.387, 105.076,
        81.715), (3.556, 2.342, 96.563, 1.389, 104.208, 81.024), (3.559, 2.339, 96.484, 1.392,
        104.398, 81.051), (3.553, 2.342, 96.324, 1.392, 103.951, 80.658), (3.553, 2.339,
        96.424, 1.387, 104.127, 80.685), (3.553, 2.342, 96.350, 1.392, 103.842, 81.254),
        (3.561, 2.342, 97.336, 1.387, 105.225, 81.946), (3.553, 2.339, 96.187, 1.397, 103.720,
        80.441), (3.546, 2.334, 95.476, 1.387, 102.120, 80.210)]
    for d, h, m, xcg_b, ixx, iyy in rows:
        b = body_from_spec({"kind": "capsule", "preset": "M1", "d_cm": d, "h_cm": h})
        sp = solid_properties(b)
        rho_g_cc = m / (sp.volume_m3 * 1e6)
        assert 7.75 < rho_g_cc < 8.05                                   # steel
        x_from_base_cm = (sp.centroid_s_m - b.base_s_m) * 100
        # OML centroid 1.40-1.41 cm vs measured 1.387-1.397: 0.1-0.2 mm forward (docs/bodies.md)
        assert x_from_base_cm == pytest.approx(xcg_b, abs=0.025)
        assert sp.ixx_kg_m2 / sp.mass_kg * 1e4 == pytest.approx(ixx / m, rel=0.01)
        assert sp.itrans_kg_m2 / sp.mass_kg * 1e4 == pytest.approx(iyy / m, rel=0.025)


def test_solid_properties_sphere_and_cone_closed_forms():
    R = 0.01
    sp = solid_properties(sphere(2 * R), density_kg_m3=7800.0)
    assert sp.volume_m3 == pytest.approx(4 / 3 * np.pi * R**3, rel=1e-9)
    assert abs(sp.centroid_s_m) < 1e-15
    assert sp.ixx_kg_m2 == pytest.approx(0.4 * sp.mass_kg * R**2, rel=1e-9)
    assert sp.itrans_kg_m2 == pytest.approx(sp.ixx_kg_m2, rel=1e-9)
    c = cone(0.02, np.radians(10.0))
    sc = solid_properties(c)
    L, r = c.nose_s_m, 0.01
    assert sc.volume_m3 == pytest.approx(np.pi * r**2 * L / 3, rel=1e-9)
    assert sc.centroid_s_m == pytest.approx(L / 4, rel=1e-9)            # from the base
    assert sc.ixx_kg_m2 == pytest.approx(0.3 * sc.mass_kg * r**2, rel=1e-9)
    assert sc.itrans_kg_m2 == pytest.approx(sc.mass_kg * (3 / 20 * r**2 + 3 / 80 * L**2),
                                            rel=1e-9)


def test_table2_cg_offset_from_reference_point():
    b = body_from_spec({"kind": "capsule", "preset": "M2", "d_cm": 3.556, "h_cm": 2.337})
    # base centre = nose - h, independent of where the reference point is
    expect = (b.nose_s_m - 0.02337) + 0.01389
    assert cg_offset_from_table2(b, 1.389) == pytest.approx(expect, abs=1e-15)
    assert axial_offset_from_base(b, 0.0) == b.base_s_m
    assert -0.0046 < cg_offset_from_table2(b, 1.389) < -0.0043      # cg 0.44 cm aft of max-d
    # seed 004's design cg "0.676 d from the virtual apex"
    apex = axial_offset_from_virtual_apex(b, 0.0)
    assert apex == pytest.approx(-b.oml.shoulder_s_m)
    assert apex < b.base_s_m                                         # the apex is behind the base
    assert axial_offset_from_base(sphere(0.02), 0.01) == pytest.approx(0.0, abs=1e-18)


@pytest.mark.parametrize("kw, key", [
    (dict(d_m=0.03557, h_m=0.003, R1_m=0.04267, R2_m=0.00178, l1_m=0.01008), "h_m"),
    (dict(d_m=0.03557, h_m=0.02338, R1_m=0.017, R2_m=0.00178, l1_m=0.01008), "R1_m"),
    (dict(d_m=0.03557, h_m=0.02338, R1_m=0.04267, R2_m=0.02, l1_m=0.01008), "R2_m"),
    (dict(d_m=0.03557, h_m=0.02338, R1_m=0.04267, R2_m=0.00178, l1_m=1e-4), "l1_m"),
])
def test_impossible_capsules_name_the_dimension(kw, key):
    with pytest.raises(ValueError, match=f"^{key}:"):
        solve_capsule_oml(**kw)


# --------------------------------------------------------------------------- specs


@pytest.mark.parametrize("spec, key", [
    ({}, "kind"),
    ({"kind": "ogive"}, "kind"),
    ({"kind": "sphere"}, "d_cm"),
    ({"kind": "sphere", "d_cm": 2.0, "colour": "red"}, "colour"),
    ({"kind": "sphere", "d_cm": 2.0, "d_mm": 20.0}, "d_mm"),
    ({"kind": "sphere", "d_cm": -2.0}, "d_cm"),
    ({"kind": "sphere", "d_cm": "2"}, "d_cm"),
    ({"kind": "sphere", "d_cm": True}, "d_cm"),
    ({"kind": "cone", "d_cm": 2.0}, "half_angle_deg"),
    ({"kind": "cone", "d_cm": 2.0, "half_angle_deg": 95.0}, "half_angle_deg"),
    ({"kind": "cone", "d_cm": 2.0, "half_angle_deg": 10.0, "nose_radius_cm": 5.0},
     "nose_radius_cm"),
    ({"kind": "capsule", "preset": "M9"}, "preset"),
    ({"kind": "capsule", "d_cm": 3.557}, "h_cm"),
    ({"kind": "capsule", "preset": "M2", "h_cm": 0.3}, "h_cm"),
    ({"kind": "capsule", "preset": "M2", "half_angle_deg": 10.0}, "half_angle_deg"),
    ({"kind": "capsule", "preset": "M2", "name": 3}, "name"),
])
def test_body_from_spec_errors_name_the_key(spec, key):
    with pytest.raises(ValueError, match=f"^{key}:"):
        body_from_spec(spec)


@pytest.mark.parametrize("spec", [
    {"kind": "sphere", "d_cm": 2.54},
    {"kind": "cone", "d_cm": 2.0, "half_angle_deg": 10.0},
    {"kind": "cone", "d_mm": 20.0, "half_angle_rad": 0.2, "nose_radius_mm": 0.5, "name": "bc"},
    {"kind": "capsule", "preset": "M2"},
    {"kind": "capsule", "preset": "M3", "d_cm": 1.524, "h_cm": 1.006},
    {"kind": "capsule", "d_cm": 3.557, "h_cm": 2.338, "R1_cm": 4.267, "R2_cm": 0.178,
     "l1_cm": 1.008},
])
def test_to_spec_round_trip(spec):
    b = body_from_spec(spec)
    spec2 = b.to_spec()
    b2 = body_from_spec(spec2)
    assert b2.kind == b.kind and b2.name == b.name and b2.preset == b.preset
    assert set(spec2) == set(b2.to_spec())
    for k, v in spec2.items():
        if isinstance(v, float):
            assert b2.to_spec()[k] == pytest.approx(v, rel=1e-15), k
    np.testing.assert_allclose(b2.s_m, b.s_m, rtol=0, atol=1e-16)
    np.testing.assert_allclose(b2.r_m, b.r_m, rtol=0, atol=1e-16)
    assert b2.nose_s_m == pytest.approx(b.nose_s_m, abs=1e-16)


def test_per_shot_capsule_uses_measured_d_and_h():
    b = body_from_spec({"kind": "capsule", "preset": "M2", "d_cm": 3.556, "h_cm": 2.327})
    assert b.diameter_m == 0.03556 and b.length_m == pytest.approx(0.02327, rel=1e-14)
    assert 2 * b.r_m.max() == pytest.approx(0.03556, rel=1e-12)
    assert b.param["R1_m"] == pytest.approx(0.04267 * 3.556 / 3.557, rel=1e-14)
    assert b.name == "M2" and b.to_spec()["preset"] == "M2"


# --------------------------------------------------------------------------- silhouettes


def test_sphere_silhouette_is_the_circle():
    d = 0.0254
    b = sphere(d)
    centre = np.array([1.3, -0.02, 0.01])
    for R in random_rotations(1, 5):
        for P in (TOP, SIDE):
            poly = silhouette(b, R, centre, P)
            rad = np.hypot(*(poly - P @ centre).T)
            np.testing.assert_allclose(rad, d / 2, rtol=0, atol=1e-15)
            assert shoelace(poly) > 0
            assert silhouette_area_m2(b, R, P) == pytest.approx(np.pi * d**2 / 4, rel=1e-14)


def test_capsule_zero_incidence_side_view_width_and_length():
    b = capsule("M2")
    ref = np.array([3.0, 0.01, -0.02])
    poly = silhouette(b, UPRIGHT, ref, SIDE)
    x, z = poly[:, 0] - ref[0], poly[:, 1] - ref[2]
    assert z.max() - z.min() == pytest.approx(0.03557, rel=1e-14)        # d
    assert x.max() - x.min() == pytest.approx(0.02338, rel=1e-14)        # h
    assert x.max() == pytest.approx(b.nose_s_m, abs=1e-15)
    # side view at zero incidence: the area is twice the meridian half-section
    s, r = meridian(b.arcs, 400_001)
    half = float(np.sum(0.5 * (r[1:] + r[:-1]) * np.diff(s)))
    assert silhouette_area_m2(b, UPRIGHT, SIDE) == pytest.approx(2 * half, rel=1e-10)
    # the base is seen edge-on: a straight edge of length 2 * base radius at x = base
    on_base = np.abs(x - b.base_s_m) < 1e-15
    assert z[on_base].max() - z[on_base].min() == pytest.approx(2 * b.oml.base_r_m, rel=1e-13)


def test_capsule_end_on_is_the_max_diameter_circle():
    b = capsule("M3")
    ref = np.array([1.0, 0.002, 0.003])
    for R in (R_PORT, R_PORT @ np.diag([-1.0, -1.0, 1.0])):            # nose to port, to starboard
        poly = silhouette(b, R, ref, SIDE)                                # axis along hidden y
        np.testing.assert_allclose(np.hypot(*(poly - SIDE @ ref).T), 0.01518 / 2, rtol=0,
                                   atol=1e-15)
        assert silhouette_area_m2(b, R, SIDE) == pytest.approx(np.pi * 0.01518**2 / 4,
                                                               rel=1e-14)


def _cone_check(b, R, P, ref):
    """Sharp cone: apex + tangents to the base ellipse, written out in 3-D."""
    poly = silhouette(b, R, ref, P)
    a = R[:, 0]
    w = np.cross(P[0], P[1])
    r0 = b.diameter_m / 2
    # base ellipse in the view plane: the projection of the base circle
    e1 = np.cross(a, w)
    if np.linalg.norm(e1) < 1e-12:                                    # end-on
        e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    c = P @ ref
    M = np.stack([P @ e1, P @ e2], axis=1) * r0                       # ellipse = c + M (cos, sin)
    apex = P @ (ref + b.nose_s_m * a)
    is_apex = np.hypot(*(poly - apex).T) < 1e-15
    if abs(a @ w) < 1e-12:                  # axis in the view plane: a triangle, base edge-on
        ends = c + np.array([1.0, -1.0])[:, None] * (P @ e1) * r0
        assert is_apex.sum() == 1
        assert all(np.hypot(*(poly - e).T).min() < 1e-15 for e in ends)
        base = poly[~is_apex]
        assert np.abs((base - c) @ (P @ a)).max() < 1e-15             # all on the base line
        return poly
    z = np.linalg.solve(M, (poly[~is_apex] - c).T)                   # ellipse coordinates
    grad = 2 * np.linalg.solve(M.T, z)                                 # of |z|^2, per metre
    dist = (np.sum(z * z, axis=0) - 1.0) / np.hypot(*grad)            # metres off the ellipse
    assert np.abs(dist).max() < 1e-15
    za = np.linalg.solve(M, apex - c)
    outside = np.hypot(*za) > 1.0
    assert is_apex.sum() == (1 if outside else 0)
    if outside:                                                        # tangent points: polar line
        phi0 = np.arctan2(za[1], za[0])
        dphi = np.arccos(1.0 / np.hypot(*za))
        tang = c + (M @ np.array([np.cos(phi0 + np.array([-dphi, dphi])),
                                  np.sin(phi0 + np.array([-dphi, dphi]))])).T
        i = int(np.flatnonzero(is_apex)[0])
        nbrs = poly[[(i - 1) % len(poly), (i + 1) % len(poly)]]
        dist = np.min(np.hypot(*(nbrs[:, None, :] - tang[None]).transpose(2, 0, 1)), axis=1)
        assert dist.max() < 1e-14
    return poly


def test_sharp_cone_outline_is_apex_plus_tangents_to_base_ellipse():
    b = cone(0.02, np.radians(10.0))
    ref = np.array([5.0, 0.01, 0.0])
    for R in random_rotations(2, 6):
        for P in (TOP, SIDE):
            _cone_check(b, R, P, ref)
    # looking nearly down the nose (inside the half-angle): the apex is inside the ellipse
    Rn = Rotation.from_euler("z", 85.0, degrees=True).as_matrix()    # axis 5 deg from hidden y
    _cone_check(b, Rn, SIDE, ref)
    _cone_check(b, R_PORT, SIDE, ref)                                  # exactly end-on
    _cone_check(b, UPRIGHT, SIDE, ref)                                 # axis in the view plane


ATTITUDES = [
    ("random", None),
    ("side, zero incidence", UPRIGHT),
    ("axis 1e-7 rad out of the view plane", Rotation.from_euler("z", 1e-7).as_matrix() @ UPRIGHT),
    ("axis 1e-7 rad from the line of sight", Rotation.from_euler("z", np.pi / 2 - 1e-7)
     .as_matrix()),
    ("end-on", R_PORT),
]


@pytest.mark.parametrize("body", [capsule("M2"), capsule("M3"), cone(0.02, np.radians(10.0)),
                                  cone(0.02, np.radians(15.0), nose_radius_m=0.002),
                                  sphere(0.0356)], ids=lambda b: b.name)
def test_silhouette_lies_on_the_true_outline(body):
    """Polygon vs the brute-force support function: < 1e-8 m everywhere (1e-4 px at 0.127
    mm/px); vertices on the outline to < 1e-11 m (the truth's own resolution)."""
    ref = np.zeros(3)                   # translation: tested separately
    Rs = [*random_rotations(3, 3), *(R for _, R in ATTITUDES[1:])]
    worst = [0.0, 0.0, 0.0]
    for R in Rs:
        poly = silhouette(body, R, ref, SIDE)
        assert len(poly) <= 4096
        assert shoelace(poly) > 0
        gap, outside, off = outline_deviation(body, R, SIDE, ref, poly)
        worst = [max(w, v) for w, v in zip(worst, (gap, outside, off), strict=True)]
    assert worst[0] < 1e-8, worst           # chord gap to the outline (sagitta)
    assert worst[1] < 1e-11, worst          # no vertex outside the outline
    assert worst[2] < 1e-11, worst          # every vertex on it


@pytest.mark.parametrize("body", [capsule("M2"), cone(0.02, np.radians(10.0)),
                                  cone(0.02, np.radians(20.0), nose_radius_m=0.003)],
                         ids=lambda b: b.name)
def test_silhouette_agrees_with_convex_hull_of_projected_surface(body):
    """Independent projection: dense surface points -> facility -> view plane -> ConvexHull."""
    pts_B = surface_points(body, n_axial=500, n_around=512)
    ref = np.array([2.0, 0.001, -0.002])
    for R in random_rotations(4, 4):
        for P in (TOP, SIDE):
            poly = silhouette(body, R, ref, P)
            proj = (pts_B @ R.T + ref) @ P.T
            hull = ConvexHull(proj)
            hv = proj[hull.vertices]
            u, c = edge_normals(poly)
            signed = np.max(hv @ u.T - c, axis=1)          # > 0 outside the polygon
            assert signed.max() < 1e-8                      # outside by < the chord sagitta
            assert signed.min() > -1e-6                     # hull vertices on it, to sampling
            hp = hv[np.argsort(np.arctan2(*(hv - hv.mean(0)).T[::-1]))]
            uh, ch = edge_normals(hp)
            assert np.max(poly @ uh.T - ch, axis=1).max() < 1e-6   # polygon inside hull + tol
            area = silhouette_area_m2(body, R, P)
            assert hull.volume == pytest.approx(area, rel=2e-4)
            assert hull.volume < area


@pytest.mark.parametrize("body", [capsule("M2"), capsule("M3"), cone(0.02, np.radians(10.0)),
                                  cone(0.02, np.radians(15.0), nose_radius_m=0.002),
                                  sphere(0.02)], ids=lambda b: b.name)
def test_exact_area_matches_the_polygon(body):
    """Closed-form area vs shoelace: at 2^17 vertices to 1e-9 relative; at the default 4096
    the inscribed-polygon deficit is O(n^-2) and Richardson extrapolation recovers the area."""
    ref = np.array([1.0, 0.0, 0.0])
    Rs = [*random_rotations(5, 3), *(R for _, R in ATTITUDES[1:])]
    for R in Rs:
        for P in (TOP, SIDE):
            area = silhouette_area_m2(body, R, P)
            fine = shoelace(silhouette(body, R, ref, P, n_points=1 << 17))
            assert abs(fine - area) < 1e-9 * area
            a1 = shoelace(silhouette(body, R, ref, P, n_points=4096))
            a2 = shoelace(silhouette(body, R, ref, P, n_points=8192))
            assert a1 <= area * (1 + 1e-14) and a2 <= area * (1 + 1e-14)
            assert abs(a2 + (a2 - a1) / 3 - area) < 1e-8 * area
            assert (area - a1) < 1e-6 * area


def test_silhouette_translates_with_the_reference_point_and_rejects_bad_input():
    b = capsule("M2")
    R = random_rotations(6, 1)[0]
    p0 = silhouette(b, R, np.zeros(3), TOP)
    p1 = silhouette(b, R, np.array([1.5, 0.2, -0.3]), TOP)
    np.testing.assert_allclose(p1 - p0, np.broadcast_to([1.5, 0.2], p0.shape), atol=1e-15)
    with pytest.raises(ValueError, match="P_view"):
        silhouette(b, R, np.zeros(3), np.array([[1.0, 0, 0], [1.0, 0, 0]]))
    with pytest.raises(ValueError, match="r_ref_F"):
        silhouette(b, R, np.zeros(2), TOP)
    with pytest.raises(ValueError, match="R_FB"):
        silhouette(b, np.eye(2), np.zeros(3), TOP)


def test_surface_points_lie_on_the_body():
    from scipy.spatial import cKDTree

    b = capsule("M2")
    pts = surface_points(b, n_axial=300, n_around=64)
    s, r = pts[:, 0], np.hypot(pts[:, 1], pts[:, 2])
    assert s.min() == b.base_s_m and s.max() == b.nose_s_m
    assert r.max() == pytest.approx(b.diameter_m / 2, rel=1e-14)
    # every point is on the meridian (a dense one: points 2e-7 m apart)
    dense = np.stack(meridian(b.arcs, 200_001), axis=1)
    dist, _ = cKDTree(dense).query(np.stack([s, r], axis=1))
    assert dist.max() < 2e-7
