"""``cadra2 plan TRAJECTORY [TRAJECTORY ...] --model MODEL -o OUT_DIR --angle-deg LO:HI ...``:
what to fire next. The shots are fitted as ``cadra2 fit`` fits them; candidate shots built
from one of them and launched within the given ranges are then ranked by the information they
would add (:mod:`cadra.studies.design`, docs/design.md), written by
:func:`cadra.report.design.write_plan`."""

from __future__ import annotations

from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._inputs import Command
from cadra.studies.candidates import DIMENSIONS

#: each candidate dimension's option help (the option is the dimension's name with dashes)
_RANGE_HELP = {
    "angle_deg": "total angle between the nose axis and the flight path at launch, deg",
    "rate_deg_s": "transverse angular rate at launch, deg/s",
    "mach": "Mach number at launch",
    "roll_deg": "roll angle about the nose axis at launch, deg (0: body z down)",
    "cg_shift_mm": "axial cg shift from the template's, mm (+ toward the nose)",
    "stations": "number of stations (the template's first ones)",
}


def _range(text: str) -> tuple[float, float]:
    """``LO:HI`` or one value (fixed)."""
    import argparse
    import math

    parts = text.split(":")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be LO:HI or a number, not {text!r}") from None
    if len(vals) not in (1, 2) or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"must be LO:HI or a number, not {text!r}")
    lo, hi = vals[0], vals[-1]
    if hi < lo:
        raise argparse.ArgumentTypeError(f"LO must not exceed HI, got {text!r}")
    return lo, hi


def _plan_arguments(p) -> None:
    cli.add_data_options(p)
    p.add_argument("--model", required=True, help="aero model (bundled name or file)")
    add_plan_options(p)


def add_plan_options(p) -> None:
    """The candidates' ranges and the plan's settings (``cadra2 plan``, ``cadra campaign
    plan``)."""
    for name in DIMENSIONS:
        p.add_argument(f"--{name.replace('_', '-')}", type=_range, default=None,
                       metavar="LO:HI", help=_RANGE_HELP[name] + " (default: the template's)")
    p.add_argument("--target", action="append", metavar="NAME",
                   help="a parameter whose sigma to reduce, repeatable (default: none, the whole "
                        "covariance: --criterion A)")
    p.add_argument("--criterion", choices=("sigmas", "A", "D"), default=None,
                   help="'sigmas': the targets' sigmas; 'A': every unknown's sigma "
                        "(A-optimal); 'D': the covariance's determinant (D-optimal)")
    p.add_argument("--plan-free", action="append", metavar="NAME",
                   help="a held parameter to treat as unknown in the plan, at its held value "
                        "(\"could more shots fix it?\"); it may also be a --target")
    p.add_argument("--template", default=None, metavar="SHOT_ID",
                   help="the shot candidates are built from (default: the one with the "
                        "most stations)")
    p.add_argument("--candidates", type=cli.number(int, 1), default=1000,
                   help="candidates sampled (a Latin hypercube over the ranges)")
    p.add_argument("--refine", type=cli.number(int, 0), default=3,
                   help="the best candidates a bounded search starts from")
    p.add_argument("--shots", type=cli.number(int, 1, 20), default=1,
                   help="shots to choose one after another (each scored with the ones "
                        "before it fired)")
    p.add_argument("--seed", type=cli.number(int, 0), default=0, help="the sample's seed")


def run(args) -> int:
    """``cadra2 plan`` (module doc); returns the exit status."""
    from cadra.fitting import FitOptions, fit_shots
    from cadra.flight.starts import start_estimates

    try:
        model = cli.model_of(args)
        free = set(model.free_names()) | set(args.plan_free or ())
        wrong = [t for t in args.target or () if t not in free]
        if wrong:      # before the fit: fail early
            raise ValueError(f"--target {wrong[0]}: not a free parameter of {model.name} (free: "
                             f"{', '.join(model.free_names())}; a held one needs --plan-free)")
        shots, _ = cli.shots_of(args)
        result, _ = fit_shots(shots, model, options=FitOptions(
            max_iterations=args.max_iterations, progress=not cli.quiet(args)),
            estimates=start_estimates(shots, "auto", model))
        if not result:
            raise ValueError(f"the fit did not converge ({result.message}); a plan needs the "
                             "group's converged fit")
    except cli.REFUSED as exc:
        return cli.refused("cadra2 plan", exc)
    return plan_and_write(result, args, f"{model.name}, {len(shots)} shot(s)", "cadra2 plan")


def plan_and_write(result, args, title: str, prog: str) -> int:
    """Plan from the fit ``result`` with ``args``'s options (:func:`add_plan_options`),
    write it to ``args.output``, print its report; the exit status."""
    from cadra.report.design import write_plan
    from cadra.studies.candidates import CandidateSpace
    from cadra.studies.design import planner, sequence

    out = Path(args.output)
    ranges = {n: getattr(args, n) for n in DIMENSIONS if getattr(args, n) is not None}
    try:
        p = planner(result, targets=tuple(args.target or ()), criterion=args.criterion,
                    free=tuple(args.plan_free or ()), template=args.template)
        plans = sequence(p, CandidateSpace(p.template.base, ranges), args.shots,
                         n_candidates=args.candidates, refine=args.refine, seed=args.seed,
                         progress=not cli.quiet(args))
    except cli.REFUSED as exc:
        return cli.refused(prog, exc)
    write_plan(plans, title, out, overwrite=getattr(args, "overwrite", False))
    if not cli.quiet(args):
        print(plans[0].report())
    if len(plans) > 1:
        for k, pl in enumerate(plans, start=1):
            c = pl.best_candidate
            print(f"shot {k}: angle {c.angle_deg:.1f} deg, rate {c.rate_deg_s:.0f} deg/s, "
                  f"Mach {c.mach:.3f}, {c.stations} stations: objective "
                  f"{pl.best.iloc[0]['objective']:.4g}")
    cli.say(args, f"wrote {out}/ (report.md, candidates.csv, best.csv, sigmas.csv, plan.png"
            + (", sequence.csv" if len(plans) > 1 else "") + ")")
    return 0


#: the subcommands this module runs
COMMANDS = (
    Command("plan", run, "what to fire next: candidate shots ranked by the information they add",
            "Fit the shots (as cadra2 fit does), then rank candidate shots built from one of "
            "them and launched within the ranges given (--angle-deg, --rate-deg-s, --mach, "
            "--roll-deg, --cg-shift-mm, --stations) by how much they would reduce the sigmas "
            "of --target parameters, or of the whole covariance (--criterion A or D). The "
            "expected reduction is the Fisher information of each simulated candidate from "
            "the fit's own Jacobian, added to the group's; a sample of the ranges is searched "
            "further by a bounded optimizer. Writes the best candidates with their predicted "
            "sigmas, what each moves, and a plot of predicted sigma against launch angle and "
            "Mach (docs/design.md).",
            _plan_arguments),
)


__all__ = ["COMMANDS", "add_plan_options", "plan_and_write"]
