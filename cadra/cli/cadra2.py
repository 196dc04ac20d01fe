"""``cadra2``: stage two of the pipeline (6-DOF dynamics), one module per subcommand.

* ``cadra2 fit TRAJECTORY [TRAJECTORY ...] --model MODEL -o OUT_DIR`` — the fit
  (:mod:`cadra.cli.fit`, docs/fitting.md);
* ``cadra2 single`` / ``cadra2 holdone`` — seed 004's single fits with quasi-linear trends and
  its Fig. 15 hold-one study (:mod:`cadra.cli.studies`);
* ``cadra2 plan`` — what to fire next: candidate shots ranked by the information they add
  (:mod:`cadra.cli.plan`, docs/design.md);
* ``cadra2 calibrate`` — sphere calibration and the station history
  (:mod:`cadra.cli.calibrate`, docs/calibration.md);
* ``cadra2 diagnose`` — the gap diagnosis (:mod:`cadra.cli.diagnose`, docs/gap.md);
* ``cadra2 motion`` — the classic angular-motion reduction (:mod:`cadra.cli.motion`,
  docs/motion.md);
* ``cadra2 roll`` — seed 003's segmented roll fit (:mod:`cadra.cli.roll`);
* ``cadra2 simulate SPEC.toml -o OUT_DIR`` and ``cadra2 models`` (:mod:`cadra.cli.simulate`).

Every command takes ``-q`` (no progress bars: only the result or status line, warnings and
errors; warnings go to stderr, ``cadra2 CMD: warning: ...``) and ``-v`` (more detail);
``cadra2 --version`` prints the version (docs/cli.md).

Exit status: 0 success, 1 the input was refused (message names the key), the output folder
would destroy an input (is or holds an input — trajectory, shot, image, facility, model, spec
or bias-table files and folders, the station history —, the working folder or a file; links
and ``..`` resolved; with or without ``--overwrite``) or the fit did not converge (its best
point is written, marked so), 2 usage error, 3 calibrate: outputs written but the estimate is
not in the station history, 130 interrupted (Ctrl-C: no traceback, nothing written), 141
stdout closed by its reader (``| head``; no traceback).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.cli import calibrate, diagnose, fit, motion, plan, roll, simulate, studies
from cadra.cli._format import (
    HelpFormatter,
    add_verbosity,
    add_version,
    console_main,
    join_number_lists,
)
from cadra.cli._inputs import input_paths

#: the top-level help's description (plain text: the module doc is rST)
DESCRIPTION = (
    "Stage two of CADRA: fit aerodynamic coefficients and initial states to stage one's "
    "trajectory files, with seed 004's studies, sphere calibration, gap diagnosis and the "
    "shot simulator. Exit status: 0 success; 1 input refused, output would destroy an input, "
    "or the fit did not converge; 2 usage error; 3 calibrate: outputs written but the "
    "estimate is not in the station history; 130 interrupted. See docs/cli.md.")

#: options whose value may be a comma-separated list of numbers starting with '-'
NUMBER_LIST_OPTIONS = ("--values",)


#: the subcommands, in the order of ``cadra2 --help``
MODULES = (fit, studies, plan, diagnose, calibrate, motion, roll, simulate)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cadra2", description=DESCRIPTION,
                                     formatter_class=HelpFormatter)
    add_version(parser)
    add_verbosity(parser)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in MODULES:
        for cmd in module.COMMANDS:
            # each subcommand: its summary in ``cadra2 --help``, its plain-text description
            # in ``cadra2 NAME --help``, defaults shown, -q/-v
            p = sub.add_parser(cmd.name, help=cmd.summary, description=cmd.description,
                               formatter_class=HelpFormatter)
            add_verbosity(p, top=False)
            p.set_defaults(func=cmd.run)
            cmd.arguments(p)
    return parser


#: the kind of output folder each command writes (``cadra.atomic.output_kind``): with
#: --overwrite a command replaces only an output of its own kind
OUTPUT_KINDS = {"simulate": "shot", "fit": "fit", "single": "single fits",
                "holdone": "hold-one study", "calibrate": "calibration",
                "diagnose": "diagnosis", "motion": "motion", "roll": "roll", "plan": "plan"}


def main(argv: list[str] | None = None) -> int:
    """The ``cadra2`` console script (module doc); returns the exit status."""
    return console_main("cadra2", _main, argv)


def _main(argv: list[str] | None) -> int:
    from cadra.atomic import UnsafeOutputError, check_output_dir

    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(join_number_lists(argv, NUMBER_LIST_OPTIONS))
    if getattr(args, "output", None) is None:  # a command that writes nothing (models)
        return args.func(args)
    try:  # every command writes one folder, never over its inputs
        check_output_dir(args.output, input_paths(args), kind=OUTPUT_KINDS.get(args.command))
    except UnsafeOutputError as exc:
        print(f"cadra2 {args.command}: {exc}", file=sys.stderr)
        return 1
    out = Path(args.output)
    if out.exists() and not args.overwrite:
        print(f"cadra2 {args.command}: {out} exists; refusing to overwrite (use --overwrite)",
              file=sys.stderr)
        return 1
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
