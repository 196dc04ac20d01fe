"""cadra.body.bullet: the ogive-cylinder-boattail projectile (BRL MR 1833's 7.62 mm M-80).

Truth used here, independent of the code under test:
* BRL MR 1833 Fig. 1 / Table I (inches): d = 0.308, length 1.108, ogive
  0.554, a 9 deg boattail 0.173 long;
* the radius r(x) of the body written out here from those dimensions (a tangent or secant
  ogive through its two end points, a cylinder, a cone frustum), integrated with scipy's
  adaptive quadrature: volume, centroid, inertias, and the side-view projected area 2 ∫ r dx
  (the ogive's part in closed form); pi d^2 / 4 end-on;
* scipy's ConvexHull of surface points revolved from that r(x) (not from cadra's meridian).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from cadra.body import (
    KINDS,
    M80_MASS_G,
    body_from_spec,
    bullet,
    silhouette,
    silhouette_area_m2,
    solid_properties,
)
from cadra.io.shotfile import MODEL_KINDS, shot_from_dict, validate_model_spec

IN = 0.0254
SIDE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
TOP = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


class Profile:
    """r(x) of an ogive-cylinder-boattail body from its dimensions, x from the base plane.

    The ogive is the circle of radius R through (x_o, a) and (L, b) (a = d/2, b = meplat/2,
    x_o = L − L_o), centred on the far side of the axis and at or aft of x_o; R = None takes the
    tangent ogive, whose centre (x_o, a − R) gives R² = L_o² + (R − (a − b))²."""

    def __init__(self, d, length, lo, lb, theta, R=None, meplat=0.0):
        self.a, self.b, self.L, self.lo, self.lb, self.th = d / 2, meplat / 2, length, lo, lb, theta
        self.xo = length - lo
        h = self.a - self.b
        self.R = (lo**2 + h**2) / (2 * h) if R is None else R
        # centre (xc, rc): on the chord's perpendicular bisector, R from both ends, xc <= xo
        chord = np.array([lo, self.b - self.a])
        c = np.linalg.norm(chord)
        normal = np.array([-chord[1], chord[0]]) / c          # points away from the axis
        mid = np.array([self.xo, self.a]) + chord / 2
        self.xc, self.rc = mid - normal * np.sqrt(self.R**2 - c**2 / 4)
        self.rb = self.a - lb * np.tan(theta)
        self.breaks = [0.0, lb, self.xo, length]

    def r(self, x):
        x = np.asarray(x, dtype=float)
        boat = self.rb + x * np.tan(self.th)
        ogive = self.rc + np.sqrt(np.clip(self.R**2 - (x - self.xc) ** 2, 0.0, None))
        return np.where(x < self.lb, boat, np.where(x <= self.xo, self.a, ogive))

    def integral(self, f):
        """∫_0^L f(x, r(x)) dx, piecewise adaptive quadrature."""
        total = 0.0
        for x0, x1 in zip(self.breaks[:-1], self.breaks[1:], strict=True):
            if x1 > x0:
                total += quad(lambda x: f(x, float(self.r(x))), x0, x1, epsabs=0.0,
                              epsrel=1e-13, limit=200)[0]
        return total

    def side_area(self):
        """2 ∫ r dx: trapezoid, rectangle and the ogive's circular segment in closed form."""
        def prim(u):        # ∫ sqrt(R² − u²) du
            return 0.5 * (u * np.sqrt(self.R**2 - u**2) + self.R**2 * np.arcsin(u / self.R))
        ogive = self.rc * self.lo + prim(self.L - self.xc) - prim(self.xo - self.xc)
        return 2.0 * ((self.a + self.rb) / 2 * self.lb + self.a * (self.xo - self.lb) + ogive)

    def surface(self, n_axial=1500, n_around=720):
        x = np.unique(np.concatenate([np.linspace(0.0, self.L, n_axial), self.breaks]))
        r = self.r(x)
        phi = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
        ring = np.stack([np.repeat(x, n_around), np.outer(r, np.cos(phi)).ravel(),
                         np.outer(r, np.sin(phi)).ravel()], axis=1)
        base = np.array([[0.0, 0.0, 0.0]])
        return np.concatenate([base, ring])


