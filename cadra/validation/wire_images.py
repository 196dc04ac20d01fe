"""Wire-only images with an exact truth: the fiducial wires' fixtures and their sigma study.

The renderer draws a view's wires and reference mark through a known film affine (a perturbed
placement, :func:`cadra.synthetic.simulate.film_affine`: ~4 px shift, 0.05 deg rotation, 5e-4
scale, 1-sigma), so the true image->plane map and the true image line of every wire are
exact. The wire tests and ``tools/validate_wire_sigma.py`` render and score through here:

- :data:`FAC`, :data:`VIEWS`: the HFFAF facility and the two views used (station 1 top,
  station 5 side); :data:`QUIET`: a noise-free render configuration;
- :func:`true_affine`, :func:`make_image`, :func:`circle`: the truth and the image;
- :func:`affine_error_m`, :func:`line_errors_px`, :func:`true_offset_px`, :func:`drift_px`:
  a :class:`~cadra.imaging.wires.fit.WireMeasurement` scored against the truth;
- :func:`wire_sigma`: is the wire affine's reported uncertainty honest at the image centre
  (where the model flies)?
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from cadra.geometry import apply_affine
from cadra.imaging.wires.fit import measure_wires
from cadra.io.facility_file import load_facility
from cadra.synthetic.render import RenderConfig, Scene, render
from cadra.synthetic.simulate import FilmPlacement, film_affine

#: the HFFAF facility (its views and wires)
FAC = load_facility("hffaf")
#: the views rendered: (station, view name)
VIEWS = [(1, "top"), (5, "side")]

#: a noise-free render: no read, shot or grain noise, no scratches, dust, shock or wake, 16 bits
QUIET = RenderConfig(read_noise_sigma=0.0, shot_noise_sigma=0.0, film_grain_sigma=0.0,
                     scratches=0, dust=0, bow_shock=False, wake=False, bit_depth=16)


def circle(uc, vc, radius, n=720):
    """A circle's outline, ``(n, 2)`` px: a disc-shaped body to put in a scene."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.column_stack([uc + radius * np.cos(t), vc + radius * np.sin(t)])


def true_affine(view, seed):
    """A perturbed film placement's true image->plane affine of ``view`` (seeded)."""
    rng = np.random.default_rng(seed)
    return film_affine(view.image_to_plane, FilmPlacement(), rng, view.width_px,
                       view.height_px)


def make_image(view, affine, config=None, seed=0, drop=(), bodies=()):
    """Render ``view``'s wires (minus ``drop``) and mark through ``affine``; float in [0, 1]."""
    config = RenderConfig() if config is None else config
    segs = view.wire_lines_px(affine=affine, margin_px=20.0)
    wires = tuple((np.array(s[0]), np.array(s[1]), view.wire_width_px(w))
                  for s, w in zip(segs, view.wires, strict=True) if w.name not in drop)
    mark = view.reference_mark
    scene = Scene(width_px=view.width_px, height_px=view.height_px, bodies=tuple(bodies),
                  wires=wires, reference_mark=(mark.u_px, mark.v_px, mark.arm_px,
                                               mark.width_px))
    img = render(scene, config, np.random.default_rng(seed + 12345))
    return img.astype(np.float64) / ((1 << config.bit_depth) - 1)


def affine_error_m(view, result, affine):
    """Largest distance (m) between the solved and true maps of the corners and centre."""
    W, H = view.width_px - 1.0, view.height_px - 1.0
    pts = np.array([[0, 0], [W, 0], [0, H], [W, H], [W / 2, H / 2]])
    d = apply_affine(result.affine, pts) - apply_affine(affine, pts)
    return float(np.max(np.hypot(d[:, 0], d[:, 1])))


def line_errors_px(view, result, affine):
    """Per wire: largest distance (px) of the true segment's in-image ends from the fitted
    line (NaN if not found)."""
    out = []
    for f, seg in zip(result.wires, view.wire_lines_px(affine=affine), strict=True):
        out.append(float(np.max(np.abs(f.distance_px(np.array(seg))))) if f.found
                   else math.nan)
    return np.array(out)


def true_offset_px(view, result, affine):
    """Per wire: signed distance (px) of the fitted line's reference point from the true line."""
    out = []
    for f, seg in zip(result.wires, view.wire_lines_px(affine=affine), strict=True):
        p0, p1 = np.array(seg)
        t = (p1 - p0) / np.linalg.norm(p1 - p0)
        out.append(float((np.asarray(f.point_px) - p0) @ np.array([-t[1], t[0]])))
    return np.array(out)


