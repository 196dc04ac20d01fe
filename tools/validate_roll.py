"""Rolling finned missiles, every acceptance figure of the roll validation in one run (last
line JSON).

Four parts; the first three are their own tools, run here as subprocesses (each prints a
JSON last line, merged below), the fourth is cadra.validation.finner_range's:

1. ``validate_roll_seed001.py`` -- seed 001 Table IV (roll lock-in from 70 deg): the MDC
   pure-roll reduction's errors beside the paper's, stage two's fit of the same record, the
   limit cycle of Eq. 31 (docs/pureroll.md);
2. ``validate_roll_seed003.py`` -- seed 003 Table 2 as truth: segmented roll-bearing records,
   the global fit of the 14 coefficients over noise draws, pulls, signal/noise against the
   paper's, the steady spins of the fitted coefficients, the correlations
   (docs/segmented_roll.md);
3. ``validate_roll_images.py`` -- the roll from Basic Finner renders at default realism:
   error against the Cramer-Rao bound, sigma / actual, position and axis against the
   capsule's figures (docs/stage1.md, "Roll of a finned body");
4. the finned range shot end to end: FINNER-1 (sample_shots/specs/finner_1.toml, canted fins
   rolling the model up from rest) flown with new seeds, rendered, measured by cadra1 (roll
   included) and fitted by cadra2 with the bundled ``basic_finner`` forms from automatic
   starting values; the pulls (fit - truth) / sigma of every free coefficient, the roll
   coefficients (Cl_delta, Clp_0) named.

Usage::

    python tools/validate_roll.py                       # all parts (about 25 min)
    python tools/validate_roll.py --parts e2e --e2e-realisations 2
    python tools/validate_roll.py --seed003-draws 10 --images-n 8

The last printed line is a JSON object with at least lockin_cadra_over_mdc_error_max,
limit_cycle_rel_err, seed003_pull_std_min, seed003_pull_std_max, seed003_snr_over_paper_min,
steady_spin_rel_err_max, roll_crb_ratio, roll_sigma_ratio_min, roll_sigma_ratio_max,
finner_e2e_within_2sigma_frac.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.finner_range import finner_e2e  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("seed001", "seed003", "images", "e2e")


def run_part(script: str, args: list[str]) -> dict:
    """Run ``tools/<script>`` and return its last line's JSON (its table goes to stdout)."""
    cmd = [sys.executable, str(ROOT / "tools" / script), *args]
    print(f"$ {' '.join(cmd[1:])}", flush=True)
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    print(proc.stdout.rstrip("\n"), flush=True)
    if proc.returncode != 0:
        print(proc.stderr, file=sys.stderr)
        raise SystemExit(f"{script} failed (exit {proc.returncode})")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--parts", default=",".join(PARTS),
                    help=f"comma-separated parts to run (default: {','.join(PARTS)})")
    ap.add_argument("--seed003-draws", type=int, default=50,
                    help="noise draws of seed 003's records (default: 50)")
    ap.add_argument("--images-n", type=int, default=24,
                    help="Basic Finner stations rendered for the roll from images (default: 24)")
    ap.add_argument("--e2e-realisations", type=int, default=4,
                    help="realisations of the finned range shot end to end (default: 4)")
    ap.add_argument("--seed", type=int, default=20, help="seed of the end-to-end part "
                    "(default: 20)")
    args = ap.parse_args(argv)
    parts = [p.strip() for p in args.parts.split(",") if p.strip()]
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        ap.error(f"unknown part(s) {unknown}; choose from {list(PARTS)}")
    run_tool("validate_roll", ROOT, lambda: run(parts, args), argv=argv)
    return 0


def run(parts, args) -> dict:
    """The parts in ``parts``: the three tools' figures and the end-to-end shot's."""
    out: dict = {}
    if "seed001" in parts:
        out.update(run_part("validate_roll_seed001.py", []))
    if "seed003" in parts:
        out.update(run_part("validate_roll_seed003.py", ["--draws", str(args.seed003_draws)]))
    if "images" in parts:
        out.update(run_part("validate_roll_images.py", ["--n", str(args.images_n)]))
    if "e2e" in parts:
        out.update(finner_e2e(args.e2e_realisations, args.seed))
    out["parts"] = parts
    return out


if __name__ == "__main__":
    raise SystemExit(main())
