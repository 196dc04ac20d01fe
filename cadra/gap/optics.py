"""Station effects of a facility's optics for the gap library (docs/gap.md): a point-source
view's spark off its surveyed distance from the film.

A spark surveyed ``delta`` too close to (or far from) the film changes the shadow's
magnification, so the lateral coordinates a view measures come out scaled about the spark's
foot: an error that grows with the model's offset (seed 004's HFFAF is collimated and has
none). Stage one solves each film's placement from the wires' shadows, cast by the same
spark, so part of the change is taken up by the film's affine; what is left depends on the
model's depth and offset from the wires. This module computes that response as stage one
would meet it, from the facility's own geometry: the shadows of the wires and of the model
cast by the spark moved, the affine solved from the wires
(:func:`cadra.facility.reference.fit_affine_to_wires`) with the spark where the facility
file puts it, the model's film point and axis image mapped with it, and the two views
combined (:func:`cadra.imaging.combine.combine_views`, stage one's own code). The response
is linear in ``delta`` over any plausible survey error; central differences of
:data:`SPARK_STEP_M`.

The geometry is the shot's facility (``ShotData.facility``, a bundled name or a file),
loaded once per name; a shot whose facility cannot be loaded, or has no point-source
stations, gets no spark candidates.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

from cadra.channels import NAMES as CHANNELS
from cadra.conventions import axis_from_inclinations

__all__ = ["SPARK_STEP_M", "film_view_pose", "point_source_facility", "spark_moved",
           "spark_response", "spark_responses"]

#: the spark displacement the response is differenced over, m
SPARK_STEP_M = 1e-4
#: the view-plane sigmas the two views are combined with (m, rad): equal weights, as stage
#: one's are near equal for the two views; the response hardly depends on them
_WEIGHTS = (3e-7, 3e-7, 3e-5)


@functools.lru_cache(maxsize=8)
def point_source_facility(name: str):
    """The facility named ``name`` (bundled or a file), or None when it cannot be loaded or
    has no point-source station."""
    from cadra.io.facility_file import load_facility

    if not name:
        return None
    try:
        fac = load_facility(name)
    except Exception:  # noqa: BLE001 - an unknown facility simply gets no candidates
        return None
    if not any(v.projection == "point_source" for s in fac.stations for v in s.views.values()):
        return None
    return fac


def spark_moved(view, delta_m: float):
    """``view`` with its spark ``delta_m`` farther from its film (the film where it was)."""
    k = view.sight_axis
    S = np.array(view.source_position_m, dtype=float)
    S[k] += delta_m * math.copysign(1.0, S[k])
    return replace(view, source_position_m=S, film_distance_m=view.film_distance_m + delta_m)


def film_view_pose(declared, true, r, axis):
    """The view pose stage one measures from an image cast by ``true`` (its spark), its film
    placement solved from the wires' shadows with ``declared``'s geometry."""
    from cadra.facility.reference import fit_affine_to_wires
    from cadra.imaging.combine import ViewPose

    M = fit_affine_to_wires(declared, true.wire_lines_px()).affine
    to_px = true.plane_to_image
    ends = true.optics().plane_point(np.array([r, r + 1e-3 * np.asarray(axis)]))
    px = ends @ to_px[:, :2].T + to_px[:, 2]
    film = px @ M[:, :2].T + M[:, 2]
    d = film[1] - film[0]
    return ViewPose(float(film[0, 0]), float(film[0, 1]), math.atan2(d[1], d[0]),
                    *_WEIGHTS, projection=declared.optics(M))


def spark_response(station, view_name: str, pose) -> np.ndarray:
    """d(x, y, z, theta, psi) / d(delta) (m and rad per m) of ``station``'s measured pose at
    the 3-D ``pose`` (x, y, z in m; theta, psi in rad, NaN for a sphere) when ``view_name``'s
    spark is ``delta`` farther from its film than the facility file says (module doc)."""
    from cadra.imaging.combine import combine_views

    r = np.asarray(pose[:3], dtype=float)
    angles = [0.0 if not math.isfinite(a) else float(a) for a in pose[3:5]]
    axis = axis_from_inclinations(*angles)

    fixed = {n: film_view_pose(v, v, r, axis) for n, v in station.views.items()
             if n != view_name}           # the other view: its spark where the file says

    def measured(delta):
        v = station.views[view_name]
        poses = {**fixed, view_name: film_view_pose(v, spark_moved(v, delta), r, axis)}
        p = combine_views(poses["top"], poses["side"])
        return np.array([p.x_m, p.y_m, p.z_m, p.theta_rad, p.psi_rad])

    return (measured(SPARK_STEP_M) - measured(-SPARK_STEP_M)) / (2 * SPARK_STEP_M)


def spark_responses(shots) -> dict:
    """For every point-source station and view of the shots' facilities: ``(station id, view
    name)`` -> ``((shot id, the 5 values of :func:`spark_response` at the shot's measured
    pose there), ...)``. Empty without a point-source facility."""
    pose_columns = [CHANNELS.index(c) for c in ("x", "y", "z", "theta", "psi")]
    out: dict = {}
    for sd in shots:
        fac = point_source_facility(sd.facility)
        if fac is None:
            continue
        by_id = {s.id: s for s in fac.stations}
        for i, st in enumerate(np.asarray(sd.stations, dtype=int)):
            station = by_id.get(int(st))
            pose = sd.meas[i, pose_columns]
            if station is None or not np.all(np.isfinite(pose[:3])):
                continue
            if any(v.projection != "point_source" for v in station.views.values()):
                continue
            for name in station.views:
                resp = spark_response(station, name, pose)
                out.setdefault((int(st), name), []).append((sd.shot_id, tuple(map(float, resp))))
    return {k: tuple(v) for k, v in out.items()}
