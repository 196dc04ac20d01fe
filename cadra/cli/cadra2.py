"""``cadra2``: stage two of the pipeline (6-DOF dynamics).

Subcommands:

* ``cadra2 fit TRAJECTORY [TRAJECTORY ...] --model MODEL -o OUT_DIR`` — least-squares
  differential correction of the model's free parameters and each shot's initial state to stage
  one's measurements (one trajectory file: a single fit; several: a multi-fit); writes the
  coefficient table, covariances, residuals, report and plots (docs/fitting.md).
* ``cadra2 single TRAJECTORY [...] -o OUT_DIR`` — seed 004 step 1 and 2: each shot fitted on
  its own with a linear model (default: the bundled linear template that suits the body),
  the quasi-linear coefficients vs amplitude (alpha_rms, sigma_rms) with straight-line tests
  and plots.
* ``cadra2 holdone TRAJECTORY [...] --model MODEL --param NAME --values V1,V2,... -o OUT_DIR``
  — seed 004 Fig. 15: hold one parameter at each value (model file's unit), refit the rest
  on all shots; table of rms and the other parameters, and a plot.
* ``cadra2 calibrate TRAJECTORY [...] -o OUT_DIR`` — sphere calibration shots: per-station
  position and timing biases with sigmas, compared with the facility's station history, to
  which the new estimate is appended under its lock (docs/calibration.md: where the history
  lives, exit status 3); ``cadra2 fit --bias-table current|FILE`` applies a table.
* ``cadra2 diagnose TRAJECTORY [...] --model MODEL -o OUT_DIR`` — fit, then rank the library
  of unmodelled effects by score tests, add the significant ones, and say where any remaining
  gap lies (docs/gap.md).
* ``cadra2 motion TRAJECTORY [...] -o OUT_DIR`` — epicyclic fit, linear-theory and K-B
  coefficients, yaw card (:mod:`cadra.cli.motion`, docs/motion.md).
* ``cadra2 roll TRAJECTORY [...] -o OUT_DIR`` — seed 003's segmented fit (:mod:`cadra.cli.roll`).
* ``cadra2 simulate SPEC.toml -o OUT_DIR`` — fly a synthetic shot (6-DOF, the same code the fit
  uses), render its shadowgraphs and write the shot file, images and exact truth.
* ``cadra2 models`` — list the bundled aero models (name, case, angle plane, free parameters).

Every command takes ``-q`` (no progress bars: only the result or status line, warnings and
errors; warnings go to stderr, ``cadra2 CMD: warning: ...``) and
``-v`` (more detail); ``cadra2 --version`` prints the version (docs/cli.md).

Exit status: 0 success, 1 the input was refused (message names the key), the output folder
would destroy an input (is or holds an input — trajectory, shot, image, facility, model, spec
or bias-table files and folders, the station history —, the working folder or a file; links
and ``..`` resolved; with or without ``--overwrite``) or the fit did not converge (its best
point is written, marked so), 2 usage error, 130 interrupted (Ctrl-C: no traceback, nothing
written), 141 stdout closed by its reader (``| head``; no traceback).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.cli._format import (
    HelpFormatter,
    add_verbosity,
    add_version,
    console_main,
    join_number_lists,
    warn,
)
from cadra.cli.motion import add_parser as add_motion_parser
from cadra.cli.roll import add_parser as add_roll_parser
from cadra.flight.starts import start_estimates
from cadra.numfmt import pm

#: the top-level help's description (plain text: the module doc is rST)
DESCRIPTION = (
    "Stage two of CADRA: fit aerodynamic coefficients and initial states to stage one's "
    "trajectory files, with seed 004's studies, sphere calibration, gap diagnosis and the "
    "shot simulator. Exit status: 0 success; 1 input refused, output would destroy an input, "
    "or the fit did not converge; 2 usage error; 3 calibrate: outputs written but the "
    "estimate is not in the station history; 130 interrupted. See docs/cli.md.")

#: options whose value may be a comma-separated list of numbers starting with '-'
NUMBER_LIST_OPTIONS = ("--values",)


def _quiet(args) -> bool:
    return bool(getattr(args, "quiet", False))


def _verbose(args) -> bool:
    return bool(getattr(args, "verbose", False)) and not _quiet(args)


def _say(args, *lines: str) -> None:
    """Print unless -q (the result/status line is printed with plain ``print``)."""
    if lines and not _quiet(args):
        print("\n".join(lines))


def _exists(out: Path, args, command: str) -> bool:
    """True (and says so) when ``out`` exists and --overwrite was not given."""
    if out.exists() and not args.overwrite:
        print(f"cadra2 {command}: {out} exists; refusing to overwrite (use --overwrite)",
              file=sys.stderr)
        return True
    return False


def _input_paths(args) -> list[Path]:
    """Every file and folder the command reads, for the output guard (best effort: an input
    that cannot be read here is reported by the command itself, before it writes)."""
    from contextlib import suppress

    from cadra.io.facility_file import resolve_facility_path
    from cadra.io.shotfile import load_shot

    paths: list[Path] = []
    readable = (ValueError, KeyError, OSError)

    def facility(name: str) -> None:
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
        return paths
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
    if args.command == "calibrate" or getattr(args, "stations_root", None):
        from cadra.calibration.history import stations_root

        with suppress(*readable):  # the station history (calibrate, fit --bias-table)
            paths.append(stations_root(getattr(args, "stations_root", None)) / "stations")
    return paths


def _refused(command: str, exc: Exception) -> int:
    """Print why the input was refused; exit status 1."""
    msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
    print(f"cadra2 {command}: {msg}", file=sys.stderr)
    return 1


def _simulate(args) -> int:
    from cadra.synthetic.simulate import SpecError, load_shot_spec, simulate_shot, write_shot

    out = Path(args.output)
    try:
        spec = load_shot_spec(args.spec)
        shot = simulate_shot(spec)
        write_shot(shot, out, images=not args.no_images, overwrite=args.overwrite,
                   progress=not _quiet(args))
    except (SpecError, ValueError, FileNotFoundError) as exc:
        msg = str(exc)  # errors of the spec file name it already
        where = "" if msg.startswith(str(args.spec)) else f"{args.spec}: "
        print(f"cadra2 simulate: {where}{msg}", file=sys.stderr)
        return 1
    t = shot.truth
    if _verbose(args):
        cols = [c for c in ("station", "t_s", "x_m", "y_m", "z_m", "theta_deg", "psi_deg",
                            "mach", "alpha_deg", "beta_deg") if c in t]
        print(t[cols].to_string(index=False))
    print(f"{spec.shot_id}: {len(t)} stations, x {t.x_m.iloc[0]:.3f}..{t.x_m.iloc[-1]:.3f} m, "
          f"Mach {t.mach.min():.3f}..{t.mach.max():.3f}, "
          f"alpha {t.alpha_deg.min():+.2f}..{t.alpha_deg.max():+.2f} deg, "
          f"beta {t.beta_deg.min():+.2f}..{t.beta_deg.max():+.2f} deg")
    extra = ", station_biases.csv" if (out / "station_biases.csv").is_file() else ""
    _say(args, f"wrote {out}/shot.toml, truth.csv{extra}" + (
        "" if args.no_images else ", truth_images.csv, images/"))
    return 0


def _model(args):
    """The aero model named by --model (bundled name or file) with --hold/--free/--bound."""
    from cadra.aero import resolve_model
    from cadra.fitting.inputs import apply_holds

    return apply_holds(resolve_model(args.model), args.hold, args.free, args.bound)


def _shots(args):
    """The shots named on the command line and their trajectory files."""
    from cadra.flight.load import load_shots

    return load_shots(args.trajectories, args.shot, sigma_time_s=args.sigma_time_s,
                      min_sigma_position_m=args.min_sigma_position_m,
                      min_sigma_angle_deg=args.min_sigma_angle_deg)


#: what a refused input raises (FitDataError, SpecError, CalibrationError and a missing model
#: are ValueErrors; unknown parameter names KeyErrors)
_REFUSED = (ValueError, KeyError, FileNotFoundError)


def _fit(args) -> int:
    from cadra.calibration.bias_table import correct_by_bias_table
    from cadra.fitting import FitOptions, fit_shots
    from cadra.fitting.report import write_fit_outputs
    from cadra.io.toml_file import toml_text

    out = Path(args.output)
    try:
        model = _model(args)
        shots, _ = _shots(args)
        notes = []
        if args.bias_table:
            shots, note = correct_by_bias_table(shots, args.bias_table, args.stations_root)
            notes.append(note)
        options = FitOptions(max_iterations=args.max_iterations, progress=not _quiet(args))
        reference = None
        if args.reference:
            from cadra.fitting.reference import load_reference

            reference = load_reference(args.reference)   # before the fit: fail early
        estimates = None if args.no_auto_start else start_estimates(shots, args.start)
        result, start = fit_shots(shots, model, options=options,
                                  auto_start=not args.no_auto_start,
                                  variance_components=args.variance_components,
                                  estimates=estimates)
        if result.options.get("variance_components") and result.problem is not None:
            shots = list(result.problem.shots)   # the rescaled sigmas the fit used
    except _REFUSED as exc:
        return _refused("fit", exc)
    config = {k: (v if v is not None else "") for k, v in vars(args).items() if k != "func"}
    extra = {"model_fitted.toml": toml_text(result.model.to_dict(), "CADRA aerodynamic model "
                                            "(docs/aero_models.md): the fitted values, written "
                                            "by cadra2 fit"),
             "config.toml": toml_text(config, "cadra2 fit: the command's settings")}
    write_fit_outputs(result, shots, out, overwrite=args.overwrite, plots=not args.no_plots,
                      start_model=start, extra_files=extra, notes=notes, reference=reference)
    _print_summary(result, args)
    _say(args, f"wrote {out}/ (report.md, results.json, coefficients.csv, plots/)")
    return 0 if result.converged else 1


def _single(args) -> int:
    from cadra.aero import load_bundled_model
    from cadra.fitting import FitOptions
    from cadra.fitting.studies import (
        linear_template_for,
        single_fit_warnings,
        single_fits,
        write_single_fits,
    )

    out = Path(args.output)
    try:
        shots, _ = _shots(args)
        model = _model(args) if args.model else linear_template_for(shots[0])
        if args.model is None and any(linear_template_for(s).name != model.name
                                      for s in shots[1:]):
            model = load_bundled_model("linear_template_alpha_beta")
        table = single_fits(shots, model, None,
                            options=FitOptions(max_iterations=args.max_iterations))
    except _REFUSED as exc:
        return _refused("single", exc)
    write_single_fits(table, model, out, overwrite=args.overwrite)
    warnings = single_fit_warnings(table)
    if not _quiet(args):
        names = model.free_names()
        print(f"{'shot':10s} {'status':10s} {'chi^2/nu':>9s}  " + "  ".join(names))
        for _, row in table.iterrows():
            cells = [pm(row[n], row[f"{n}_sigma"]) for n in names]
            print(f"{row['shot_id']:10s} {row['status']:10s} {row['reduced_chi2']:9.3g}  "
                  + "  ".join(cells))
            if _verbose(args):
                print(f"  {row['message']}")
    for w in warnings:
        warn("cadra2 single", w)
    n_ok = int(table["converged"].sum())
    trend = ("not computed (fewer than two converged shots)"
             if any(w.startswith("quasi-linear") for w in warnings) else "computed")
    print(f"single: {n_ok}/{len(table)} single fits converged with {model.name}; quasi-linear "
          f"trends {trend}" + (f"; {len(warnings)} warning(s)" if warnings else ""))
    _say(args, f"wrote {out}/ (single_fits.csv, quasi_linear.json, report.md, plots/)")
    return 0 if table["converged"].all() else 1


def _holdone(args) -> int:
    from cadra.fitting import FitOptions, fit_shots
    from cadra.fitting.inputs import values_to_si
    from cadra.fitting.studies import hold_one_study, plot_hold_one
    from cadra.io.atomic import atomic_output_dir

    out = Path(args.output)
    try:
        shots, _ = _shots(args)
        model = _model(args)
        values = [float(v) for v in args.values.split(",") if v.strip()]
        si = values_to_si(model, args.param, values)
        options = FitOptions(max_iterations=args.max_iterations)
        # the study starts from the free fit's solution (its parameters and states)
        free, _ = fit_shots(shots, model, options=FitOptions(
            max_iterations=args.max_iterations, progress=not _quiet(args)))
        if not free:
            raise ValueError(f"the free fit did not converge ({free.message}); the study "
                             "needs a converged starting point")
        start = free.model.with_vary({args.param: model.parameter(args.param).vary})
        table = hold_one_study(shots, start, [sf.state for sf in free.shots], args.param, si,
                               options=options)
    except _REFUSED as exc:
        return _refused("holdone", exc)
    with atomic_output_dir(out, overwrite=args.overwrite) as tmp:
        table.to_csv(tmp / "hold_one.csv", index=False)
        plot_hold_one(table, args.param).savefig(tmp / "hold_one.png", dpi=110)
    cols = ["value", "status", "reduced_chi2", "theta_rms_deg", "psi_rms_deg"]
    if _verbose(args):
        print(table.to_string(index=False))
    elif not _quiet(args):
        print(table[[c for c in cols if c in table]].to_string(index=False))
    best = table.loc[table["chi2"].idxmin(), "value"] if table["chi2"].notna().any() else None
    print(f"holdone: {args.param} held at {len(table)} values, "
          f"{int(table['converged'].sum())} converged"
          + (f"; chi^2 lowest at {best:g}" if best is not None else ""))
    _say(args, f"wrote {out}/ (hold_one.csv, hold_one.png)")
    return 0 if table["converged"].all() else 1


def _models(args) -> int:
    """List the bundled aero models (``cadra.aero.resolve_model``): name, case, angle plane,
    number of free parameters, description; -v adds the free parameters' names."""
    from cadra.aero import bundled_model_names, resolve_model

    rows = []
    for name in bundled_model_names():
        m = resolve_model(name)
        rows.append((name, str(m.reference.get("case", "—")), m.angle_plane,
                     len(m.free_names()), m.description, m.free_names()))
    if not _quiet(args):
        print(f"{'name':28s} {'case':9s} {'plane':10s} {'free':>4s}  description")
        for name, case, plane, n_free, text, free in rows:
            print(f"{name:28s} {case:9s} {plane:10s} {n_free:4d}  {text}")
            if _verbose(args):
                print(f"{'':28s} free: {', '.join(free)}")
    print(f"{len(rows)} bundled models (use one with --model NAME; a model file by its path; "
          "docs/aero_models.md)")
    return 0


