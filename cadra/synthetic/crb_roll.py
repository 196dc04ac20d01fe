"""Cramér–Rao bound of a finned body's roll from one shadowgraph (docs/stage1.md, "Roll of a
finned body").

The same image model and noise as :func:`cadra.synthetic.crb.pose_crb` (the renderer's
``render_clean`` as the expectation, film grain, shot and read noise and quantization as the
covariance ``C``, solved by conjugate gradients), with one more parameter: the roll ``gamma``
about the nose axis, which moves the fins. Its derivative image is a central difference of
the expectation at the outlines ``outline_fn(gamma +- h)`` (the exact outline at the trial roll,
the body's pose held). The Fisher information ``F = G^T C^-1 G`` over
``(u, v, phi, gamma, gain, blur_sigma)`` gives

* ``sigma_roll_rad``: the bound with the in-plane pose ``(u, v, phi)`` and the nuisances
  unknown (marginalized): what any unbiased estimator of the roll from this image can reach;
* ``sigma_roll_known_pose_rad``: the bound with the pose and nuisances known exactly.

Clutter and film defects are not in the bound (as for the pose).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from cadra.synthetic.crb import _roi_box, correlated_fisher, model_image, nuisance_columns
from cadra.synthetic.render import RenderConfig, illumination_field

__all__ = ["RollCRB", "roll_crb"]


@dataclass(frozen=True, eq=False)
class RollCRB:
    """Cramér–Rao bound of the roll from one image (:func:`roll_crb`).

    ``params`` names the rows of ``fisher``/``cov`` (``u``, ``v`` px, ``phi``, ``roll`` rad,
    then ``gain``, ``blur_sigma``); ``roi`` the sub-image ``(u0, v0, width, height)``.
    """

    params: tuple[str, ...]
    fisher: np.ndarray
    cov: np.ndarray
    sigma_roll_rad: float
    sigma_roll_known_pose_rad: float
    roi: tuple[int, int, int, int]
    runtime_s: float


def roll_crb(outline_fn, roll_rad: float, ref_px, config: RenderConfig | None = None, *,
             motion_blur_px=(0.0, 0.0), width_px: int | None = None,
             height_px: int | None = None, roi_margin_px: float = 8.0,
             step_px: float = 1e-3, step_rad: float = 1e-5, step_roll_rad: float = 2e-4,
             step_blur_px: float = 1e-3, cg_tol: float = 1e-9) -> RollCRB:
    """Cramér–Rao bound of the roll of a finned body from one rendered image.

    Parameters
    ----------
    outline_fn
        ``roll_rad -> (N, 2)`` exact outline, full-frame ``(u, v)`` px, at the true pose.
    roll_rad
        The true roll.
    ref_px
        The reference point ``(u, v)`` px (rotation centre of the in-plane angle).
    config, motion_blur_px, width_px, height_px, roi_margin_px, step_px, step_rad,
    step_blur_px, cg_tol
        As :func:`cadra.synthetic.crb.pose_crb`.
    step_roll_rad
        Central-difference step of the roll.
    """
    t0 = time.perf_counter()
    config = RenderConfig() if config is None else config
    poly = np.asarray(outline_fn(roll_rad), dtype=np.float64)
    ref = np.asarray(ref_px, dtype=np.float64).reshape(2)
    motion = tuple(float(x) for x in motion_blur_px)
    margin = float(roi_margin_px) + (0.5 * math.hypot(*motion) if config.motion_blur else 0.0)
    roi = _roi_box(poly, margin, width_px, height_px)
    u0, v0, w, h = roi
    if width_px is not None and height_px is not None:
        illum = illumination_field(int(width_px), int(height_px), config)[v0:v0 + h,
                                                                          u0:u0 + w]
    else:
        illum = float(config.background_level)

    def model(polygon=poly, pose=(0.0, 0.0, 0.0), blur=None):
        return model_image(polygon, ref, config, roi, pose=pose, motion_blur_px=motion,
                           illumination=illum, blur_sigma_px=blur)

    expected = model()
    names = ["u", "v", "phi", "roll"]
    cols = []
    for i, step in enumerate((step_px, step_px, step_rad)):
        dp = np.zeros(3)
        dp[i] = step
        cols.append((model(pose=dp) - model(pose=-dp)) / (2.0 * step))
    cols.append((model(outline_fn(roll_rad + step_roll_rad))
                 - model(outline_fn(roll_rad - step_roll_rad))) / (2.0 * step_roll_rad))
    extra_names, extra_cols = nuisance_columns(model, expected, config, step_blur_px)
    names += extra_names
    cols += extra_cols
    fisher = correlated_fisher(np.stack(cols, axis=-1), expected, config, cg_tol)[0]
    cov = np.linalg.inv(fisher)
    k = names.index("roll")
    return RollCRB(params=tuple(names), fisher=fisher, cov=cov,
                   sigma_roll_rad=float(math.sqrt(cov[k, k])),
                   sigma_roll_known_pose_rad=float(1.0 / math.sqrt(fisher[k, k])),
                   roi=roi, runtime_s=time.perf_counter() - t0)
