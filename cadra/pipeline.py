"""The whole job in a few calls, data in memory between them (docs/api.md).

::

    import cadra

    shot = cadra.simulate("sample_shots/specs/m2_2429.toml")    # flown and rendered
    stage1 = cadra.measure(shot)                                # images -> trajectory
    result = cadra.fit(stage1, "m2_m070")                       # trajectory -> coefficients
    print(result.report())

Each call is the library function the command line runs, over plain data: a shot
specification or a simulated shot, a stage-one result, stage two's
:class:`~cadra.flight.data.ShotData`, a :class:`~cadra.fitting.result.FitResult`. Files are
read only where a path is given, and nothing is written: the writers are
:mod:`cadra.report` (what ``cadra1`` and ``cadra2`` write).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence

from cadra.aero import AeroModel, resolve_model
from cadra.calibration.sphere import StationBiasEstimate, estimate_station_biases
from cadra.fitting import FitOptions, FitResult, fit_shots
from cadra.fitting.inputs import apply_holds
from cadra.flight.data import ShotData, with_launch_spin
from cadra.flight.starts import start_estimates
from cadra.gap.score import GapDiagnosis, diagnose_gap
from cadra.gap.where import where_analysis
from cadra.imaging.shot import Stage1Result, measure_shot
from cadra.imaging.view import ViewResult, measure_view
from cadra.synthetic.simulate import (
    ShotSpec,
    SimulatedShot,
    load_shot_spec,
    render_images,
    simulate_shot,
    spec_from_dict,
)


def simulate(spec: ShotSpec | str | os.PathLike | dict, *, images: bool = True,
             progress: bool = False) -> SimulatedShot:
    """Fly a shot specification (a file, its parsed table or a :class:`ShotSpec`) through its
    range with the 6-DOF dynamics the fit uses, and (``images``) render its shadowgraphs in
    memory (:func:`cadra.synthetic.simulate.render_images`). The result holds the exact
    truth (``truth``), the images (``images``) and the shot's record (``shot_file()``)."""
    if isinstance(spec, dict):
        spec = spec_from_dict(spec)
    elif not isinstance(spec, ShotSpec):
        spec = load_shot_spec(spec)
    shot = simulate_shot(spec)
    return render_images(shot, progress=progress) if images else shot


def measure(shot, images=None, *, facility=None, workers: int | None = 1,
            progress: bool = False, overlays: bool = False,
            formation="view", settings=None) -> Stage1Result:
    """Stage one: every station's images -> the shot's trajectory, in memory.

    ``shot``: a :class:`SimulatedShot` with its images rendered (its images, record and
    facility are used), a :class:`cadra.io.shotfile.ShotFile`, or a shot file. ``images``:
    ``(station, view)`` -> array or file (default: the simulated shot's, or the shot file's
    image files). ``workers``: processes (1: in this process; None: every core).
    ``overlays``: draw each image's overlay (what ``cadra1`` writes in ``overlays/``).
    ``formation``: the wires' image formation once per ``"view"`` of the shot (default), per
    ``"image"``, given (view name -> formation, e.g. another shot's ``formations``), or
    ``"centroid"``: no profile model (a quick look, docs/stage1.md). ``settings``: the
    silhouette fit's :class:`~cadra.imaging.silhouette.fit.FitSettings` (default: its
    defaults).
    """
    if isinstance(shot, SimulatedShot):
        if images is None:
            if shot.images is None:
                raise ValueError(f"{shot.spec.shot_id}: its images are not rendered (simulate "
                                 "it with images=True, or give the images)")
            images = shot.images
        facility = facility if facility is not None else shot.facility
        shot = shot.shot_file()
    return measure_shot(shot, images, facility=facility, workers=workers, progress=progress,
                        overlays=overlays, formation=formation, settings=settings)


def _shot_data(item) -> ShotData:
    if isinstance(item, ShotData):
        return item
    if isinstance(item, Stage1Result):
        return item.shot_data()
    raise TypeError(f"expected ShotData or a stage-one result, got {type(item).__name__}")


