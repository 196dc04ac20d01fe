"""A spin-stabilised projectile: ogive nose, cylinder, boattail, flat base (docs/bodies.md).

The meridian, nose to base (s from the reference point, the centre of the base plane, + toward
the nose; a = d/2, b = meplat/2, θ the boattail half-angle):

* the nose: a corner on the axis (pointed, b = 0) or the rim of a flat meplat of radius b;
* the ogive: a circular arc of radius R from (L, b) to (L_b + L_c, a) whose centre lies
  *off the axis on the far side*, rc < 0 (a spindle torus). The tangent ogive, tangent to the
  cylinder, has its centre in the plane of the ogive's base, rc = a − R, and
  ``R_t = (L_o² + (a − b)²) / (2 (a − b))``. A larger R is a secant ogive: the arc still passes
  through both end points, its centre lies aft of that plane, and it meets the cylinder at a
  corner. A smaller R would bulge past the cylinder (not convex): refused;
* the cylinder r = a (a flat), of length L_c = L − L_o − L_b (>= 0);
* a corner at the boattail start (s = L_b, r = a), the boattail cone at half-angle θ (a flat),
  a corner at the base rim (s = 0, r = a − L_b tan θ), and the flat base.

The outline code (:mod:`cadra.body.outline`) and the solid properties (:mod:`cadra.body.mass`)
take the arc's signed centre radius as it is: the outline point formula and the support
function ``h = σ sc cos t + ρ + rc D`` are linear in rc, and on the visible part of the arc
(sin β >= −rc/ρ, where r >= 0) the outline's radius of curvature ρ + rc κ²/D³ >= r / sin β >= 0.
tests/test_body_bullet.py checks both against independent integrations.

Preset ``"M80"``: the 7.62 mm M-80 ball round of BRL MR 1833 (Fig. 1, Table I), in inches:
d = 0.308, overall length 1.108, ogive length 0.554, a 9 deg boattail 0.173 long; the
tangent ogive is this module's default (the report gives no ogive radius).
"""

from __future__ import annotations

import numpy as np

from cadra.body.model import Body, make_body

#: Body kind of :func:`bullet`.
KIND = "bullet"

_IN = 0.0254

#: BRL MR 1833 Fig. 1 / Table I, the 7.62 mm M-80 ball round, in inches (``cg_from_base`` is
#: the measured cg of the jacketed lead-core bullet, ``mass_g`` 147 grains; neither is geometry).
M80_IN: dict[str, float] = {"d": 0.308, "length": 1.108, "ogive_length": 0.554,
                            "boattail_length": 0.173, "boattail_angle_deg": 9.0,
                            "cg_from_base": 0.431}
#: M-80 bullet mass, g (147 grains = 9.5254 g; BRL MR 1833 quoted as 9.53 g)
M80_MASS_G = 9.53

#: Presets: geometry keyword arguments of :func:`bullet`, SI.
PRESETS: dict[str, dict[str, float]] = {
    "M80": {"d_m": M80_IN["d"] * _IN, "length_m": M80_IN["length"] * _IN,
            "ogive_length_m": M80_IN["ogive_length"] * _IN,
            "boattail_length_m": M80_IN["boattail_length"] * _IN,
            "boattail_angle_rad": float(np.radians(M80_IN["boattail_angle_deg"]))},
}


def tangent_ogive_radius_m(d_m: float, ogive_length_m: float, meplat_m: float = 0.0) -> float:
    """Radius of the tangent ogive of length ``ogive_length_m`` from the meplat (diameter
    ``meplat_m``, 0 for a point) to the body diameter ``d_m``: (L_o² + (a − b)²) / (2 (a − b))."""
    h = 0.5 * (float(d_m) - float(meplat_m))
    return (float(ogive_length_m) ** 2 + h * h) / (2.0 * h)


def _positive(name: str, value: float, allow_zero: bool = False) -> float:
    v = float(value)
    if not (np.isfinite(v) and (v > 0 or (allow_zero and v == 0))):
        what = "a non-negative" if allow_zero else "a positive"
        raise ValueError(f"{name}: must be {what} length, got {value!r}")
    return v


def _ogive_centre(a: float, b: float, lo: float, R: float, tangent: bool) -> tuple[float, float]:
    """Centre (sc, rc) of the ogive arc through (0, a) and (lo, b), s from the ogive's base."""
    if tangent:
        return 0.0, a - R
    c = np.hypot(lo, a - b)
    n = np.array([a - b, lo]) / c               # chord normal, away from the axis and aft
    mid = 0.5 * np.array([lo, a + b])
    centre = mid - n * np.sqrt(max(R * R - 0.25 * c * c, 0.0))
    return float(centre[0]), float(centre[1])


