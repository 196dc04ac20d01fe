"""Station effects of a facility's optics for the gap library (docs/gap.md): a point-source
view's spark off its surveyed distance from the film, and a facility that declares parallel
optics for images cast by point sources.

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

A facility file that declares a view parallel when its images are shadows cast by a spark
(a direct shadowgraph) makes each point's magnification depend on its depth: what the view
measures is scaled about the spark's foot by ``(H - d_w) / (H - d)`` (``H`` the spark's
distance from the line of flight, ``d`` the point's depth and ``d_w`` the wires'), an error
that grows with the product of the model's offset and its depth. Its response
(:func:`perspective_response`) is that of ``kappa = 1 / H``: the view's images cast from a
spark on its sight axis through the image centre, the film placement solved from the wires
as the parallel file has them (:func:`film_view_pose`), first order in ``kappa`` (central
differences of :data:`PERSPECTIVE_STEP_PER_M`). Where the film lies does not enter at first
order: its part is an affine map of the view plane, which the wires' affine takes up. Two
more parameters per view complete it: a scale of the view about the spark's foot (a file
whose map is right at another depth than its wires', e.g. calibrated at the line of flight)
and the station's x, moved by the depth times the distance from the foot along x in the
share stage one gave that view's x (its weighting of the two views is not known here).
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

from cadra.channels import NAMES as CHANNELS
from cadra.conventions import axis_from_inclinations
from cadra.geometry import apply_affine

__all__ = ["PERSPECTIVE_STEP_PER_M", "SPARK_STEP_M", "film_view_pose", "parallel_facility",
           "perspective_response", "perspective_responses", "perspective_view",
           "point_source_facility", "spark_moved", "spark_response", "spark_responses"]

#: the spark displacement the response is differenced over, m
SPARK_STEP_M = 1e-4
#: the view-plane sigmas the two views are combined with (m, rad): equal weights, as stage
#: one's are near equal for the two views; the response hardly depends on them
_WEIGHTS = (3e-7, 3e-7, 3e-5)


#: the steps of 1 / (spark distance) the perspective response is differenced over, 1/m
PERSPECTIVE_STEP_PER_M = 1e-3
#: how far beyond the line of flight a hypothetical spark's film lies, m (it does not enter
#: the response at first order: module doc)
_FILM_BEYOND_M = 0.5


@functools.lru_cache(maxsize=8)
def _facility(name: str):
    from cadra.io.facility_file import load_facility

    if not name:
        return None
    try:
        return load_facility(name)
    except Exception:  # noqa: BLE001 - an unknown facility simply gets no candidates
        return None


def _loaded(name_or_facility):
    """A facility given as itself, or by name or file (None when it cannot be loaded)."""
    if name_or_facility is None or isinstance(name_or_facility, str):
        return _facility(name_or_facility or "")
    return name_or_facility


def point_source_facility(name):
    """The facility ``name`` (bundled or a file, or a facility itself), or None when it
    cannot be loaded or has no point-source station."""
    fac = _loaded(name)
    if fac is None or not any(v.projection == "point_source" for s in fac.stations
                              for v in s.views.values()):
        return None
    return fac


def parallel_facility(name):
    """The facility ``name`` (as :func:`point_source_facility` takes it), or None when it
    cannot be loaded or any of its views is not parallel."""
    fac = _loaded(name)
    if fac is None or not fac.stations or any(
            v.projection != "parallel" for s in fac.stations for v in s.views.values()):
        return None
    return fac


def spark_moved(view, delta_m: float):
    """``view`` with its spark ``delta_m`` farther from its film (the film where it was)."""
    k = view.sight_axis
    S = np.array(view.source_position_m, dtype=float)
    S[k] += delta_m * math.copysign(1.0, S[k])
    return replace(view, source_position_m=S, film_distance_m=view.film_distance_m + delta_m)


def film_view_pose(declared, true, r, axis, affine=None):
    """The view pose stage one measures from an image cast by ``true`` (its spark), its film
    placement solved from the wires' shadows with ``declared``'s geometry (or ``affine``, that
    solution made once)."""
    from cadra.imaging.combine import ViewPose

    M = _wire_affine(declared, true) if affine is None else affine
    to_px = true.plane_to_image
    ends = true.optics().plane_point(np.array([r, r + 1e-3 * np.asarray(axis)]))
    film = apply_affine(M, apply_affine(to_px, ends))
    d = film[1] - film[0]
    return ViewPose(float(film[0, 0]), float(film[0, 1]), math.atan2(d[1], d[0]),
                    *_WEIGHTS, projection=declared.optics(M))


def _wire_affine(declared, true):
    """The image -> plane affine solved from the wires' images cast by ``true``, with
    ``declared``'s geometry."""
    from cadra.facility.reference import fit_affine_to_wires

    return fit_affine_to_wires(declared, true.wire_lines_px()).affine


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


