"""Predicted measurements and their exact sensitivities (forward mode) for stage two.

The fitter predicts what stage one measured with the simulator's own code: the 6-DOF
equations and aero-model evaluator (:mod:`cadra.dynamics`, :mod:`cadra.aero`) integrated by
:func:`cadra.dynamics.integrate.propagate_adaptive`, and the observation model
:func:`cadra.dynamics.observe.observe` (reference point seen from the cg, axis inclinations).

Sensitivities are forward-mode derivatives (``method="forward"``; the default ``"auto"`` uses
them once their compiled code is on the machine, :data:`METHODS`): one run of the
integrator's tangent version (:mod:`cadra.dynamics.tangent`, generated from the integrator's
own source) carries a derivative lane per free unknown, sharing the float run's values, so a
Jacobian costs a few trajectories instead of one per unknown. ``method="complex"`` is the
independent check the tests hold it to: each free unknown gets one complex propagation with
``i * EPS`` added to it, and ``Im(prediction) / EPS`` is its Jacobian column. Both are exact
derivatives of the same discrete scheme (same steps, no step-size trade-off); they agree to
rounding (docs/fitting.md, "Sensitivities"). Runs are shared out over threads (the compiled
integrators release the GIL).

Per-shot unknowns (the *local* parameters, :data:`LOCAL_NAMES`) are corrections to a nominal
state at the shot's epoch: cg position and velocity (facility frame F), a small rotation of the
attitude about the body axes (rotation vector, rad; applied multiplicatively), and body rates.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from cadra import cores
from cadra.channels import N_CHANNELS, OBSERVED
from cadra.conventions import quat_mul, rotvec_quat
from cadra.dynamics import tangent
from cadra.dynamics.integrate import propagate_batch
from cadra.dynamics.layout import N_STATE, P_CG_OFFSET
from cadra.dynamics.observe import observe
from cadra.dynamics.setup import plane_code
from cadra.dynamics.tangent import propagate_tangent

#: the 12 per-shot unknowns, in order
LOCAL_NAMES = ("x_cg_m", "y_cg_m", "z_cg_m", "vx_m_s", "vy_m_s", "vz_m_s",
               "rot_x_rad", "rot_y_rad", "rot_z_rad", "p_rad_s", "q_rad_s", "r_rad_s")
N_LOCAL = len(LOCAL_NAMES)
#: complex-step size (any tiny value gives the same derivative to rounding)
EPS = 1e-20
#: how a Jacobian is computed: forward-mode lanes, complex step (the check), or "auto":
#: forward mode once its compiled code is on this machine, complex step until then (the
#: first compile, one to two minutes, then runs in a background process)
METHODS = ("auto", "forward", "complex")
#: environment variable that chooses what ``method="auto"`` means, for every fit of a process
#: and its workers: ``forward`` (wait for the compile if needed) or ``complex``; unset or
#: ``auto``: as above (docs/fitting.md, "Sensitivities")
METHOD_ENV = "CADRA_SENSITIVITIES"

_POOL: ThreadPoolExecutor | None = None


def _pool() -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=max(1, os.cpu_count() or 1),
                                   thread_name_prefix="cadra-propagate")
    return _POOL


@dataclass(frozen=True)
class Integration:
    """Integrator settings of the fit (docs/fitting.md, "Integration").

    ``tol_position_m`` and ``tol_angle_rad`` bound the local error of each step; 1e-8 keeps the
    whole-shot error below ~0.002 um and 1e-6 deg on seed 004's shots, Table 4's kinks
    included (docs/dynamics.md), far below what stage one measures.
    """

    h_max_s: float = 2e-3
    tol_position_m: float = 1e-8
    tol_angle_rad: float = 1e-8
    threads: int = 0        # 0: all cores (cadra.cores.available)

    def __post_init__(self):
        for k in ("h_max_s", "tol_position_m", "tol_angle_rad"):
            if not getattr(self, k) > 0:
                raise ValueError(f"integration.{k} must be positive")


def apply_local(y_nom: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The state ``y_nom`` corrected by the 12 local unknowns ``u`` (real)."""
    y = np.array(y_nom, dtype=float)
    y[0:6] += u[0:6]
    q = quat_mul(y_nom[6:10], rotvec_quat(u[6:9]))
    y[6:10] = q / np.linalg.norm(q)
    y[10:13] += u[9:12]
    return y


