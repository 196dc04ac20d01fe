"""``cadra``: the whole range test, ``cadra campaign run|status|export`` (docs/campaign.md).

* ``cadra campaign run MANIFEST -o DIR [--workers N | --scheduler ADDRESS]`` runs (or
  resumes) the campaign into DIR: stage one of every shot, the sphere calibration, single
  fits, each group's multi-fit, hold study and gap diagnosis, the report page;
* ``cadra campaign status DIR`` says what is done, failed, interrupted, stale or to do;
* ``cadra campaign export DIR [-o OUT]`` writes the database's tables as CSV and Parquet;
* ``cadra campaign plan DIR --group NAME -o OUT [ranges]`` ranks candidate shots for a group
  by the information they would add to its stored multi-fit (docs/design.md).

Exit status: 0 success (run: every task done), 1 refused input, a folder in use or a task
failed (the others ran; ``status`` names it), 2 usage error, 130 interrupted, 143 terminated
(the tasks done so far are kept: rerun to resume).
"""

from __future__ import annotations

import argparse
import sys

from cadra.cli._format import HelpFormatter, add_verbosity, add_version, console_main, number

DESCRIPTION = ("A whole range test as one resumable run on Dask: a campaign manifest's shots "
               "through stage one, the sphere calibration, single fits, grouped multi-fits, "
               "hold studies and gap diagnoses, into a folder with a SQLite database and a "
               "report page. See docs/campaign.md.")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cadra", description=DESCRIPTION,
                                     formatter_class=HelpFormatter)
    add_version(parser)
    add_verbosity(parser)
    top = parser.add_subparsers(dest="group", required=True, metavar="COMMAND")
    camp = top.add_parser("campaign", help="run a campaign, see its status, export its tables",
                          description=DESCRIPTION, formatter_class=HelpFormatter)
    add_verbosity(camp, top=False)
    sub = camp.add_subparsers(dest="command", required=True, metavar="ACTION")
    run = sub.add_parser("run", help="run or resume a campaign",
                         description="Run the manifest's campaign into DIR, or resume it: "
                                     "only tasks whose inputs changed or that failed run "
                                     "again; nothing is overwritten.",
                         formatter_class=HelpFormatter)
    run.add_argument("manifest", help="the campaign manifest (TOML, docs/campaign.md)")
    run.add_argument("-o", "--output", required=True, help="the campaign folder")
    where = run.add_mutually_exclusive_group()
    where.add_argument("--workers", type=number(int, 1), default=None,
                       help="local Dask workers, one process each (default: one per core)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    add_verbosity(run, top=False)
    st = sub.add_parser("status", help="what is done, failed, stale or to do",
                        description="Every task of the campaign's manifest and its state.",
                        formatter_class=HelpFormatter)
    st.add_argument("folder", help="the campaign folder")
    st.add_argument("--manifest", default=None,
                    help="judge against this manifest (default: the one last run)")
    add_verbosity(st, top=False)
    ex = sub.add_parser("export", help="the database's tables as CSV and Parquet",
                        description="Write every table of the campaign database as "
                                    "<table>.csv and <table>.parquet.",
                        formatter_class=HelpFormatter)
    ex.add_argument("folder", help="the campaign folder")
    ex.add_argument("-o", "--output", default=None,
                    help="the export folder (default: FOLDER/export)")
    ex.add_argument("--overwrite", action="store_true", help="replace an earlier export")
    add_verbosity(ex, top=False)
    pl = sub.add_parser("plan", help="what to fire next for a group of a campaign",
                        description="Rank candidate shots for a group by the information "
                                    "they would add to its stored multi-fit (as cadra2 plan "
                                    "does from trajectory files; docs/design.md).",
                        formatter_class=HelpFormatter)
    pl.add_argument("folder", help="the campaign folder")
    pl.add_argument("--group", required=True, help="the group whose multi-fit to plan from")
    pl.add_argument("-o", "--output", required=True, help="the plan's folder (must not exist)")
    pl.add_argument("--overwrite", action="store_true", help="replace an earlier plan")
    from cadra.cli.plan import add_plan_options

    add_plan_options(pl)
    add_verbosity(pl, top=False)
    return parser


def _run(args) -> int:
    from cadra.campaign import CampaignError, ManifestError, run_campaign

    try:
        summary = run_campaign(args.manifest, args.output, scheduler=args.scheduler,
                               workers=args.workers, progress=not args.quiet)
    except (ManifestError, CampaignError, ValueError, OSError) as exc:
        print(f"cadra campaign run: {exc}", file=sys.stderr)
        return 1
    print(summary)
    if not args.quiet:
        print(f"report: {summary.folder / 'report.html'}")
    return 1 if summary.failed else 0


def _status(args) -> int:
    from cadra.campaign import ManifestError, campaign_status
    from cadra.campaign.status import status_lines

    try:
        table = campaign_status(args.folder, args.manifest)
    except (ManifestError, FileNotFoundError, ValueError) as exc:
        print(f"cadra campaign status: {exc}", file=sys.stderr)
        return 1
    print("\n".join(status_lines(table, verbose=args.verbose)))
    return 0


def _export(args) -> int:
    from pathlib import Path

    from cadra.campaign import export_tables

    out = args.output or Path(args.folder) / "export"
    try:
        export_tables(args.folder, out, overwrite=args.overwrite)
    except (FileNotFoundError, FileExistsError, ValueError) as exc:
        print(f"cadra campaign export: {exc}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(f"wrote {out}/ (<table>.csv and <table>.parquet)")
    return 0


def _plan(args) -> int:
    from cadra.atomic import UnsafeOutputError, check_output_dir
    from cadra.campaign import ManifestError, group_fit
    from cadra.cli.plan import plan_and_write

    try:
        check_output_dir(args.output, [args.folder], kind="plan")
        result = group_fit(args.folder, args.group)
    except (UnsafeOutputError, ManifestError, FileNotFoundError, ValueError) as exc:
        print(f"cadra campaign plan: {exc}", file=sys.stderr)
        return 1
    return plan_and_write(result, args, f"group {args.group} of {args.folder}",
                          "cadra campaign plan")


def main(argv: list[str] | None = None) -> int:
    """The ``cadra`` console script (module doc); returns the exit status."""
    return console_main("cadra", _main, argv)


def _main(argv) -> int:
    args = build_parser().parse_args(sys.argv[1:] if argv is None else list(argv))
    return {"run": _run, "status": _status, "export": _export,
            "plan": _plan}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