def drift_px(view, affine):
    """How far (px) each wire's image strays across the pixel grid over the image."""
    return np.array([min(abs(s[1][0] - s[0][0]), abs(s[1][1] - s[0][1]))
                     for s in view.wire_lines_px(affine=affine)])


def wire_sigma(n: int = 120, seed0: int = 1000, profile_model: bool = True,
               blur_px: float | None = None) -> tuple[dict, list[str]]:
    """Is the wire affine's reported uncertainty honest at the model's position?

    ``n`` placements alternate over :data:`VIEWS` (placement and noise seeded from
    ``seed0``); each is rendered twice, with the default noise and noise-free (:data:`QUIET`,
    same wires and placement), and measured by :func:`~cadra.imaging.wires.fit.measure_wires`
    (``profile_model``: the profile model; False: the centroids with their phase term).
    ``blur_px``: another optics blur sigma for both renders. The solved map of the image
    centre is compared with the true map in units of the noisy render's
    ``position_sigma_m`` (a along the range, b across it); the noise-free error is the
    deterministic part.

    Returns (figures, failures): the rms of error / sigma (a, b) with noise and noise-free,
    the error rms and median sigma (um), the median and largest ``sigma_sys_px`` of the
    lines, the centroids' median phase gain (None with the profile model) and the number of
    renders scored; and one line per render whose measurement failed."""
    noisy_cfg, quiet_cfg = RenderConfig(), QUIET
    if blur_px is not None:
        noisy_cfg = replace(noisy_cfg, optics_blur_sigma_px=blur_px)
        quiet_cfg = replace(quiet_cfg, optics_blur_sigma_px=blur_px)
    err_um, failures = [], []
    z_noisy, z_quiet, sig, sig_sys, gains = [], [], [], [], []
    for k in range(n):
        station, name = VIEWS[k % len(VIEWS)]
        view = FAC.view(station, name)
        seed = seed0 + k
        M = true_affine(view, 100 * station + seed)
        centre = np.array([[(view.width_px - 1) / 2.0, (view.height_px - 1) / 2.0]])
        truth = apply_affine(M, centre)[0]
        res = measure_wires(make_image(view, M, noisy_cfg, seed=seed), view,
                            profile_model=profile_model)
        quiet = measure_wires(make_image(view, M, quiet_cfg, seed=seed), view,
                              profile_model=profile_model)
        if not (res.ok and quiet.ok):
            failures.append(f"render {k}: {res.reason or quiet.reason}")
            continue
        s = res.position_sigma_m(centre[0])
        z_noisy.append((apply_affine(res.affine, centre)[0] - truth) / s)
        err_um.append((apply_affine(res.affine, centre)[0] - truth) * 1e6)
        z_quiet.append((apply_affine(quiet.affine, centre)[0] - truth) / s)
        sig.append(s)
        sig_sys.append([getattr(f, "sigma_sys_px", 0.0) for f in res.wires])
        gains.append(getattr(res, "phase_gain", (np.nan,) * 3))
    z_noisy, z_quiet, sig = np.array(z_noisy), np.array(z_quiet), np.array(sig)

    def rms(z):
        return [round(float(x), 3) for x in np.sqrt(np.mean(z ** 2, axis=0))]

    figures = {
        "n": len(sig), "centres": "profile model" if profile_model else "centroid",
        "blur_px": blur_px, "z_rms_ab": rms(z_noisy), "z_rms_noise_free_ab": rms(z_quiet),
        "error_rms_um_ab": [round(float(x), 4)
                            for x in np.sqrt(np.mean(np.square(err_um), axis=0))],
        "sigma_median_um_ab": [round(float(x), 4) for x in np.median(sig, axis=0) * 1e6],
        "sigma_sys_px_median": round(float(np.median(sig_sys)), 5),
        "sigma_sys_px_max": round(float(np.max(sig_sys)), 5),
        # the centroids' phase gain (NaN with the profile model, which has none)
        "phase_gain_median": ([round(float(x), 3) for x in np.nanmedian(gains, axis=0)]
                              if np.isfinite(gains).any() else None)}
    return figures, failures


__all__ = ["FAC", "QUIET", "VIEWS", "affine_error_m", "circle", "drift_px", "line_errors_px",
           "make_image", "true_affine", "true_offset_px", "wire_sigma"]
