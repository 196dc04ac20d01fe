"""Sphere and cone (the capsule has its own module, :mod:`cadra.body.capsule`).

Reference points (docs/bodies.md): sphere = centre; cone = centre of the base plane.
"""

from __future__ import annotations

import numpy as np

from cadra.body.model import Body, make_body


def sphere(d_m: float, *, name: str = "sphere") -> Body:
    """Sphere of diameter ``d_m``; reference point at the centre."""
    d = float(d_m)
    if not (np.isfinite(d) and d > 0):
        raise ValueError(f"d_m: must be a positive length, got {d_m!r}")
    arcs = np.array([[0.0, 0.0, 0.5 * d, 0.0, np.pi]])
    return make_body("sphere", name, arcs, {"d_m": d}, diameter_m=d)


def cone(d_m: float, half_angle_rad: float, *, nose_radius_m: float = 0.0,
         name: str = "cone") -> Body:
    """Right circular cone with a flat base; reference point at the centre of the base plane.

    Parameters
    ----------
    d_m : base diameter (the reference length d), m.
    half_angle_rad : cone half-angle θ, 0 < θ < 90 deg.
    nose_radius_m : optional spherical nose blunting, tangent to the flank (0: sharp apex).
        The length is then ``d/2/tan θ − r_n/sin θ + r_n``.
    name : body name.
    """
    d, th, rn = float(d_m), float(half_angle_rad), float(nose_radius_m)
    if not (np.isfinite(d) and d > 0):
        raise ValueError(f"d_m: must be a positive length, got {d_m!r}")
    if not (np.isfinite(th) and 0.0 < th < 0.5 * np.pi):
        raise ValueError(f"half_angle_rad: must lie in (0, pi/2), got {half_angle_rad!r}")
    if not (np.isfinite(rn) and rn >= 0.0):
        raise ValueError(f"nose_radius_m: must be >= 0, got {nose_radius_m!r}")
    if rn * np.cos(th) >= 0.5 * d:
        raise ValueError(f"nose_radius_m: {rn} m is too large for a {d} m base at "
                         f"{np.degrees(th):.3f} deg (the blunting would pass the base)")
    apex_s = 0.5 * d / np.tan(th)
    beta_flank = 0.5 * np.pi - th
    arcs = np.array([
        [apex_s - rn / np.sin(th), 0.0, rn, 0.0, beta_flank],  # apex (corner) or nose sphere
        # (flat: the flank)
        [0.0, 0.5 * d, 0.0, beta_flank, np.pi],                # base rim (corner)
        # (flat: the base disc)
    ])
    params = {"d_m": d, "half_angle_rad": th}
    if rn > 0:
        params["nose_radius_m"] = rn
    return make_body("cone", name, arcs, params, diameter_m=d)


__all__ = ["cone", "sphere"]