def _add_data_options(p) -> None:
    p.add_argument("trajectories", nargs="+",
                   help="stage one's trajectory.csv files (or their directories)")
    p.add_argument("-o", "--output", required=True, help="output directory (must not exist)")
    p.add_argument("--shot", action="append",
                   help="shot file of each trajectory, same order (default: the one the "
                        "trajectory file names)")
    p.add_argument("--hold", action="append", metavar="NAME[=VALUE]",
                   help="hold a parameter (at VALUE, in the model file's unit)")
    p.add_argument("--free", action="append", metavar="NAME", help="free a held parameter")
    p.add_argument("--bound", action="append", metavar="NAME=LO:HI",
                   help="bounds of a parameter (file unit; either side may be empty)")
    p.add_argument("--max-iterations", type=int, default=60,
                   help="most Levenberg-Marquardt iterations per fit phase (a fit whose data "
                        "are finer than film level runs two phases: docs/cli.md)")
    p.add_argument("--sigma-time-s", type=float, default=0.0,
                   help="spark-time sigma, s (adds V sigma_t to the x sigma)")
    p.add_argument("--min-sigma-position-m", type=float, default=0.0,
                   help="floor of the stage-one position sigmas, m")
    p.add_argument("--min-sigma-angle-deg", type=float, default=0.0,
                   help="floor of the stage-one angle sigmas, deg")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")


