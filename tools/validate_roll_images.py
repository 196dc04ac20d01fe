"""Stage one on the Basic Finner against the renderer's exact truth: roll, position, axis.

Usage::

    python tools/validate_roll_images.py            # 24 stations (~2-3 min on one core)
    python tools/validate_roll_images.py --n 6      # a smoke test

Each case is one HFFAF station (both views, 1600 x 1200 px, default realism: default
``RenderConfig``, film placement, wires, clutter) showing the sample shot's finned body
(``sample_shots/specs/finner_1.toml``: the Basic Finner at d = 0.7 cm, 551 px long) at a
random roll (uniform over a turn), a random axis within 3 deg of the range axis and a random
reference point within 5 mm of the station's centre, flying at 690 m/s (motion blur, a Mach 2
bow shock). The images are measured by ``cadra.imaging.station.measure_station`` (wires, pose
fit, the roll of docs/stage1.md "Roll of a finned body"). The station's best roll candidate is
compared with the truth modulo 90 deg (one station: no continuity); the Cramér–Rao bound of
each view's roll (``cadra.synthetic.crb_roll``, pose and nuisances marginalized) on every case,
combined over the views as the measurement combines them (inverse variance).

Figures: roll error rms (per view and combined, and per fold bin) over the rms bound; the
reported sigma over the
actual error (rms over rms), per view and combined and over three bins of the roll's distance
from the nearest mirror fold (0 or 45 deg modulo 90: near a fold the two mirror solutions merge);
the per-view reference-point error (px) and image axis-angle error (deg) over the M2 capsule's
figures of tools/bench_cadra1.py (0.00196 px, 0.00141 deg). The last printed line is JSON.
The cases and figures are cadra.validation.roll_images'.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.roll_images import run  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=24, help="stations (two renders each)")
    parser.add_argument("--seed", type=int, default=2020)
    parser.add_argument("--no-crb", action="store_true", help="skip the Cramér–Rao bounds")
    args = parser.parse_args(argv)
    run_tool("validate_roll_images", ROOT, lambda: run(args.n, args.seed, crb=not args.no_crb),
             argv=argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
