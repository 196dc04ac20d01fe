"""What ``cadra2``'s subcommands share: the data options, the shots and model they name, every
input a command reads (for the output guard) and how a refused input is reported."""

from __future__ import annotations

import sys
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path

from cadra.cli._format import number, warn

#: what a refused input raises (FitDataError, SpecError, CalibrationError and a missing model
#: are ValueErrors; unknown parameter names KeyErrors)
REFUSED = (ValueError, KeyError, FileNotFoundError)


@dataclass(frozen=True)
class Command:
    """One ``cadra2`` subcommand: its name, the function that runs it (``run(args) -> exit
    status``), its one-line summary for ``cadra2 --help``, its description for ``cadra2 NAME
    --help`` and the function that adds its options to its parser."""

    name: str
    run: Callable
    summary: str
    description: str
    arguments: Callable


def quiet(args) -> bool:
    return bool(getattr(args, "quiet", False))


def verbose(args) -> bool:
    return bool(getattr(args, "verbose", False)) and not quiet(args)


def say(args, *lines: str) -> None:
    """Print unless -q (the result/status line is printed with plain ``print``)."""
    if lines and not quiet(args):
        print("\n".join(lines))


def refused(prog: str, exc: Exception) -> int:
    """Print why the input was refused; exit status 1."""
    msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
    print(f"{prog}: {msg}", file=sys.stderr)
    return 1


def add_data_options(p, *, model: bool = True) -> None:
    """Trajectories, output, shot files, holds/frees/bounds, iteration budget, sigma floors,
    --overwrite: what every fitting subcommand takes."""
    p.add_argument("trajectories", nargs="+",
                   help="stage one's trajectory.csv files (or their directories)")
    p.add_argument("-o", "--output", required=True, help="output directory (must not exist)")
    p.add_argument("--shot", action="append",
                   help="shot file of each trajectory, same order (default: the one the "
                        "trajectory file names)")
    if model:
        p.add_argument("--hold", action="append", metavar="NAME[=VALUE[+-SIGMA]]",
                       help="hold a parameter (at VALUE, in the model file's unit; +-SIGMA: "
                            "the value's uncertainty, carried into the free parameters' "
                            "sigmas as a consider covariance)")
        p.add_argument("--free", action="append", metavar="NAME",
                       help="free a held parameter")
        p.add_argument("--prior", action="append", metavar="NAME[=VALUE+-SIGMA]",
                       help="free a parameter with a Gaussian prior (VALUE +- SIGMA in the "
                            "model file's unit; NAME alone: its value and the model's sigma): "
                            "the Bayesian alternative to --hold NAME=VALUE+-SIGMA")
        p.add_argument("--bound", action="append", metavar="NAME=LO:HI",
                       help="bounds of a parameter (file unit; either side may be empty)")
        p.add_argument("--max-iterations", type=number(int, 1), default=60,
                       help="most Levenberg-Marquardt iterations per fit phase (a fit whose "
                            "data are finer than film level runs two phases: docs/cli.md)")
    p.add_argument("--sigma-time-s", type=number(float, 0.0, 1.0), default=0.0,
                   help="spark-time sigma, s (adds V sigma_t to the x sigma)")
    p.add_argument("--min-sigma-position-m", type=number(float, 0.0, 1.0), default=0.0,
                   help="floor of the stage-one position sigmas, m")
    p.add_argument("--min-sigma-angle-deg", type=number(float, 0.0, 90.0), default=0.0,
                   help="floor of the stage-one angle sigmas, deg")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")


def add_gun_options(parser) -> None:
    """--spin, --twist, --muzzle-velocity: the spin a shot was launched at, which no station
    shows (docs/spark_range.md); they override the shot file's ``[gun]`` table."""
    parser.add_argument("--spin", action="append", type=number(float), metavar="RAD_S",
                        help="the spin at launch, rad/s, right-handed about the nose: one for "
                             "every shot or one per trajectory (default: the shot file's "
                             "[gun] table)")
    parser.add_argument("--twist", action="append", type=number(float), metavar="IN_PER_TURN",
                        help="the gun's rifling twist, inches per turn (negative: left-hand): "
                             "the spin is 2 pi V / twist at the muzzle velocity; one for every "
                             "shot or one per trajectory")
    parser.add_argument("--muzzle-velocity", action="append", type=number(float, 0.0),
                        metavar="M_S",
                        help="the muzzle velocity for --twist, m/s (default: the shot file's, "
                             "else the speed measured in the range)")


def with_gun(args, shots: list) -> list:
    """``shots`` with the spin that --spin or --twist (and --muzzle-velocity) give (the shot
    files' own otherwise); a count that matches neither one nor the shots is refused."""
    from cadra.flight.data import with_launch_spin
    from cadra.units import M_PER_IN

    def per_shot(name):
        vals = getattr(args, name, None)
        if not vals:
            return [None] * len(shots)
        if len(vals) not in (1, len(shots)):
            raise ValueError(f"--{name.replace('_', '-')}: give one value for every shot or "
                             f"one per trajectory ({len(shots)}), not {len(vals)}")
        return list(vals) * len(shots) if len(vals) == 1 else list(vals)

    spins, twists, speeds = per_shot("spin"), per_shot("twist"), per_shot("muzzle_velocity")
    return [with_launch_spin(sd, spin_rad_s=p, twist_m_per_turn=None if tw is None
                             else tw * M_PER_IN, muzzle_velocity_m_s=v)
            for sd, p, tw, v in zip(shots, spins, twists, speeds, strict=True)]


