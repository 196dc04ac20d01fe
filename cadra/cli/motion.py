"""``cadra2 motion TRAJECTORY [...] -o OUT_DIR``: the classic angular-motion reduction of a
range shot (docs/motion.md, "cadra2 motion"): :func:`cadra.flight.classic.analyse_shot` on
each shot, written and printed by :mod:`cadra.report.motion`.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._format import number, warn
from cadra.cli._inputs import Command

PROG = "cadra2 motion"


def _motion_arguments(p) -> None:
    cli.add_data_options(p, model=False)
    p.add_argument("--variable", choices=("distance", "time"), default="distance",
                   help="the fit's independent variable")
    p.add_argument("--spin", action="append", type=number(float), metavar="RAD_S",
                   help="the model's roll rate p, rad/s, right-handed about the nose (stage "
                        "one does not see roll): one value for every shot or one per "
                        "trajectory; gives the tricyclic fit (trim arm at p) and C_mp_alpha "
                        "(default: none, epicyclic fit)")
    p.add_argument("--offset", action="store_true",
                   help="fit a constant angle too (a fixed trim)")
    p.add_argument("--nonrolling", action="store_true",
                   help="seed 002's nonrolling-axis correction (docs/motion.md)")
    p.add_argument("--path-degree", type=number(int, 0, 6), default=2,
                   help="degree of the polynomials in time fitted to the cg positions for "
                        "the mean flight path")
    p.add_argument("--window", type=number(int, 3), default=None,
                   help="points per sectional fit (default: 1.2 cycles of the slower arm, at "
                        "least 12)")
    p.add_argument("--step", type=number(int, 1), default=None,
                   help="points between sections (default: a tenth of the window)")


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
    from cadra.motion import MotionFitError
    from cadra.report.motion import console_lines, write_outputs

    out = Path(args.output)
    try:
        if args.path_degree < 1:
            raise ValueError(f"--path-degree: at least 1, got {args.path_degree}")
        shots, _ = cli.shots_of(args)
        spins = _spins(args, len(shots))
        results = []
        for shot, spin in tqdm(list(zip(shots, spins, strict=True)), desc="motion",
                               disable=cli.quiet(args) or len(shots) < 2, file=sys.stderr,
                               leave=False):
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
    except cli.REFUSED as exc:
        return cli.refused(PROG, exc)
    files = write_outputs(results, out, overwrite=args.overwrite, command=vars(args))
    for r in results:
        for w in r.warnings:
            warn(PROG, w)
    if not cli.quiet(args):
        print("\n".join(console_lines(results, verbose=cli.verbose(args))))
    n_kb = sum(r.kb is not None for r in results)
    print(f"motion: {len(results)} shot(s) reduced ({results[0].fit.variable}); "
          f"linear-theory coefficients for {sum(r.coefficients is not None for r in results)}, "
          f"K-B reduction for {n_kb}")
    cli.say(args, f"wrote {out}/ ({', '.join(files)})")
    return 0


#: the subcommands this module runs
COMMANDS = (
    Command("motion", run, "epicyclic fit, linear-theory and K-B coefficients, yaw card",
            "The classic angular-motion reduction of each shot: the angle of attack "
            "and sideslip relative to the mean flight path (axis inclinations minus the path's, "
            "from a polynomial fit of the cg positions), the epicyclic fit (tricyclic with "
            "--spin) with sigmas, the Nonplanar Ratio, C_L_alpha from the swerve, linear-theory "
            "C_m_alpha, C_mq + C_m_alpha_dot and C_mp_alpha with sigmas, and sectional fits with "
            "the Kryloff-Bogoliuboff reduction when the record holds enough cycles. Writes "
            "report.md, angles.csv, arms.csv, coefficients.csv and plots (yaw card, arms against "
            "distance, sectional coefficients against amplitude); docs/motion.md.",
            _motion_arguments),
)


__all__ = ["COMMANDS"]
