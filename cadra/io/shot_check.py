"""Preflight of a shot: its shot file, its facility reference file and its images, checked
before stage one measures anything (``cadra1 --check``, docs/stage1.md)."""

from __future__ import annotations

import os

#: largest model size (diameter, length) as a fraction of a view's smaller field of view
MAX_FIELD_FRACTION = 0.5


def check_shot(path: str | os.PathLike) -> list[str]:
    """Problems found in a shot file, its facility and its images (empty list = all good).

    One line per problem: the shot file or the facility file does not load (the first error,
    naming the key), a station the facility lacks, an image of a view the station does not
    have (naming the known views), a view without an image, an image that is missing,
    unreadable, not greyscale, or of another size or bit depth than its view declares, or a
    model larger than half a view's field of view (:data:`MAX_FIELD_FRACTION`: a diameter in
    the wrong unit).
    """
    import numpy as np

    from cadra.io.facility_file import load_facility
    from cadra.io.images import load_station_image
    from cadra.io.shotfile import load_shot

    try:
        shot = load_shot(path)
    except (ValueError, OSError) as exc:
        return [f"shot file: {exc}"]
    try:
        facility = load_facility(shot.facility)
    except (ValueError, OSError) as exc:
        return [f"facility {shot.facility!r}: {exc}"]
    by_id = {s.id: s for s in facility.stations}
    problems = size_problems(shot, facility)
    for rec in shot.stations:
        station = by_id.get(rec.station)
        if station is None:
            problems.append(f"station {rec.station}: not in facility {facility.name!r}")
            continue
        for view_name in sorted(set(rec.images) - set(station.views)):
            problems.append(f"station {rec.station} images.{view_name}: unknown view (station "
                            f"{rec.station} of {facility.name!r} has views "
                            f"{', '.join(sorted(station.views))})")
        for view_name, view in station.views.items():
            if view_name not in rec.images:
                problems.append(f"station {rec.station} {view_name}: no image listed")
                continue
            p = shot.image_path(rec.station, view_name)
            img = load_station_image(p, view.width_px, view.height_px, view.bit_depth)
            if not isinstance(img, np.ndarray):
                problems.append(f"station {rec.station} {view_name}: {img.reason}: {p}")
    return problems


#: model-spec size keys (``cadra.io.shotfile.MODEL_SIZE_KEYS``) of each checked dimension
_SIZE_KEYS = {"diameter": ("d", "diameter"), "length": ("h", "length", "l")}


def size_problems(shot, facility) -> list[str]:
    """The model's diameter and length against the smallest field of view of the facility's
    views (:data:`MAX_FIELD_FRACTION`; a diameter 10x too large does not fit): one line per
    dimension that does not fit, naming the shot file's key, its value and the view's figures
    (width x height px at its scale). The one home of this check: ``cadra1 --check``
    (:func:`check_shot`), stage one and stage two (:func:`check_model_size`) all use it.
    A wind-tunnel record (``[test_mode]`` not ``range``) is not checked: its frames are not
    the range's shadowgraphs (a 2-in model on a roll bearing fills no HFFAF view)."""
    from cadra import units
    from cadra.body import body_from_spec

    if shot.test_mode.kind != "range":
        return []
    body = body_from_spec(shot.model)
    views = [(s.id, n, v) for s in facility.stations for n, v in s.views.items()]
    if not views:
        return []
    sid, name, view = min(views, key=lambda t: min(t[2].width_px, t[2].height_px)
                          * t[2].scale_m_per_px)
    fov = min(view.width_px, view.height_px) * view.scale_m_per_px
    out = []
    for what, size in (("diameter", body.diameter_m), ("length", body.length_m)):
        if size > MAX_FIELD_FRACTION * fov:
            keys = [f"model.{k} = {v!r}" for k, v in shot.model.items()
                    if (u := units.split_unit_key(k, "length")) and u[0] in _SIZE_KEYS[what]]
            if not keys and out:   # the length follows from the diameter already named
                continue
            key = keys[0] if keys else f"model ({what} set by the model's other keys)"
            out.append(f"{key}: the model's {what}, {size * 100:.4g} cm, is more than "
                       f"{MAX_FIELD_FRACTION:g} of the field of view of station {sid} {name} "
                       f"({fov * 100:.4g} cm: {view.width_px}x{view.height_px} px at "
                       f"{view.scale_m_per_px * 1e3:.4g} mm/px); a model that large cannot be "
                       f"measured: check the unit")
    return out


def check_model_size(shot, facility=None) -> None:
    """Raise :class:`~cadra.io.shotfile.ShotFileError` (naming the shot file, the key and the
    figures, :func:`size_problems`) when the model does not fit the facility's field of view.
    ``facility`` None: the shot's own (``load_facility(shot.facility)``, whose errors pass)."""
    from cadra.io.shotfile import ShotFileError

    if facility is None:
        from cadra.io.facility_file import load_facility

        facility = load_facility(shot.facility)
    problems = size_problems(shot, facility)
    if problems:
        where = f"{shot.source_path}: " if shot.source_path else ""
        raise ShotFileError(where + "; ".join(problems))


__all__ = ["MAX_FIELD_FRACTION", "check_model_size", "check_shot", "size_problems"]
