"""Is the wire affine's reported uncertainty honest at the model's position?

Renders wire-only views (:mod:`cadra.validation.wire_images`: HFFAF station 1 top and 5 side,
a perturbed film affine per placement, default realism), measures them with
:func:`cadra.imaging.wires.fit.measure_wires` and compares the solved map of the image centre
(where the model flies) with the true map, in units of the reported
``WireMeasurement.position_sigma_m`` (a along the range, b across it). Each placement is
rendered twice: with the default noise, and noise-free (same wires, same placement), whose
error is the deterministic part; both are divided by the noisy render's sigma
(:func:`cadra.validation.wire_images.wire_sigma`).

Usage::

    OMP_NUM_THREADS=1 python tools/validate_wire_sigma.py [--n 120] [--centroid] [--blur PX]

``--centroid`` measures with the centroids and their phase term instead of the profile model
(the default); ``--blur`` renders with another optics blur.

The last printed line is a JSON object: the rms of error / sigma (a, b) with noise and
noise-free, the median reported sigma (um) and the number of renders; it is also recorded in
``results/validate_wire_sigma.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cadra.validation.tool import run_tool
from cadra.validation.wire_images import wire_sigma

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=120, help="renders (split over the two views)")
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--centroid", action="store_true",
                    help="centroid centres with the phase term (profile_model=False)")
    ap.add_argument("--blur", type=float, default=None,
                    help="optics blur sigma (px) of the renders (default: the renderer's)")
    args = ap.parse_args(argv)
    return run_tool("validate_wire_sigma", ROOT, lambda: run(args), argv=argv,
                    seconds_key=None)


def run(args) -> dict:
    """The renders' error-over-sigma figures, printed; the failures listed first."""
    out, failures = wire_sigma(args.n, args.seed0, profile_model=not args.centroid,
                               blur_px=args.blur)
    for line in failures:
        print(line)
    print(f"{out['centres']}: error / sigma at the image centre, {out['n']} renders: rms a "
          f"{out['z_rms_ab'][0]}, b {out['z_rms_ab'][1]}; noise-free "
          f"{out['z_rms_noise_free_ab']}; error rms {out['error_rms_um_ab']} um; sigma "
          f"{out['sigma_median_um_ab']} um")
    return out


if __name__ == "__main__":
    main()
