"""Stage one on a view whose image is distorted (docs/stage1.md, "Distorted images"): the
sigma a calibrated distortion's uncertainty puts on a view's pose; a distortion the facility
file does not declare, found from the bow of the wires and removed; the ideal image the
overlay is drawn on. The wires are fitted in the recorded image through the distortion
(:func:`cadra.imaging.wires.fit.measure_wires`), the silhouette through
:class:`cadra.optics.distortion.DistortedProjection`."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["BOW_PASSES", "add_bows", "bow_warning", "declare_bows", "distortion_pose_jacobian",
           "distortion_pose_sigma", "ideal_image", "undeclared_bows", "wires_miss_cause"]


def ideal_image(view, img):
    """``img`` with the view's distortion removed, for the overlay: resampled at ``D`` of
    every ideal pixel (:meth:`cadra.optics.distortion.Distortion.undistort_image`), where
    the wires are straight and the fitted lines, outline and reference point are drawn. The
    measurement itself never resamples: the wires and the silhouette are fitted in the
    recorded image, through the distortion (docs/stage1.md, "Distorted images"). Unchanged
    without a distortion (or for a loader's failure)."""
    if view.distortion is None or not isinstance(img, np.ndarray):
        return img
    return view.distortion.undistort_image(img)


def _line_points(wire) -> np.ndarray:
    """A found wire's points on its fitted line where its centres were used (the centres
    projected onto the line)."""
    c = np.asarray(wire.centres_px, float)
    p, t = np.asarray(wire.point_px, float), np.asarray(wire.direction_px, float)
    return p + ((c - p) @ t)[:, None] * t


def distortion_pose_jacobian(view, wires, pose, distortion) -> np.ndarray:
    """(3, 4) d(a, b, phi) / d(coefficient) of the view pose ``(a, b, phi)`` (m, m, rad)
    measured with ``wires`` when ``distortion``'s coefficients, which stage one removed,
    are off by ``dk``. Such an error moves every ideal point by ``F dk = -J^-1 B dk`` (``B``
    the recorded displacement per coefficient, :meth:`~cadra.optics.distortion.Distortion.
    basis`): the model's, and the wires' too, whose affine (re-solved here from their lines
    so moved, :func:`fit_affine_to_wires`) then takes up the part of the field it can. The
    pose's change is the difference."""
    from cadra.facility.reference import fit_affine_to_wires

    # each found wire as the centres its line was fitted to (stretches left out stay out):
    # the line moves with the field's mean over them, not its ends'
    by_name = {w.name: w for w in wires.wires if w.found}
    lines = [None if w.name not in by_name else _line_points(by_name[w.name])
             for w in view.wires]

    def field(points):                       # (..., 2, 4): ideal px per unit coefficient
        return -np.linalg.solve(distortion.jacobian(points), distortion.basis(points))

    def plane_pose(M, uv, t):                # plane point and direction angle of (uv, t)
        ab = M[:, :2] @ uv + M[:, 2]
        d = M[:, :2] @ t
        return ab, math.atan2(d[1], d[0])

    M0 = fit_affine_to_wires(view, lines).affine
    uv = wires.projection.from_plane(np.array(pose[:2], dtype=float))
    t = np.linalg.solve(M0[:, :2], np.array([math.cos(pose[2]), math.sin(pose[2])]))
    t /= np.linalg.norm(t)
    ab0, ang0 = plane_pose(M0, uv, t)
    h, step = 1e-6, 0.5                      # coefficient step; px along the axis
    F_uv = field(uv)
    dF = (field(uv + step * t) - field(uv - step * t)) / (2 * step)     # d field / d s
    G = np.zeros((3, 4))
    for j in range(4):
        moved = [None if ln is None else ln + h * field(ln)[..., j] for ln in lines]
        M1 = fit_affine_to_wires(view, moved).affine
        ab1, ang1 = plane_pose(M1, uv + h * F_uv[:, j], t + h * dF[:, j])
        G[:2, j] = (ab1 - ab0) / h
        G[2, j] = math.remainder(ang1 - ang0, 2 * math.pi) / h
    return G


def distortion_pose_sigma(view, wires, pose) -> tuple[float, float, float]:
    """The sigmas (m, m, rad) ``view``'s calibrated distortion (its coefficient covariance)
    puts on the view pose ``(a, b, phi)`` measured with ``wires``: the covariance carried by
    :func:`distortion_pose_jacobian`. Zeros without a distortion or its covariance."""
    distortion = view.distortion
    if distortion is None or distortion.covariance is None or wires.affine is None:
        return 0.0, 0.0, 0.0
    G = distortion_pose_jacobian(view, wires, pose, distortion)
    C = G @ distortion.covariance @ G.T
    return tuple(float(math.sqrt(max(C[i, i], 0.0))) for i in range(3))


#: passes a station is measured again in with the distortion its wires show: the first bow
#: is measured on straight predicted paths, a few hundredths off for a bow of pixels; each
#: pass measures what the last one left, along the curved paths
BOW_PASSES = 3


def add_bows(found: dict, bows: dict) -> dict:
    """The distortions ``found`` so far (view name -> ``WireBow``) with the residual ``bows``
    a measurement with them declared shows added (radial terms about one centre add to first
    order); the sigma is the last residual's, the ``k1`` before it being held."""
    from dataclasses import replace

    out = dict(found)
    for name, bow in bows.items():
        out[name] = replace(bow, k1=out[name].k1 + bow.k1) if name in out else bow
    return out


def undeclared_bows(station, views) -> dict:
    """The views of ``station`` that declare no distortion but whose wires, as measured
    (``views``: name -> :class:`cadra.imaging.view.ViewResult`, measured as declared or
    with a distortion found before), bow as one radial distortion bows them
    (:func:`cadra.imaging.wires.distortion.radial_from_centres`,
    :attr:`~cadra.imaging.wires.distortion.WireBow.found`): name -> the
    :class:`~cadra.imaging.wires.distortion.WireBow`. The wires' centres are measured to
    thousandths of a pixel, so a bow of a few hundredths is found before it biases the pose
    beyond its sigma; left alone, the straight-line fits of bowed wires, which leave their
    bent stretches out as a shock's, bias it by several (docs/stage1.md, "An undeclared
    distortion")."""
    from cadra.imaging.wires.distortion import radial_from_centres

    out = {}
    for name, result in views.items():
        view = station.views.get(name)
        wires = getattr(result, "wires", None)
        if view is None or view.distortion is not None or wires is None:
            continue
        bow = radial_from_centres(view, wires)
        if bow is not None and bow.found:
            out[name] = bow
    return out


def declare_bows(station, bows: dict):
    """``station`` with each view of ``bows`` declaring the distortion its wires show, its
    ``k1``'s variance as its covariance (so it reaches the pose's sigma)."""
    from dataclasses import replace

    views = dict(station.views)
    for name, bow in bows.items():
        v = views[name]
        views[name] = replace(v, distortion=bow.distortion(v.width_px, v.height_px))
    return replace(station, views=views)


def bow_warning(bow) -> str:
    """What a station's warnings say of a view measured with the distortion its wires
    showed."""
    return (f"its wires bow as a radial image distortion k1 = {bow.k1:.3g} +- "
            f"{bow.sigma_k1:.2g} ({bow.max_angle_deg:.2g} deg at most on a line's direction) "
            f"bows them, which the facility file does not declare: measured with it removed "
            f"(calibrate it: docs/calibration.md, \"Distortion from a grid\")")


def wires_miss_cause(found, limit_px: float) -> str:
    """Why a view's wires miss their surveyed lines beyond ``limit_px`` rms, given what
    removing a radial distortion does to them (``found``: a
    :func:`~cadra.imaging.wires.distortion.radial_from_wires` result, or None)."""
    if found is None:
        return "another station's or view's image?"
    removing = (f"removing a radial distortion k1 = {found.k1:.3g} ({found.max_angle_deg:.2g} "
                f"deg at most on a line's direction) brings them to {found.rms_after_px:.2g} px")
    if found.explains(limit_px):
        return (f"{removing}: an image distortion the facility file does not declare "
                f"(calibrate it: docs/calibration.md, \"Distortion from a grid\")")
    if found.rms_after_px < 0.5 * found.rms_before_px:
        return (f"{removing}, not within {limit_px:g}: an undeclared image distortion with "
                f"more than a radial term, or another station's or view's image?")
    return "another station's or view's image?"