def _subcommand(sub, name: str, func, summary: str, description: str):
    """A subcommand's parser: its one-line summary in ``cadra2 --help``, its plain-text
    description in ``cadra2 NAME --help``, defaults shown, -q/-v."""
    p = sub.add_parser(name, help=summary, description=description,
                       formatter_class=HelpFormatter)
    add_verbosity(p, top=False)
    p.set_defaults(func=func)
    return p


def _calibrate(args) -> int:
    import math

    from cadra.calibration.bias_table import shots_facility
    from cadra.calibration.history import (
        StationHistoryError,
        append_compared,
        compare,
        history_path,
        load_history,
        stations_root,
    )
    from cadra.calibration.report import write_calibration
    from cadra.calibration.sphere import CalibrationError, estimate_station_biases
    from cadra.units import from_si

    out = Path(args.output)
    try:
        root = stations_root(args.stations_root)
        shots, _ = _shots(args)
        facility = shots_facility(shots, CalibrationError)
        history, hist_warnings = load_history(root, facility)  # refuse a bad history early
        est = estimate_station_biases(shots, facility=facility)
    except _REFUSED as exc:
        return _refused("calibrate", exc)
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
    except OSError as exc:
        done = f" (the estimate IS recorded: {hfile}, entry {entry})" if entry else ""
        print(f"cadra2 calibrate: writing {out} failed: {' '.join(str(exc).split())}{done}",
              file=sys.stderr)
        return 3
    unit = {"x": "mm", "y": "mm", "z": "mm", "time": "us"}
    head = (f"{facility}: station biases from {len(shots)} sphere shot(s) "
            f"(speeds {', '.join(f'{v:.0f}' for v in est.shot_speeds_m_s)} m/s)")
    if entry is None and failed is None:   # -q: the one status line (else the history's)
        print(head)
    else:
        _say(args, head)
    for k, st in enumerate(table.stations):
        cells = []
        for c, name in enumerate(("x", "y", "z", "time")):
            u = unit[name]
            b, sg = table.bias[k, c], table.sigma[k, c]
            if math.isfinite(sg) and sg > 0:
                mark = " *" if abs(b) > args.threshold_sigma * sg else ""
                cells.append(f"{name} {pm(from_si(b, u), from_si(sg, u), u)}{mark}")
        _say(args, f"  station {st:2d}: " + ", ".join(cells))
    for w in (*est.warnings, *hist_warnings):
        warn("cadra2 calibrate", w)
    _say(args, f"wrote {out}/ (bias_table.csv, comparison.csv, biases.png, report.md)")
    if failed is not None:
        print(f"cadra2 calibrate: NOT recorded in the station history: {failed}",
              file=sys.stderr)
        return 3
    if entry is not None:
        print(f"recorded in {hfile} as entry {entry} (compared with the {entry - 1} before it)")
    return 0


