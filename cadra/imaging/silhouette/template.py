"""The body's outline template in one view and its pixel outline at a pose (stage one).

A :class:`Template` is the exact outline of the body (:func:`cadra.body.outline_polygon`) in a
view's plane at zero pose: the reference point at the origin, the projected axis along the
first view axis (view-plane metres, counter-clockwise), for one out-of-plane tilt of the axis
(seen by the other view; the outline depends on |cos| of the axis' angle to the line of
sight, so the tilt's sign does not matter). The pose of one view is ``(a, b, phi)``: the
reference point's view-plane coordinates and the in-plane axis angle from the first view axis
toward the second (top view: psi_p = atan2(a_y, a_x); side view: theta_p = atan2(a_z, a_x);
docs/conventions.md). :func:`outline_px` and :func:`pose_px` place it in the image through the
view's :class:`~cadra.optics.projection.Projection`. A finned body's outline depends on its
roll too (docs/bodies.md): its template is made at a given roll (``roll_rad``, about the nose
axis as ``conventions.quat_from_axis_roll`` defines it; docs/stage1.md, "Roll of a finned
body"), which :mod:`cadra.imaging.roll` measures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cadra.body import Body, FinnedBody, outline_polygon
from cadra.conventions import FLIP, quat_from_axis_roll, quat_to_matrix
from cadra.facility.reference import VIEW_AXES
from cadra.geometry import polygon_moments
from cadra.optics.projection import Projection

__all__ = ["Template", "make_conical_template", "make_template", "outline_px", "pose_px",
           "rot"]


@dataclass(frozen=True, eq=False)
class Template:
    """The body's outline in one view at zero pose: reference point at the origin, projected
    axis along the first view axis; view-plane metres, counter-clockwise."""

    outline_m: np.ndarray
    centroid_m: np.ndarray        # area centroid relative to the reference point
    area_m2: float
    tilt_rad: float
    axisymmetric_point: bool      # a sphere: the in-plane angle is not observable
    principal_is_axis: bool       # the body axis is the major (True) or minor principal axis
    #: a finned body's (its outline depends on the roll): no uniform edge offset is fitted to
    #: it (docs/stage1.md, "Wide edges")
    finned: bool = False


def make_template(body: Body | FinnedBody, view_name: str, tilt_rad: float = 0.0,
                  n_points: int = 1024, roll_rad: float = 0.0) -> Template:
    """Outline template of ``body`` for a view (``"top"``/``"side"``) at out-of-plane tilt
    and, for a finned body, roll (ignored by a body of revolution)."""
    axes = VIEW_AXES[view_name]
    P = np.zeros((2, 3))
    P[0, axes[0]] = 1.0
    P[1, axes[1]] = 1.0
    out_axis = 3 - axes[0] - axes[1]
    a = np.zeros(3)
    a[axes[0]] = math.cos(tilt_rad)
    a[out_axis] = math.sin(tilt_rad)
    R_FB = FLIP @ quat_to_matrix(quat_from_axis_roll(a, float(roll_rad)))
    poly = outline_polygon(body, R_FB, np.zeros(3), P, n_points=n_points)
    area, centroid, m2 = polygon_moments(poly)
    # principal axes of the outline: is the body axis (the first view axis) the major one?
    principal_is_axis = bool(m2[0, 0] >= m2[1, 1])
    return Template(outline_m=poly, centroid_m=centroid, area_m2=area, tilt_rad=float(tilt_rad),
                    axisymmetric_point=body.kind == "sphere",
                    principal_is_axis=principal_is_axis, finned=isinstance(body, FinnedBody))




def make_conical_template(body: Body | FinnedBody, projection: Projection, r_ref_F,
                          axis_F, n_points: int = 1024, roll_rad: float = 0.0,
                          tilt_rad: float = 0.0) -> Template:
    """Outline template of ``body``'s shadow in a point-source view, for the 3-D pose
    (reference point ``r_ref_F``, m, and unit nose axis ``axis_F``) it is expected at.

    Under a point source the shadow's size and shape follow the model's position, not only
    its attitude (docs/stage1.md, "Point-source views"): the template is the exact shadow
    (``projection.outline``) at that pose, moved to the film point of the reference point and
    turned so that the film image of the axis lies along the first view axis. The fitted
    ``(a, b, phi)`` is then the film point of the reference point and the film angle of the
    axis' image, which the two-view combination reads as rays from the sparks and planes
    through them. ``tilt_rad`` is recorded (the axis' tilt out of the film's plane)."""
    r = np.asarray(r_ref_F, dtype=float)
    a = np.asarray(axis_F, dtype=float)
    a = a / np.linalg.norm(a)
    R_FB = FLIP @ quat_to_matrix(quat_from_axis_roll(a, float(roll_rad)))
    ab0 = projection.plane_point(r)
    d = projection.plane_point_jacobian(r) @ a
    phi0 = math.atan2(d[1], d[0])
    poly = (projection.outline(body, R_FB, r, n_points=n_points) - ab0) @ rot(phi0)
    area, centroid, m2 = polygon_moments(poly)
    return Template(outline_m=poly, centroid_m=centroid, area_m2=area, tilt_rad=float(tilt_rad),
                    axisymmetric_point=body.kind == "sphere",
                    principal_is_axis=bool(m2[0, 0] >= m2[1, 1]),
                    finned=isinstance(body, FinnedBody))


def rot(phi: float) -> np.ndarray:
    """2x2 rotation by ``phi`` (rad)."""
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s], [s, c]])


def outline_px(template: Template, pose: tuple[float, float, float],
               projection: Projection) -> np.ndarray:
    """The template at ``pose = (a_m, b_m, phi_rad)`` in pixels ``(N, 2)`` (u, v)."""
    a, b, phi = pose
    plane = template.outline_m @ rot(phi).T + np.array([a, b])
    # a distorted view's (cadra.optics.distortion.DistortedProjection): edges cut first
    return getattr(projection, "polygon_from_plane", projection.from_plane)(plane)


def pose_px(pose, projection: Projection) -> tuple[np.ndarray, float]:
    """The reference point (px) and the image angle ``atan2(dv, du)`` of the nose direction
    of a view-plane pose ``(a, b, phi)``."""
    ref = projection.from_plane(np.array(pose[:2]))
    tip = projection.from_plane(np.array(pose[:2]) + 1e-3 * np.array([math.cos(pose[2]),
                                                                      math.sin(pose[2])]))
    return ref, math.atan2(tip[1] - ref[1], tip[0] - ref[0])
