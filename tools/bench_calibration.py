"""Sphere calibration: recovery of injected station biases, false flags, correction of a
capsule shot. Last printed line: a JSON object.

Trials (default 50): the three sphere sample shots (450, 800, 1200 m/s; exact simulator truth)
measured through a facility whose stations carry random biases -- y and z biases of 0.2-1 mm
(random sign) at three stations each, and a 1 microsecond timing bias at one station -- plus
Gaussian noise at stage one's sphere precision (``--sigma-um``, default 0.25 um). Each trial
estimates the biases (:func:`cadra.calibration.sphere.estimate_station_biases`) and reports:

- bias_within_2sigma_frac: injected components (y, z, timing) within 2 sigma of truth;
- all_within_2sigma_frac: every station channel (biased or not) within 2 sigma;
- false_flag_rate: unbiased station channels flagged as biased (|b| > 3 sigma);
- detection_rate: injected components flagged;
- residual_ratio_after_correction: a capsule shot (M2-2429, same noise) measured through the
  same biased stations, fitted after the recovered table is applied, residual rms over the rms
  of the same shot's fit without biases (mean and max over trials; target <= 1.10);
- seconds_per_calibration.

With ``--e2e`` it also calibrates from images: the sphere_bias_{1,2,3} sample shots (biases
injected in the rendered scenes, sample_shots/<name>/station_biases.csv) are rendered, measured
by stage one and calibrated; their recovered biases are compared with the injected ones.

Usage:
    python tools/bench_calibration.py [--trials N] [--sigma-um S] [--seed K] [--e2e]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.calibration_trials import end_to_end, trials
from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=50)
    parser.add_argument("--sigma-um", type=float, default=0.22,
                        help="sphere position noise, um (stage one: 0.22)")
    parser.add_argument("--capsule-sigma-um", type=float, default=0.28,
                        help="capsule position noise, um (stage one: 0.28)")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--e2e", action="store_true", help="also calibrate from images")
    args = parser.parse_args(argv)
    run_tool("bench_calibration", ROOT, lambda: run(args), argv=argv, seconds_key=None)
    return 0


def run(args) -> dict:
    """The trials (each figure printed) and, with ``--e2e``, the calibration from images."""
    figures = trials(ROOT, args.trials, args.sigma_um * 1e-6,
                     args.seed, args.capsule_sigma_um * 1e-6)
    for k, v in figures.items():
        print(f"{k}: {v}")
    if args.e2e:
        figures.update(end_to_end(ROOT))
    return figures


if __name__ == "__main__":
    sys.exit(main())
