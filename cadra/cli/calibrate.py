"""``cadra2 calibrate TRAJECTORY [...] -o OUT_DIR``: sphere calibration shots -> per-station
position and timing biases with sigmas (:func:`cadra.calibration.sphere.
estimate_station_biases`), compared with the facility's station history, to which the new
estimate is appended under its lock (:func:`cadra.calibration.history.append_compared`;
docs/calibration.md); written by :func:`cadra.report.calibration.write_calibration`.

Exit status 3: the outputs are written but the estimate is not in the station history (the
message says why)."""

from __future__ import annotations

import sys
from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._format import number, warn
from cadra.cli._inputs import Command


def _calibrate_arguments(p) -> None:
    cli.add_data_options(p)
    p.add_argument("--stations-root", default=None, metavar="DIR",
                   help="directory holding stations/<facility>/ (default: "
                        "$CADRA_STATIONS_ROOT, else the repository root beside facilities/; "
                        "'.' for the working folder)")
    p.add_argument("--no-history", action="store_true",
                   help="do not append the estimate to the station history")
    p.add_argument("--threshold-sigma", type=number(float, 0.0, above=True), default=3.0,
                   help="a station is flagged when its bias moved by more than this many "
                        "sigma")
    p.add_argument("--note", default="", help="a note stored with the history entry")


def run(args) -> int:
    """``cadra2 calibrate`` (module doc); returns the exit status."""
    from cadra.calibration.bias_table import shots_facility
    from cadra.calibration.history import (
        StationHistoryError,
        append_compared,
        compare,
        history_path,
        load_history,
        stations_root,
    )
    from cadra.calibration.sphere import CalibrationError, estimate_station_biases
    from cadra.report.calibration import station_lines, write_calibration

    out = Path(args.output)
    try:
        root = stations_root(args.stations_root)
        shots, _ = cli.shots_of(args)
        facility = shots_facility(shots, CalibrationError)
        history, hist_warnings = load_history(root, facility)  # refuse a bad history early
        est = estimate_station_biases(shots, facility=facility)
    except cli.REFUSED as exc:
        return cli.refused("cadra2 calibrate", exc)
    table = est.to_table(note=args.note or "")
    hfile = None if args.no_history else history_path(root, facility)
    entry = failed = None
    if hfile is not None:
        # read, date, compare and append under the history's lock; the report comes after
        try:
            rec = append_compared(table, root, threshold_sigma=args.threshold_sigma)
        except (StationHistoryError, OSError) as exc:
            failed = " ".join(str(exc).split())  # one line
        else:
            table, history, hist_warnings, entry = rec.table, rec.history, rec.warnings, rec.entry
            comparison = rec.comparison
    if hfile is None or failed is not None:
        comparison = compare(table, history, threshold_sigma=args.threshold_sigma)
    try:
        write_calibration(est, table, comparison, history, out, warnings=hist_warnings,
                          history_file=hfile, entry=entry, append_error=failed,
                          overwrite=args.overwrite)
    except KeyboardInterrupt:      # Ctrl-C or SIGTERM after the append: say what stands
        if entry is not None:
            print(f"cadra2 calibrate: the estimate IS recorded in {hfile} as entry {entry}; "
                  f"its report ({out}) was not written", file=sys.stderr)
        raise
    except OSError as exc:
        done = f" (the estimate IS recorded: {hfile}, entry {entry})" if entry else ""
        print(f"cadra2 calibrate: writing {out} failed: {' '.join(str(exc).split())}{done}",
              file=sys.stderr)
        return 3
    head = (f"{facility}: station biases from {len(shots)} sphere shot(s) "
            f"(speeds {', '.join(f'{v:.0f}' for v in est.shot_speeds_m_s)} m/s)")
    if entry is None and failed is None:   # -q: the one status line (else the history's)
        print(head)
    else:
        cli.say(args, head)
    cli.say(args, *station_lines(table, args.threshold_sigma))
    for w in (*est.warnings, *hist_warnings):
        warn("cadra2 calibrate", w)
    cli.say(args, f"wrote {out}/ (bias_table.csv, comparison.csv, biases.png, report.md)")
    if failed is not None:
        print(f"cadra2 calibrate: NOT recorded in the station history: {failed}",
              file=sys.stderr)
        return 3
    if entry is not None:
        print(f"recorded in {hfile} as entry {entry} (compared with the {entry - 1} before it)")
    return 0


#: the subcommands this module runs
COMMANDS = (
    Command("calibrate", run, "station biases from sphere calibration shots",
            "Sphere calibration: per-station position and timing biases with sigmas, compared "
            "with the facility's station history, to which the estimate is appended "
            "(docs/calibration.md). Exit status 3: the outputs are written but the estimate is "
            "not in the station history (the message says why).",
            _calibrate_arguments),
)


__all__ = ["COMMANDS"]
