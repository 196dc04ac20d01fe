"""The campaign's tasks: pure functions over plain data that a Dask worker runs.

Every task is :func:`run_task` ``(kind, name, key, payload, *upstream)``: it returns an
:class:`Outcome` (never raises), whose ``value`` is the library's own result (a stage-one
result, a station-bias estimate, a single fit's row, a :class:`~cadra.fitting.FitResult`, a
hold study's table, a gap diagnosis). A failed task returns its reason; a task whose inputs
failed says which. Nothing here writes a file: the client stores the outcomes and writes the
database and the folders (:mod:`cadra.campaign.run`).

Kinds (docs/campaign.md, "Tasks"): ``stage1`` (render a specification if given, then stage
one), ``calibrate`` (sphere shots -> station biases), ``single`` (one shot, the linear
template), ``multifit`` (a group's shots, its model), ``holdone`` (the group's hold study,
from its multi-fit), ``diagnose`` (the group's gap diagnosis).
"""

from __future__ import annotations

import math
import os
import socket
import time
import traceback
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class Outcome:
    """A task's result, as its worker returns it."""

    kind: str
    name: str
    key: str
    ok: bool
    value: Any = None
    error: str = ""
    seconds: float = 0.0
    worker: str = ""
    started_utc: str = ""
    #: the inputs (``kind:name``) that had failed when this task ran: a rerun reuses this
    #: outcome only if the same inputs fail again
    failed_inputs: tuple[str, ...] = ()
    #: the task's report folder, drawn on the worker (:func:`cadra.campaign.folders.run_drawn`);
    #: the client writes it and stores the outcome without it
    folder: Any = None

    @property
    def id(self) -> str:
        return f"{self.kind}:{self.name}"

    def __repr__(self) -> str:
        state = "ok" if self.ok else f"failed: {self.error[:60]}"
        return f"<Outcome {self.kind}:{self.name} {state}, {self.seconds:.1f} s>"


class UpstreamFailed(RuntimeError):
    """An input of the task failed; the message names it."""


def _worker() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"


def _utc() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def first_line(text: str | None) -> str:
    """The first non-empty line of an error text ("" for none): what tables and status show;
    the whole text stays in the ``tasks`` table."""
    return next((line.strip() for line in (text or "").splitlines() if line.strip()), "")


# --------------------------------------------------------------------------- stage one


def stage_one(entry, formation: str = "view") -> dict:
    """A shot's trajectory: its specification flown and rendered in memory, or its shot
    file's images, through stage one on this worker's one core."""
    import cadra
    from cadra.flight.estimates import kinematics_at_epoch
    from cadra.io.spec_file import spec_from_dict

    truth = None
    if entry.spec is not None:
        spec = spec_from_dict(dict(entry.spec), source_path=Path(entry.spec_path)
                              if entry.spec_path else None)
        shot = cadra.simulate(spec)
        truth = shot.truth
        result = cadra.measure(shot, workers=1, formation=formation)
    else:
        result = cadra.measure(entry.shot, workers=1, formation=formation)
    sd = result.shot_data()
    try:   # the speed at the shot's epoch (its middle station), as linear theory reads it
        v = float(np.linalg.norm(kinematics_at_epoch(sd)[1]))
    except ValueError:      # fewer than three positions: no speed to read
        v = math.nan
    return {"stage1": result, "truth": truth, "velocity_m_s": v,
            "mach": v / sd.rigid.speed_of_sound_m_s, "n_stations": int(result.n_measured)}


def _shot_data(outcome: Outcome, table=None, significance: float = 3.0):
    from cadra.calibration.sphere import apply_bias_table

    sd = outcome.value["stage1"].shot_data()
    if table is None or (sd.facility and table.facility and sd.facility != table.facility):
        return sd     # a shot of another range: its stations are not the spheres'
    return apply_bias_table(sd, table, min_significance=significance)


def _bias_table(calibration: Outcome | None):
    """The campaign's bias table and a note: (None, "") without sphere shots; (None, why) when
    the calibration failed (the fits go on uncorrected and say so)."""
    if calibration is None:
        return None, ""
    if not calibration.ok:
        return None, ("not corrected for station biases: the sphere calibration failed "
                      f"({first_line(calibration.error)})")
    return calibration.value.to_table(created_utc="2000-01-01T00:00:00Z",
                                      note="campaign calibration"), ""


