"""Wide optics blur: the M-80's along-axis error and the bodies' sigmas with and without the
uniform edge offset (``FitSettings.edge_offset``; docs/stage1.md, "Wide edges"), the figures
of ``tools/validate_wide_blur.py``.

Two sections, each on random views (:func:`cadra.synthetic.cases.random_view_case`) measured
per view with their true affine (:func:`cadra.validation.views.measure_case`):

- ``bias``: M-80 views nearly noise-free (read and shot noise 0.0005, no grain, 16 bit) at
  20 deg of inclination, where a uniform edge offset becomes an along-axis error: u's mean
  error and spread;
- ``random``: M-80 and M2 capsule views at default realism: u's mean error, the rms of u, v
  and the axis, and the sigmas' rms over the errors' rms.
"""

from __future__ import annotations

import numpy as np

from cadra.body import bullet_preset, capsule
from cadra.imaging.silhouette.fit import FitSettings
from cadra.synthetic.cases import random_view_case
from cadra.synthetic.render_config import RenderConfig
from cadra.validation.views import case_errors, measure_case

__all__ = ["BODIES", "blur_views"]

#: The bodies of the sections, by name.
BODIES = {"M-80": lambda: bullet_preset("M80"), "M2": lambda: capsule("M2")}


def blur_views(body_name: str, blur_px: float, n: int, seed: int, modes: tuple[str, ...],
               *, quiet: bool = False, inclination_deg: float | None = None) -> dict:
    """``n`` random views of ``body_name`` at optics blur ``blur_px`` (seed ``seed``; ``quiet``:
    nearly noise-free), each measured once per ``FitSettings.edge_offset`` value of ``modes``.
    Returns mode -> ``{"n", "u_mean_px", "u_sd_px", "rms", "sigma_over_rms", "width_px"}``
    (``rms`` and ``sigma_over_rms`` per channel: u, v in px, the axis in deg)."""
    body = BODIES[body_name]()
    cfg = (RenderConfig(read_noise_sigma=0.0005, shot_noise_sigma=0.0005, film_grain_sigma=0.0,
                        optics_blur_sigma_px=blur_px, bit_depth=16) if quiet
           else RenderConfig(optics_blur_sigma_px=blur_px))
    rng = np.random.default_rng(seed)
    views = [random_view_case(body, rng, cfg, inclination_deg=inclination_deg)
             for _ in range(n)]
    out = {}
    for mode in modes:
        errs, sigmas, widths = [], [], []
        for case in views:
            fit = measure_case(case, body, FitSettings(edge_offset=mode))
            if not fit.ok:
                continue
            e, s = case_errors(case, fit, body)
            errs.append(e)
            sigmas.append(s)
            widths.append(fit.edge_sigma_px)
        E, S = np.array(errs), np.array(sigmas)
        rms = np.sqrt(np.mean(E ** 2, axis=0))
        out[mode] = {"n": len(E), "u_mean_px": float(E[:, 0].mean()),
                     "u_sd_px": float(E[:, 0].std(ddof=1)), "rms": rms.tolist(),
                     "sigma_over_rms": (np.sqrt(np.mean(S ** 2, axis=0)) / rms).tolist(),
                     "width_px": float(np.mean(widths))}
    return out
