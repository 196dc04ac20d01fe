"""``cadra1``: stage one of the pipeline (shadowgraphs -> trajectory measurements).

Available now:

* ``cadra1 --check SHOT_FILE`` — preflight a shot: the shot file and its facility reference
  file load and validate, and every station image exists, is readable and has the size and bit
  depth its view declares. One line per problem; nothing is written.

Exit status: 0 all good, 1 problems found, 2 usage error.
"""

from __future__ import annotations

import argparse
import sys


def check_shot(path) -> list[str]:
    """Problems found in a shot file, its facility and its images (empty list = all good)."""
    import cv2

    from cadra.facility import load_facility
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="cadra1", description=__doc__.split("\n")[0])
    parser.add_argument("shot_file", help="shot file (TOML, docs/shot_file.md)")
    parser.add_argument("--check", action="store_true", required=True,
                        help="validate the shot, its facility and images (measuring images "
                             "is the stage-one issue, not yet in this version)")
    args = parser.parse_args(argv)
    problems = check_shot(args.shot_file)
    for p in problems:
        print(f"cadra1: {p}", file=sys.stderr)
    if not problems:
        print(f"cadra1: {args.shot_file}: shot file, facility and images OK")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