M80 = dict(d=0.308 * IN, length=1.108 * IN, lo=0.554 * IN, lb=0.173 * IN,
           theta=np.radians(9.0))

BODIES = {
    "M80": ({"kind": "bullet", "preset": "M80"}, Profile(**M80)),
    "M80 secant, meplat": (
        {"kind": "bullet", "preset": "M80", "ogive_radius_cm": 4.5, "meplat_mm": 0.6},
        Profile(**M80, R=0.045, meplat=0.0006)),
    "square base": (
        {"kind": "bullet", "d_cm": 1.0, "length_cm": 4.0, "ogive_length_cm": 2.0},
        Profile(d=0.01, length=0.04, lo=0.02, lb=0.0, theta=0.0)),
}
#: specs for the round trip only
ROUND_TRIP = [spec for spec, _ in BODIES.values()] + [
    {"kind": "bullet", "preset": "M80", "boattail_length_mm": 0.0},     # M80, square base
    {"kind": "bullet", "preset": "M80", "ogive_length_cm": 1.2, "name": "short ogive"},
]


def test_m80_preset_is_brl_mr_1833_table_i():
    b = body_from_spec({"kind": "bullet", "preset": "M80"})
    assert b.diameter_m == pytest.approx(0.308 * IN, rel=1e-15)
    assert b.length_m == pytest.approx(1.108 * IN, rel=1e-14)
    assert b.base_s_m == 0.0 and b.nose_s_m == pytest.approx(1.108 * IN, rel=1e-15)
    s, r = b.s_m, b.r_m
    # the cylinder 1.108 - 0.554 - 0.173 = 0.381 in long at r = d/2; the 9 deg boattail
    cyl = np.abs(r - 0.154 * IN) < 1e-12
    assert s[cyl].min() == pytest.approx(0.173 * IN, abs=1e-12)
    assert s[cyl].max() - s[cyl].min() == pytest.approx(0.381 * IN, abs=1e-12)
    rim = r[s == 0.0].max()
    assert rim == pytest.approx((0.154 - 0.173 * np.tan(np.radians(9.0))) * IN, rel=1e-12)
    # tangent ogive: R = (L_o^2 + a^2) / 2a = 1.07348 in, centre 0.91948 in beyond the axis
    og = b.arcs[1]
    assert og[2] == pytest.approx((0.554**2 + 0.154**2) / 0.308 * IN, rel=1e-14)
    assert og[1] == pytest.approx(0.154 * IN - og[2], rel=1e-14) and og[1] < 0
    assert og[4] == 0.5 * np.pi                                # tangent to the cylinder
    assert b.to_spec()["preset"] == "M80"


@pytest.mark.parametrize("label", list(BODIES))
def test_solid_properties_match_quadrature_of_r(label):
    spec, prof = BODIES[label]
    sp = solid_properties(body_from_spec(spec))
    vol = prof.integral(lambda x, r: np.pi * r * r)
    xc = prof.integral(lambda x, r: np.pi * r * r * x) / vol
    ixx = prof.integral(lambda x, r: 0.5 * np.pi * r**4)
    iyy = prof.integral(lambda x, r: np.pi * r * r * (0.25 * r * r + (x - xc) ** 2))
    assert sp.volume_m3 == pytest.approx(vol, rel=1e-6)
    assert sp.centroid_s_m == pytest.approx(xc, rel=1e-6)
    assert sp.ixx_kg_m2 == pytest.approx(ixx, rel=1e-6)
    assert sp.itrans_kg_m2 == pytest.approx(iyy, rel=1e-6)


@pytest.mark.parametrize("label", list(BODIES))
def test_side_and_end_on_areas_are_analytic(label):
    spec, prof = BODIES[label]
    b = body_from_spec(spec)
    side = silhouette_area_m2(b, np.eye(3), SIDE)       # axis in the view plane
    assert side == pytest.approx(prof.side_area(), rel=1e-6)
    end_on = Rotation.from_euler("y", 90, degrees=True).as_matrix()   # axis along the sight
    assert silhouette_area_m2(b, end_on, TOP) == pytest.approx(np.pi * prof.a**2, rel=1e-6)