def _add_start_option(parser) -> None:
    parser.add_argument("--start", choices=("auto", "linear", "epicyclic"), default="auto",
                        help="starting values: theta, psi damped sines (linear), epicyclic "
                             "arms and spin (epicyclic), arms if it spins (auto) (default: auto)")


def _diagnose(args) -> int:
    from cadra.fitting import FitOptions, fit_shots
    from cadra.gap.report import write_diagnosis
    from cadra.gap.score import diagnose_gap
    from cadra.gap.where import where_analysis
    from cadra.io.trajectory import load_trajectory

    out = Path(args.output)
    try:
        model = _model(args)
        shots, trajs = _shots(args)
        # a fit short of convergence is still diagnosed: diagnose_gap continues it with more
        # budget and, if it still falls short, runs from its best point and says so
        result, _ = fit_shots(shots, model, estimates=start_estimates(shots, args.start),
                              options=FitOptions(max_iterations=args.max_iterations))
        dg = diagnose_gap(result, shots, model, alpha=args.alpha, progress=not _quiet(args))
        stage_one = {}
        for sd, traj in zip(shots, trajs, strict=True):
            table = load_trajectory(traj).table
            if "x_consistency" in table:
                stage_one[sd.shot_id] = table
        base = dg.fit_given if dg.fit_given is not None else result
        tables = where_analysis(base, shots, base.residuals, stage_one or None)
    except _REFUSED as exc:
        return _refused("diagnose", exc)
    write_diagnosis(dg, base, out, overwrite=args.overwrite, where_tables=tables)
    print(dg.verdict)
    if not _quiet(args):
        ranking = dg.ranking if _verbose(args) else dg.ranking.head(8)[
            ["candidate", "dchi2", "p_adjusted", "size"]]
        print(ranking.to_string(index=False))
        for line in tables["findings"]:
            print(f"where: {line}")
    _say(args, f"wrote {out}/ (report.md, ranking.csv, where*.csv, where.png)")
    return 0


