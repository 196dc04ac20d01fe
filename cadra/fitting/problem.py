"""One fit problem behind every prediction: the solver's, the report's, the gap's.

A :class:`FitProblem` is the whole forward model of a fit as plain data -- the shots
(:class:`cadra.flight.data.ShotData`), the aerodynamic model, the extra unknowns
(:mod:`cadra.fitting.extras`: effects made free or held, station terms), the integration
settings, each shot's reference state at its epoch and its free local unknowns -- with

- :attr:`FitProblem.param_names` / :meth:`FitProblem.layout`: the entries of ``theta``: the
  free aero parameters (values), the free extras (values), then each shot's free local
  unknowns (corrections to its reference state, :data:`LOCAL_NAMES`; 0 at the reference);
- :meth:`FitProblem.predict`: each shot's predicted channels (n, N_CHANNELS) at its stations;
- :meth:`FitProblem.jacobian` / :meth:`FitProblem.predict_with_jacobian`: their complex-step
  derivatives, per shot ``(n, N_CHANNELS, n_local + n_shared)`` (the shot's free locals, then
  the shared unknowns in ``theta``'s order);
- :meth:`FitProblem.states`: the state histories (at the stations, or at any times: plots),
  and :meth:`FitProblem.histories` the reference point, axis inclinations and air angles
  along them, with the fit's physics (held and free physics extras included).

Every consumer -- the solver (:func:`cadra.fitting.solver.fit`), the report's histories
(:func:`cadra.fitting.histories.fitted_histories`), the gap's scores and where-tests
(:mod:`cadra.gap`), the sphere calibration and the studies -- predicts through this object,
so none can integrate a model other than the one fitted (lmfit's ``Model.eval``). A
:class:`cadra.fitting.result.FitResult` carries its problem at the fitted point
(``result.problem``; :func:`result_problem` rebuilds it for a result without one).

Picklable (a frozen dataclass of arrays, the model and frozen extras): a campaign can ship it
to workers. Numerics: exactly the solver's (same calls, same order of the floating-point
operations).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from cadra.aero import AeroModel
from cadra.dynamics.layout import FRAME_BODY, FRAME_NONROLLING, P_FRAME
from cadra.dynamics.observe import air_angles, observe
from cadra.dynamics.setup import FRAMES, non_rolling_obstacle
from cadra.fitting.extras import (
    Extra,
    add_station_terms,
    shot_phys,
    shot_ref,
    station_columns,
)
from cadra.fitting.sensitivity import (
    LOCAL_NAMES,
    N_LOCAL,
    Integration,
    apply_local,
    observables,
    over_shots,
    predict_states,
    predict_with_jacobian,
)
from cadra.flight.data import ShotData


def default_local_free(data: ShotData, model: AeroModel | None = None) -> np.ndarray:
    """Free local unknowns of a shot (indices into :data:`LOCAL_NAMES`).

    All 12, except what the data cannot see: a shot with no angle measurements (a sphere)
    fits position and velocity only; a symmetric body (total-angle model, transverse inertia
    equal within 1e-3, no products of inertia) whose roll was not measured does not fit its
    roll angle about the axis -- turning such a body about its axis changes no measurement.
    A wind-tunnel mount (:mod:`cadra.dynamics.modes`) fits the attitude (on a pitch pivot it
    includes the pivot axis's direction) and the rates the mount allows: all three on a
    gimbal, q on a pitch pivot, p on a roll bearing; never the position or velocity. A mounted
    record that measures the roll angle (phi) but not the axis's inclinations fits the roll
    about the axis only: the axis stays where the reference state puts it.
    """
    if not (data.has_angles or data.has_roll):
        return np.arange(6)
    mode = data.rigid.mode
    hide_roll = _axisymmetric(data, model) and not data.has_roll
    if mode.mounted:
        # a mount leaves the attitude and the rates it allows free: the pivot holds the
        # position and the rotation sets the cg velocity (cadra.dynamics.modes). The attitude
        # keeps all three rotations: on a pitch pivot two of them set the pivot axis (body y)
        # in the facility, on a roll bearing the axis held in the stream
        rotations = ("rot_x_rad", "rot_y_rad", "rot_z_rad") if data.has_angles else ("rot_x_rad",)
        rates = {"gimbal": ("p_rad_s", "q_rad_s", "r_rad_s"), "pitch_pivot": ("q_rad_s",),
                 "roll_bearing": ("p_rad_s",)}[mode.kind]
        names = rotations + rates
        if mode.kind != "pitch_pivot" and hide_roll:
            names = names[1:]       # turning the body about its own axis shows nowhere
        return np.array([LOCAL_NAMES.index(n) for n in names])
    if hide_roll:
        return np.array([k for k in range(N_LOCAL) if LOCAL_NAMES[k] != "rot_x_rad"])
    return np.arange(N_LOCAL)


def _axisymmetric(data: ShotData, model: AeroModel | None) -> bool:
    """A total-angle model on a body whose transverse inertias agree within 1e-3 and that
    has no products of inertia: turning it about its axis changes no measurement."""
    if model is None or model.angle_plane != "sigma":
        return False
    I = data.rigid.phys()[1:10].reshape(3, 3)
    off = np.abs(I - np.diag(np.diag(I))).max()
    return bool(abs(I[1, 1] - I[2, 2]) <= 1e-3 * I[1, 1] and off <= 1e-3 * I[1, 1])



def check_one_body(shots: Sequence[ShotData]) -> None:
    """Refuse (``ValueError``) shots of different kinds of body in one fit: they share one
    aerodynamic model, which only the same body has (a capsule and a sphere fitted together
    ran to "not converged" instead)."""
    kinds = {s.body_kind for s in shots}
    if len(kinds) > 1:
        listed = ", ".join(f"{s.shot_id}: {s.body_kind}" for s in shots)
        raise ValueError(f"fit: the shots are of different bodies ({listed}); one "
                         "aerodynamic model describes one body: fit them separately")

@dataclass(frozen=True, eq=False)
class FitProblem:
    """The forward model of a fit (module doc).

    Parameters
    ----------
    shots : the shots (one for a single fit).
    model : the aerodynamic model; its values are the aero part of :attr:`theta0`, ``vary``
        says which are free (``min``/``max`` bound them in the solver).
    epoch_states : per shot, the (13,) reference state at the shot's epoch
        (``shot.t_s[shot.epoch_index]``); the local unknowns correct it.
    extras : the extra unknowns, free ones at their ``value`` (part of :attr:`theta0`) and
        held ones (``held=True``: part of the shots' physics, not of ``theta``).
    local_free : per shot, indices into :data:`LOCAL_NAMES` (default
        :func:`default_local_free`).
    integration : integrator settings.
    """

    shots: tuple[ShotData, ...]
    model: AeroModel
    epoch_states: tuple[np.ndarray, ...]
    extras: tuple[Extra, ...] = ()
    local_free: tuple[np.ndarray, ...] | None = None
    integration: Integration = field(default_factory=Integration)

    def __post_init__(self):
        shots = tuple(self.shots)
        if len(shots) == 0:
            raise ValueError("fit: no shots")
        if len(self.epoch_states) != len(shots):
            raise ValueError("fit: one initial state per shot is needed")
        if len({s.shot_id for s in shots}) != len(shots):
            raise ValueError("fit: a shot is listed twice")
        check_one_body(shots)
        extras = tuple(self.extras)
        if len({e.name for e in extras}) != len(extras) or any(e.name in self.model.names
                                                                for e in extras):
            raise ValueError("fit: extra unknowns need names of their own")
        states = []
        for sd, y0 in zip(shots, self.epoch_states, strict=True):
            y0 = np.array(y0, dtype=float)
            if y0.shape != (13,) or not np.all(np.isfinite(y0)):
                raise ValueError(f"fit: initial state of shot {sd.shot_id} must be 13 finite "
                                 "numbers")
            states.append(y0)
        lf = tuple(np.asarray(self.local_free[k] if self.local_free is not None
                              else default_local_free(sd, self.model), dtype=int)
                   for k, sd in enumerate(shots))
        object.__setattr__(self, "shots", shots)
        object.__setattr__(self, "epoch_states", tuple(states))
        object.__setattr__(self, "extras", extras)
        object.__setattr__(self, "local_free", lf)
        object.__setattr__(self, "_frames", tuple(self._frame_of(k) for k in range(len(shots))))

    # ------------------------------------------------------------------ layout

    @property
    def free_extras(self) -> tuple[Extra, ...]:
        return tuple(e for e in self.extras if not e.held)

    @property
    def held_extras(self) -> tuple[Extra, ...]:
        return tuple(e for e in self.extras if e.held)

    @property
    def aero_indices(self) -> np.ndarray:
        """Indices of the free aero parameters in ``model.values()``."""
        return self.model.free_indices()

    @property
    def n_shared(self) -> int:
        return int(self.aero_indices.size) + len(self.free_extras)

    @property
    def shot_ids(self) -> tuple[str, ...]:
        return tuple(s.shot_id for s in self.shots)

    @property
    def epochs(self) -> tuple[float, ...]:
        """Each shot's epoch (the time of its reference state), s."""
        return tuple(float(s.t_s[s.epoch_index]) for s in self.shots)

    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of ``theta``'s entries: free aero parameters, free extras, then
        ``"<shot_id>:<local>"`` per shot."""
        names = [self.model.parameters[i].name for i in self.aero_indices]
        names += [e.name for e in self.free_extras]
        for sd, lf in zip(self.shots, self.local_free, strict=True):
            names += [f"{sd.shot_id}:{LOCAL_NAMES[k]}" for k in lf]
        return tuple(names)

    def layout(self) -> dict:
        """Where ``theta``'s parts sit: ``{"aero": slice, "extras": slice, "locals":
        {shot_id: slice}}``."""
        na, ns = int(self.aero_indices.size), self.n_shared
        out = {"aero": slice(0, na), "extras": slice(na, ns), "locals": {}}
        at = ns
        for sd, lf in zip(self.shots, self.local_free, strict=True):
            out["locals"][sd.shot_id] = slice(at, at + lf.size)
            at += lf.size
        return out

    @property
    def n_params(self) -> int:
        return self.n_shared + sum(lf.size for lf in self.local_free)

    @property
    def theta0(self) -> np.ndarray:
        """``theta`` at the problem's own point: the model's and the extras' values, no
        local corrections."""
        params = self.model.values()
        return np.concatenate([params[self.aero_indices],
                               np.array([e.value for e in self.free_extras], dtype=float),
                               np.zeros(self.n_params - self.n_shared)])

    def split(self, theta=None):
        """``theta`` (default :attr:`theta0`) as (full aero parameter vector, free extras'
        values, per shot the local corrections (n_free_local,))."""
        if theta is None:
            return (self.model.values(),
                    np.array([e.value for e in self.free_extras], dtype=float),
                    [np.zeros(lf.size) for lf in self.local_free])
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.n_params,):
            raise ValueError(f"theta must have shape ({self.n_params},), got {theta.shape}")
        lay = self.layout()
        params = self.model.values()
        params[self.aero_indices] = theta[lay["aero"]]
        return (params, theta[lay["extras"]].copy(),
                [theta[lay["locals"][sid]] for sid in self.shot_ids])

    def initial_states(self, theta=None) -> list[np.ndarray]:
        """Each shot's (13,) state at its epoch at ``theta`` (the reference state itself
        where its local corrections are all 0)."""
        _, _, locs = self.split(theta)
        out = []
        for y, lf, u in zip(self.epoch_states, self.local_free, locs, strict=True):
            if not np.any(u):
                out.append(y.copy())
                continue
            full = np.zeros(N_LOCAL)
            full[lf] = u
            out.append(apply_local(y, full))
        return out

    # ------------------------------------------------------------------ physics

    def _frame_of(self, k: int) -> int:
        """Shot k's attitude frame: the non-rolling one where the fit does not use the
        body's roll (its roll neither measured nor fitted) and the frame is exact for its
        physics and every physics extra that applies to it (docs/dynamics.md, "The
        non-rolling frame"); else the body's own."""
        sd = self.shots[k]
        if sd.has_roll or LOCAL_NAMES.index("rot_x_rad") in self.local_free[k]:
            return FRAME_BODY
        dirs = [e.phys_direction for e in self.extras if e.is_phys and e.applies(sd.shot_id)]
        why = non_rolling_obstacle(sd.rigid.phys(), self.model.compile(), dirs,
                                   sd.rigid.ref_from_cg_body_m())
        return FRAME_BODY if why else FRAME_NONROLLING

    @property
    def frames(self) -> tuple[str, ...]:
        """Each shot's attitude frame, ``"body"`` or ``"non_rolling"``."""
        names = {v: k for k, v in FRAMES.items()}
        return tuple(names[f] for f in self._frames)

    def held_physics(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Shot k's physics and reference point with the held extras on (the nominal point
        of the free extras)."""
        sd = self.shots[k]
        held = self.held_extras
        phys0 = sd.rigid.phys()
        phys0[P_FRAME] = self._frames[k]
        phys_held = shot_phys(phys0, held, [e.value for e in held], sd.shot_id)
        return phys_held, shot_ref(sd.rigid.ref_from_cg_body_m(), phys0, phys_held)

    def physics(self, k: int, extra_values=None) -> tuple[np.ndarray, np.ndarray]:
        """Shot k's ``phys`` vector and reference point from the cg (body axes, m) with
        every physics extra on (held ones at their values, free ones at ``extra_values``,
        default their values)."""
        phys_h, ref_h = self.held_physics(k)
        xv = (np.array([e.value for e in self.free_extras], dtype=float)
              if extra_values is None else np.asarray(extra_values, dtype=float))
        phys = shot_phys(phys_h, self.free_extras, xv, self.shots[k].shot_id)
        return phys, shot_ref(ref_h, phys_h, phys)

    def times_of(self, k: int, times=None) -> np.ndarray:
        """Shot k's times out of a ``times`` argument (:meth:`states`)."""
        if times is None:
            return self.shots[k].t_s
        if isinstance(times, dict):
            return np.asarray(times[self.shots[k].shot_id], dtype=float)
        if (isinstance(times, np.ndarray) and times.ndim == 1) or (
                isinstance(times, (list, tuple)) and all(np.ndim(t) == 0 for t in times)):
            return np.asarray(times, dtype=float)       # one set of times for every shot
        return np.asarray(times[k], dtype=float)

    def states_of(self, k: int, theta=None, times=None) -> np.ndarray:
        """Shot k's (n, 13) states at ``times`` (default its spark times)."""
        params, xv, _ = self.split(theta)
        y0 = self.initial_states(theta)[k]
        phys, _ = self.physics(k, xv)
        return predict_states(y0, self.epochs[k], self.times_of(k, times), phys,
                              self.model.compile(), params, self.integration)

    def states(self, theta=None, times=None) -> list[np.ndarray]:
        """Each shot's (n, 13) states (facility frame; :mod:`cadra.dynamics.layout`) at
        ``times``: None (its spark times), one array for every shot, a sequence of arrays
        (one per shot) or ``{shot_id: array}``; any order."""
        return [self.states_of(k, theta, times) for k in range(len(self.shots))]

    def predict(self, theta=None) -> list[np.ndarray]:
        """Each shot's predicted (n, N_CHANNELS) channels at its stations: the physics of
        the fit (extras on) observed, plus the station extras' terms."""
        params, xv, _ = self.split(theta)
        ys = self.initial_states(theta)
        return self.predict_from(params, xv, ys)

    def predict_from(self, params: np.ndarray, extra_values, initial_states
                     ) -> list[np.ndarray]:
        """:meth:`predict` from the full aero parameter vector, the free extras' values and
        each shot's (13,) state at its epoch (what the solver's trial steps give)."""
        program = self.model.compile()
        free, held = self.free_extras, self.held_extras
        held_values = [e.value for e in held]
        runs = [(k, sd, y0, *self.physics(k, extra_values))
                for k, (sd, y0) in enumerate(zip(self.shots, initial_states, strict=True))]

        def shot(run, integ):   # the shots run in parallel, as the Jacobian's do
            k, sd, y0, phys, _ = run
            return predict_states(y0, self.epochs[k], sd.t_s, phys, program, params, integ)

        out = []
        for (_, sd, _, _, ref), y in zip(runs, over_shots(shot, runs, self.integration),
                                         strict=True):
            sid = sd.shot_id
            pred = observables(y, ref)
            pred = add_station_terms(pred, free, extra_values, sid, sd.stations, y)
            out.append(add_station_terms(pred, held, held_values, sid, sd.stations, y))
        return out

    def predict_with_jacobian(self, theta=None, extra_phys_dirs=None, with_states=False):
        """Per shot the prediction (n, N_CHANNELS) and its Jacobian (n, N_CHANNELS,
        n_local_k + n_shared): the shot's free locals, then the shared unknowns in
        ``theta``'s order (free aero parameters, free extras), all by complex step at
        ``theta``. The local columns are derivatives with respect to corrections applied at
        ``theta``'s states (the solver's convention; d/d(local) itself where the local
        corrections are 0).

        ``extra_phys_dirs``: per shot, further (m, N_PHYS) directions in ``phys`` whose
        columns are appended after the shared ones (the gap's candidate effects), or None.
        ``with_states``: also return each shot's (n, 13) states.
        """
        params, xv, _ = self.split(theta)
        return self.jacobian_from(params, xv, self.initial_states(theta),
                                  extra_phys_dirs=extra_phys_dirs, with_states=with_states)

    def jacobian_from(self, params: np.ndarray, extra_values, initial_states, *,
                      extra_phys_dirs=None, with_states: bool = False):
        """:meth:`predict_with_jacobian` from the full aero parameter vector, the free
        extras' values and each shot's (13,) state at its epoch."""
        program = self.model.compile()
        aero_idx = self.aero_indices
        free, held = self.free_extras, self.held_extras
        held_values = [e.value for e in held]
        xv = np.asarray(extra_values, dtype=float)
        na, ne = aero_idx.size, len(free)
        preds, jacs, sts, runs = [], [], [], []
        for k, sd in enumerate(self.shots):
            sid = sd.shot_id
            phys, ref = self.physics(k, xv)
            lf = self.local_free[k]
            on = [j for j, e in enumerate(free) if e.is_phys and e.applies(sid)]
            dirs = [free[j].phys_direction for j in on]
            more = None if extra_phys_dirs is None else extra_phys_dirs[k]
            n_more = 0 if more is None else len(more)
            if n_more:
                dirs += list(more)
                if phys[P_FRAME] != FRAME_BODY and non_rolling_obstacle(phys, program, more):
                    phys = phys.copy()
                    phys[P_FRAME] = FRAME_BODY     # e.g. a gap candidate's lateral cg offset
            runs.append((sd, lf, on, n_more, (
                initial_states[k], self.epochs[k], sd.t_s, phys, program, params, ref, lf,
                aero_idx), np.array(dirs) if dirs else None))

        def shot(run, integ):
            *_, args, dirs = run
            return predict_with_jacobian(*args, integ, phys_dirs=dirs, with_states=True)

        outs = over_shots(shot, runs, self.integration)
        for (sd, lf, on, n_more, _, _), (pred, jac, y) in zip(runs, outs, strict=True):
            sid = sd.shot_id
            base = lf.size + na
            if ne or n_more:
                full = np.zeros(jac.shape[:2] + (base + ne + n_more,))
                full[:, :, :base] = jac[:, :, :base]
                full[:, :, base + np.array(on, dtype=int)] = jac[:, :, base:base + len(on)]
                full[:, :, base + ne:] = jac[:, :, base + len(on):]
                if ne:
                    C = station_columns(free, sid, sd.stations, pred, y)
                    full[:, :, base:base + ne] += C
                    pred = pred + C @ xv
                jac = full
            pred = add_station_terms(pred, held, held_values, sid, sd.stations, y)
            preds.append(pred)
            jacs.append(jac)
            sts.append(y)
        return (preds, jacs, sts) if with_states else (preds, jacs)

    def jacobian(self, theta=None) -> list[np.ndarray]:
        """Per shot the (n, N_CHANNELS, n_local_k + n_shared) Jacobian of :meth:`predict`
        (:meth:`predict_with_jacobian`)."""
        return self.predict_with_jacobian(theta)[1]

    def shot_columns(self, k: int) -> np.ndarray:
        """Indices into ``theta`` of the columns of shot k's Jacobian."""
        lay = self.layout()
        loc = lay["locals"][self.shots[k].shot_id]
        return np.r_[loc.start:loc.stop, 0:self.n_shared]

    def histories(self, theta=None, times=None) -> list[dict]:
        """Per shot, along :meth:`states` at ``times``: ``states`` (n, 13), the observed
        channels ``channels`` (n, N_CHANNELS: the reference point and axis inclinations of
        the fitted physics, without the station extras' measurement terms) and the air
        angles ``air`` (:func:`cadra.dynamics.observe.air_angles`, with the fit's wind)."""
        params, xv, _ = self.split(theta)
        ys = self.initial_states(theta)
        out = []
        for k, sd in enumerate(self.shots):
            phys, ref = self.physics(k, xv)
            y = predict_states(ys[k], self.epochs[k], self.times_of(k, times), phys,
                               self.model.compile(), params, self.integration)
            obs = observe(y, ref)
            out.append({"states": y, "observed": obs, "channels": observables(y, ref),
                        "air": air_angles(y, sd.rigid, phys=phys)})
        return out

    # ------------------------------------------------------------------ moving on

    def at(self, params: np.ndarray | None = None, extra_values=None,
           initial_states=None) -> FitProblem:
        """The same problem at another point: the aero values ``params`` (full vector),
        the free extras at ``extra_values``, the reference states ``initial_states``."""
        model = self.model
        if params is not None:
            model = model.with_values({self.model.parameters[i].name: float(params[i])
                                       for i in self.aero_indices})
        extras = self.extras
        if extra_values is not None:
            it = iter(np.asarray(extra_values, dtype=float))
            extras = tuple(e if e.held else replace(e, value=float(next(it)))
                           for e in self.extras)
        return replace(self, model=model, extras=extras,
                       epoch_states=(self.epoch_states if initial_states is None
                                     else tuple(initial_states)))




def result_problem(result, shots: Sequence[ShotData] | None = None) -> FitProblem:
    """The :class:`FitProblem` of a :class:`cadra.fitting.result.FitResult` at its fitted
    point: the fitted model, the extras at their values (held ones included), each shot's
    fitted state and free locals, the fit's integration settings -- the one the solver
    stored (``result.problem``), or rebuilt from those for a result without one. ``shots``
    (default: the problem's own): the measurements to predict for, matched by shot id (the
    same shots the fit used, perhaps with other sigmas)."""
    stored = getattr(result, "problem", None)
    if shots is None:
        if stored is None:
            raise ValueError("the result carries no fit problem: give its shots")
        return stored
    by_id = {s.shot_id: s for s in shots}
    missing = [sf.shot_id for sf in result.shots if sf.shot_id not in by_id]
    if missing:
        raise ValueError(f"no ShotData given for shot {missing[0]!r} of the result")
    data = tuple(by_id[sf.shot_id] for sf in result.shots)
    if stored is not None:
        if all(a is b for a, b in zip(data, stored.shots, strict=True)):
            return stored
        return replace(stored, shots=data)
    integ = result.options.get("integration") if result.options else None
    return FitProblem(data, result.model, tuple(sf.state for sf in result.shots),
                      tuple(result.extras_at_values()),
                      tuple(sf.local_free_indices for sf in result.shots),
                      Integration(**integ) if integ else Integration())


__all__ = ["FitProblem", "check_one_body", "default_local_free", "result_problem"]
