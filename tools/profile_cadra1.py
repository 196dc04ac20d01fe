"""Profile: where stage one's time goes in a whole shot, stage by stage.

Renders sample shot M2-2429 (16 stations, 32 images of 1600x1200), measures it on one core
(best of three) and once under cProfile, and splits the time into named stages (read, locate,
templates, the wires' lines, formation, centres and affine, the silhouette, the rest):
``cadra/validation/stage1_profile.py``. Run it on an idle machine.

Usage: python tools/profile_cadra1.py [--formation view|image]
Last line: a JSON object: ``shot_seconds_one_core``, ``share`` (stage -> fraction of the
profiled time) and ``seconds_unprofiled_scale`` (the shares times the unprofiled time, s).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--formation", choices=("view", "image"), default="view",
                        help="the wires' formation once per view (default) or per image")
    args = parser.parse_args()
    from cadra.validation.stage1_profile import profile_shot

    spec = ROOT / "sample_shots" / "specs" / "m2_2429.toml"

    def compute():
        out = profile_shot(spec, args.formation)
        for stage, share in sorted(out["share"].items(), key=lambda kv: -kv[1]):
            print(f"{stage:15s} {100 * share:5.1f} %  "
                  f"~{out['seconds_unprofiled_scale'][stage]:.2f} s")
        return out

    run_tool("profile_cadra1", ROOT, compute)

if __name__ == "__main__":
    main()