def add_start_option(parser) -> None:
    add_gun_options(parser)
    parser.add_argument(
        "--start", choices=("auto", "linear", "epicyclic"), default="auto",
        help="where the starting values come from: 'linear', damped sines fitted to theta "
             "and psi (one frequency); 'epicyclic', the epicyclic fit's two arms and the "
             "spin they imply (a spinning body; the sign of C_m_alpha of a gyroscopically "
             "stable one); 'auto', the arms for a shot whose arms show a spin, the damped "
             "sines otherwise; a shot whose spin is known (--spin, --twist or the shot "
             "file's [gun]) starts from the arms put in the spin's frequency bands "
             "(docs/fitting.md, \"Starting values\")")


def model_of(args):
    """The aero model named by --model (bundled name or file) with
    --hold/--free/--bound/--prior."""
    from cadra.aero import resolve_model
    from cadra.fitting.inputs import apply_holds

    return apply_holds(resolve_model(args.model), getattr(args, "hold", None),
                       getattr(args, "free", None), getattr(args, "bound", None),
                       getattr(args, "prior", None))


def shots_of(args):
    """The shots named on the command line and their trajectory files; a facility a shot
    file names that cannot be found is warned about (a typo: the fit itself does not need
    the facility, a bias table and the report's provenance do)."""
    from cadra.flight.load import load_shots
    from cadra.io.facility_file import resolve_facility_path

    out = load_shots(args.trajectories, args.shot, sigma_time_s=args.sigma_time_s,
                     min_sigma_position_m=args.min_sigma_position_m,
                     min_sigma_angle_deg=args.min_sigma_angle_deg)
    out = (with_gun(args, out[0]), out[1])
    for name in sorted({s.facility for s in out[0] if s.facility}):
        try:
            found = resolve_facility_path(name).is_file()
        except (ValueError, OSError, KeyError):
            found = False
        if not found:
            warn(f"cadra2 {args.command}", f"the facility {name!r} the shot file names is not "
                 "found (a typo?); the fit goes on without it")
    return out


def input_paths(args) -> list[Path]:
    """Every file and folder the command reads, for the output guard (best effort: an input
    that cannot be read here is reported by the command itself, before it writes). The
    station history is an input of every command that may read it."""
    from cadra.io.facility_file import resolve_facility_path
    from cadra.io.shotfile import load_shot

    paths: list[Path] = []
    readable = (ValueError, KeyError, OSError)
    facilities: list[str] = []

    def facility(name: str) -> None:
        facilities.append(name)
        with suppress(*readable):
            paths.append(Path(resolve_facility_path(name)))

    if args.command == "simulate":
        from cadra.synthetic.simulate import load_shot_spec

        paths.append(Path(args.spec))
        with suppress(*readable):
            spec = load_shot_spec(args.spec)
            facility(spec.facility)
            if Path(spec.aero_model).exists():
                paths.append(Path(spec.aero_model))
        return paths + cache_paths()
    from cadra.flight.load import trajectory_and_shot

    given = args.shot or []
    paths += [Path(p) for p in (*args.trajectories, *given)]
    for k, item in enumerate(args.trajectories):
        with suppress(*readable):
            traj, shot_path = trajectory_and_shot(item, given[k] if k < len(given) else None)
            paths += [traj, shot_path]
            shot = load_shot(shot_path)
            paths += [shot.image_path(rec.station, view)
                      for rec in shot.stations for view in rec.images]
            facility(shot.facility)
    for name in ("model", "bias_table", "reference"):
        value = getattr(args, name, None)
        if value and Path(value).exists():
            paths.append(Path(value))
    if getattr(args, "model", None):       # a bundled model by name: its file in the package
        from cadra.aero.model import resolve_model_path

        with suppress(*readable):
            paths.append(Path(resolve_model_path(args.model)))
    paths += cache_paths()
    from cadra.calibration.bias_table import CURRENT

    if (args.command == "calibrate" or getattr(args, "bias_table", None) == CURRENT
            or getattr(args, "stations_root", None)):
        paths += _history_paths(getattr(args, "stations_root", None), facilities)
    return paths


def cache_paths() -> list[Path]:
    """CADRA's compiled-code cache folder (:mod:`cadra._numba_cache`), an input of every
    command: no output may be it or hold it."""
    import os

    folder = os.environ.get("NUMBA_CACHE_DIR")
    return [Path(folder)] if folder else []


def _history_paths(root, facilities) -> list[Path]:
    """The station history a command may read or append to, wherever its root comes from
    (``--stations-root``, ``$CADRA_STATIONS_ROOT`` or the default): the ``stations/`` folder,
    every facility's history file in it, and the history file of each facility the shots
    name, existing or not (a first calibration creates it, so no output may be its folder)."""
    from cadra.calibration.history import history_path, stations_root

    out: list[Path] = []
    with suppress(ValueError, KeyError, OSError):
        base = stations_root(root) / "stations"
        out.append(base)
        out += sorted(base.glob("*/bias_history.jsonl"))
        for name in facilities:
            with suppress(ValueError):
                out.append(history_path(root, name))
    return out


__all__ = ["REFUSED", "Command", "add_data_options", "add_start_option", "cache_paths",
           "input_paths", "model_of", "quiet", "refused", "say", "shots_of", "verbose"]
