"""The 7.62 mm M-80 end to end: shadowgraphs -> cadra1 -> linear theory and the 6-DOF fit,
against the simulator's truth (BRL MR 1833 Table II values, docs/m80.md).

Each noise draw flies the sample rounds M80-1 and M80-2 (``sample_shots/specs/m80_*.toml``,
the small-arms range), renders their 120 shadowgraphs (draw 0 with the specs' own seeds,
draw k with seed + 1000 k: other image noise, film placement and trigger offsets), measures
them with stage one (one process), and then

* **linear theory** (the classic method, per round): the tricyclic fit of the measured angles
  with the trim arm at the spin from the twist, C_L_alpha from the swerve, and C_M_alpha,
  C_Mq + C_Malphadot and C_Mpalpha from the arms (``cadra.flight.classic.analyse_shot``,
  docs/motion.md), in MR 1833's normalisation (q d/V, p d/V: cadra.motion's p d/2V values
  divided by 2);
* **the 6-DOF fit** (``cadra.fitting.fit_shots``, both rounds together, the model ``m80``
  with CD0, CNA, CMA, CMQ, CMPA free), started from the rounds' mean linear-theory values
  and each round's spin from the twist: p0 = 2 pi V_muzzle / twist (1 turn in 12 in at
  838 m/s), as a range engineer knows it. Nothing is borrowed from the truth.

Reported per coefficient: value, sigma, truth, pull = (value - truth) / sigma; over the draws
the fraction of |pull| <= 2 (``m80_within_2sigma_frac``, 6-DOF) and the pulls' mean and
standard deviation. Then one round with film-range noise (0.1 mm, 0.1 deg: stage one's sigmas
on real film, cadra.flight.FILM_SIGMAS) added to the exact truth gives a realistic per-round
sigma of CMQ to set beside the round-to-round spread of MR 1833 Table II (-2.8 to -4.5).

A draw whose stage-one output the fit refuses to load (``FitDataError``: stage one can write
an angle sigma of hundreds of degrees where the axis lies almost in a view's plane,
docs/m80.md) is listed in ``failures``, left out of the fractions, and makes the exit
status 1. The work is cadra.validation.m80's.

Rendered shots and stage-one outputs go to ``out/m80/draw_<k>/`` (images are deleted after
measuring unless ``--keep-images``: 63 MB a round).

Usage: python tools/validate_m80.py [--draws 8] [--out DIR] [--reuse] [--keep-images] [--no-film]
(about 47 s a draw on one core -- render 2 x 7 s, stage one 2 x 13 s, fit 21 s: the default
8 draws about 6.5 min; --draws 20, the acceptance run, about 16 min; ``--reuse`` refits
the stage-one outputs already in --out). Last line: a JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.m80 import DEFAULT_OUT, run  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--draws", type=int, default=8, help="noise draws (rendered image sets)")
    ap.add_argument("--reuse", action="store_true",
                    help="reuse the draws' shot files and stage-one outputs already in --out")
    ap.add_argument("--out", default=str(DEFAULT_OUT))
    ap.add_argument("--keep-images", action="store_true")
    ap.add_argument("--no-film", action="store_true", help="skip the film-noise round")
    ap.add_argument("--seed", type=int, default=1, help="seed of the film-noise draw")
    args = ap.parse_args(argv)
    s = run_tool("validate_m80", ROOT, lambda: show(run(
        args.draws, Path(args.out), args.keep_images, not args.no_film, args.seed,
        reuse=args.reuse)), argv=argv, seconds_key="run_s")
    return 0 if not s["failures"] else 1


def show(s: dict) -> dict:
    """Print the tables of ``s``; returns it."""
    print("\nS_g and Mach (first/last station):", json.dumps(s["conditions"]))
    print(f"{'6-DOF':6s} {'truth':>9s} {'pull mean':>10s} {'pull std':>9s} {'max|pull|':>10s} "
          f"{'mean sigma':>11s}")
    for n, r in s["six_dof"].items():
        print(f"{n:6s} {r['truth']:9.4g} {r['pull_mean']:+10.2f} {r['pull_std']:9.2f} "
              f"{r['max_abs_pull']:10.2f} {r['sigma_mean']:11.3g}")
    print(f"{'linear':6s} {'truth':>9s} {'pull mean':>10s} {'pull std':>9s} {'max|pull|':>10s}")
    for n, r in s["linear_theory"].items():
        print(f"{n:6s} {r['truth']:9.4g} {r['pull_mean']:+10.2f} {r['pull_std']:9.2f} "
              f"{r['max_abs_pull']:10.2f}")
    print(f"6-DOF within 2 sigma: {s['m80_within_2sigma_frac']} of {s['n_pulls']} (sigma), "
          f"{s['m80_within_2sigma_frac_scaled']} (sigma_scaled), "
          f"{s['m80_within_2sigma_frac_coloured']} (sigma_coloured); linear theory "
          f"{s['m80_linear_within_2sigma_frac']}")
    if "cmq_sigma_film_per_round" in s:
        print(f"CMQ per-round sigma with film-range noise (0.1 mm, 0.1 deg): "
              f"{s['cmq_sigma_film_per_round']:.3g}; MR 1833 Table II spread -4.5 to -2.8")
    return s


if __name__ == "__main__":
    sys.exit(main())
