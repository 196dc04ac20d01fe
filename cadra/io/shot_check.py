"""Preflight of a shot: its shot file, its facility reference file and its images, checked
before stage one measures anything (``cadra1 --check``, docs/stage1.md)."""

from __future__ import annotations

import os


def check_shot(path: str | os.PathLike) -> list[str]:
    """Problems found in a shot file, its facility and its images (empty list = all good).

    One line per problem: the shot file or the facility file does not load (the first error,
    naming the key), a station the facility lacks, a view without an image, or an image that
    is missing, unreadable, not greyscale, or of another size or bit depth than its view
    declares.
    """
    import cv2

    from cadra.io.facility_file import load_facility
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
    problems = []
    for rec in shot.stations:
        station = by_id.get(rec.station)
        if station is None:
            problems.append(f"station {rec.station}: not in facility {facility.name!r}")
            continue
        for view_name, view in station.views.items():
            if view_name not in rec.images:
                problems.append(f"station {rec.station} {view_name}: no image listed")
                continue
            p = shot.image_path(rec.station, view_name)
            if not p.is_file():
                problems.append(f"station {rec.station} {view_name}: missing image {p}")
                continue
            img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
            if img is None:
                problems.append(f"station {rec.station} {view_name}: unreadable image {p}")
                continue
            if img.ndim != 2:
                problems.append(f"station {rec.station} {view_name}: {p} is not greyscale")
            elif img.shape != (view.height_px, view.width_px):
                problems.append(f"station {rec.station} {view_name}: {p} is "
                                f"{img.shape[1]}x{img.shape[0]} px, the view declares "
                                f"{view.width_px}x{view.height_px}")
            bits = {"uint8": 8, "uint16": 16}.get(str(img.dtype))
            if bits != view.bit_depth:
                problems.append(f"station {rec.station} {view_name}: {p} has dtype {img.dtype}"
                                f", the view declares {view.bit_depth}-bit")
    return problems


__all__ = ["check_shot"]
