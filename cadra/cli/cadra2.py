"""``cadra2``: stage two of the pipeline (6-DOF dynamics).

Subcommands available now:

* ``cadra2 simulate SPEC.toml -o OUT_DIR`` — fly a synthetic shot (6-DOF, the same code the fit
  uses), render its shadowgraphs and write the shot file, images and exact truth.

Exit status: 0 success, 1 the input was refused (message names the key), 2 usage error.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _simulate(args) -> int:
    from cadra.simulate import SpecError, load_shot_spec, simulate_shot, write_shot

    out = Path(args.output)
    if out.exists() and not args.overwrite:
        print(f"cadra2 simulate: {out} exists; refusing to overwrite (use --overwrite)",
              file=sys.stderr)
        return 1
    try:
        spec = load_shot_spec(args.spec)
        shot = simulate_shot(spec)
        write_shot(shot, out, images=not args.no_images, overwrite=args.overwrite,
                   progress=not args.quiet)
    except (SpecError, ValueError, FileNotFoundError) as exc:
        print(f"cadra2 simulate: {args.spec}: {exc}", file=sys.stderr)
        return 1
    t = shot.truth
    print(f"{spec.shot_id}: {len(t)} stations, x {t.x_m.iloc[0]:.3f}..{t.x_m.iloc[-1]:.3f} m, "
          f"Mach {t.mach.min():.3f}..{t.mach.max():.3f}, "
          f"alpha {t.alpha_deg.min():+.2f}..{t.alpha_deg.max():+.2f} deg, "
          f"beta {t.beta_deg.min():+.2f}..{t.beta_deg.max():+.2f} deg")
    print(f"wrote {out}/shot.toml, truth.csv" + ("" if args.no_images else
                                                  ", truth_images.csv, images/"))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cadra2", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="simulate and render a synthetic shot")
    sim.add_argument("spec", help="shot specification TOML (docs/simulation.md)")
    sim.add_argument("-o", "--output", required=True, help="output directory (must not exist)")
    sim.add_argument("--no-images", action="store_true", help="trajectory and truth only")
    sim.add_argument("--overwrite", action="store_true", help="replace an existing output")
    sim.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    sim.set_defaults(func=_simulate)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