def observables(states: np.ndarray, ref_from_cg_body_m: np.ndarray) -> np.ndarray:
    """(..., N_CHANNELS) predicted channels (:data:`cadra.channels.OBSERVED`: x, y, z,
    theta, psi, SI) from (..., 13) states."""
    shape = states.shape[:-1]
    with np.errstate(invalid="ignore", divide="ignore"):   # NaN states: a failed run
        o = observe(states.reshape(-1, N_STATE), ref_from_cg_body_m)
    out = np.stack([o[c.si_column] for c in OBSERVED], axis=-1)
    return out.reshape(*shape, N_CHANNELS)


def _run(Y0, t0, times, PHYS, program, PARAMS, integ: Integration) -> np.ndarray:
    """States (m, n, 13) of m runs, shared out over the thread pool."""
    m = Y0.shape[0]
    OUT = np.empty((m, len(times), N_STATE), dtype=Y0.dtype)
    plane = plane_code(program.angle_plane)
    workers = integ.threads or cores.available()
    chunks = [c for c in np.array_split(np.arange(m), min(workers, m)) if c.size]

    def job(idx):
        sl = slice(int(idx[0]), int(idx[-1]) + 1)
        out = np.empty((idx.size, len(times), N_STATE), dtype=Y0.dtype)
        propagate_batch(Y0[sl], float(t0), times, integ.h_max_s, integ.tol_position_m,
                        integ.tol_angle_rad, PHYS[sl], program.ops, program.args,
                        program.starts, PARAMS[sl], plane, int(program.stack_size), out)
        OUT[sl] = out

    if len(chunks) == 1:
        job(chunks[0])
    else:
        for f in [_pool().submit(job, c) for c in chunks]:
            f.result()
    return OUT


def predict_states(y0: np.ndarray, t0: float, times: np.ndarray, phys: np.ndarray, program,
                   params: np.ndarray, integ: Integration | None = None) -> np.ndarray:
    """(n, 13) states at ``times`` (any order) from ``y0`` at epoch ``t0``, integrated as the
    fit integrates -- the states behind its predictions (the one home for "the fitted
    trajectory": reports, studies, calibration and the gap diagnosis call this)."""
    integ = integ or Integration()
    times = np.asarray(times, dtype=float)
    order = np.argsort(times, kind="stable")
    states = _run(np.asarray(y0, float)[None, :], t0, np.ascontiguousarray(times[order]),
                  np.asarray(phys, float)[None, :], program,
                  np.asarray(params, float)[None, :], integ)[0]
    out = np.empty_like(states)
    out[order] = states
    return out


def predict(y0: np.ndarray, t0: float, times: np.ndarray, phys: np.ndarray, program,
            params: np.ndarray, ref_from_cg_body_m: np.ndarray,
            integ: Integration = Integration()) -> np.ndarray:
    """Predicted (n, 5) measurements at ``times`` from state ``y0`` at epoch ``t0``."""
    return observables(predict_states(y0, t0, times, phys, program, params, integ),
                       ref_from_cg_body_m)


def _seeds(y0, n_params, local_free, aero_free, phys_dirs):
    """The lanes' seeds: d(y0), d(params), d(phys) per unknown, (13, m), (n_params, m),
    (N_PHYS, m), in the column order of :func:`predict_with_jacobian`."""
    m = local_free.size + aero_free.size + phys_dirs.shape[0]
    Y = np.zeros((N_STATE, m))
    P = np.zeros((n_params, m))
    H = np.zeros((phys_dirs.shape[1], m))
    q = np.asarray(y0[6:10], dtype=float)
    for row, k in enumerate(local_free):
        if k < 6:
            Y[k, row] = 1.0
        elif k < 9:
            e = np.zeros(4)
            e[1 + k - 6] = 0.5                     # d/du of q (x) (1, u/2): q (x) (0, e/2)
            Y[6:10, row] = quat_mul(q, e)
        else:
            Y[10 + k - 9, row] = 1.0
    for row, j in enumerate(aero_free, start=local_free.size):
        P[j, row] = 1.0
    H[:, local_free.size + aero_free.size:] = phys_dirs.T
    return Y, P, H


