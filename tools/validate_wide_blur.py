"""Wide optics blur: the M-80's along-axis error and the sigmas, without and with the uniform
edge offset (docs/stage1.md, "Wide edges"; :mod:`cadra.validation.wide_blur`).

Section ``bias``: 20 nearly noise-free M-80 views at 20 deg of inclination (seed 3), at 1.0
px optics blur ("never" / "always": the band has not widened there) and 2.0 px ("never" /
"wide"). Section ``random``: 40 views a body (M-80, M2; seed 21, default realism) at 1.5 and
2.0 px, "never" / "wide".

Usage: python tools/validate_wide_blur.py
Last line: a JSON object: ``bias_u_mean_px`` and ``bias_u_sd_px`` (blur, as ``2px`` or
``1_5px`` -> mode -> u's mean error or spread, px), and per body (``m80``, ``m2``)
``*_u_mean_px``, ``*_rms`` (u, v px; axis deg) and ``*_sigma_over_rms`` (blur -> mode).
"""

from __future__ import annotations

from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

ROOT = Path(__file__).resolve().parents[1]


def _key(blur: float) -> str:
    return f"{blur:g}px".replace(".", "_")


def compute() -> dict:
    from cadra.validation.wide_blur import blur_views

    out = {"bias_u_mean_px": {}, "bias_u_sd_px": {}}
    for blur, modes in ((1.0, ("never", "always")), (2.0, ("never", "wide"))):
        r = blur_views("M-80", blur, 20, 3, modes, quiet=True, inclination_deg=20.0)
        out["bias_u_mean_px"][_key(blur)] = {m: round(v["u_mean_px"], 5) for m, v in r.items()}
        out["bias_u_sd_px"][_key(blur)] = {m: round(v["u_sd_px"], 5) for m, v in r.items()}
        for m, v in r.items():
            print(f"bias {blur} px M-80 {m}: u {v['u_mean_px']:+.4f} +- {v['u_sd_px']:.4f} px "
                  f"(width {v['width_px']:.3f} px)")
    for body, tag in (("M-80", "m80"), ("M2", "m2")):
        for name in ("u_mean_px", "rms", "sigma_over_rms"):
            out[f"{tag}_{name}"] = {}
        for blur in (1.5, 2.0):
            r = blur_views(body, blur, 40, 21, ("never", "wide"))
            out[f"{tag}_u_mean_px"][_key(blur)] = {m: round(v["u_mean_px"], 5)
                                                  for m, v in r.items()}
            out[f"{tag}_rms"][_key(blur)] = {m: [round(x, 5) for x in v["rms"]]
                                            for m, v in r.items()}
            out[f"{tag}_sigma_over_rms"][_key(blur)] = {
                m: [round(x, 3) for x in v["sigma_over_rms"]] for m, v in r.items()}
            for m, v in r.items():
                print(f"random {blur} px {body} {m}: u mean {v['u_mean_px']:+.4f}, rms u v axis "
                      + " ".join(f"{x:.4f}" for x in v["rms"]) + ", sigma / rms "
                      + " ".join(f"{x:.2f}" for x in v["sigma_over_rms"]))
    return out


if __name__ == "__main__":
    run_tool("validate_wide_blur", ROOT, compute)
