"""``cadra2 simulate SPEC.toml -o OUT_DIR``: fly a synthetic shot (the 6-DOF the fit uses),
render its shadowgraphs and write the shot file, images and exact truth
(:func:`cadra.synthetic.simulate.write_shot`; docs/simulation.md). ``cadra2 models``: the
bundled aero models."""

from __future__ import annotations

import sys
from pathlib import Path

from cadra.cli import _inputs as cli
from cadra.cli._format import write_error
from cadra.cli._inputs import Command


def _simulate_arguments(p) -> None:
    p.add_argument("spec", help="shot specification TOML (docs/simulation.md)")
    p.add_argument("-o", "--output", required=True, help="output directory (must not exist)")
    p.add_argument("--no-images", action="store_true", help="trajectory and truth only")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")


def run_simulate(args) -> int:
    """``cadra2 simulate`` (module doc); returns the exit status."""
    from cadra.report.simulation import summary_line, truth_text
    from cadra.synthetic.simulate import SpecError, load_shot_spec, simulate_shot, write_shot

    out = Path(args.output)
    try:
        spec = load_shot_spec(args.spec)
        shot = simulate_shot(spec)
        write_shot(shot, out, images=not args.no_images, overwrite=args.overwrite,
                   progress=not cli.quiet(args))
    except (SpecError, ValueError, FileNotFoundError) as exc:
        msg = str(exc)  # errors of the spec file name it already
        where = "" if msg.startswith(str(args.spec)) else f"{args.spec}: "
        print(f"cadra2 simulate: {where}{msg}", file=sys.stderr)
        return 1
    except OSError as exc:   # a read-only folder, a full disk: the output as the user named it
        print(f"cadra2 simulate: could not write {out}: {write_error(exc)} (nothing written)",
              file=sys.stderr)
        return 1
    if cli.verbose(args):
        print(truth_text(shot))
    print(summary_line(shot))
    extra = ", station_biases.csv" if (out / "station_biases.csv").is_file() else ""
    cli.say(args, f"wrote {out}/shot.toml, truth.csv{extra}" + (
        "" if args.no_images else ", truth_images.csv, images/"))
    return 0


def run_models(args) -> int:
    """List the bundled aero models (:func:`cadra.aero.bundled_model_table`): name, case,
    angle plane, number of free parameters, description; -v adds the free parameters."""
    from cadra.aero import bundled_model_table

    rows = bundled_model_table()
    if not cli.quiet(args):
        print(f"{'name':28s} {'case':9s} {'plane':10s} {'free':>4s}  description")
        for r in rows:
            print(f"{r['name']:28s} {r['case']:9s} {r['plane']:10s} {len(r['free']):4d}  "
                  f"{r['description']}")
            if cli.verbose(args):
                print(f"{'':28s} free: {', '.join(r['free'])}")
    print(f"{len(rows)} bundled models (use one with --model NAME; a model file by its path; "
          "docs/aero_models.md)")
    return 0


#: the subcommands this module runs
COMMANDS = (
    Command("simulate", run_simulate, "simulate and render a synthetic shot",
            "Fly a synthetic shot from a shot specification (6-DOF, the same code the fit "
            "uses), render its shadowgraphs and write the shot file, images and exact truth "
            "(docs/simulation.md).",
            _simulate_arguments),
    Command("models", run_models, "list the bundled aero models",
            "List the bundled aero models (cadra/aero/models): name, case, angle plane, "
            "free parameters, description; give one to --model by name.",
            lambda p: None),
)


__all__ = ["COMMANDS"]