# --------------------------------------------------------------------------- tasks


def calibrate(spheres: list[Outcome]) -> dict:
    """Station biases from the sphere shots that came through stage one."""
    import cadra

    ok = [o for o in spheres if o.ok]
    if not ok:
        raise UpstreamFailed("no sphere shot came through stage one: "
                             + "; ".join(f"{o.name}: {o.error}" for o in spheres))
    est = cadra.calibrate([o.value["stage1"] for o in ok])
    return est


def single(payload: dict, stage1: Outcome, calibration: Outcome | None) -> dict:
    """Seed 004 step 1 for one shot: its single fit with a linear model."""
    from cadra.aero import resolve_model
    from cadra.fitting import FitOptions
    from cadra.studies.single import linear_template_for, single_fit

    if not stage1.ok:
        raise UpstreamFailed(f"stage one failed: {stage1.error}")
    table, note = _bias_table(calibration)
    sd = _shot_data(stage1, table, payload["bias_significance"])
    if payload.get("model"):
        model = resolve_model(payload["model"])
    elif sd.body_kind == "sphere":     # a sphere has drag only: its own model
        model = resolve_model("sphere")
    else:
        model = linear_template_for(sd)
    row = single_fit(sd, model, None,
                     options=FitOptions(max_iterations=payload["max_iterations"]))
    return {"row": row, "model": model.name, "mach": stage1.value["mach"], "note": note}


def multifit(payload: dict, calibration: Outcome | None, *members: Outcome) -> dict:
    """A group's multi-fit on the shots that came through stage one (the others are named
    in ``missing``), with its coefficient curves along the flights' angles."""
    import cadra

    group = payload["group"]
    table, note = _bias_table(calibration)
    missing = {o.name: o.error for o in members if not o.ok}
    shots = [_shot_data(o, table, payload["bias_significance"]) for o in members if o.ok]
    if not shots:
        raise UpstreamFailed("no shot of the group came through stage one: "
                             + "; ".join(f"{k}: {v}" for k, v in missing.items()))
    result = cadra.fit(shots, group.model, hold=group.hold or None, free=group.free or None,
                       max_iterations=payload["max_iterations"])
    return {"result": result, "shots": shots, "missing": missing, "note": note,
            "curves": coefficient_curve_table(result, shots) if result.problem else None}


def coefficient_curve_table(result, shots, n_points: int = 61) -> pd.DataFrame:
    """The fitted coefficients and their 1-sigma along the angles the flights covered, at
    the flights' mean Mach (the points of seed 004 Figs. 9-14's curves), the angles and Mach
    from the fit's own forward model (:func:`cadra.fitting.histories.flown_angles`):
    ``coefficient``, ``angle`` (``alpha`` or ``sigma``), ``angle_deg``, ``mach``, ``value``,
    ``sigma`` (with the held values' own uncertainty where the model gives them one: the
    consider covariance, :mod:`cadra.fitting.consider`)."""
    from cadra.fitting.histories import flown_angles
    from cadra.report.fit_plots import coefficient_curves

    flown = flown_angles(result, shots, n_points)
    grid = flown.grid_rad
    na = len(result.aero_names)
    ca = result.consider
    cov = result.covariance if ca is None else ca.covariance   # same order: param_names
    curves = coefficient_curves(result.model, result.aero_names, cov[:na, :na],
                                *flown.path(), flown.mach)
    rows = []
    for c, (v, s) in curves.items():
        v = np.broadcast_to(np.asarray(v, dtype=float), grid.shape)
        s = np.broadcast_to(np.asarray(s, dtype=float), grid.shape)
        rows.append(pd.DataFrame({"coefficient": c, "angle": flown.angle,
                                  "angle_deg": np.degrees(grid), "mach": flown.mach,
                                  "value": v, "sigma": s}))
    return pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()


