"""``cadra2 motion TRAJECTORY [...] -o OUT_DIR``: the classic angular-motion reduction of a
range shot (docs/motion.md, "cadra2 motion"): :func:`cadra.flight.classic.analyse_shot` on
each shot, written and printed by :mod:`cadra.report.motion`.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._format import number, warn
from cadra.cli._inputs import Command

PROG = "cadra2 motion"
RATES = ("d/2V", "d/V")


def _motion_arguments(p) -> None:
    cli.add_data_options(p, model=False)
    p.add_argument("--variable", choices=("distance", "time"), default="distance",
                   help="the fit's independent variable")
    cli.add_gun_options(p)
    p.add_argument("--trim", action=argparse.BooleanOptionalAction, default=None,
                   help="the tricyclic trim arm at the spin (default: with --spin, not with "
                        "--twist or a shot file's [gun]: a gun-launched body of revolution "
                        "has no trim, and on a spark range the arm aliases onto the others)")
    p.add_argument("--curvature", action="store_true",
                   help="the 12-constant form: each arm's frequency changes linearly along "
                        "the record (p / V grows along a long bullet record)")
    p.add_argument("--rates", choices=tuple(RATES), default=None,
                   help="the rate normalisation of the damping and Magnus coefficients "
                        "written: CADRA's d/2V (rates q d / 2V, p d / 2V) or McCoy's and "
                        "BRL's d/V (half the d/2V values) (default: the --model's, else d/2V)")
    p.add_argument("--model", default=None,
                   help="an aero model (bundled name or file) whose C_m_alpha tells apart "
                        "frequency bands of equal sum and whose rate normalisation is the "
                        "default of --rates (default: none)")
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


def run(args) -> int:
    """``cadra2 motion`` (module doc); returns the exit status."""
    from tqdm import tqdm

    from cadra.flight.classic import analyse_shot
    from cadra.flight.data import launch_spin
    from cadra.flight.estimates import estimate_motion
    from cadra.flight.starts import cm_alpha_of
    from cadra.motion import MotionFitError
    from cadra.report.motion import console_lines, write_outputs

    out = Path(args.output)
    try:
        if args.path_degree < 1:
            raise ValueError(f"--path-degree: at least 1, got {args.path_degree}")
        shots, _ = cli.shots_of(args)
        # the spins --spin, --twist or the shot files' [gun] give (cli.with_gun, in
        # shots_of); --spin keeps the tricyclic trim arm by default, a twist does not
        trim_default = bool(args.spin)
        model, rates = _model_and_rates(args)
        guess = None if model is None else cm_alpha_of(model)
        results = []
        for shot in tqdm(shots, desc="motion", disable=cli.quiet(args) or len(shots) < 2,
                         file=sys.stderr, leave=False):
            if not shot.has_angles:
                raise ValueError(f"{shot.source.get('trajectory_file', shot.shot_id)}: no "
                                 "measured angles (theta, psi): nothing to reduce")
            known = launch_spin(shot)
            if not math.isfinite(known) and math.isfinite(shot.twist_m_per_turn):
                known = launch_spin(shot, estimate_motion(shot).speed_m_s)   # twist alone
            spin = known if math.isfinite(known) else None
            trim = args.trim if args.trim is not None else trim_default
            try:
                results.append(analyse_shot(
                    shot, variable=args.variable, spin=spin, offset=args.offset,
                    nonrolling=args.nonrolling, degree=args.path_degree, window=args.window,
                    step=args.step, trim=trim and spin is not None,
                    curvature=args.curvature, cm_alpha_guess=guess))
            except MotionFitError as exc:
                raise ValueError(f"{shot.shot_id}: {exc}") from None
    except cli.REFUSED as exc:
        return cli.refused(PROG, exc)
    files = write_outputs(results, out, overwrite=args.overwrite, command=vars(args),
                          rates=rates)
    for r in results:
        for w in r.warnings:
            warn(PROG, w)
    if not cli.quiet(args):
        print("\n".join(console_lines(results, verbose=cli.verbose(args), rates=rates)))
    n_kb = sum(r.kb is not None for r in results)
    print(f"motion: {len(results)} shot(s) reduced ({results[0].fit.variable}); "
          f"linear-theory coefficients for {sum(r.coefficients is not None for r in results)}, "
          f"K-B reduction for {n_kb}")
    cli.say(args, f"wrote {out}/ ({', '.join(files)})")
    from cadra.stats import POOR_MINIMUM_P

    poor = [r.shot_id for r in results if r.fit.chi2_p_value < POOR_MINIMUM_P]
    if poor:
        print(f"{PROG}: POOR MINIMUM: the arms of {', '.join(poor)} leave residuals far above "
              f"the angle sigmas (p(chi^2) < {POOR_MINIMUM_P:g}; the warnings say where): not "
              "a reduction to use", file=sys.stderr)
        return 1
    return 0


def _model_and_rates(args):
    """The --model (or None) and the rate normalisation: --rates, else the model's own
    (a model whose reference says its rates are d / V, as the m80's), else d/2V."""
    if args.model is None:
        return None, args.rates or "d/2V"
    from cadra.aero import resolve_model

    model = resolve_model(args.model)
    own = str(model.reference.get("rate_normalisation", "")) if model.reference else ""
    default = "d/V" if "d / V" in own and "d / 2V" not in own else "d/2V"
    return model, args.rates or default


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