@pytest.mark.parametrize("label", list(BODIES))
@pytest.mark.parametrize("angle_deg", [30.0, 75.0])
def test_oblique_silhouette_is_the_hull_of_the_revolved_profile(label, angle_deg):
    """The axis at ``angle_deg`` to the line of sight (x_F up the view, sight along z_F)."""
    spec, prof = BODIES[label]
    b = body_from_spec(spec)
    R = Rotation.from_euler("zy", [20.0, 90.0 - angle_deg], degrees=True).as_matrix()
    ref = np.array([0.1, -0.2, 0.3])
    proj = (prof.surface() @ R.T + ref) @ TOP.T
    hull = ConvexHull(proj)
    exact = silhouette_area_m2(b, R, TOP)
    poly = silhouette(b, R, ref, TOP, n_points=8192)
    x, y = poly[:, 0], poly[:, 1]
    shoelace = 0.5 * float(np.sum(x * np.roll(y, -1) - y * np.roll(x, -1)))
    # the hull is inscribed: short by ~(pi/720)^2 / 2 = 1e-5 at most (measured 5e-6 .. 7e-6)
    assert hull.volume == pytest.approx(exact, rel=2e-5)
    assert hull.volume < exact
    assert shoelace == pytest.approx(exact, rel=1e-6) and shoelace < exact
    # the polygon lies within the hull to the hull's sampling (the sagitta of the 720-gon
    # of radius d/2, 3.7e-8 m for the M-80; hull facets between rings at different azimuths
    # add a few per cent), the hull within the polygon to the polygon's chords
    eq = hull.equations
    sagitta = prof.a * (1.0 - np.cos(np.pi / 720))
    assert np.max(poly @ eq[:, :2].T + eq[:, 2]) < 1.1 * sagitta
    e = np.roll(poly, -1, axis=0) - poly
    u = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.hypot(e[:, 0], e[:, 1])[:, None]
    offs = np.einsum("ij,ij->i", u, poly)
    assert np.max(proj[hull.vertices] @ u.T - offs) < 1e-9            # chord sagitta


@pytest.mark.parametrize(("spec", "key", "words"), [
    ({"length_cm": -2.8}, "length_cm", "positive"),
    ({"d_mm": 0.0}, "d_mm", "positive"),
    ({"boattail_length_cm": 1.5}, "boattail_length_cm", "longer than the body"),
    ({"ogive_length_cm": 3.0}, "ogive_length_cm", "longer than the body"),
    ({"ogive_radius_cm": 2.7}, "ogive_radius_cm", "tangent ogive"),
    ({"boattail_angle_deg": 45.0}, "boattail_length_cm", "closes before the base"),
    ({"boattail_angle_deg": 0.0}, "boattail_angle_deg", "(0, pi/2)"),
    ({"meplat_cm": 0.8}, "meplat_cm", "narrower"),
    ({"meplat_cm": -0.1}, "meplat_cm", "non-negative"),
    ({"preset": "M855"}, "preset", "M80"),
    ({"nose_radius_cm": 0.1}, "nose_radius_cm", "unknown key"),
    ({"ogive_length_cm": 1.4, "ogive_length_mm": 14.0}, "ogive_length_mm", "twice"),
])
def test_impossible_bullets_are_refused_naming_the_key(spec, key, words):
    with pytest.raises(ValueError, match=rf"^{key}: .*{re.escape(words)}"):
        body_from_spec({"kind": "bullet", "preset": "M80", **spec})


def test_explicit_spec_needs_its_dimensions():
    with pytest.raises(ValueError, match=r"^ogive_length_cm: missing"):
        body_from_spec({"kind": "bullet", "d_cm": 0.78, "length_cm": 2.8})
    with pytest.raises(ValueError, match=r"^boattail_angle_deg: missing"):
        body_from_spec({"kind": "bullet", "d_cm": 0.78, "length_cm": 2.8,
                        "ogive_length_cm": 1.4, "boattail_length_cm": 0.4})
    # the tangent radius itself is accepted (tangent within rounding), a hair less is not
    r_t = (1.4**2 + 0.39**2) / 0.78
    spec = {"kind": "bullet", "d_cm": 0.78, "length_cm": 2.8, "ogive_length_cm": 1.4}
    assert body_from_spec({**spec, "ogive_radius_cm": r_t}).arcs[1, 4] == 0.5 * np.pi
    with pytest.raises(ValueError, match=r"^ogive_radius_cm: .* smaller than the tangent"):
        body_from_spec({**spec, "ogive_radius_cm": r_t * (1 - 1e-9)})


