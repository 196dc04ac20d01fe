"""A spark surveyed off its place, named by the gap diagnosis (docs/gap.md; the harness of
``tools/validate_spark_gap.py``).

Each trial flies two M-80 rounds through the bundled point-source range (``brl_spark``),
off the line of flight on opposite sides: the sample round ``m80_direct_1`` (20 mm to port,
15 mm high at launch) and the same round launched at the mirror offset, each reseeded per
trial. In a *spark* trial one view of one station (drawn at random among the middle
stations) records through a spark :data:`SPARK_ERROR_M` farther from its film than the
facility file says: the rounds are rendered with the spark moved, measured by stage one with
the facility file as it is, fitted together (the 6-DOF fit of the M-80's free coefficients,
:func:`cadra.validation.m80.six_dof`) and diagnosed (:func:`cadra.gap.score.diagnose_gap`).
A *null* trial renders with the spark where the file says. Scored: whether the candidate
added first is that station's spark distance for that view, its fitted size against the
truth in its sigma, and, in the null trials, whether anything was added.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

__all__ = ["SPARK_ERROR_M", "fly_and_fit", "run_trial", "summarize"]

#: the spark survey error of a spark trial, m (a spark's position is surveyed to millimetres;
#: on the rounds' offsets this moves the station's lateral position by several of stage
#: one's sigmas)
SPARK_ERROR_M = 0.003
#: the stations a spark error is put at (ids; the middle of the range's 25)
STATIONS = tuple(range(6, 21))


def _rounds(k: int):
    """The two round specs of trial ``k`` (point-source range, mirror offsets, reseeded)."""
    from cadra.synthetic.simulate import load_shot_spec
    from cadra.validation.m80 import SPECS_DIR

    base = load_shot_spec(SPECS_DIR / "m80_direct_1.toml")
    a = dataclasses.replace(base, seed=base.seed + 1000 * k)
    launch = dataclasses.replace(a.launch, y_m=-a.launch.y_m, z_m=-a.launch.z_m)
    b = dataclasses.replace(a, shot_id=a.shot_id + "-M", launch=launch,
                            seed=base.seed + 1000 * k + 500)
    return a, b


def _with_spark(facility, station_id: int, view: str, delta_m: float):
    """``facility`` with ``station_id``'s ``view`` spark ``delta_m`` farther from its film."""
    from cadra.gap.optics import spark_moved

    stations = tuple(dataclasses.replace(s, views={**s.views,
                                                   view: spark_moved(s.views[view], delta_m)})
                     if s.id == station_id else s for s in facility.stations)
    return dataclasses.replace(facility, stations=stations)


def fly_and_fit(k: int, true, declared):
    """Trial ``k``'s two rounds rendered through facility ``true``, measured by stage one
    under ``declared`` and fitted together: ``(shots, stations failed, the fit)``."""
    from cadra.imaging.shot import measure_shot
    from cadra.synthetic.simulate import render_images, simulate_shot
    from cadra.validation.m80 import linear_theory, six_dof, start_from_linear, truth_model

    shots, failed = [], 0
    for spec in _rounds(k):
        flown = render_images(simulate_shot(spec, true), progress=False)
        stage1 = measure_shot(flown.shot_file(), images=flown.images, facility=declared,
                              workers=1, progress=False, overlays=False)
        failed += int(stage1.trajectory["status"].eq("failed").sum())
        shots.append(stage1.shot_data())
    res = six_dof(shots, start_from_linear([linear_theory(s) for s in shots]), truth_model())
    return shots, failed, res


def run_trial(k: int, spark: bool) -> dict:
    """One trial (module doc): the rounds rendered (through a moved spark if ``spark``),
    measured, fitted and diagnosed. Returns what was injected, what was added first, its
    fitted value and sigma, and the seconds taken."""
    from cadra.gap.score import diagnose_gap
    from cadra.io.facility_file import load_facility

    t0 = time.perf_counter()
    rng = np.random.default_rng([k, 4242])
    declared = load_facility("brl_spark")
    station = int(rng.choice(STATIONS))
    view = str(rng.choice(["top", "side"]))
    true = _with_spark(declared, station, view, SPARK_ERROR_M) if spark else declared
    shots, _, res = fly_and_fit(k, true, declared)
    out = {"trial": k, "spark": spark, "station": station, "view": view,
           "expected": f"station {station} {view} spark distance" if spark else "",
           "fit_status": res.status, "chi2_nu": float(res.reduced_chi2)}
    dg = diagnose_gap(res, shots)
    out["added"] = [a["effect"] for a in dg.added]
    out["aliases"] = [list(a["aliases"]) for a in dg.added]
    out["verdict"] = dg.verdict
    out["top_ranked"] = str(dg.ranking.iloc[0]["candidate"]) if len(dg.ranking) else None
    out["named_first"] = bool(spark and out["added"] and out["added"][0] == out["expected"])
    if out["named_first"]:
        first = dg.added[0]
        out["fitted_m"], out["sigma_m"] = first["size"][0], first["sigma"][0]
    out["seconds"] = time.perf_counter() - t0
    return out


def summarize(rows: list[dict]) -> dict:
    """Named-first rate among the spark trials (with its Clopper-Pearson interval), the
    fitted sizes' pulls, and the null trials' false additions."""
    from cadra.validation.tool import binomial_rate

    sp = [r for r in rows if r["spark"]]
    nu = [r for r in rows if not r["spark"]]
    out = {"spark_trials": len(sp), "null_trials": len(nu)}
    if sp:
        out["named_first"] = binomial_rate(sum(r["named_first"] for r in sp), len(sp))
        pulls = [(r["fitted_m"] - SPARK_ERROR_M) / r["sigma_m"] for r in sp
                 if r.get("named_first") and r.get("sigma_m")]
        out["size_pulls"] = pulls
        out["size_within_2sigma_frac"] = (float(np.mean(np.abs(pulls) <= 2)) if pulls
                                          else None)
    if nu:
        out["null_added"] = binomial_rate(sum(bool(r["added"]) for r in nu), len(nu))
    out["median_seconds"] = float(np.median([r["seconds"] for r in rows])) if rows else None
    return out