def _measured_stations(shots, facility, loader):
    """``(shot id, station, its measured pose (x, y, z, theta, psi))`` of every station of
    the shots measured where their facility (``facility`` for all, default each shot's own,
    loaded by ``loader``: None skips the shot) has it."""
    pose_columns = [CHANNELS.index(c) for c in ("x", "y", "z", "theta", "psi")]
    for sd in shots:
        fac = loader(sd.facility if facility is None else facility)
        if fac is None:
            continue
        by_id = {s.id: s for s in fac.stations}
        for i, st in enumerate(np.asarray(sd.stations, dtype=int)):
            station = by_id.get(int(st))
            pose = sd.meas[i, pose_columns]
            if station is not None and np.all(np.isfinite(pose[:3])):
                yield sd.shot_id, station, pose


def spark_responses(shots, facility=None) -> dict:
    """For every point-source station and view of the shots' facilities (``facility``, a
    facility or its name or file, for every shot: default each shot's own): ``(station id,
    view name)`` -> ``((shot id, the 5 values of :func:`spark_response` at the shot's
    measured pose there), ...)``. Empty without a point-source facility."""
    out: dict = {}
    for sid, station, pose in _measured_stations(shots, facility, point_source_facility):
        if any(v.projection != "point_source" for v in station.views.values()):
            continue
        for name in station.views:
            resp = spark_response(station, name, pose)
            out.setdefault((station.id, name), []).append((sid, tuple(map(float, resp))))
    return {k: tuple(v) for k, v in out.items()}


def _foot(view) -> np.ndarray:
    """A view's image centre in its view plane (m): where a direct shadowgraph's spark
    stands opposite its film."""
    return apply_affine(view.image_to_plane, view.image_centre_px)


def perspective_view(view, kappa_per_m: float):
    """A parallel ``view`` as a direct shadowgraph: the same image map and wires, its images
    cast from a spark on its sight axis through the image centre, ``1 / kappa_per_m`` from the
    line of flight (on the axis' negative side for a negative ``kappa_per_m``), the film
    :data:`_FILM_BEYOND_M` beyond the line of flight."""
    k = view.sight_axis
    S = np.zeros(3)
    S[list(view.axes)] = _foot(view)
    S[k] = 1.0 / kappa_per_m
    return replace(view, projection="point_source", source_position_m=S,
                   film_distance_m=abs(S[k]) + _FILM_BEYOND_M)


@functools.lru_cache(maxsize=4096)
def _perspective_affines(station, view_name: str):
    """``view_name`` of ``station`` as the two columns of :func:`perspective_response` see
    it, at + and -:data:`PERSPECTIVE_STEP_PER_M`: ``(kappa, scale)``, each the view its
    images are cast by and the wire affine they are mapped with (cast from a spark 1/step
    away, the affine re-solved from its wires; the view as it is, its affine scaled about the
    spark's foot)."""
    v = station.views[view_name]
    M, foot = np.asarray(_wire_affine(v, v), dtype=float), _foot(v)
    out = []
    for s in (1.0, -1.0):
        e = s * PERSPECTIVE_STEP_PER_M
        c = perspective_view(v, e)
        out.append(((c, _wire_affine(v, c)),
                    (v, np.column_stack([(1 + e) * M[:, :2], (1 + e) * M[:, 2] - e * foot]))))
    return out


