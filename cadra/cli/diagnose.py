"""``cadra2 diagnose TRAJECTORY [...] --model MODEL -o OUT_DIR``: fit, then rank the library of
unmodelled effects by score tests and nonlinear refits, add the significant ones, and say
where any remaining gap lies (:func:`cadra.gap.score.diagnose_gap`,
:func:`cadra.gap.where.where_analysis`; docs/gap.md); written by
:func:`cadra.report.gap.write_diagnosis`."""

from __future__ import annotations

from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._format import number
from cadra.cli._inputs import Command


def _diagnose_arguments(p) -> None:
    cli.add_data_options(p)
    p.add_argument("--model", required=True, help="aero model (bundled name or file)")
    p.add_argument("--alpha", type=number(float, 0.0, 0.5, above=True), default=0.01,
                   help="family-wise significance of adding an effect")
    cli.add_start_option(p)


def run(args) -> int:
    """``cadra2 diagnose`` (module doc); returns the exit status."""
    from cadra.fitting import FitOptions, fit_shots
    from cadra.flight.starts import start_estimates
    from cadra.gap.score import diagnose_gap
    from cadra.gap.where import where_analysis
    from cadra.io.trajectory import load_trajectory
    from cadra.report.gap import write_diagnosis

    out = Path(args.output)
    try:
        model = cli.model_of(args)
        shots, trajs = cli.shots_of(args)
        # a fit short of convergence is still diagnosed: diagnose_gap continues it with more
        # budget and, if it still falls short, runs from its best point and says so
        result, _ = fit_shots(shots, model, estimates=start_estimates(shots, args.start, model),
                              options=FitOptions(max_iterations=args.max_iterations))
        dg = diagnose_gap(result, shots, model, alpha=args.alpha, progress=not cli.quiet(args))
        stage_one = {}
        for sd, traj in zip(shots, trajs, strict=True):
            table = load_trajectory(traj).table
            if "x_consistency" in table:
                stage_one[sd.shot_id] = table
        base = dg.fit_given if dg.fit_given is not None else result
        tables = where_analysis(base, shots, base.residuals, stage_one or None)
    except cli.REFUSED as exc:
        return cli.refused("cadra2 diagnose", exc)
    write_diagnosis(dg, base, out, overwrite=args.overwrite, where_tables=tables)
    print(dg.verdict)
    if not cli.quiet(args):
        ranking = dg.ranking if cli.verbose(args) else dg.ranking.head(8)[
            ["candidate", "dchi2", "p_adjusted", "size"]]
        print(ranking.to_string(index=False))
        for line in tables["findings"]:
            print(f"where: {line}")
    cli.say(args, f"wrote {out}/ (report.md, ranking.csv, where*.csv, where.png)")
    return 0


#: the subcommands this module runs
COMMANDS = (
    Command("diagnose", run, "where the fit misses, which unmodelled effect, how far it shrinks",
            "Fit, then rank a library of unmodelled effects (dynamics, aero, station) by score "
            "tests and nonlinear refits, add the significant ones, and say where any remaining "
            "gap lies (docs/gap.md).",
            _diagnose_arguments),
)


__all__ = ["COMMANDS"]