def fit(shots, model: AeroModel | str | os.PathLike, *, hold: Iterable[str] | None = None,
        free: Iterable[str] | None = None, bound: Iterable[str] | None = None,
        prior: Iterable[str] | None = None,
        start: str = "auto", auto_start: bool = True, max_iterations: int = 60,
        variance_components: bool = False, options: FitOptions | None = None,
        progress: bool = False, spin_rad_s: float | None = None,
        twist_m_per_turn: float | None = None,
        muzzle_velocity_m_s: float | None = None) -> FitResult:
    """Stage two: fit ``model``'s free parameters and each shot's initial state.

    ``shots``: one shot or several (a multi-fit), each a :class:`ShotData` or a stage-one
    result. ``model``: a bundled model's name, a model file or an :class:`AeroModel`;
    ``hold``, ``free``, ``bound`` as ``cadra2 fit`` takes them (``"NAME[=VALUE]"``,
    ``"NAME"``, ``"NAME=LO:HI"`` in the model file's units); ``prior``: parameters freed
    with a Gaussian prior (``"NAME=VALUE+-SIGMA"``, or ``"NAME"`` for its value and the
    model's sigma; :mod:`cadra.fitting.priors`). ``start``: the linear theory the
    starting values come from (``"auto"``, ``"linear"`` or ``"epicyclic"``,
    :func:`cadra.flight.starts.start_estimates`); ``auto_start=False`` starts from the
    model's own values. ``variance_components``: rescale each channel's sigmas by what its
    residuals ask for and refit. ``spin_rad_s`` or ``twist_m_per_turn`` (with
    ``muzzle_velocity_m_s``): the spin every shot was launched at, which no station shows
    (default: each shot's own, from its shot file's ``[gun]``); the start then puts aliased
    yaw arms in the spin's frequency bands (docs/spark_range.md). Returns the
    :class:`FitResult` (``bool(result)`` is True only when it converged)."""
    items = [shots] if isinstance(shots, ShotData | Stage1Result) else list(shots)
    data = [with_launch_spin(_shot_data(s), spin_rad_s=spin_rad_s,
                             twist_m_per_turn=twist_m_per_turn,
                             muzzle_velocity_m_s=muzzle_velocity_m_s) for s in items]
    if not isinstance(model, AeroModel):
        model = resolve_model(model)
    model = apply_holds(model, hold, free, bound, prior)
    if options is None:
        options = FitOptions(max_iterations=max_iterations, progress=progress)
    estimates = start_estimates(data, start, model) if auto_start else None
    result, _ = fit_shots(data, model, options=options, auto_start=auto_start,
                          variance_components=variance_components, estimates=estimates)
    return result


def diagnose(result: FitResult, *, alpha: float = 0.01,
             stage_one: Sequence[Stage1Result] | None = None,
             progress: bool = False) -> GapDiagnosis:
    """The gap diagnosis of a fit (docs/gap.md): where the fit misses, which unmodelled
    effect of the library explains it, and how far the residual shrinks once it is added.

    ``result``: a fit (not converged: it is continued first); its shots and model are the
    fit's own. ``alpha``: the family-wise significance of adding an effect. ``stage_one``:
    the shots' stage-one results, whose two views' x consistency joins the "where" tests.
    The returned diagnosis carries those tests in ``where_tables``."""
    if result.problem is None:
        raise ValueError("the fit has no forward model (its start failed): nothing to diagnose")
    shots = list(result.problem.shots)
    dg = diagnose_gap(result, shots, alpha=alpha, progress=progress)
    tables = {r.shot.shot_id: r.trajectory for r in stage_one or ()
              if "x_consistency" in r.trajectory}
    base = dg.fit_given if dg.fit_given is not None else result
    from dataclasses import replace

    return replace(dg, where_tables=where_analysis(base, shots, base.residuals,
                                                   tables or None))


def calibrate(shots, *, facility: str = "") -> StationBiasEstimate:
    """Station biases (x, y, z, timing) from sphere calibration shots (docs/calibration.md):
    ``shots`` as :func:`fit` takes them. The station history is a file concern: ``cadra2
    calibrate`` appends the estimate to it."""
    items = [shots] if isinstance(shots, ShotData | Stage1Result) else list(shots)
    data = [_shot_data(s) for s in items]
    if not facility:
        from cadra.calibration.bias_table import shots_facility
        from cadra.calibration.sphere import CalibrationError

        facility = shots_facility(data, CalibrationError)
    return estimate_station_biases(data, facility=facility)


def plan(result: FitResult, ranges: dict, *, targets: Iterable[str] = (),
         criterion: str | None = None, free: Iterable[str] = (), template: str | None = None,
         candidates: int = 1000, refine: int = 3, seed: int = 0, progress: bool = False):
    """What to fire next (docs/design.md): candidate shots built from one of the fit's shots
    (``template``, default the one with the most stations), launched within ``ranges``
    (dimension -> ``(low, high)`` or one value: ``angle_deg``, ``rate_deg_s``, ``mach``,
    ``roll_deg``, ``cg_shift_mm``, ``stations``; the rest stay at the template's), ranked by
    how much they would reduce the sigmas of ``targets`` (or the whole covariance:
    ``criterion`` "A" or "D"). ``free``: held parameters to treat as unknown ("could more
    shots fix it?"). ``candidates`` are sampled, then the best ``refine`` improved by a
    bounded search. Returns the :class:`cadra.studies.design.PlanResult`; its ``report()``
    is what ``cadra2 plan`` prints."""
    from cadra.studies.candidates import CandidateSpace
    from cadra.studies.design import planner

    p = planner(result, targets=tuple(targets), criterion=criterion, free=tuple(free),
                template=template)
    return p.plan(CandidateSpace(p.template.base, dict(ranges)), candidates, refine=refine,
                  seed=seed, progress=progress)


__all__ = ["ViewResult", "calibrate", "diagnose", "fit", "measure", "measure_view", "plan",
           "simulate"]
