"""``cadra2 motion TRAJECTORY [...] -o OUT_DIR``: the classic angular-motion reduction of a
range shot (docs/motion.md, "cadra2 motion"): :func:`cadra.flight.classic.analyse_shot` on
each shot, written and printed by :mod:`cadra.report.motion`.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from cadra.cli._format import HelpFormatter, add_verbosity, warn
from cadra.numfmt import pm

PROG = "cadra2 motion"
#: what a refused input raises (FitDataError and bad arguments are ValueErrors)
_REFUSED = (ValueError, KeyError, FileNotFoundError)


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``cadra2 motion`` on ``cadra2``'s subparsers."""
    p = sub.add_parser(
        "motion", help="epicyclic fit, linear-theory and K-B coefficients, yaw card",
        description="The classic angular-motion reduction of each shot: the angle of attack "
        "and sideslip relative to the mean flight path (axis inclinations minus the path's, "
        "from a polynomial fit of the cg positions), the epicyclic fit (tricyclic with "
        "--spin) with sigmas, the Nonplanar Ratio, C_L_alpha from the swerve, linear-theory "
        "C_m_alpha, C_mq + C_m_alpha_dot and C_mp_alpha with sigmas, and sectional fits with "
        "the Kryloff-Bogoliuboff reduction when the record holds enough cycles. Writes "
        "report.md, angles.csv, arms.csv, coefficients.csv and plots (yaw card, arms against "
        "distance, sectional coefficients against amplitude); docs/motion.md.",
        formatter_class=HelpFormatter)
    add_verbosity(p, top=False)
    p.set_defaults(func=run)
    p.add_argument("trajectories", nargs="+",
                   help="stage one's trajectory.csv files (or their directories)")
    p.add_argument("-o", "--output", required=True, help="output directory (must not exist)")
    p.add_argument("--shot", action="append",
                   help="shot file of each trajectory, same order (default: the one the "
                        "trajectory file names)")
    p.add_argument("--variable", choices=("distance", "time"), default="distance",
                   help="the fit's independent variable")
    p.add_argument("--spin", action="append", type=float, metavar="RAD_S",
                   help="the model's roll rate p, rad/s, right-handed about the nose (stage "
                        "one does not see roll): one value for every shot or one per "
                        "trajectory; gives the tricyclic fit (trim arm at p) and C_mp_alpha "
                        "(default: none, epicyclic fit)")
    p.add_argument("--offset", action="store_true",
                   help="fit a constant angle too (a fixed trim)")
    p.add_argument("--nonrolling", action="store_true",
                   help="seed 002's nonrolling-axis correction (docs/motion.md)")
    p.add_argument("--path-degree", type=int, default=2,
                   help="degree of the polynomials in time fitted to the cg positions for "
                        "the mean flight path")
    p.add_argument("--window", type=int, default=None,
                   help="points per sectional fit (default: 1.2 cycles of the slower arm, at "
                        "least 12)")
    p.add_argument("--step", type=int, default=None,
                   help="points between sections (default: a tenth of the window)")
    p.add_argument("--sigma-time-s", type=float, default=0.0,
                   help="spark-time sigma, s (adds V sigma_t to the x sigma)")
    p.add_argument("--min-sigma-position-m", type=float, default=0.0,
                   help="floor of the stage-one position sigmas, m")
    p.add_argument("--min-sigma-angle-deg", type=float, default=0.0,
                   help="floor of the stage-one angle sigmas, deg")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    return p


def _refused(exc: Exception) -> int:
    msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
    print(f"{PROG}: {msg}", file=sys.stderr)
    return 1


def _spins(args, n: int) -> list[float | None]:
    given = args.spin or []
    if len(given) not in (0, 1, n):
        raise ValueError(f"--spin: give one value for every shot or one per trajectory "
                         f"({n}), got {len(given)}")
    if any(not math.isfinite(v) for v in given):
        raise ValueError("--spin: must be finite")
    return [None] * n if not given else (given * n if len(given) == 1 else list(given))


def run(args) -> int:
    """``cadra2 motion`` (module doc); returns the exit status."""
    from tqdm import tqdm

    from cadra.flight.classic import analyse_shot
    from cadra.flight.load import load_shots
    from cadra.motion import MotionFitError

    quiet = bool(getattr(args, "quiet", False))
    verbose = bool(getattr(args, "verbose", False)) and not quiet
    out = Path(args.output)
    try:
        if args.path_degree < 1:
            raise ValueError(f"--path-degree: at least 1, got {args.path_degree}")
        shots, _ = load_shots(args.trajectories, args.shot, sigma_time_s=args.sigma_time_s,
                              min_sigma_position_m=args.min_sigma_position_m,
                              min_sigma_angle_deg=args.min_sigma_angle_deg)
        spins = _spins(args, len(shots))
        results = []
        for shot, spin in tqdm(list(zip(shots, spins, strict=True)), desc="motion",
                               disable=quiet or len(shots) < 2, file=sys.stderr, leave=False):
            if not shot.has_angles:
                raise ValueError(f"{shot.source.get('trajectory_file', shot.shot_id)}: no "
                                 "measured angles (theta, psi): nothing to reduce")
            try:
                results.append(analyse_shot(
                    shot, variable=args.variable, spin=spin, offset=args.offset,
                    nonrolling=args.nonrolling, degree=args.path_degree, window=args.window,
                    step=args.step))
            except MotionFitError as exc:
                raise ValueError(f"{shot.shot_id}: {exc}") from None
    except _REFUSED as exc:
        return _refused(exc)
    from cadra.cli._motion_output import console_lines, write_outputs

    files = write_outputs(results, out, overwrite=args.overwrite, command=vars(args))
    for r in results:
        for w in _warnings(r):
            warn(PROG, w)
    if not quiet:
        for line in console_lines(results, verbose=verbose):
            print(line)
    n_kb = sum(r.kb is not None for r in results)
    print(f"motion: {len(results)} shot(s) reduced ({results[0].fit.variable}); "
          f"linear-theory coefficients for {sum(r.coefficients is not None for r in results)}, "
          f"K-B reduction for {n_kb}")
    if not quiet:
        print(f"wrote {out}/ ({', '.join(files)})")
    return 0


def _warnings(r) -> list[str]:
    out = []
    if r.fit.chi2_dof > 2.0:
        out.append(f"{r.shot_id}: chi^2/dof = {r.fit.chi2_dof:.3g} > 2: the epicyclic form or "
                   "the angle sigmas do not describe the motion (sigmas scaled by it)")
    lc, spin = r.coefficients, r.conditions.spin_rad_s
    if lc is not None and spin and abs(lc.spin_from_fit - spin) > 3 * lc.spin_from_fit_sigma:
        out.append(f"{r.shot_id}: the arms' frequencies give a spin of "
                   f"{pm(lc.spin_from_fit, lc.spin_from_fit_sigma, 'rad/s')}, not the "
                   f"{spin:g} rad/s given")
    if not np.all(np.isfinite(r.fit.sigmas)):
        out.append(f"{r.shot_id}: some fitted constants are not determined by the data "
                   "(infinite sigma)")
    return out


__all__ = ["add_parser", "run"]
