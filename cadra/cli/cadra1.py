"""``cadra1``: stage one of the pipeline (shadowgraphs -> trajectory measurements).

* ``cadra1 SHOT_FILE [-o OUT_DIR]`` — measure every station (docs/stage1.md); outputs
  (trajectory.csv, quality.csv, trajectory.png, overlays/, report.md) go to OUT_DIR (default
  ``<shot dir>/cadra1``), written atomically, never over the inputs.
* ``cadra1 --check SHOT_FILE`` — preflight a shot: the shot file and its facility reference
  file load and validate, and every station image exists, is readable and has the size and bit
  depth its view declares. One line per problem; nothing is written.

``-q`` prints no progress bar, only the result line, warnings and errors (stderr); ``-v``
adds each station's measurement with its sigmas and every missing image of ``--check``;
``--version`` prints the version (docs/cli.md).

Exit status: 0 all stations measured, 1 some station failed (the others are still measured
and written), 2 the shot could not be processed at all (bad shot or facility file, a model
larger than half the field of view — a size in the wrong unit —, output
directory exists, an output that is or holds an input — shot file, facility file, image,
truth table — or the working folder, usage error), 130 interrupted (Ctrl-C: one line, no
traceback, nothing written), 141 stdout closed by its reader (``| head``; no traceback).
"""

from __future__ import annotations

import argparse
import sys

from cadra.cli._format import HelpFormatter, add_verbosity, add_version, console_main, number
from cadra.io.shot_check import check_shot

#: ``--check`` lists this many missing images (``-v``: all of them)
MISSING_SHOWN = 3


def main(argv: list[str] | None = None) -> int:
    """The ``cadra1`` console script (module doc); returns the exit status."""
    return console_main("cadra1", _main, argv)


def _main(argv: list[str] | None) -> int:
    parser = argparse.ArgumentParser(
        prog="cadra1",
        formatter_class=HelpFormatter,
        description="Stage one: measure the model's position and attitude in every station's "
                    "shadowgraphs (docs/stage1.md). Exit status: 0 all stations measured "
                    "(--check: all OK); 1 some station failed (the others are written; "
                    "--check: a problem found); 2 the shot could not be processed (bad shot "
                    "or facility file, unsafe output, usage error); 130 interrupted. See "
                    "docs/cli.md.")
    add_version(parser)
    parser.add_argument("shot_file", help="shot file (TOML, docs/shot_file.md)")
    parser.add_argument("-o", "--out", default=None,
                        help="output directory (default: <shot file's directory>/cadra1)")
    parser.add_argument("--check", action="store_true",
                        help="only validate the shot, its facility and images; write nothing")
    parser.add_argument("--workers", type=number(int, 1), default=None,
                        help="processes (default: all cores; 1 = no subprocesses)")
    parser.add_argument("--no-overlays", action="store_true", help="skip the overlay PNGs")
    parser.add_argument("--formation", choices=("view", "image", "centroid"), default="view",
                        help="fit the wires' image formation once per view over the shot's "
                             "images, each image then held to it unless its score test "
                             "rejects it (view, the default), or from each image alone "
                             "(image); centroid: no profile model, the wires' centroids "
                             "(a quick look: faster, the affine's sigma less honest)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an existing output directory (atomically, at the end)")
    parser.add_argument("--truth", default=None,
                        help="optional truth table (CSV with x_m, y_m, z_m, theta_deg, "
                             "psi_deg, e.g. a synthetic shot's truth.csv): drawn on the "
                             "trajectory plot and, with a station column, compared station "
                             "by station (report.md, truth_comparison.csv)")
    add_verbosity(parser)
    args = parser.parse_args(argv)
    if args.check:
        return _check(args)
    from pathlib import Path

    from cadra.atomic import check_output_dir
    from cadra.imaging.shot import measure_shot
    from cadra.io.shot_check import check_model_size
    from cadra.io.shotfile import load_shot
    from cadra.io.trajectory import load_truth
    from cadra.report.stage1 import write_stage1

    out = Path(args.out) if args.out else Path(args.shot_file).resolve().parent / "cadra1"
    try:
        check_output_dir(out, _input_paths(args), kind="stage one")  # never over an input
        if out.exists() and not args.overwrite:
            raise FileExistsError(f"{out} exists; refusing to overwrite (use --overwrite)")
        check_model_size(load_shot(args.shot_file))  # a size in the wrong unit: no measuring
        truth = load_truth(args.truth) if args.truth else None  # errors name row, column
        res = measure_shot(args.shot_file, workers=args.workers, progress=not args.quiet,
                           overlays=not args.no_overlays, formation=args.formation)
        write_stage1(res, out, truth=truth, overwrite=args.overwrite)
    except (ValueError, OSError) as exc:
        print(f"cadra1: {exc}", file=sys.stderr)
        return 2
    t = res.trajectory
    if args.verbose and not args.quiet:
        from cadra.report.stage1 import station_lines

        print("\n".join(station_lines(t)))
    n_fail = int((t["status"] == "failed").sum())
    n_warn = int((t["status"] == "warning").sum())
    for r in t.itertuples():
        if r.status == "failed":
            print(f"cadra1: station {r.station}: FAILED: {r.reason}", file=sys.stderr)
        elif r.status == "warning":
            print(f"cadra1: station {r.station}: warning: {r.warnings}", file=sys.stderr)
    print(f"cadra1: {len(t) - n_fail}/{len(t)} stations measured ({n_warn} with warnings) "
          f"in {res.seconds:.1f} s; wrote {out}/trajectory.csv, quality.csv, trajectory.png, "
          f"overlays/, report.md"
          + (", truth_comparison.csv" if (out / "truth_comparison.csv").is_file() else ""))
    return 1 if n_fail else 0