def holdone(payload: dict, fitted: Outcome) -> pd.DataFrame:
    """The group's hold-one study (seed 004 Fig. 15), from its converged multi-fit."""
    from cadra.fitting import FitOptions
    from cadra.fitting.inputs import values_to_si
    from cadra.studies.holdone import hold_one_study, with_linear_prediction

    if not fitted.ok:
        raise UpstreamFailed(f"the group's multi-fit failed: {fitted.error}")
    result, shots = fitted.value["result"], fitted.value["shots"]
    if not result:
        raise UpstreamFailed(f"the group's multi-fit did not converge ({result.status}): the "
                             "study needs a converged start")
    study = payload["group"].hold_study
    si = values_to_si(result.model, study.parameter, list(study.values))
    table = hold_one_study(shots, result.model, [sf.state for sf in result.shots],
                           study.parameter, si,
                           options=FitOptions(max_iterations=payload["max_iterations"]))
    return with_linear_prediction(table, result, study.parameter)


def diagnose(payload: dict, fitted: Outcome):
    """The group's gap diagnosis (docs/gap.md), from its multi-fit."""
    import cadra

    if not fitted.ok:
        raise UpstreamFailed(f"the group's multi-fit failed: {fitted.error}")
    result = fitted.value["result"]
    if result.problem is None:
        raise UpstreamFailed("the group's multi-fit has no forward model")
    return cadra.diagnose(result)


def bootstrap(payload: dict, fitted: Outcome):
    """The group's parametric bootstrap (:mod:`cadra.campaign.bootstrap`) from its converged
    multi-fit: its refits as further tasks on the campaign's own cluster (this task waits
    for them off its worker's slot), or here when it runs outside a worker."""
    from cadra.campaign.bootstrap import bootstrap as run_bootstrap

    if not fitted.ok:
        raise UpstreamFailed(f"the group's multi-fit failed: {fitted.error}")
    result = fitted.value["result"]
    if not result:
        raise UpstreamFailed(f"the group's multi-fit did not converge ({result.status}): the "
                             "bootstrap resamples a converged fit")
    from distributed import get_worker, worker_client

    from cadra.studies.bootstrap import peak_quantities, sommer_tobak_quantities

    # the C_mq peak (its height and angle) and seed 004's Eq. (1) where the model has them
    derived = {**peak_quantities(result), **sommer_tobak_quantities(result)}
    try:
        get_worker()
    except ValueError:       # not on a Dask worker: the refits run here
        return run_bootstrap(result, payload["n"], noise=payload["noise"], workers=0,
                             derived=derived)
    with worker_client() as client:
        return run_bootstrap(result, payload["n"], noise=payload["noise"], client=client,
                             derived=derived)


_KINDS = {
    "stage1": lambda p, *up: stage_one(p["entry"], p["formation"]),
    "calibrate": lambda p, *up: calibrate(list(up)),
    "single": lambda p, *up: single(p, up[0], up[1] if len(up) > 1 else None),
    "multifit": lambda p, *up: multifit(p, *up),
    "holdone": lambda p, *up: holdone(p, up[0]),
    "diagnose": lambda p, *up: diagnose(p, up[0]),
    "bootstrap": lambda p, *up: bootstrap(p, up[0]),
}
#: the kinds, in the order a campaign runs them
KINDS = tuple(_KINDS)


def run_task(kind: str, name: str, key: str, payload: dict, *upstream: Outcome) -> Outcome:
    """Run one task and return its :class:`Outcome`; never raises (a failure is the
    outcome's ``error``: for an input's failure, that input's reason; otherwise the
    exception and its last frames)."""
    from cadra import cores

    started, t0 = _utc(), time.perf_counter()
    try:
        with cores.limit(1):     # Dask gives the task one core: the library's pools give way
            value = _KINDS[kind](payload, *upstream)
        ok, error = True, ""
    except UpstreamFailed as exc:
        value, ok, error = None, False, str(exc)
    except Exception as exc:  # noqa: BLE001 - a task never takes the campaign down
        tb = traceback.format_exception(exc, limit=-3)
        value, ok, error = None, False, f"{type(exc).__name__}: {exc}\n{''.join(tb)}"
    failed = tuple(sorted(u.id for u in upstream if isinstance(u, Outcome) and not u.ok))
    return Outcome(kind=kind, name=name, key=key, ok=ok, value=value, error=error,
                   seconds=time.perf_counter() - t0, worker=_worker(), started_utc=started,
                   failed_inputs=failed)


__all__ = ["KINDS", "Outcome", "UpstreamFailed", "coefficient_curve_table", "first_line",
           "run_task"]
