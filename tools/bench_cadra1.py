"""Stage-one accuracy, honesty and speed against the renderer's exact truth.

Usage::

    python tools/bench_cadra1.py            # full run (~6-8 min on 2 cores)
    python tools/bench_cadra1.py --quick    # fewer cases, for a smoke test

Sections (all on the M2 capsule, 3.556 cm = 280 px across, and a sphere of the same diameter;
the cases and scoring are :mod:`cadra.validation.stage1_bench`):

1. default realism, random subpixel positions and attitudes: bias and rms of the reference
   point (px, mm) and of the image axis angle (deg), the reported sigma and its ratio to the
   actual error (1000 renders per body), the Cramer-Rao bound (cadra.synthetic.crb) on a few
   of the same cases and the ratio rms / bound;
2. the pixel-level baseline (Otsu threshold + image moments, cadra.validation.otsu) on the
   same images, and its error over CADRA's;
3. "no inverse crime": renders with settings the measurement does not model (Airy-like and
   disk PSFs, a stronger diffraction fringe, coarser film grain, heavy clutter);
   image formations it does model but away from the default
   (cadra.validation.views.IMAGE_FORMATION: 0.4 px and 2 px optics blur, 2.5x the fringe) and
   a small model (a 6 mm sphere, ~47 px); their sigma / rms in
   ``formation_sigma_ratio_min/max``;
4. speed: one 16-station two-view shot (32 images of 1600x1200) measured on one core, against
   a plain read + cv2.GaussianBlur pass over the same files.

The last printed line is a JSON object with the figures; it is also recorded in
``results/bench_cadra1.json``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.stage1_bench import (  # noqa: E402 (after one_thread)
    SCALE_MM_PER_PX,
    accuracy,
    figures,
    speed,
)

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    from cadra.report.stage1 import write_stage1  # after OMP_NUM_THREADS: it loads SciPy

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer cases (smoke test)")
    args = ap.parse_args()
    # 1000 renders per body: the baseline ratio's standard error is then ~3 % (at 200 it is
    # ~7 %, and one 200-render draw gave 9.5 where 1000 give 11)
    n_default, n_variant, n_crb = (30, 10, 2) if args.quick else (1000, 50, 6)
    run_tool("bench_cadra1", ROOT, lambda: run(n_default, n_variant, n_crb, write_stage1),
             seconds_key=None)
    return 0


def run(n_default: int, n_variant: int, n_crb: int, write_stage1) -> dict:
    """The accuracy and speed sections, printed; their figures."""
    t0 = time.perf_counter()
    acc = accuracy(n_default, n_variant, n_crb)
    with tempfile.TemporaryDirectory() as tmp:
        spd = speed(Path(tmp), ROOT / "sample_shots" / "specs" / "m2_2429.toml", write_stage1)
    chan = {"sphere": ("u px", "v px"), "capsule": ("u px", "v px", "axis deg")}
    for name, r in acc.items():
        print(f"\n== {name}: {r['n']} renders at default realism "
              f"({r['ms_per_view']:.0f} ms per view fit)")
        for i, c in enumerate(chan[name]):
            mm = " (%.5f mm)" % (r["rms"][i] * SCALE_MM_PER_PX) if "px" in c else ""
            print(f"  {c:9s} bias {r['bias'][i]:+.5f}  rms {r['rms'][i]:.5f}{mm}  "
                  f"CRB {r['crb'][i]:.5f}  rms/CRB {r['crb_ratio'][i]:.2f}  "
                  f"sigma/rms {r['sigma_ratio'][i]:.2f}  baseline rms {r['baseline_rms'][i]:.4f}"
                  f" ({r['baseline_ratio'][i]:.1f} +- {r['baseline_ratio_se'][i]:.1f}x)")
        for vname, v in r["variants"].items():
            print(f"  {vname:14s} rms " + " ".join(f"{x:.5f}" for x in v["rms"])
                  + "  bias " + " ".join(f"{x:+.5f}" for x in v["bias"])
                  + "  sigma/rms " + " ".join(f"{x:.2f}" for x in v["sigma_ratio"]))
    print(f"\n== speed: {spd['images']} images, one core: {spd['shot_seconds_one_core']:.2f} s "
          f"best of 5 (median {spd['shot_seconds_one_core_median']:.2f} s, "
          f"{spd['images_per_s_per_core']:.1f} images/s); with outputs+overlays "
          f"{spd['shot_seconds_one_core_with_outputs']:.2f} s; {spd['cores']} cores "
          f"{spd['shot_seconds_all_cores']:.2f} s; read+GaussianBlur floor "
          f"{spd['read_blur_floor_s']:.2f} s")
    print(f"   whole-shot errors vs truth: position rms (x, y, z) "
          f"{', '.join(f'{x:.4f}' for x in spd['shot_position_rms_mm'])} mm, "
          f"(theta, psi) {', '.join(f'{x:.5f}' for x in spd['shot_angle_rms_deg'])} deg")
    return figures(acc, spd, time.perf_counter() - t0)


if __name__ == "__main__":
    sys.exit(main())