def _check(args) -> int:
    """``--check``: one line per problem on stderr; missing images are summarised (``-v``
    lists them all) with how they are rendered."""
    from pathlib import Path

    problems = check_shot(args.shot_file)
    missing = [p for p in problems
               if p.endswith(": no image listed") or ": missing image " in p]
    shown = missing if args.verbose else missing[:MISSING_SHOWN]
    for p in problems:
        if p not in missing or p in shown:
            print(f"cadra1: {p}", file=sys.stderr)
    if len(shown) < len(missing):
        print(f"cadra1: ... and {len(missing) - len(shown)} more stations' views without an "
              "image (-v lists them)", file=sys.stderr)
    if missing:
        shot_dir = Path(args.shot_file).resolve().parent
        sample = (f"python tools/make_sample_shots.py --images {shot_dir.name}"
                  if shot_dir.parent.name == "sample_shots"
                  else "python tools/make_sample_shots.py --images NAME")
        print(f"cadra1: hint: {len(missing)} station images are missing or not listed; images "
              f"are rendered, not committed: {sample} (a sample shot), or cadra2 simulate "
              "SPEC -o DIR (a shot specification)", file=sys.stderr)
    if not problems:
        print(f"cadra1: {args.shot_file}: shot file, facility and images OK")
    return 1 if problems else 0


def _input_paths(args) -> list:
    """Every file the run reads, for the output guard: shot file, truth table, images and
    facility file (best effort: a shot that cannot be read is reported when it is measured)."""
    from contextlib import suppress
    from pathlib import Path

    from cadra.io.facility_file import resolve_facility_path
    from cadra.io.shotfile import load_shot

    paths = [Path(args.shot_file)] + ([Path(args.truth)] if args.truth else [])
    with suppress(ValueError, KeyError, OSError):
        shot = load_shot(args.shot_file)
        paths += [shot.image_path(rec.station, view)
                  for rec in shot.stations for view in rec.images]
        paths.append(Path(resolve_facility_path(shot.facility)))
    from cadra.cli._inputs import cache_paths

    return paths + cache_paths()


__all__ = ["check_shot", "main"]


if __name__ == "__main__":
    sys.exit(main())