def bullet(d_m: float, length_m: float, ogive_length_m: float, *,
           boattail_length_m: float = 0.0, boattail_angle_rad: float = 0.0,
           ogive_radius_m: float | None = None, meplat_m: float = 0.0,
           name: str = "bullet", preset: str | None = None) -> Body:
    """Ogive-cylinder-boattail projectile; reference point at the centre of the base plane.

    Parameters
    ----------
    d_m : body (cylinder) diameter, the reference length d, m.
    length_m : overall length, meplat (or point) to base, m.
    ogive_length_m : axial length of the ogive, m.
    boattail_length_m : axial length of the boattail, m (0: a square base).
    boattail_angle_rad : boattail half-angle θ, 0 < θ < 90 deg (ignored without a boattail).
    ogive_radius_m : ogive arc radius; None: the tangent ogive (:func:`tangent_ogive_radius_m`).
        Larger: a secant ogive meeting the cylinder at a corner. Smaller: refused.
    meplat_m : diameter of the flat nose (meplat), m; 0: pointed.
    name : body name.
    preset : the preset the dimensions came from (recorded in the spec), or None.

    Raises ValueError naming the argument (``"boattail_length_m: ..."``) for dimensions that
    cannot make the body: non-positive sizes, an ogive (or ogive + boattail) longer than the
    body, a boattail that closes before the base, a meplat as wide as the body, an ogive radius
    below the tangent ogive's.
    """
    d = _positive("d_m", d_m)
    length = _positive("length_m", length_m)
    lo = _positive("ogive_length_m", ogive_length_m)
    lb = _positive("boattail_length_m", boattail_length_m, allow_zero=True)
    mp = _positive("meplat_m", meplat_m, allow_zero=True)
    th = float(boattail_angle_rad)
    a, b = 0.5 * d, 0.5 * mp
    if lo > length:
        raise ValueError(f"ogive_length_m: the ogive ({lo} m) is longer than the body "
                         f"({length} m)")
    if lo + lb > length:
        raise ValueError(f"boattail_length_m: the boattail ({lb} m) and the ogive ({lo} m) are "
                         f"longer than the body ({length} m)")
    if lb > 0:
        if not (np.isfinite(th) and 0.0 < th < 0.5 * np.pi):
            raise ValueError(f"boattail_angle_rad: must lie in (0, pi/2) with a boattail, got "
                             f"{boattail_angle_rad!r}")
        if lb * np.tan(th) >= a:
            raise ValueError(f"boattail_length_m: a {np.degrees(th):.3f} deg boattail {lb} m "
                             f"long closes before the base (radius {a} m)")
    if mp >= d:
        raise ValueError(f"meplat_m: the meplat ({mp} m) must be narrower than d = {d} m")
    r_tan = tangent_ogive_radius_m(d, lo, mp)
    if ogive_radius_m is None:
        R, tangent = r_tan, True
    else:
        R = _positive("ogive_radius_m", ogive_radius_m)
        if R < r_tan * (1.0 - 1e-12):
            raise ValueError(f"ogive_radius_m: {R} m is smaller than the tangent ogive's "
                             f"{r_tan} m for a {lo} m ogive from d = {d} m to a {mp} m meplat "
                             f"(the ogive would bulge past the cylinder)")
        tangent = R <= r_tan * (1.0 + 1e-12)
        R = r_tan if tangent else R
    s_og = length - lo                          # the ogive's base plane
    sc_l, rc = _ogive_centre(a, b, lo, R, tangent)
    sc = s_og + sc_l
    beta_nose = float(np.arctan2(b - rc, length - sc))
    beta_join = 0.5 * np.pi if tangent else float(np.arctan2(a - rc, s_og - sc))
    rows = [[length, b, 0.0, 0.0, beta_nose],           # the point, or the meplat's rim
            [sc, rc, R, beta_nose, beta_join]]          # the ogive (rc < 0)
    if beta_join < 0.5 * np.pi:
        rows.append([s_og, a, 0.0, beta_join, 0.5 * np.pi])   # secant ogive / cylinder corner
    # (flat: the cylinder, normal angle 90 deg)
    if lb > 0:
        beta_bt = 0.5 * np.pi + th
        rows.append([lb, a, 0.0, 0.5 * np.pi, beta_bt])       # boattail start (corner)
        # (flat: the boattail cone, normal angle 90 deg + θ)
        rows.append([0.0, a - lb * np.tan(th), 0.0, beta_bt, np.pi])   # base rim (corner)
    else:
        rows.append([0.0, a, 0.0, 0.5 * np.pi, np.pi])        # base rim (corner)
    # (flat: the base disc)
    # the boattail length always (0 too: a square base must survive a preset's round trip)
    params = {"d_m": d, "length_m": length, "ogive_length_m": lo, "boattail_length_m": lb}
    if lb > 0:
        params["boattail_angle_rad"] = th
    if not tangent:
        params["ogive_radius_m"] = R
    if mp > 0:
        params["meplat_m"] = mp
    return make_body(KIND, name, np.array(rows), params, preset=preset, diameter_m=d)


def bullet_preset(preset: str, *, name: str | None = None, **overrides) -> Body:
    """The preset's body (:data:`PRESETS`), with any :func:`bullet` keyword overridden."""
    if preset not in PRESETS:
        raise ValueError(f"preset: {preset!r} is not one of {list(PRESETS)}")
    kw = dict(PRESETS[preset]) | {k: v for k, v in overrides.items() if v is not None}
    return bullet(name=name or preset, preset=preset, **kw)


__all__ = ["KIND", "M80_IN", "M80_MASS_G", "PRESETS", "bullet", "bullet_preset",
           "tangent_ogive_radius_m"]
