"""Where stage one's time goes in a whole shot (the figures of ``tools/profile_cadra1.py``).

One 16-station two-view shot (M2-2429, 32 images of 1600x1200) is rendered, measured once to
warm the caches, then measured on one core under :mod:`cProfile`. The time is split into the
stages a range engineer would name, each the cumulative time of the functions that do it
(they do not nest in one another):

- ``read``: decoding the image files (:func:`cadra.io.images.load_station_image`);
- ``locate``: finding the model roughly (:func:`~cadra.imaging.silhouette.locate.locate_model`);
- ``templates``: the outline templates (:func:`~cadra.imaging.silhouette.template.make_template`);
- ``wire_lines``: the wires' centroid lines (finding, profiles, centroids, lines);
- ``wire_formation``: the wires' image formation (the view's, and each image's widths);
- ``wire_centres``: every profile's centre with the formation;
- ``wire_affine``: the image -> plane affines and their covariance;
- ``silhouette``: the silhouette fits (:func:`~cadra.imaging.silhouette.fit.fit_silhouette`);
- ``other``: the rest (the lines from the model's centres, combining views, tables).

The profiler's overhead falls mostly on Python-level work, so the shares are approximate;
the shot's time without the profiler is measured too (best of three), with the read + blur
floor of :func:`cadra.validation.stage1_bench.read_blur_floor` in the same run.

What the honest sigmas cost is measured, not estimated from the shares: the same shot
timed again (best of three each) without the wires' profile model (``formation="centroid"``:
the centroids and their phase term), without the predicted noise covariance of the
silhouette's offsets (``FitSettings(covariance="scaled")``: no noise autocovariance), and
without either (``quick_look``, seconds and floors).
"""

from __future__ import annotations

import cProfile
import pstats
import tempfile
import time
from pathlib import Path

#: stage -> the functions (module path suffix, name) whose cumulative time it is
STAGES = {
    "read": [("io/images.py", "load_station_image")],
    "locate": [("silhouette/locate.py", "locate_model")],
    "templates": [("silhouette/template.py", "make_template")],
    "wire_lines": [("wires/fit.py", "_centroid_pass")],
    "wire_formation": [("wires/formation.py", "fit_formation"),
                       ("wires/formation.py", "fit_widths")],
    "wire_centres": [("wires/profile.py", "fit_centres")],
    "wire_affine": [("wires/fit.py", "_solve_affine")],
    "silhouette": [("silhouette/fit.py", "fit_silhouette")],
}


def _walls(run, repeats: int = 3) -> float:
    """The best of ``repeats`` wall times of ``run()`` (s)."""
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        walls.append(time.perf_counter() - t0)
    return min(walls)


def _cumulative(stats: pstats.Stats, where: str, name: str) -> float:
    return sum(v[3] for (path, _, fn), v in stats.stats.items()
               if fn == name and path.replace("\\", "/").endswith(where))


def profile_shot(shot_spec: Path, formation: str = "view") -> dict:
    """Render ``shot_spec``'s shot, then its stage one's time on one core: the wall time
    (best of three), and under the profiler the share of each of :data:`STAGES`."""
    from cadra.imaging.shot import measure_shot
    from cadra.imaging.silhouette.fit import FitSettings
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot
    from cadra.validation.stage1_bench import read_blur_floor

    with tempfile.TemporaryDirectory() as tmp:
        shot = Path(tmp) / "shot"
        write_shot(simulate_shot(load_shot_spec(shot_spec)), shot, images=True,
                   progress=False)

        def measure():
            return measure_shot(shot / "shot.toml", workers=1, progress=False,
                                overlays=False, formation=formation)

        measure()   # warm: compiled kernels, caches
        floor = read_blur_floor(sorted((shot / "images").glob("*.png")))
        walls = _walls(measure)
        prof = cProfile.Profile()
        t0 = time.perf_counter()
        prof.runcall(measure)
        profiled = time.perf_counter() - t0
        scaled = FitSettings(covariance="scaled")
        quick = {name: _walls(lambda f=f, s=s: measure_shot(
                    shot / "shot.toml", workers=1, progress=False, overlays=False,
                    formation=f, settings=s))
                 for name, f, s in (("centroid", "centroid", None),
                                    ("scaled", formation, scaled),
                                    ("centroid_scaled", "centroid", scaled))}
    stats = pstats.Stats(prof)
    seconds = {stage: sum(_cumulative(stats, w, n) for w, n in funcs)
               for stage, funcs in STAGES.items()}
    seconds["other"] = max(profiled - sum(seconds.values()), 0.0)
    return {"formation": formation, "shot_seconds_one_core": walls,
            "read_blur_floor_s": floor, "floor_ratio": walls / floor,
            "quick_look": {**{f"{k}_s": v for k, v in quick.items()},
                           **{f"{k}_floor_ratio": v / floor for k, v in quick.items()}},
            "profiled_seconds": profiled,
            "share": {k: v / profiled for k, v in seconds.items()},
            "seconds_unprofiled_scale": {k: v / profiled * walls
                                         for k, v in seconds.items()}}


__all__ = ["STAGES", "profile_shot"]