@pytest.mark.parametrize("spec", ROUND_TRIP)
def test_to_spec_round_trip(spec):
    b = body_from_spec(spec)
    again = body_from_spec(b.to_spec())
    a_spec, b_spec = again.to_spec(), b.to_spec()
    assert a_spec.keys() == b_spec.keys()
    for k, v in b_spec.items():
        assert a_spec[k] == (pytest.approx(v, rel=1e-14) if isinstance(v, float) else v)
    np.testing.assert_allclose(again.arcs, b.arcs, rtol=1e-13, atol=1e-17)


def test_kind_is_registered_for_specs_and_shot_files():
    assert "bullet" in KINDS and "bullet" in MODEL_KINDS
    spec = {"kind": "bullet", "preset": "M80", "meplat_mm": 0.5}
    assert validate_model_spec(spec) == spec
    b = bullet(0.00782, 0.0281, 0.0141, boattail_length_m=0.0044,
               boattail_angle_rad=np.radians(9.0))
    assert b.kind == "bullet" and b.preset is None


def test_preset_keys_override_without_rescaling():
    b = body_from_spec({"kind": "bullet", "preset": "M80", "d_cm": 0.7815, "meplat_mm": 0.5})
    assert b.diameter_m == pytest.approx(0.007815, rel=1e-15)
    assert b.length_m == pytest.approx(1.108 * IN, rel=1e-14)       # the preset's, unscaled
    assert b.arcs[0, 1] == pytest.approx(0.00025, rel=1e-15)       # the meplat's rim
    assert b.r_m[-1] == 0.0 and np.sum(b.s_m == b.nose_s_m) >= 2    # a flat nose disc


def test_docs_m80_mass_properties():
    """The numbers docs/bodies.md quotes, regenerated: the uniform solid at 9.53 g, and its
    transverse inertia moved to BRL MR 1833's cg (0.431 in from the base) by parallel axes."""
    b = body_from_spec({"kind": "bullet", "preset": "M80"})
    unit = solid_properties(b)
    assert M80_MASS_G == 9.53
    sp = solid_properties(b, M80_MASS_G * 1e-3 / unit.volume_m3)
    cg = 0.431 * IN
    iy_cg = sp.itrans_kg_m2 + sp.mass_kg * (cg - sp.centroid_s_m) ** 2
    assert unit.volume_m3 * 1e6 == pytest.approx(1.009655, abs=1e-6)
    assert sp.centroid_s_m * 100 == pytest.approx(1.14306, abs=1e-5)
    assert sp.ixx_kg_m2 * 1e7 == pytest.approx(0.64695, abs=1e-5)
    assert sp.itrans_kg_m2 * 1e7 == pytest.approx(4.35400, abs=1e-5)
    assert iy_cg * 1e7 == pytest.approx(4.3762, abs=1e-4)


def test_docs_recommended_shot_file_values_load():
    """docs/bodies.md's [model] and [mass] tables for the M-80 pass the shot file's checks
    (the density check builds the body: 9.53 g over 1.0097 cm^3 is 9.44 g/cm^3)."""
    shot = shot_from_dict({
        "schema_version": 1, "shot_id": "m80", "facility": "range",
        "model": {"kind": "bullet", "preset": "M80"},
        "mass": {"mass_g": 9.53, "cg_from_reference_cm": [1.09474, 0.0, 0.0],
                 "inertia_g_cm2": [[0.6470, 0.0, 0.0], [0.0, 4.3762, 0.0],
                                   [0.0, 0.0, 4.3762]]},
        "range": {"pressure_torr": 760.0, "temperature_k": 294.0},
        "stations": [{"station": 1, "time_s": 0.0}, {"station": 2, "time_s": 0.001}],
    })
    assert shot.mass.cg_model_m[0] == pytest.approx(0.431 * IN, rel=1e-15)
