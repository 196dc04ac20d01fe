"""Point-source images reduced under a facility file that declares parallel optics, named
by the gap diagnosis (docs/gap.md; the harness of ``tools/validate_perspective_gap.py``).

Each trial flies the two M-80 rounds of :mod:`cadra.validation.spark_gap` (the sample round
``m80_direct_1`` off the line of flight and its mirror, reseeded per trial). In a *declared
parallel* trial they are rendered through the bundled point-source range (``brl_spark``,
sparks 1.5 m from the line of flight) and measured by stage one with every view declared
parallel (:func:`cadra.validation.point_source.parallel_station`: the wires and film map as
a collimated reduction would calibrate them, at the line of flight); the rounds are fitted
together (the M-80's 6-DOF fit, :func:`cadra.validation.m80.six_dof`) and diagnosed with that
declared facility (:func:`cadra.gap.score.diagnose_gap`, ``facility=``). A *null* trial
renders the rounds through the declared parallel facility itself, so its optics are what
the file says. Scored: whether the candidate added first is a view's point-source optics,
whether both views' are added, their fitted ``1 / H`` against the sparks' true
``1 / 1.5 m``, and, in the null trials, whether either was added.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

__all__ = ["SPARK_DISTANCE_M", "declared_parallel", "run_trial", "summarize"]

#: the bundled point-source range's sparks' distance from the line of flight, m (both views)
SPARK_DISTANCE_M = 1.5
#: the optics candidates' names
_NAMES = ("top view point-source optics", "side view point-source optics")


def declared_parallel(facility):
    """``facility`` as a file declaring every view parallel would have it
    (:func:`cadra.validation.point_source.parallel_station`)."""
    from cadra.validation.point_source import parallel_station

    return dataclasses.replace(facility, stations=tuple(parallel_station(s)
                                                        for s in facility.stations))


def run_trial(k: int, point_source: bool) -> dict:
    """One trial (module doc): the rounds rendered through the point-source range (or, null,
    through its declared parallel twin), measured, fitted and diagnosed with the declared
    parallel facility. Returns what was added, the optics candidates' fitted values and
    sigmas, and the seconds taken."""
    from cadra.gap.score import diagnose_gap
    from cadra.io.facility_file import load_facility
    from cadra.validation.spark_gap import fly_and_fit

    t0 = time.perf_counter()
    cast = load_facility("brl_spark")
    declared = declared_parallel(cast)
    shots, failed, res = fly_and_fit(k, cast if point_source else declared, declared)
    out = {"trial": k, "point_source": point_source, "stations_failed": failed,
           "fit_status": res.status, "chi2_nu": float(res.reduced_chi2)}
    dg = diagnose_gap(res, shots, facility=declared)
    out["added"] = [a["effect"] for a in dg.added]
    out["verdict"] = dg.verdict
    out["named_first"] = bool(out["added"] and out["added"][0] in _NAMES)
    out["both_named"] = all(n in out["added"] for n in _NAMES)
    out["kappa"] = {a["effect"]: (a["size"][0], a["sigma"][0]) for a in dg.added
                    if a["effect"] in _NAMES}
    out["chi2_nu_after"] = float(dg.reduced_chi2_after)
    out["seconds"] = time.perf_counter() - t0
    return out


def summarize(rows: list[dict]) -> dict:
    """The named-first and both-named rates among the declared-parallel trials (with their
    Clopper-Pearson intervals), their fitted ``1 / H`` over the truth's, and the null trials'
    additions of either optics candidate."""
    from cadra.validation.tool import binomial_rate

    ps = [r for r in rows if r["point_source"]]
    nu = [r for r in rows if not r["point_source"]]
    out = {"point_source_trials": len(ps), "null_trials": len(nu)}
    if ps:
        out["named_first"] = binomial_rate(sum(r["named_first"] for r in ps), len(ps))
        out["both_named"] = binomial_rate(sum(r["both_named"] for r in ps), len(ps))
        ratios = [v[0] * SPARK_DISTANCE_M for r in ps for v in r["kappa"].values()]
        out["kappa_over_truth"] = ratios
        out["kappa_over_truth_median"] = float(np.median(ratios)) if ratios else None
        out["stations_failed_median"] = float(np.median([r["stations_failed"] for r in ps]))
    if nu:
        out["null_added"] = binomial_rate(sum(any(a in _NAMES for a in r["added"])
                                              for r in nu), len(nu))
    out["median_seconds"] = float(np.median([r["seconds"] for r in rows])) if rows else None
    return out