def _run_tangent(y0, t0, times, phys, program, params, seeds, integ: Integration):
    """States (n, 13) and their derivatives (n, 13, m) along the seeded lanes, the lanes
    shared out over threads when there are enough of them to pay for a second float run."""
    Y, P, H = seeds
    m = Y.shape[1]
    n = len(times)
    states = np.empty((n, N_STATE))
    d_states = np.empty((n, N_STATE, m))
    plane = plane_code(program.angle_plane)
    workers = min(integ.threads or cores.available(), max(1, m // _LANES_PER_THREAD))
    chunks = [c for c in np.array_split(np.arange(m), workers) if c.size]
    y0 = np.ascontiguousarray(y0, dtype=float)
    phys = np.ascontiguousarray(phys, dtype=float)
    params = np.ascontiguousarray(params, dtype=float)

    def job(k, idx):
        sl = slice(int(idx[0]), int(idx[-1]) + 1)
        out = states if k == 0 else np.empty_like(states)
        out_t = np.empty((n, N_STATE, idx.size))
        propagate_tangent(y0, np.ascontiguousarray(Y[:, sl]), float(t0), times, integ.h_max_s,
                          integ.tol_position_m, integ.tol_angle_rad, phys,
                          np.ascontiguousarray(H[:, sl]), program.ops, program.args,
                          program.starts, params, np.ascontiguousarray(P[:, sl]), plane,
                          int(program.stack_size), out, out_t)
        d_states[:, :, sl] = out_t

    if len(chunks) == 1:
        job(0, chunks[0])
    else:
        for f in [_pool().submit(job, k, c) for k, c in enumerate(chunks)]:
            f.result()
    return states, d_states


#: the fewest lanes a thread of :func:`_run_tangent` takes (each thread repeats the float
#: run and the tangent code's fixed cost, so a shot's usual 20-30 lanes stay on one thread;
#: several shots run in parallel instead, :func:`over_shots`)
_LANES_PER_THREAD = 24


def over_shots(fn, items: list, integ: Integration) -> list:
    """``[fn(item, integ) for item in items]`` for the shots of a problem: several shots run
    in parallel over the thread pool, each on one thread (``fn`` gets ``integ`` with
    ``threads=1``); a single shot keeps ``integ``'s threads."""
    workers = integ.threads or cores.available()
    if len(items) < 2 or workers < 2:
        return [fn(item, integ) for item in items]
    one = replace(integ, threads=1)
    jobs = [_pool().submit(fn, item, one) for item in items]
    return [j.result() for j in jobs]


#: what "auto" resolved to in this process, kept for its life (:func:`process_method`)
_RESOLVED: str | None = None
_DECIDING = threading.Lock()


def process_method() -> str:
    """The sensitivity method this process's fits use with ``method="auto"``:
    :data:`METHOD_ENV` if set; otherwise, decided once per process, forward mode if its
    compiled code is ready, else complex step (with the compile started in the background).
    A process keeps the method it started with, so none of its results changes when a
    background compile finishes (the two methods' fits agree only to their stop rule); later
    processes use forward mode. Dask workers CADRA starts get their parent's
    (:func:`cadra.campaign.cluster.local_client`)."""
    global _RESOLVED
    chosen = os.environ.get(METHOD_ENV, "auto").strip().lower() or "auto"
    if chosen not in METHODS:
        raise ValueError(f"{METHOD_ENV} must be one of {METHODS}, got {chosen!r}")
    if chosen != "auto":
        return chosen
    with _DECIDING:   # a multi-shot problem's threads ask at once: one decides
        if _RESOLVED is None:
            _RESOLVED = "forward" if tangent.ready() else "complex"
            if _RESOLVED == "complex":
                tangent.compile_in_background()
    return _RESOLVED


def predict_with_jacobian(y0: np.ndarray, t0: float, times: np.ndarray, phys: np.ndarray,
                          program, params: np.ndarray, ref_from_cg_body_m: np.ndarray,
                          local_free: np.ndarray, aero_free: np.ndarray,
                          integ: Integration = Integration(), phys_dirs=None,
                          with_states: bool = False, method: str = "auto"):
    """Prediction (n, 5) and Jacobian (n, 5, n_local + n_aero + n_phys).

    ``local_free`` are indices into :data:`LOCAL_NAMES` (corrections at ``y0``),
    ``aero_free`` indices into ``params``, ``phys_dirs`` (k, N_PHYS) directions in the
    ``phys`` vector (the effects of :mod:`cadra.dynamics.layout`: cg offset, wind, density
    gradient, inertia; a product of inertia is a direction with two entries). Columns in
    that order. A direction that moves the cg offset also moves the observed reference point
    (``ref_from_cg -= offset``, per run: :func:`cadra.fitting.extras.shot_ref`).
    ``with_states``: also return the (n, 13) states (the float run's: no extra
    integration). ``method``: ``"forward"`` (tangent lanes), ``"complex"`` (complex step,
    the independent check; module doc) or ``"auto"`` (:data:`METHODS`).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if method == "auto":
        method = process_method()
    local_free = np.asarray(local_free, dtype=int)
    aero_free = np.asarray(aero_free, dtype=int)
    phys_dirs = (np.zeros((0, len(phys))) if phys_dirs is None
                 else np.atleast_2d(np.asarray(phys_dirs, dtype=float)))
    m = local_free.size + aero_free.size + phys_dirs.shape[0]
    if m == 0:
        states = predict_states(y0, t0, times, phys, program, params, integ)
        out = (observables(states, ref_from_cg_body_m), np.zeros((len(times), N_CHANNELS, 0)))
        return (*out, states) if with_states else out
    times = np.ascontiguousarray(times, dtype=float)
    seeds = _seeds(y0, len(params), local_free, aero_free, phys_dirs)
    if method == "forward":
        states, d_states = _run_tangent(y0, t0, times, phys, program, params, seeds, integ)
        # the observation model is cheap numpy: its directional derivatives along the lanes
        # by complex step (Im f(x + i eps dx) / eps = f'(x) dx, exact)
        lanes = states[None] + 1j * EPS * np.moveaxis(d_states, -1, 0)     # (m, n, 13)
    else:
        lanes = _complex_runs(y0, t0, times, phys, program, params, seeds, integ)
        states = lanes[0].real.copy()
    # a lane that moves the cg offset moves the observed reference point against it
    ref_dirs = -seeds[2][P_CG_OFFSET:P_CG_OFFSET + 3].T                      # (m, 3)
    if np.any(ref_dirs):
        refs = np.asarray(ref_from_cg_body_m)[None, :] + 1j * EPS * ref_dirs
        obs = np.stack([observables(lanes[i], refs[i]) for i in range(m)])
    else:
        obs = observables(lanes, ref_from_cg_body_m)      # (m, n, 5) complex
    pred = obs[0].real.copy() if method == "complex" else observables(states,
                                                                     ref_from_cg_body_m)
    jac = np.ascontiguousarray(np.moveaxis(obs.imag / EPS, 0, -1))   # (n, 5, m)
    return (pred, jac, states) if with_states else (pred, jac)


def _complex_runs(y0, t0, times, phys, program, params, seeds, integ):
    """(m, n, 13) complex states, one complex-step run per seeded lane (the check): each
    run's inputs are the float ones plus ``i * EPS`` times its lane's seed."""
    Y, P, H = seeds
    Y0 = np.asarray(y0, dtype=float)[None, :] + 1j * EPS * Y.T
    PARAMS = np.asarray(params, dtype=float)[None, :] + 1j * EPS * P.T
    PHYS = np.asarray(phys, dtype=float)[None, :] + 1j * EPS * H.T
    return _run(Y0, t0, times, PHYS, program, PARAMS, integ)