_POSE_FIELDS = ("a_m", "b_m", "angle_rad")


@functools.lru_cache(maxsize=4096)
def _combine_jacobian(station):
    """d(x, y, z, theta, psi) / d(a, b, angle) of each view of a parallel ``station``, by
    stage one's :func:`cadra.imaging.combine.combine_views` at the station's point of the
    line of flight (central differences; for parallel views the map is linear in the
    positions and near linear in the angles at the small angles of a range)."""
    from cadra.imaging.combine import combine_views

    r, axis = np.array([station.x_m, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    base = {n: film_view_pose(v, v, r, axis) for n, v in station.views.items()}
    out = {}
    for n in station.views:
        cols = []
        for f in _POSE_FIELDS:
            h, vals = 1e-6, []
            for sgn in (1.0, -1.0):
                moved = replace(base[n], **{f: getattr(base[n], f) + sgn * h})
                p = combine_views(*(moved if m == n else base[m] for m in ("top", "side")))
                vals.append(np.array([p.x_m, p.y_m, p.z_m, p.theta_rad, p.psi_rad]))
            cols.append((vals[0] - vals[1]) / (2 * h))
        out[n] = np.column_stack(cols)
    return out


def perspective_response(station, view_name: str, pose) -> np.ndarray:
    """(3, 5): d(x, y, z, theta, psi) of a parallel ``station``'s measured pose at the 3-D
    ``pose`` (as :func:`spark_response`'s) per unit of each of three parameters of
    ``view_name`` (module doc): ``kappa`` (1/m) when its images are cast by a spark
    ``1 / kappa`` from the line of flight (row 0), a scale error of the view about the
    spark's foot (row 1: the file's map may be right at another depth than its wires'), both
    without x; and x moved by the point's depth times its distance from the foot along x
    (row 2, per m: how much of it reaches the station's x is ``kappa`` times the view's share
    in stage one's weighting of the two views' x, which the diagnosis does not know). The
    view's own pose is differenced; the two views' combination is stage one's, linearized at
    the station (:func:`_combine_jacobian`)."""
    r = np.asarray(pose[:3], dtype=float)
    angles = [0.0 if not math.isfinite(a) else float(a) for a in pose[3:5]]
    axis = axis_from_inclinations(*angles)
    v = station.views[view_name]
    d_view = np.empty((2, 3))
    for i, columns in enumerate(zip(*_perspective_affines(station, view_name), strict=True)):
        plus, minus = (film_view_pose(v, cast, r, axis, affine=M) for cast, M in columns)
        d_view[i] = [(getattr(plus, f) - getattr(minus, f)) / (2 * PERSPECTIVE_STEP_PER_M)
                     for f in _POSE_FIELDS]
    out = np.zeros((3, 5))
    out[:2] = d_view @ _combine_jacobian(station)[view_name].T
    out[:2, 0] = 0.0
    foot_x = _foot(v)[list(v.axes).index(0)]
    out[2, 0] = r[v.sight_axis] * (r[0] - foot_x)
    return out


def perspective_responses(shots, facility=None) -> dict:
    """For each view name of the shots' parallel facilities (``facility`` as
    :func:`spark_responses` takes it): ``view name`` -> the three columns of
    :func:`perspective_response`, each ``((shot id, station id, its 5 values at the shot's
    measured pose there), ...)``. Empty when no shot's facility is parallel (or can be
    loaded)."""
    out: dict = {}
    for sid, station, pose in _measured_stations(shots, facility, parallel_facility):
        for name in station.views:
            g = perspective_response(station, name, pose)
            cols = out.setdefault(name, ([], [], []))
            for c, col in enumerate(cols):
                col.append((sid, int(station.id), tuple(map(float, g[c]))))
    return {k: tuple(tuple(c) for c in v) for k, v in out.items()}
