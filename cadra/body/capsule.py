"""The Orion-like capsule of seed 004 (Fig. 6, Table 1): outer mold line from (d, h, R1, R2, l1).

Fig. 6 dimensions the OML with five numbers: maximum diameter d, length h (heat shield to base),
heat-shield sphere radius R1, fore and aft shoulder radius R2, and l1, the axial distance from
the afterbody cone's *virtual apex* (behind the base) to the junction of the cone and the aft
R2 torus. The afterbody cone half-angle θc is not given; it follows from h. With s measured
from the virtual apex toward the nose and ρ_t = d/2 − R2 (docs/bodies.md has the sketch):

* fore-shoulder torus centre (s_t, ρ_t), tangent to the cone r = s tan θc:
  ``s_t sin θc − ρ_t cos θc = R2``;
* heat-shield sphere centre on the axis, internally tangent to that torus:
  ``s_c = s_t − sqrt((R1 − R2)² − ρ_t²)``, nose ``s_n = s_c + R1``;
* aft torus centre (s_a, ρ_a), tangent to the cone at the junction s = l1:
  ``s_a − R2 sin θc = l1``, ``s_a sin θc − ρ_a cos θc = R2``; flat base ``s_b = s_a − R2``
  (the aft torus is tangent to it);
* ``h = s_n − s_b`` fixes θc (h decreases monotonically with θc; solved by Brent's method).

The reference point is the centre of the maximum-diameter circle, s = s_t (the fore-shoulder
plane): see docs/bodies.md for why. Table 1's M1 and M2 have the same OML; M3 is the 42.7 %
scale model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cadra.body.model import Body, make_body

#: Seed 004 Table 1, "Model dimensions, nominal", cm (l2, d1, S: the lifting models' Mg/W
#: insert geometry, not part of the OML; None where the table says "N/A").
TABLE1_CM: dict[str, dict[str, float | None]] = {
    "M1": {"d": 3.557, "h": 2.338, "R1": 4.267, "R2": 0.178, "l1": 1.008,
           "l2": None, "d1": None, "S": None},
    "M2": {"d": 3.557, "h": 2.338, "R1": 4.267, "R2": 0.178, "l1": 1.008,
           "l2": 2.430, "d1": 1.118, "S": 0.038},
    "M3": {"d": 1.518, "h": 0.998, "R1": 1.822, "R2": 0.076, "l1": 0.431,
           "l2": 1.037, "d1": 0.477, "S": 0.016},
}

#: Preset names.
PRESETS = tuple(TABLE1_CM)

OML_KEYS = ("d", "h", "R1", "R2", "l1")


def preset_dimensions_m(preset: str) -> dict[str, float]:
    """Table 1 OML dimensions of ``preset`` in metres: keys d, h, R1, R2, l1."""
    if preset not in TABLE1_CM:
        raise ValueError(f"preset: {preset!r} is not one of {list(PRESETS)}")
    return {k: float(TABLE1_CM[preset][k]) * 1e-2 for k in OML_KEYS}


@dataclass(frozen=True)
class CapsuleOML:
    """The resolved capsule outer mold line. Axial stations ``*_s_m`` from the virtual apex
    (+ toward the nose), radii ``*_r_m`` from the axis, metres.

    Attributes
    ----------
    d_m, h_m, R1_m, R2_m, l1_m : the defining dimensions.
    theta_c_rad : afterbody cone half-angle θc.
    residual_m : (s_n − s_b) − h at the solution.
    shoulder_s_m : fore-torus centre s_t = the maximum-diameter plane (the reference point).
    torus_r_m : fore-torus centre radius ρ_t = d/2 − R2.
    sphere_centre_s_m, nose_s_m : heat-shield sphere centre and nose (s_c, s_n).
    cap_s_m, cap_r_m, cap_beta_rad : cap / fore-torus tangency (and its normal angle).
    cone_fore_s_m, cone_fore_r_m : cone / fore-torus tangency.
    junction_s_m, junction_r_m : cone / aft-torus tangency (junction_s_m = l1).
    aft_torus_s_m, base_r_m : aft-torus centre (s_a, ρ_a); ρ_a is the radius of the flat base.
    base_s_m : base plane s_b.
    """

    d_m: float
    h_m: float
    R1_m: float
    R2_m: float
    l1_m: float
    theta_c_rad: float
    residual_m: float
    shoulder_s_m: float
    torus_r_m: float
    sphere_centre_s_m: float
    nose_s_m: float
    cap_s_m: float
    cap_r_m: float
    cap_beta_rad: float
    cone_fore_s_m: float
    cone_fore_r_m: float
    junction_s_m: float
    junction_r_m: float
    aft_torus_s_m: float
    base_r_m: float
    base_s_m: float

    @property
    def nose_to_shoulder_m(self) -> float:
        """Axial distance from the nose to the maximum-diameter plane."""
        return self.nose_s_m - self.shoulder_s_m

    @property
    def shoulder_from_base_m(self) -> float:
        """Axial distance from the base plane to the maximum-diameter plane."""
        return self.shoulder_s_m - self.base_s_m


def _stations(theta: float, d: float, R1: float, R2: float, l1: float) -> dict[str, float]:
    st_, ct_ = np.sin(theta), np.cos(theta)
    rho_t = 0.5 * d - R2
    s_t = (R2 + rho_t * ct_) / st_
    s_c = s_t - np.sqrt((R1 - R2) ** 2 - rho_t**2)
    s_a = l1 + R2 * st_
    rho_a = (s_a * st_ - R2) / ct_
    return {"s_t": s_t, "rho_t": rho_t, "s_c": s_c, "s_n": s_c + R1, "s_a": s_a,
            "rho_a": rho_a, "s_b": s_a - R2}


def solve_capsule_oml(d_m: float, h_m: float, R1_m: float, R2_m: float,
                      l1_m: float) -> CapsuleOML:
    """Resolve the Fig. 6 OML: the afterbody half-angle θc that makes the length h.

    Raises ValueError (naming the dimension) if the five numbers cannot make a capsule: the
    heat-shield sphere must reach the shoulder torus (R1 − R2 > d/2 − R2 > 0), some θc in
    (0, 90) deg must give h, the cone must have non-negative length between the two tori and the
    flat base a non-negative radius.
    """
    d, h, R1, R2, l1 = (float(x) for x in (d_m, h_m, R1_m, R2_m, l1_m))
    for name, v in (("d_m", d), ("h_m", h), ("R1_m", R1), ("R2_m", R2), ("l1_m", l1)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name}: must be a positive length, got {v!r}")
    rho_t = 0.5 * d - R2
    if not rho_t > 0:
        raise ValueError(f"R2_m: the shoulder radius {R2} must be less than d/2 = {d / 2}")
    if not R1 - R2 > rho_t:
        raise ValueError(f"R1_m: the heat-shield radius {R1} must exceed d/2 = {d / 2}")

    def f(theta: float) -> float:
        st = _stations(theta, d, R1, R2, l1)
        return st["s_n"] - st["s_b"] - h

    lo, hi = 1e-9, 0.5 * np.pi - 1e-9
    f_lo, f_hi = f(lo), f(hi)
    if not (f_lo > 0 > f_hi):
        raise ValueError(f"h_m: no afterbody cone half-angle in (0, 90) deg gives h = {h} m "
                         f"with d={d}, R1={R1}, R2={R2}, l1={l1} m")
    from scipy.optimize import brentq  # here: scipy.optimize costs a process 0.5 s

    theta = brentq(f, lo, hi, xtol=1e-16, rtol=4 * np.finfo(float).eps, maxiter=200)
    st = _stations(theta, d, R1, R2, l1)
    sin_t, cos_t = np.sin(theta), np.cos(theta)
    cone_fore_s = st["s_t"] - R2 * sin_t
    if cone_fore_s < l1:
        raise ValueError(f"h_m: {h} m is too short for l1 = {l1} m: the conical afterbody "
                         f"would have negative length (theta_c = {np.degrees(theta):.3f} deg, "
                         f"fore-shoulder tangency at {cone_fore_s} m from the virtual apex)")
    if st["rho_a"] < 0:
        raise ValueError(f"l1_m: the flat base would have negative radius {st['rho_a']} m")
    beta_cap = float(np.arctan2(st["rho_t"], st["s_t"] - st["s_c"]))
    return CapsuleOML(
        d_m=d, h_m=h, R1_m=R1, R2_m=R2, l1_m=l1, theta_c_rad=float(theta),
        residual_m=float(st["s_n"] - st["s_b"] - h),
        shoulder_s_m=float(st["s_t"]), torus_r_m=float(st["rho_t"]),
        sphere_centre_s_m=float(st["s_c"]), nose_s_m=float(st["s_n"]),
        cap_s_m=float(st["s_c"] + R1 * np.cos(beta_cap)), cap_r_m=float(R1 * np.sin(beta_cap)),
        cap_beta_rad=beta_cap,
        cone_fore_s_m=float(cone_fore_s), cone_fore_r_m=float(st["rho_t"] + R2 * cos_t),
        junction_s_m=l1, junction_r_m=float(l1 * np.tan(theta)),
        aft_torus_s_m=float(st["s_a"]), base_r_m=float(st["rho_a"]), base_s_m=float(st["s_b"]),
    )


def capsule_arcs(oml: CapsuleOML) -> np.ndarray:
    """Meridian arc table of the capsule, s from the reference point (the shoulder plane)."""
    s0 = oml.shoulder_s_m
    beta_cone = 0.5 * np.pi + oml.theta_c_rad
    return np.array([
        [oml.sphere_centre_s_m - s0, 0.0, oml.R1_m, 0.0, oml.cap_beta_rad],   # heat shield
        [0.0, oml.torus_r_m, oml.R2_m, oml.cap_beta_rad, beta_cone],          # fore shoulder
        # (flat: the conical afterbody, normal angle 90 deg + theta_c)
        [oml.aft_torus_s_m - s0, oml.base_r_m, oml.R2_m, beta_cone, np.pi],   # aft shoulder
        # (flat: the base disc)
    ])


def capsule(preset: str | None = "M2", *, d_m: float | None = None, h_m: float | None = None,
            R1_m: float | None = None, R2_m: float | None = None, l1_m: float | None = None,
            name: str | None = None) -> Body:
    """Seed 004 capsule (Fig. 6 OML), reference point at the centre of the maximum-diameter
    circle (docs/bodies.md).

    Parameters
    ----------
    preset : ``"M1"``, ``"M2"``, ``"M3"`` (Table 1 nominal dimensions) or None (then all five
        dimensions are required).
    d_m, h_m : measured diameter and length (Table 2 gives them per shot), m. With a preset, a
        given d scales the preset's R1, R2, l1 (and h, unless given) by d / d_nominal: the
        per-shot model is taken as geometrically similar to the design, with its own length.
    R1_m, R2_m, l1_m : explicit Fig. 6 dimensions, m (override the preset's).
    name : defaults to the preset name, else ``"capsule"``.
    """
    if preset is not None:
        nominal = preset_dimensions_m(preset)
        scale = 1.0 if d_m is None else float(d_m) / nominal["d"]
        dims = {k: v * scale for k, v in nominal.items()}
        if d_m is not None:
            dims["d"] = float(d_m)
    else:
        dims = {}
    for key, value in (("d", d_m), ("h", h_m), ("R1", R1_m), ("R2", R2_m), ("l1", l1_m)):
        if value is not None:
            dims[key] = float(value)
        elif key not in dims:
            raise ValueError(f"{key}_m: required when no preset is given")
    oml = solve_capsule_oml(dims["d"], dims["h"], dims["R1"], dims["R2"], dims["l1"])
    params = {"d_m": oml.d_m, "h_m": oml.h_m, "R1_m": oml.R1_m, "R2_m": oml.R2_m,
              "l1_m": oml.l1_m}
    return make_body("capsule", name or preset or "capsule", capsule_arcs(oml), params,
                     preset=preset, oml=oml, diameter_m=oml.d_m)


def axial_offset_from_virtual_apex(body: Body, x_from_apex_m: float) -> float:
    """Axial coordinate from the reference point (m, + toward the nose) of a point given from
    the capsule's virtual apex (seed 004 quotes the design cg as 0.676 d "from the apex")."""
    if body.oml is None:
        raise ValueError(f"body {body.name!r} is a {body.kind}: it has no virtual apex")
    return float(x_from_apex_m - body.oml.shoulder_s_m)


__all__ = ["OML_KEYS", "PRESETS", "TABLE1_CM", "CapsuleOML", "axial_offset_from_virtual_apex",
           "capsule", "capsule_arcs", "preset_dimensions_m", "solve_capsule_oml"]
