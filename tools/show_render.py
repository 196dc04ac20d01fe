"""Render a demo shadowgraph (capsule, fiducial wires, reference mark) to a PNG to look at.

    python tools/show_render.py out.png [--config render.toml] [--clean] [--no-clutter]
                                        [--crop] [--overwrite]

The scene is a seed-004-like side view: a capsule (heat shield forward, flying to the right)
near the middle of a 1600 x 1200 frame, two wires across the range axis, one along it, a
scanner reference mark in a corner. ``--crop`` writes a 4x enlarged crop of the capsule's
front edge instead (to inspect blur, fringe and noise). The render time is printed.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from cadra.synthetic.render import (
    RenderConfig,
    Scene,
    load_render_config,
    quantize,
    render,
    render_clean,
    write_image,
)


def capsule_outline(diameter_px: float, n: int = 2048) -> np.ndarray:
    """Side silhouette (N, 2) of an Orion-like capsule about its cg, nose along +x.

    Heat shield: spherical cap of radius 1.2 d; shoulder radius 0.05 d; afterbody cone of
    half-angle 32.5 deg to a flat back of diameter 0.3 d (rough seed 004 Fig. 1 proportions).
    """
    d = diameter_px
    r_max, rn, rs = 0.5 * d, 1.2 * d, 0.05 * d
    cone = np.radians(32.5)
    # heat-shield cap: points (x, y) with x forward, from the axis to the shoulder tangency
    phi_s = np.arcsin((r_max - rs) / (rn - rs))
    phi = np.linspace(0.0, phi_s, n // 4)
    cap = np.column_stack([rn * np.cos(phi) - rn, rn * np.sin(phi)])
    # shoulder torus, from the cap tangency round to the cone tangency
    cx, cy = cap[-1, 0] - rs * np.cos(phi_s), cap[-1, 1] - rs * np.sin(phi_s)
    psi = np.linspace(phi_s, np.pi / 2 + cone, n // 8)
    shoulder = np.column_stack([cx + rs * np.cos(psi), cy + rs * np.sin(psi)])
    # afterbody cone to the back face
    x0, y0 = shoulder[-1]
    r_back = 0.15 * d
    length = (y0 - r_back) / np.tan(cone)
    s = np.linspace(0.0, 1.0, n // 8)[1:]
    conical = np.column_stack([x0 - s * length, y0 - s * (y0 - r_back)])
    back = np.column_stack([np.full(7, conical[-1, 0]), np.linspace(r_back, 0.0, 8)[1:]])
    upper = np.vstack([cap, shoulder, conical, back])
    lower = upper[::-1] * [1.0, -1.0]
    outline = np.vstack([upper, lower[1:-1]])
    outline[:, 0] -= 0.5 * outline[:, 0].min()  # put the reference point inside the body
    return outline


def demo_scene(width: int = 1600, height: int = 1200, pitch_deg: float = 12.0) -> Scene:
    """The demo scene; the capsule flies to the right (+u), nose pitched up by ``pitch_deg``."""
    d = 280.0
    body = capsule_outline(d)
    c, s = np.cos(np.radians(pitch_deg)), np.sin(np.radians(pitch_deg))
    # image v is down: nose up means the nose moves to -v
    rot = np.array([[c, s], [-s, c]])
    centre = np.array([0.5 * width + 0.37, 0.5 * height - 0.21])
    poly = body @ rot.T + centre
    wires = (
        ((310.2, -20.0), (318.9, height + 20.0), 2.1),
        ((1290.5, -20.0), (1284.0, height + 20.0), 2.0),
        ((-20.0, 182.3), (width + 20.0, 176.8), 1.9),
    )
    return Scene(
        width_px=width,
        height_px=height,
        bodies=(poly,),
        wires=wires,
        reference_mark=(96.0, height - 110.0, 22.0, 3.0),
        motion_blur_px=(0.09, 0.0),  # 0.0003 d x (d / 0.95 px per px) ~ seed 004's Kerr cell
        body_hint=(centre[0], centre[1], 1.0, 0.0, 0.5 * d),
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="output .png")
    ap.add_argument("--config", help="RenderConfig TOML")
    ap.add_argument("--clean", action="store_true", help="no noise (render_clean, quantized)")
    ap.add_argument("--no-clutter", action="store_true", help="no shock, wake, scratches, dust")
    ap.add_argument("--crop", action="store_true", help="4x crop of the capsule's front edge")
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args(argv)
    config = load_render_config(args.config) if args.config else RenderConfig()
    if args.no_clutter:
        config = config.replace(bow_shock=False, wake=False, scratches=0, dust=0)
    scene = demo_scene()
    render(scene, config)  # compile (numba) before timing
    t0 = time.perf_counter()
    if args.clean:
        image = quantize(render_clean(scene, config), config.bit_depth)
    else:
        image = render(scene, config)
    dt = time.perf_counter() - t0
    if args.crop:
        u, v = int(scene.body_hint[0]), int(scene.body_hint[1])
        image = image[v - 60 : v + 60, u + 40 : u + 200]
        image = cv2.resize(image, None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST)
    write_image(args.out, image, overwrite=args.overwrite)
    print(f"rendered {scene.width_px}x{scene.height_px} in {dt:.3f} s -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
