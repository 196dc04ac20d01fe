"""``cadra2 single`` and ``cadra2 holdone``: seed 004's single fits with quasi-linear trends
(steps 1-2, :mod:`cadra.studies.single`) and its hold-one-parameter study (Fig. 15,
:mod:`cadra.studies.holdone`); written by :mod:`cadra.report.studies`."""

from __future__ import annotations

from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._format import warn
from cadra.cli._inputs import Command


def _single_arguments(p) -> None:
    cli.add_data_options(p)
    p.add_argument("--model", default=None,
                   help="linear model (default: linear_template_sigma for symmetric "
                        "bodies, linear_template_alpha_beta for lifting ones)")


def _holdone_arguments(p) -> None:
    cli.add_data_options(p)
    p.add_argument("--model", required=True, help="aero model (bundled name or file)")
    p.add_argument("--param", required=True, help="the parameter to hold")
    p.add_argument("--values", required=True, metavar="V1,V2,...",
                   help="comma-separated values to hold it at, model file's unit "
                        "(negative values are fine: --values -1.0,-1.5)")


def run_single(args) -> int:
    """``cadra2 single`` (module doc); returns the exit status."""
    from cadra.aero import load_bundled_model
    from cadra.fitting import FitOptions
    from cadra.report.studies import single_fits_lines, write_single_fits
    from cadra.studies.single import check_single_fits, linear_template_for, single_fits

    out = Path(args.output)
    try:
        shots, _ = cli.shots_of(args)
        model = cli.model_of(args) if args.model else linear_template_for(shots[0])
        if args.model is None and any(linear_template_for(s).name != model.name
                                      for s in shots[1:]):
            model = load_bundled_model("linear_template_alpha_beta")
        table = single_fits(shots, model, None,
                            options=FitOptions(max_iterations=args.max_iterations))
    except cli.REFUSED as exc:
        return cli.refused("cadra2 single", exc)
    write_single_fits(table, model, out, overwrite=args.overwrite)
    checks = check_single_fits(table)
    if not cli.quiet(args):
        print("\n".join(single_fits_lines(table, model, cli.verbose(args))))
    for w in checks.messages:
        warn("cadra2 single", w)
    n_ok = int(table["converged"].sum())
    trend = "computed" if checks.trends else "not computed (fewer than two converged shots)"
    n_warn = len(checks.messages)
    print(f"single: {n_ok}/{len(table)} single fits converged with {model.name}; quasi-linear "
          f"trends {trend}" + (f"; {n_warn} warning(s)" if n_warn else ""))
    cli.say(args, f"wrote {out}/ (single_fits.csv, quasi_linear.json, report.md, plots/)")
    return 0 if table["converged"].all() else 1


def run_holdone(args) -> int:
    """``cadra2 holdone`` (module doc); returns the exit status."""
    from cadra.fitting import FitOptions, fit_shots
    from cadra.fitting.inputs import values_to_si
    from cadra.report.studies import write_hold_one
    from cadra.studies.holdone import hold_one_study, lowest_converged, with_linear_prediction

    out = Path(args.output)
    try:
        shots, _ = cli.shots_of(args)
        model = cli.model_of(args)
        values = [float(v) for v in args.values.split(",") if v.strip()]
        si = values_to_si(model, args.param, values)
        options = FitOptions(max_iterations=args.max_iterations)
        # the study starts from the free fit's solution (its parameters and states)
        free, _ = fit_shots(shots, model, options=FitOptions(
            max_iterations=args.max_iterations, progress=not cli.quiet(args)))
        if not free:
            raise ValueError(f"the free fit did not converge ({free.message}); the study "
                             "needs a converged starting point")
        start = free.model.with_vary({args.param: model.parameter(args.param).vary})
        table = hold_one_study(shots, start, [sf.state for sf in free.shots], args.param, si,
                               options=options)
        table = with_linear_prediction(table, free, args.param)
    except cli.REFUSED as exc:
        return cli.refused("cadra2 holdone", exc)
    write_hold_one(table, args.param, out, overwrite=args.overwrite)
    cols = ["value", "status", "reduced_chi2", "theta_rms_deg", "psi_rms_deg"]
    if cli.verbose(args):
        print(table.to_string(index=False))
    elif not cli.quiet(args):
        print(table[[c for c in cols if c in table]].to_string(index=False))
    best = lowest_converged(table)
    print(f"holdone: {args.param} held at {len(table)} values, "
          f"{int(table['converged'].sum())} converged"
          + (f"; chi^2 lowest at {best:g} (of the converged)" if best is not None else ""))
    cli.say(args, f"wrote {out}/ (hold_one.csv, hold_one.png)")
    return 0 if table["converged"].all() else 1


#: the subcommands this module runs
COMMANDS = (
    Command("single", run_single,
            "single fits with linear forms and quasi-linear trends (seed 004 steps 1-2)",
            "Seed 004 steps 1 and 2: each shot fitted on its own with a linear model, then the "
            "quasi-linear coefficients against amplitude (alpha_rms, sigma_rms) with "
            "straight-line tests and plots. The trends need at least two converged shots; a fit "
            "with chi^2/nu far above 1 is flagged (its sigmas are not meaningful).",
            _single_arguments),
    Command("holdone", run_holdone, "hold-one-parameter study (seed 004 Fig. 15)",
            "Seed 004 Fig. 15: fit freely, then hold one parameter at each given value (model "
            "file's unit) and refit the rest on all shots; writes a table of chi^2, residual rms "
            "and the other parameters, and a plot.",
            _holdone_arguments),
)


__all__ = ["COMMANDS"]
