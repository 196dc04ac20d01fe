"""M-80 rounds on the BRL-like spark range, reduced from the twist alone (docs/spark_range.md).

Each round is flown by the bundled simulator on ``facilities/spark_range.toml`` (25 stations
4.0 m apart over 96 m), its coefficients drawn over MR 1833 Table II's ranges and its yaw
drag over 1.5-3.5; measured as the truth plus 0.1 mm and 0.1 deg of noise; and reduced from
the twist (1 in 12 in) and the muzzle velocity only: the 6-DOF fit from its automatic start
(CD0, CNA, CDD2, CMA, CMQ, CMPA free), the same fit started at the truth (the truth's chi^2
basin), and the classic 12-constant reduction (``cadra2 motion --twist``). The work is
cadra.validation.spark_range's.

Reported: the fraction of rounds in the truth's basin (``right_basin_frac``), the rounds
called converged outside it (``false_converged``), the 6-DOF pulls' standard deviations and
fraction within 2 sigma per coefficient, the classic reduction's sigmas over the 6-DOF's,
its C_m_alpha within 2 sigma (``motion_cma_within_2sigma_frac``) and the time per fit.

Usage: python tools/validate_spark_range.py [--rounds 20] [--seed 1880] [--no-muzzle-velocity]
(about 8 s a round on one core). Last line: a JSON object.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.spark_range import FREE, run  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=20, help="rounds flown and reduced")
    ap.add_argument("--seed", type=int, default=1880, help="seed of the draws")
    ap.add_argument("--no-muzzle-velocity", action="store_true",
                    help="give the reducer the twist alone (the spin at the range's speed)")
    args = ap.parse_args(argv)
    s = run_tool("validate_spark_range", ROOT, lambda: show(run(
        args.rounds, args.seed, not args.no_muzzle_velocity)), argv=argv, seconds_key="run_s")
    return 0 if s["false_converged"] == 0 else 1


def show(s: dict) -> dict:
    """Print the per-round lines and the pull table of ``s``; returns it."""
    for r in s["per_round"]:
        print(f"{r['shot_id']:10s} {r['verdict']:14s} basin {str(r['in_basin']):5s} chi2 "
              f"{r['chi2']:9.2f} (truth start {r['chi2_truth_start']:8.2f}, dof {r['dof']}) "
              f"{r['seconds']:5.1f} s")
    print(f"{'coef':6s} {'pull std':>9s} {'within 2s':>10s}")
    for n in FREE:
        print(f"{n:6s} {s['pull_std'][n]:9.2f} {s['within_2sigma'][n]:10.2f}")
    return s


if __name__ == "__main__":
    sys.exit(main())
