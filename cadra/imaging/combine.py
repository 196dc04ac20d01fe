"""Combine the top and side views of a station into a 3-D position and attitude.

Each view measures the reference point's two view-plane coordinates and the in-plane angle of
the model's axis (top: psi_p = atan2(a_y, a_x); side: theta_p = atan2(a_z, a_x);
docs/conventions.md). The position is the weighted least-squares intersection of the two
views' rays through their measured points (:func:`cadra.optics.projection.intersect_rays`,
through each view's :class:`~cadra.optics.projection.Projection`). For the two orthogonal
parallel views of the default facility (top sees (x, y), side (x, z)) that is the
inverse-variance mean of x, seen twice, with y from the top view and z from the side view;
the x difference is a consistency figure. The in-plane angles give the axis (each view's
plane through its ray along the measured direction; the two planes meet in the axis) and so
the seed-004 inclinations theta, psi. Pure functions on plain numbers (SI, radians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cadra.conventions import axis_from_projected_angles, inclinations_from_axis
from cadra.facility.reference import VIEW_AXES
from cadra.optics.projection import ParallelProjection, Projection, intersect_rays

#: Stand-in projections for a ViewPose without one: the nominal parallel top and side views
#: (only their view planes matter to the combination; the image affine is the identity).
_DEFAULT_PROJECTIONS = {name: ParallelProjection.for_axes(axes, np.eye(2, 3))
                        for name, axes in VIEW_AXES.items()}


@dataclass(frozen=True)
class ViewPose:
    """One view's measurement in its view plane: reference point (a, b), m, and the in-plane
    axis angle (from the first view-plane axis toward the second), rad, each with 1-sigma;
    ``projection`` the view's optics (None: the nominal parallel view of its role, top or
    side)."""

    a_m: float
    b_m: float
    angle_rad: float
    sigma_a_m: float
    sigma_b_m: float
    sigma_angle_rad: float
    projection: Projection | None = None
    #: d(a_m, b_m, angle_rad) / d(tilt) of the view's fit (ViewFit.tilt_sensitivity): the
    #: tilt its template used comes from the other view's angle, whose error moves this pose
    tilt_sensitivity: tuple[float, float, float] = (0.0, 0.0, 0.0)


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
    #: roll about the nose axis (a finned body's; ``quat_from_axis_roll``'s roll), rad, and
    #: its sigma: set along the shot by cadra.imaging.shot (continuity, docs/stage1.md "Roll
    #: of a finned body"); NaN where not measured (a body of revolution)
    phi_rad: float = math.nan
    sigma_phi_rad: float = math.nan


def inclinations_from_views(theta_p: float, psi_p: float) -> tuple[float, float]:
    """(theta, psi) inclinations from the side-view and top-view projected angles (the
    nominal parallel views)."""
    return inclinations_from_axis(axis_from_projected_angles(theta_p, psi_p))


def axis_from_views(projections, plane_points, angles) -> np.ndarray:
    """Unit nose axis in F (a_x > 0) from two views' in-plane axis angles.

    View k sees the axis through its view-plane point ``plane_points[k]`` along the in-plane
    direction ``e_k = cos(phi_k) plane_basis[0] + sin(phi_k) plane_basis[1]``; the 3-D axis
    lies in the plane spanned by ``e_k`` and the view's ray there (normal ``e_k x d_k``), so it
    is the cross product of the two views' normals. For the nominal parallel views this is
    :func:`cadra.conventions.axis_from_projected_angles` (to rounding).
    """
    normals = []
    for proj, ab, phi in zip(projections, plane_points, angles, strict=True):
        e = math.cos(phi) * proj.plane_basis[0] + math.sin(phi) * proj.plane_basis[1]
        _, d = proj.plane_ray(np.asarray(ab, dtype=float))
        normals.append(np.cross(e, d))
    a = np.cross(normals[0], normals[1])
    a = a / np.linalg.norm(a)
    return -a if a[0] < 0 else a


def view_tilts(theta_p: float, psi_p: float) -> tuple[float, float]:
    """The axis' tilts out of the top and side view planes, (asin a_z, asin a_y), from the
    side-view and top-view projected angles: the tilts stage one builds each view's outline
    template at (cadra.imaging.station)."""
    a = axis_from_projected_angles(theta_p, psi_p)
    return math.asin(a[2]), math.asin(a[1])


def _tilt_propagated(top: ViewPose, side: ViewPose):
    """Each view's (a, b) covariance and angle sigma with the error of the tilt its template
    used: the tilt comes from the angles of both views (:func:`view_tilts`), and a tilt error
    e moves the view's pose by ``tilt_sensitivity * e`` (the outline's foreshortening moves
    the reference point along the projected axis; at 30 deg tilt ~7 mm per rad, about the
    pose's own sigma for the side view's 0.0015 deg angle error: docs/stage1.md, step 5).
    First order; the cross-covariances this makes (a view's position with the other view's
    angle) are left out of the per-channel sigmas."""
    h = 1e-7
    J = np.empty((2, 2))     # d(tilt_top, tilt_side) / d(theta_p, psi_p)
    for j, (dt, dp) in enumerate(((h, 0.0), (0.0, h))):
        plus = view_tilts(side.angle_rad + dt, top.angle_rad + dp)
        minus = view_tilts(side.angle_rad - dt, top.angle_rad - dp)
        J[:, j] = (np.array(plus) - np.array(minus)) / (2 * h)
    var_tilt = (J**2) @ np.array([side.sigma_angle_rad**2, top.sigma_angle_rad**2])
    covs, sig_angle = [], []
    for v, vt in zip((top, side), var_tilt, strict=True):
        s = np.asarray(v.tilt_sensitivity, dtype=float)
        covs.append(np.diag([v.sigma_a_m**2, v.sigma_b_m**2]) + np.outer(s[:2], s[:2]) * vt)
        sig_angle.append(math.sqrt(v.sigma_angle_rad**2 + s[2]**2 * vt))
    return covs, sig_angle


def combine_views(top: ViewPose, side: ViewPose) -> StationPose:
    """3-D pose from the two views: the position by the rays' weighted least-squares
    intersection (module docstring), the axis from the two views' planes through it
    (:func:`axis_from_views`) and so theta, psi, with first-order error propagation of the
    in-plane angles. ``x_top_minus_side_m`` is the x difference of the two rays' points
    closest to the intersection (for parallel views, of the two measured x), and
    ``x_consistency_sigma`` the square root of the intersection's chi-square (one degree of
    freedom: ``|x_top - x_side| / sqrt(s_top^2 + s_side^2)`` for parallel views)."""
    views = (top, side)
    projections = [v.projection if v.projection is not None else _DEFAULT_PROJECTIONS[name]
                   for v, name in zip(views, ("top", "side"), strict=True)]
    covs, sig_angle = _tilt_propagated(top, side)
    hit = intersect_rays(projections, [(v.a_m, v.b_m) for v in views], covs)
    sig = np.sqrt(np.diag(hit.cov))
    dx = hit.closest[0, 0] - hit.closest[1, 0]
    points = [(v.a_m, v.b_m) for v in views]

    def inclinations(theta_p, psi_p):
        return inclinations_from_axis(axis_from_views(projections, points, (psi_p, theta_p)))

    theta, psi = inclinations(side.angle_rad, top.angle_rad)
    # first-order propagation: d(theta, psi) / d(theta_p, psi_p), central differences
    h = 1e-7
    J = np.empty((2, 2))
    for j, (dtp, dpp) in enumerate(((h, 0.0), (0.0, h))):
        plus = inclinations(side.angle_rad + dtp, top.angle_rad + dpp)
        minus = inclinations(side.angle_rad - dtp, top.angle_rad - dpp)
        J[:, j] = (np.array(plus) - np.array(minus)) / (2 * h)
    C = J @ np.diag([sig_angle[1]**2, sig_angle[0]**2]) @ J.T
    return StationPose(
        x_m=float(hit.r_F[0]), y_m=float(hit.r_F[1]), z_m=float(hit.r_F[2]),
        theta_rad=float(theta), psi_rad=float(psi),
        sigma_x_m=float(sig[0]), sigma_y_m=float(sig[1]), sigma_z_m=float(sig[2]),
        sigma_theta_rad=float(np.sqrt(C[0, 0])), sigma_psi_rad=float(np.sqrt(C[1, 1])),
        x_top_minus_side_m=float(dx),
        x_consistency_sigma=float(np.sqrt(hit.chi2)),
    )