def status_line(result) -> str:
    """The fit's one status line: status, why, chi^2/nu, iterations (per phase), time. The
    solver's message may start with its status (``converged: ...``); it is not repeated."""
    detail = result.message
    if detail.lower().startswith(f"{result.status}:"):
        detail = detail[len(result.status) + 1:].strip()
    phases = result.options.get("phases") if isinstance(result.options, dict) else None
    its = f"{result.iterations} iterations"
    if phases:
        its += " (" + " + ".join(f"{p['iterations']} {p['label'][5:-1]}" for p in phases) + ")"
    return (f"{result.status}: {detail}; chi^2/nu = {result.chi2:.4g}/{result.dof} = "
            f"{result.reduced_chi2:.3g}, {its}, {result.elapsed_s:.2f} s")


def _phase_lines(result) -> list[str]:
    """Two lines on the fit's two phases (continuation), or none: why chi^2 jumps."""
    phases = result.options.get("phases") if isinstance(result.options, dict) else None
    if not phases:
        return []
    a, b = phases
    return [f"two phases: {a['label']}: {a['iterations']} iterations, chi^2 -> "
            f"{a['chi2_end']:.4g} ({a['status']}); {b['label']}: {b['iterations']} iterations, "
            f"chi^2 {b['chi2_start']:.4g} -> {b['chi2_end']:.4g}",
            "  (stage one's sigmas are finer than film level: the fit first converges with "
            "them floored, then refines; chi^2 jumps between the phases because the weights "
            "change, not because the fit got worse; docs/cli.md)"]


