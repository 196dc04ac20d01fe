"""Seed 001 Table IV re-run: pure roll (roll lock-in) about the π/4 trim, eqs. 27-31.

A cruciform finner on a roll bearing at α = 10° is released at 70° roll orientation (25°
above the trim), with seed 001's inputs C_lp0 −2, C_lp2 15, C_l(α) 0.5 as aero-model forms
(``Cl = Cla sin 4φ``, ``Clp = Clp0 + Clp2 (φ − π/4)²``; cadra.validation.roll_bearing), and
simulated by CADRA's 6-DOF dynamics in the ``roll_bearing`` test mode. The record of the
aerodynamic roll angle φ = γ, noise-free and with 0.05° of white noise, is reduced by

* the method of differential corrections of ``cadra.motion.pureroll`` (whole record, the
  sin 4γ pendulum averaged exactly: docs/pureroll.md), the seed's own harmonic averaging
  (eqs. 28-30) with and without its frequency-variation amplitude correction, and the
  sectional estimates that start them;
* CADRA's 6-DOF fit of the same record with C_l(α), C_lp0, C_lp2 free: stage two
  (``fit_shots``) on the ``phi`` channel alone, or a least-squares fallback without it.

Then the limit cycle (eq. 31) against the exact energy balance and the simulated one.
The seed gives no conditions: the choices are the constants of cadra.validation.lockin,
which does the work (docs/pureroll.md).

Usage: python tools/validate_roll_seed001.py [--noise-seed 1] [--draws 5]   (about 10 s)
Last line: a JSON object (lockin_mdc_err_pct, lockin_cadra_err_pct,
lockin_cadra_over_mdc_error_max, limit_cycle_rel_err, seconds, and the other figures).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.lockin import run  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--noise-seed", type=int, default=1)
    ap.add_argument("--draws", type=int, default=5, help="noise realisations (default 5)")
    args = ap.parse_args(argv)
    return run_tool("validate_roll_seed001", ROOT, lambda: run(args.noise_seed, args.draws),
                    argv=argv)


if __name__ == "__main__":
    main()
