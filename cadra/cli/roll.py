"""``cadra2 roll``: seed 003's global segmented fit of pure-roll records (docs/segmented_roll.md).

A finned model on a roll bearing at a fixed angle of attack (a shot file whose
``[test_mode]`` is ``roll_bearing``) measured in its roll angle phi, frame by frame (a
trajectory file with ``phi_deg``; theta and psi optional). The records are cut into segments
as the paper does, each with its own initial roll angle and rate, and fitted with one shared
coefficient set (:func:`cadra.studies.segmented_roll.segmented_fit`); written by
:func:`cadra.report.roll.write_roll`.
"""

from __future__ import annotations

import sys
from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._format import number
from cadra.cli._inputs import Command
from cadra.cli.fit import CHI2_WARN

PROG = "cadra2 roll"


def _roll_arguments(p) -> None:
    cli.add_data_options(p, model=False)
    p.add_argument("--model", default="seed003_romof",
                   help="aero model (bundled name or file) whose Cl is linear in the "
                        "stepped coefficients")
    p.add_argument("--alpha-deg", type=number(float, -90.0, 90.0), default=None,
                   help="the bearing's angle of attack, deg (default: from the measured "
                        "theta and psi)")
    p.add_argument("--window", type=number(int, 3), default=11,
                   help="frames of the smoothing filter that finds the zero-rate peaks")


def _roll_bearings_only(args) -> None:
    """Refuse, naming the shot file, a record whose shot file is not a roll bearing's."""
    from cadra.flight.load import trajectory_and_shot
    from cadra.io.shotfile import load_shot

    given = args.shot or []
    for k, item in enumerate(args.trajectories):
        _, shot_path = trajectory_and_shot(item, given[k] if k < len(given) else None)
        mode = load_shot(shot_path).test_mode
        if mode is None or mode.kind != "roll_bearing":
            kind = ("a free flight" if mode is None or mode.kind == "range"
                    else f"a {mode.kind!r} record")
            raise ValueError(f"{shot_path}: {kind}, not a roll bearing; cadra2 roll fits roll "
                             "bearings (the shot file's [test_mode] kind = 'roll_bearing')")


def run(args) -> int:
    """``cadra2 roll`` (module doc); returns the exit status."""
    from cadra.aero import resolve_model
    from cadra.report.roll import write_roll
    from cadra.studies.segmented_roll import (
        bearing_alpha,
        records_of,
        seed003_tables,
        segmented_fit,
        steady_spins,
    )

    try:
        if args.window < 5 or args.window % 2 == 0:
            raise ValueError(f"--window: an odd number of frames >= 5, got {args.window}")
        model = resolve_model(args.model)
        _roll_bearings_only(args)       # before the trajectories' own checks speak of positions
        shots, _ = cli.shots_of(args)
        alpha = bearing_alpha(shots, args.alpha_deg)
        records = records_of(shots)
        fit = segmented_fit(records, model, shots[0].rigid, alpha, window=args.window)
    except cli.REFUSED as exc:
        return cli.refused(PROG, exc)
    tables = seed003_tables(fit)
    res = fit.result
    out = Path(args.output)
    write_roll(fit, tables, records, alpha, out, overwrite=args.overwrite)
    for note in fit.notes:
        print(f"{PROG}: warning: {note}", file=sys.stderr)
    if res.poor_minimum:
        print(f"{PROG}: CONVERGED TO A POOR MINIMUM: p(chi^2) = {res.chi2_p_value:.2g}: the "
              f"residuals are far above the roll sigmas ({res.worst_residual()}); not a "
              "result to use", file=sys.stderr)
    elif res.converged and res.reduced_chi2 > CHI2_WARN:
        print(f"{PROG}: warning: chi^2/nu = {res.reduced_chi2:.3g} > {CHI2_WARN:g}: the roll "
              "sigmas or the model do not describe the record (sigmas too small?); the "
              "coefficients' sigmas are not to be trusted as they stand", file=sys.stderr)
    spins = steady_spins(res.model)
    spun = ", ".join(f"{v:+.4f}" + ("" if st else " (unstable)")
                     for v, st in zip(spins["p_hat"], spins["stable"], strict=True))
    print(f"roll: {len(records)} record(s), {len(fit.segments)} segments, {res.status}, "
          f"chi^2/dof {res.reduced_chi2:.3f}; steady spins p_hat: {spun or 'none'}")
    if not cli.quiet(args):
        print(f"wrote {out}/ (report.md, table2, table3, paper_table3, segments, steady_spins "
              "(.csv, .md), roll_fit.png)")
    # the best point is written, marked so
    return 0 if res.verdict == "converged" else 1


#: the subcommands this module runs
COMMANDS = (
    Command("roll", run, "seed 003's global segmented fit of pure-roll records",
            "Seed 003's (ROMOF) global nonlinear least-squares fit of the rolling "
            "motion of a finned model on a roll bearing: the records cut into segments, each with "
            "its own initial roll angle and rate, one coefficient set for all, fitted in the "
            "paper's steps (its start set, then the others 3-4 at a time) from equation-error "
            "starting values. Writes report.md, Tables 2 and 3 (coefficients, sigmas, "
            "signal/noise, correlations), the segments' bias, rms and runs of sign, the steady "
            "spins of the fitted coefficients, and roll_fit.png; docs/segmented_roll.md.",
            _roll_arguments),
)


__all__ = ["COMMANDS"]
