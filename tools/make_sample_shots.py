"""Regenerate the sample shots from their specifications, deterministically.

Every ``sample_shots/specs/*.toml`` is flown and written to ``sample_shots/<name>/`` (shot
file + exact truth, a few kB: committed). Images are rendered only for the shots named with
``--images`` (``all`` for every shot); they are about 34 MB a shot of incompressible film
noise, so they are regenerated (about 30 s a shot), never committed (.gitignore). Same seed ->
same bytes.

Usage:
    python tools/make_sample_shots.py [--only NAME ...] [--images NAME ... | all | none]
                                      [--out DIR] [--overwrite]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--specs", default=str(ROOT / "sample_shots" / "specs"))
    parser.add_argument("--out", default=str(ROOT / "sample_shots"))
    parser.add_argument("--only", nargs="*", help="spec names (file stems) to regenerate")
    parser.add_argument("--images", nargs="*", default=["none"],
                        help="spec names to render images for, 'all' or 'none'")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace existing outputs (otherwise existing shots are skipped)")
    args = parser.parse_args(argv)

    from tqdm import tqdm

    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    specs = sorted(Path(args.specs).glob("*.toml"))
    if args.only:
        specs = [s for s in specs if s.stem in set(args.only)]
        missing = set(args.only) - {s.stem for s in specs}
        if missing:
            print(f"no such spec(s): {sorted(missing)}", file=sys.stderr)
            return 1
    with_images = set(s.stem for s in specs) if args.images == ["all"] else (
        set() if args.images == ["none"] else set(args.images))
    t0 = time.perf_counter()
    for path in tqdm(specs, desc="sample shots", unit="shot"):
        out = Path(args.out) / path.stem
        if out.exists() and not args.overwrite:
            tqdm.write(f"{path.stem}: exists, skipped (use --overwrite)")
            continue
        shot = simulate_shot(load_shot_spec(path))
        write_shot(shot, out, images=path.stem in with_images, overwrite=args.overwrite,
                   progress=False)
        t = shot.truth
        tqdm.write(f"{path.stem}: {len(t)} stations, Mach {t.mach.mean():.3f}, "
                   f"alpha {t.alpha_deg.min():+.1f}..{t.alpha_deg.max():+.1f} deg, "
                   f"z {t.z_m.min() * 100:+.1f}..{t.z_m.max() * 100:+.1f} cm"
                   + (", images" if path.stem in with_images else ""))
    print(f"done in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