def _print_summary(result, args) -> None:
    """Status line (stdout when converged, stderr otherwise) and the warnings (stderr, also
    under -q), then unless -q the parameter table and the two phases; -v adds the chi^2
    history and per-shot rms."""
    line = status_line(result)
    if result.converged:
        print(line)
    else:
        print(f"cadra2 fit: NOT CONVERGED: {line} (the best point reached is written, marked "
              "as not converged)", file=sys.stderr)
    if result.converged and result.reduced_chi2 > 2.0:
        warn("cadra2 fit", f"chi^2/nu = {result.reduced_chi2:.3g} > 2: the sigmas or the model "
             "do not describe the data; use the scaled or coloured sigmas (report.md)")
    for w in result.warnings:
        warn("cadra2 fit", w)
    if _quiet(args):
        return
    vc = result.options.get("variance_components")
    if vc:
        print("variance components: sigma scale " + ", ".join(
            f"{ch} ×{v:.3f}" for ch, v in vc["sigma_scale"].items())
            + f" (chi^2/nu with stage one's sigmas {vc['reduced_chi2_before']:.3f})")
    verbose = _verbose(args)
    head = f"{'parameter':12s} {'value ± sigma':>24s}"
    print(head + (f" {'sigma coloured':>15s} {'sigma scaled':>13s}" if verbose else ""))
    for k, name in enumerate(result.aero_names):
        row = f"{name:12s} {pm(result.aero_values[k], result.aero_sigma[k]):>24s}"
        if verbose:
            row += (f" {result.aero_sigma_coloured[k]:>15.2g}"
                    f" {result.aero_sigma_scaled[k]:>13.2g}")
        print(row)
    for text in _phase_lines(result):
        print(text)
    if verbose:
        print("chi^2 history: " + ", ".join(f"{c:.4g}" for c in result.history))
        for sf in result.shots:
            print(f"{sf.shot_id}: residual rms " + ", ".join(
                f"{ch} {v * 1e6:.3g} um" if ch in ("x", "y", "z") else
                f"{ch} {v * 57.29577951308232:.3g} deg" for ch, v in sf.rms.items()))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cadra2", description=DESCRIPTION,
                                     formatter_class=HelpFormatter)
    add_version(parser)
    add_verbosity(parser)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    fit = _subcommand(
        sub, "fit", _fit, "fit aerodynamic coefficients to measured trajectories",
        "Least-squares differential correction of the model's free parameters and each "
        "shot's initial state to stage one's measurements: one trajectory file is a single "
        "fit, several a multi-fit. Data finer than film level are fitted in two phases (first "
        "with the sigmas floored at 0.1 mm and 0.1 deg, then with stage one's own), each with "
        "its own progress bar. Writes the coefficient table, covariances, residuals, report "
        "and plots (docs/fitting.md). Exit status 1 if the fit did not converge.")
    _add_data_options(fit)
    fit.add_argument("--model", required=True,
                     help="aero model: a bundled name (cadra2 models lists them) or a model "
                          "file (docs/aero_models.md)")
    fit.add_argument("--no-auto-start", action="store_true",
                     help="start from the model file's values, not linear-theory estimates")
    _add_start_option(fit)
    fit.add_argument("--no-plots", action="store_true", help="tables and report only")
    fit.add_argument("--bias-table", default=None, metavar="current|FILE",
                     help="correct the measurements by a station bias table: 'current' (the "
                          "facility history's latest entry) or a bias-table CSV (default: "
                          "none)")
    fit.add_argument("--stations-root", default=None, metavar="DIR",
                     help="directory holding stations/<facility>/ (default: $CADRA_STATIONS_ROOT"
                          ", else the repository holding facilities/; as for calibrate)")
    fit.add_argument("--variance-components", action="store_true",
                     help="after convergence, rescale each channel's sigmas (x, y, z, theta, "
                          "psi) by the factor its residuals ask for and refit: coefficient "
                          "sigmas that carry the noise the data show when stage one's sigmas "
                          "are off; the factors are reported (default: off, stage one's "
                          "sigmas as they are)")
    fit.add_argument("--reference", default=None, metavar="MODEL|FIT_DIR",
                     help="compare with a reference: a model (bundled name or file: values "
                          "only) or an earlier cadra2 fit's output folder (values, sigmas and "
                          "covariance); adds a pulls table and a joint chi^2 to the report and "
                          "draws it on the coefficient plots (default: none)")
    single = _subcommand(
        sub, "single", _single,
        "single fits with linear forms and quasi-linear trends (seed 004 steps 1-2)",
        "Seed 004 steps 1 and 2: each shot fitted on its own with a linear model, then the "
        "quasi-linear coefficients against amplitude (alpha_rms, sigma_rms) with "
        "straight-line tests and plots. The trends need at least two converged shots; a fit "
        "with chi^2/nu far above 1 is flagged (its sigmas are not meaningful).")
    _add_data_options(single)
    single.add_argument("--model", default=None,
                        help="linear model (default: linear_template_sigma for symmetric "
                             "bodies, linear_template_alpha_beta for lifting ones)")
    hold = _subcommand(
        sub, "holdone", _holdone, "hold-one-parameter study (seed 004 Fig. 15)",
        "Seed 004 Fig. 15: fit freely, then hold one parameter at each given value (model "
        "file's unit) and refit the rest on all shots; writes a table of chi^2, residual rms "
        "and the other parameters, and a plot.")
    _add_data_options(hold)
    hold.add_argument("--model", required=True, help="aero model (bundled name or file)")
    hold.add_argument("--param", required=True, help="the parameter to hold")
    hold.add_argument("--values", required=True, metavar="V1,V2,...",
                      help="comma-separated values to hold it at, model file's unit "
                           "(negative values are fine: --values -1.0,-1.5)")
    diag = _subcommand(
        sub, "diagnose", _diagnose,
        "where the fit misses, which unmodelled effect, how far it shrinks",
        "Fit, then rank a library of unmodelled effects (dynamics, aero, station) by score "
        "tests and nonlinear refits, add the significant ones, and say where any remaining "
        "gap lies (docs/gap.md).")
    _add_data_options(diag)
    diag.add_argument("--model", required=True, help="aero model (bundled name or file)")
    diag.add_argument("--alpha", type=float, default=0.01,
                      help="family-wise significance of adding an effect")
    _add_start_option(diag)
    cal = _subcommand(
        sub, "calibrate", _calibrate, "station biases from sphere calibration shots",
        "Sphere calibration: per-station position and timing biases with sigmas, compared "
        "with the facility's station history, to which the estimate is appended "
        "(docs/calibration.md). Exit status 3: the outputs are written but the estimate is "
        "not in the station history (the message says why).")
    _add_data_options(cal)
    cal.add_argument("--stations-root", default=None, metavar="DIR",
                     help="directory holding stations/<facility>/ (default: "
                          "$CADRA_STATIONS_ROOT, else the repository root beside facilities/; "
                          "'.' for the working folder)")
    cal.add_argument("--no-history", action="store_true",
                     help="do not append the estimate to the station history")
    cal.add_argument("--threshold-sigma", type=float, default=3.0,
                     help="a station is flagged when its bias moved by more than this many "
                          "sigma")
    cal.add_argument("--note", default="", help="a note stored with the history entry")
    add_motion_parser(sub)   # cadra2 motion: cadra/cli/motion.py, docs/motion.md
    add_roll_parser(sub)     # cadra2 roll: cadra/cli/roll.py, docs/segmented_roll.md
    sim = _subcommand(
        sub, "simulate", _simulate, "simulate and render a synthetic shot",
        "Fly a synthetic shot from a shot specification (6-DOF, the same code the fit uses), "
        "render its shadowgraphs and write the shot file, images and exact truth "
        "(docs/simulation.md).")
    sim.add_argument("spec", help="shot specification TOML (docs/simulation.md)")
    sim.add_argument("-o", "--output", required=True, help="output directory (must not exist)")
    sim.add_argument("--no-images", action="store_true", help="trajectory and truth only")
    sim.add_argument("--overwrite", action="store_true", help="replace an existing output")
    _subcommand(sub, "models", _models, "list the bundled aero models",
                "List the bundled aero models (cadra/aero/models): name, case, angle plane, "
                "free parameters, description; give one to --model by name.")
    return parser


def main(argv: list[str] | None = None) -> int:
    """The ``cadra2`` console script (module doc); returns the exit status."""
    return console_main("cadra2", _main, argv)


def _main(argv: list[str] | None) -> int:
    from cadra.io.atomic import UnsafeOutputError, check_output_dir

    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(join_number_lists(argv, NUMBER_LIST_OPTIONS))
    if getattr(args, "output", None) is None:  # a command that writes nothing (models)
        return args.func(args)
    try:  # every command writes one folder, never over its inputs
        check_output_dir(args.output, _input_paths(args))
    except UnsafeOutputError as exc:
        print(f"cadra2 {args.command}: {exc}", file=sys.stderr)
        return 1
    if _exists(Path(args.output), args, args.command):
        return 1
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
