"""``cadra2 fit TRAJECTORY [TRAJECTORY ...] --model MODEL -o OUT_DIR``: least-squares
differential correction of the model's free parameters and each shot's initial state to
stage one's measurements (docs/fitting.md): :func:`cadra.fitting.fit_shots` from the starting
estimates :func:`cadra.flight.starts.start_estimates` gives, written by
:func:`cadra.report.fit.write_fit_outputs` and printed as :meth:`FitResult.report` says."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._format import warn, write_error
from cadra.cli._inputs import Command

#: chi^2/nu above which a converged fit is said not to describe the data
CHI2_WARN = 2.0


def _fit_arguments(p) -> None:
    cli.add_data_options(p)
    p.add_argument("--model", required=True,
                   help="aero model: a bundled name (cadra2 models lists them) or a model "
                        "file (docs/aero_models.md)")
    p.add_argument("--no-auto-start", action="store_true",
                   help="start from the model file's values, not linear-theory estimates")
    cli.add_start_option(p)
    p.add_argument("--no-plots", action="store_true", help="tables and report only")
    p.add_argument("--bias-table", default=None, metavar="current|FILE",
                   help="correct the measurements by a station bias table: 'current' (the "
                        "facility history's latest entry) or a bias-table CSV (default: "
                        "none)")
    p.add_argument("--stations-root", default=None, metavar="DIR",
                   help="directory holding stations/<facility>/ (default: $CADRA_STATIONS_ROOT"
                        ", else the repository holding facilities/; as for calibrate)")
    p.add_argument("--variance-components", action="store_true",
                   help="after convergence, rescale each channel's sigmas (x, y, z, theta, "
                        "psi) by the factor its residuals ask for and refit: coefficient "
                        "sigmas that carry the noise the data show when stage one's sigmas "
                        "are off; the factors are reported (default: off, stage one's "
                        "sigmas as they are)")
    p.add_argument("--bootstrap", type=cli.number(int, 2), default=None, metavar="N",
                   help="after a converged fit, N parametric bootstrap refits on Dask (the "
                        "fit's prediction plus fresh noise, refitted): each parameter's "
                        "bootstrap sigma against its covariance sigma, a 95 %% percentile "
                        "interval, the bias; bootstrap.csv and bootstrap_samples.csv "
                        "(docs/fitting.md, \"Bootstrap\")")
    p.add_argument("--bootstrap-noise", choices=("white", "residuals"), default="white",
                   help="the replicates' noise: 'white', each measurement's own sigma; "
                        "'residuals', the fit's standardized residuals resampled in blocks "
                        "of stations (their real scale and correlation)")
    p.add_argument("--bootstrap-profile", action="store_true",
                   help="beside each percentile interval, the parameter's 95 %% "
                        "profile-likelihood interval, about 10-20 held refits of the whole "
                        "fit per parameter (default: off)")
    p.add_argument("--workers", type=cli.number(int, 0), default=None,
                   help="Dask worker processes of the bootstrap (default: the cores; 0: in "
                        "this process)")
    p.add_argument("--reference", default=None, metavar="MODEL|FIT_DIR",
                   help="compare with a reference: a model (bundled name or file: values "
                        "only) or an earlier cadra2 fit's output folder (values, sigmas and "
                        "covariance); adds a pulls table and a joint chi^2 to the report and "
                        "draws it on the coefficient plots (default: none)")


def run(args) -> int:
    """``cadra2 fit`` (module doc); returns the exit status."""
    from cadra.calibration.bias_table import correct_by_bias_table
    from cadra.fitting import FitOptions, fit_shots
    from cadra.flight.starts import start_estimates
    from cadra.io.toml_file import toml_text
    from cadra.report.fit import write_fit_outputs

    out = Path(args.output)
    try:
        model = cli.model_of(args)
        shots, _ = cli.shots_of(args)
        notes = []
        if args.bias_table:
            shots, note = correct_by_bias_table(shots, args.bias_table, args.stations_root)
            notes.append(note)
            if "the history warns" in note:
                warn("cadra2 fit", note)
        options = FitOptions(max_iterations=args.max_iterations, progress=not cli.quiet(args))
        reference = None
        if args.reference:
            from cadra.fitting.reference import load_reference

            reference = load_reference(args.reference)   # before the fit: fail early
        unspun = [sd.shot_id for sd in shots if sd.body_kind == "bullet"
                  and not (math.isfinite(sd.launch_spin_rad_s)
                           or math.isfinite(sd.twist_m_per_turn))]
        if unspun and not args.no_auto_start:
            warn("cadra2 fit", f"{', '.join(unspun)}: a bullet whose spin is not known (give "
                 "--twist or --spin, or the shot file's [gun]): the stations do not show it, "
                 "and on a spark range its fast yaw arm aliases (docs/spark_range.md)")
        estimates = None if args.no_auto_start else start_estimates(shots, args.start, model)
        for sd, e in zip(shots, estimates or (), strict=False):
            if e is not None and e.alias_note:
                notes.append(f"{sd.shot_id}: the start's arms at the spin "
                             f"{e.spin_rad_s:.6g} rad/s: {e.alias_note}")
        result, start = fit_shots(shots, model, options=options,
                                  auto_start=not args.no_auto_start,
                                  variance_components=args.variance_components,
                                  estimates=estimates)
        if result.options.get("variance_components") and result.problem is not None:
            shots = list(result.problem.shots)   # the rescaled sigmas the fit used
    except cli.REFUSED as exc:
        return cli.refused("cadra2 fit", exc)
    boot = None
    if args.bootstrap and result.converged:
        from cadra.campaign.bootstrap import bootstrap
        from cadra.studies.bootstrap import peak_quantities, sommer_tobak_quantities

        boot = bootstrap(result, args.bootstrap, noise=args.bootstrap_noise,
                         workers=args.workers, progress=not cli.quiet(args),
                         derived={**peak_quantities(result),
                                  **sommer_tobak_quantities(result)})
        if args.bootstrap_profile:
            from cadra.studies.bootstrap import with_profiles

            boot = with_profiles(boot, result)
        notes.append(f"bootstrap ({boot.noise} noise): {boot.n_converged} of "
                     f"{boot.n_requested} refits converged; per parameter the bootstrap "
                     "sigma, its ratio to the covariance sigma, the bias and the 95 % "
                     "percentile interval are in bootstrap.csv (SI), the refits in "
                     "bootstrap_samples.csv")
    elif args.bootstrap:
        notes.append("no bootstrap: the fit did not converge")
    config = {k: (v if v is not None else "") for k, v in vars(args).items() if k != "func"}
    extra = {"model_fitted.toml": toml_text(result.model.to_dict(), "CADRA aerodynamic model "
                                            "(docs/aero_models.md): the fitted values, written "
                                            "by cadra2 fit"),
             "config.toml": toml_text(config, "cadra2 fit: the command's settings")}
    if boot is not None:
        extra["bootstrap.csv"] = boot.table.to_csv(index=False)
        extra["bootstrap_samples.csv"] = boot.samples.to_csv(index=False)
        if len(boot.derived):
            extra["bootstrap_derived.csv"] = boot.derived.to_csv(index=False)
    try:
        write_fit_outputs(result, shots, out, overwrite=args.overwrite,
                          plots=not args.no_plots, start_model=start, extra_files=extra,
                          notes=notes, reference=reference)
    except OSError as exc:   # a read-only folder, a full disk: the result is not lost
        print_result(result, args, full=True)
        print(f"cadra2 fit: could not write {out}: {write_error(exc)}; the result is printed "
              "above, nothing was written", file=sys.stderr)
        return 1
    print_result(result, args)
    if boot is not None and not cli.quiet(args):
        print(boot.report())
    cli.say(args, f"wrote {out}/ (report.md, results.json, coefficients.csv, plots/"
            + (", bootstrap.csv" if boot is not None else "") + ")")
    return 0 if result.verdict == "converged" else 1


def print_result(result, args, full: bool = False) -> None:
    """The status line (stdout when converged, stderr otherwise) and the warnings (stderr,
    also under -q), then unless -q (or if ``full``) the result's report
    (:meth:`FitResult.report`)."""
    line = result.status_line()
    if result.poor_minimum:
        print(f"cadra2 fit: CONVERGED TO A POOR MINIMUM: {line} (not a result to use: a wrong "
              "minimum, a start in the wrong alias band, or physics the model lacks; cadra2 "
              "diagnose asks which)", file=sys.stderr)
    elif result.converged:
        print(line)
    else:
        print(f"cadra2 fit: NOT CONVERGED: {line} (the best point reached is written, marked "
              "as not converged)", file=sys.stderr)
    if result.converged and not result.poor_minimum and result.reduced_chi2 > CHI2_WARN:
        warn("cadra2 fit", f"chi^2/nu = {result.reduced_chi2:.3g} > {CHI2_WARN:g}: the sigmas "
             "or the model do not describe the data; use the scaled or coloured sigmas "
             "(report.md)")
    for w in result.warnings:
        warn("cadra2 fit", w)
    if full or not cli.quiet(args):
        print(result.report(verbose=full or cli.verbose(args), status=False, warnings=False))


#: the subcommands this module runs
COMMANDS = (
    Command("fit", run, "fit aerodynamic coefficients to measured trajectories",
            "Least-squares differential correction of the model's free parameters and each "
            "shot's initial state to stage one's measurements: one trajectory file is a single "
            "fit, several a multi-fit. Data finer than film level are fitted in two phases (first "
            "with the sigmas floored at 0.1 mm and 0.1 deg, then with stage one's own), each with "
            "its own progress bar. Writes the coefficient table, covariances, residuals, report "
            "and plots (docs/fitting.md). Exit status 1 if the fit did not converge, or "
            "converged to a poor minimum (p(chi^2) < 1e-6).",
            _fit_arguments),
)


__all__ = ["COMMANDS"]
