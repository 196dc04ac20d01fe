"""Combine the top and side views of a station into a 3-D position and attitude.

Parallel projection (docs/conventions.md): the top view sees (x, y), the side view (x, z).
Each view measures the reference point's two view-plane coordinates and the in-plane angle of
the model's axis (top: psi_p = atan2(a_y, a_x); side: theta_p = atan2(a_z, a_x)). Downrange x is
seen twice: the weighted mean is reported, and the difference is a consistency figure.
The projected angles give the axis and so the seed-004 inclinations theta, psi.
Pure functions on plain numbers (SI, radians).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cadra.conventions import axis_from_projected_angles, inclinations_from_axis


@dataclass(frozen=True)
class ViewPose:
    """One view's measurement in its view plane: reference point (a, b), m, and the in-plane
    axis angle (from the first view-plane axis toward the second), rad, each with 1-sigma."""

    a_m: float
    b_m: float
    angle_rad: float
    sigma_a_m: float
    sigma_b_m: float
    sigma_angle_rad: float


@dataclass(frozen=True)
class StationPose:
    """A station's 3-D measurement (facility frame, SI) with 1-sigma and the x consistency."""

    x_m: float
    y_m: float
    z_m: float
    theta_rad: float
    psi_rad: float
    sigma_x_m: float
    sigma_y_m: float
    sigma_z_m: float
    sigma_theta_rad: float
    sigma_psi_rad: float
    x_top_minus_side_m: float
    x_consistency_sigma: float   # |x_top - x_side| / sqrt(s_top^2 + s_side^2)


def inclinations_from_views(theta_p: float, psi_p: float) -> tuple[float, float]:
    """(theta, psi) inclinations from the side-view and top-view projected angles."""
    return inclinations_from_axis(axis_from_projected_angles(theta_p, psi_p))


def combine_views(top: ViewPose, side: ViewPose) -> StationPose:
    """3-D pose from the two views (inverse-variance mean of x; first-order error propagation
    of the projected angles into theta, psi)."""
    w_top, w_side = 1.0 / top.sigma_a_m**2, 1.0 / side.sigma_a_m**2
    x = (w_top * top.a_m + w_side * side.a_m) / (w_top + w_side)
    sigma_x = 1.0 / np.sqrt(w_top + w_side)
    dx = top.a_m - side.a_m
    theta, psi = inclinations_from_views(side.angle_rad, top.angle_rad)
    # first-order propagation: d(theta, psi) / d(theta_p, psi_p), central differences
    h = 1e-7
    J = np.empty((2, 2))
    for j, (dtp, dpp) in enumerate(((h, 0.0), (0.0, h))):
        plus = inclinations_from_views(side.angle_rad + dtp, top.angle_rad + dpp)
        minus = inclinations_from_views(side.angle_rad - dtp, top.angle_rad - dpp)
        J[:, j] = (np.array(plus) - np.array(minus)) / (2 * h)
    C = J @ np.diag([side.sigma_angle_rad**2, top.sigma_angle_rad**2]) @ J.T
    return StationPose(
        x_m=float(x), y_m=float(top.b_m), z_m=float(side.b_m),
        theta_rad=float(theta), psi_rad=float(psi),
        sigma_x_m=float(sigma_x), sigma_y_m=float(top.sigma_b_m),
        sigma_z_m=float(side.sigma_b_m),
        sigma_theta_rad=float(np.sqrt(C[0, 0])), sigma_psi_rad=float(np.sqrt(C[1, 1])),
        x_top_minus_side_m=float(dx),
        x_consistency_sigma=float(abs(dx) / np.sqrt(top.sigma_a_m**2 + side.sigma_a_m**2)),
    )
