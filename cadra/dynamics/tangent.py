"""Forward-mode sensitivities of the integrator: its tangent version, generated from its source.

:func:`propagate_tangent` is :func:`cadra.dynamics.integrate.propagate_adaptive` with
derivative lanes: besides the run's states it integrates their derivatives with respect to
whatever the caller seeds in the lanes of the initial state, the physical constants and the
aero parameters (``y0_t``, ``phys_t``, ``params_t``, each with a trailing lane axis). The
code is the integrator's own (the equations of motion, the aero interpreter, RK4 with
step doubling), transformed statement by statement by :mod:`cadra.dynamics.forward_ad`, so
it is the exact derivative of the discrete scheme, as complex step is, and it takes the same
steps (decided on the primal values). One run with ``L`` lanes costs about what 2-4 real runs
cost, where complex step costs ``L`` complex runs (docs/fitting.md, "Sensitivities").

The generated module is written once per build of the compiled sources into numba's cache
folder (:mod:`cadra._numba_cache`: a folder per source key, so a changed source gets a new
module) and imported from there, so numba caches its compiled code like any other's.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from filelock import FileLock

from cadra.aero.program import (
    HEADER,
    N_COEFFICIENTS,
    PROGRAM_FORMAT,
    eval_coefficients,
)
from cadra.dynamics.eom import aero_force_moment, air_data, derivative, rotation_fb
from cadra.dynamics.forward_ad import Spec, tangent_module
from cadra.dynamics.integrate import (
    _rk4_span,
    _start,
    _workspace,
    inverse3,
    propagate_adaptive,
)
from cadra.dynamics.layout import N_PHYS, N_STATE, P_INERTIA, P_MASS
from cadra.dynamics.modes import constrain, mount

_A, _S, _T = "a", "s", "t"
_STATE_SCRATCH = {"R": _A, "v_b": _A, "variables": _A, "F_b": _A, "M_b": _A, "coef": _A,
                  "stack": _A}

#: njit options of the generated functions (the run releases the GIL). The small helpers of
#: the equations of motion are inlined at numba's level into the derivative; the aero
#: interpreter's tangent is not (nor the derivative into the RK4 span, which calls it four
#: times). Measured on the M2 shot, 28 lanes, one thread: a Jacobian about half the time of
#: calls alone, 10-15 % slower than with the interpreter inlined too, for a first compile of
#: 100 s against 184 s (calls alone: 97 s); docs/fitting.md, "Sensitivities"
_JIT = {"cache": True, "error_model": "numpy", "inline": "always"}
_SPAN = {"cache": True, "error_model": "numpy"}
_TOP = {"cache": True, "error_model": "numpy", "nogil": True}

#: the functions transformed, with the parameters that carry derivatives
SPECS = (
    Spec(rotation_fb, {"y": _A, "R": _A}, jit=_JIT),
    Spec(air_data, {"y": _A, "phys": _A, "R": _A, "v_b": _A, "variables": _A},
         returns=(_S, _S), jit=_JIT),
    Spec(eval_coefficients, {"variables": _A, "params": _A, "out": _A, "stack": _A},
         jit=_SPAN),
    Spec(aero_force_moment, {"v_b": _A, "V": _S, "rho": _S, "phys": _A, "coef": _A,
                             "F_b": _A, "M_b": _A}, returns=(_S, _S, _S), jit=_JIT),
    Spec(mount, {"y": _A, "phys": _A, "R": _A}, jit=_JIT),
    Spec(constrain, {"y": _A, "phys": _A, "R": _A, "F_b": _A, "M_b": _A, "dy": _A},
         jit=_JIT),
    Spec(derivative, {"y": _A, "phys": _A, "I": _A, "Iinv": _A, "params": _A,
                      **_STATE_SCRATCH, "dy": _A}, jit=_SPAN),
    Spec(inverse3, {"A": _A, "out": _A}, jit=_JIT),
    Spec(_rk4_span, {"y": _A, "phys": _A, "I": _A, "Iinv": _A, "params": _A,
                     "scratch": _T, "coef": _A, "stack": _A, "k1": _A, "k2": _A, "k3": _A,
                     "k4": _A, "tmp": _A}, jit=_SPAN),
    Spec(_start, {"y0": _A, "phys": _A, "R": _A, "y": _A}, jit=_JIT),
    Spec(_workspace, {"y0": _A, "phys": _A},
         returns=(_A, _A, _T, _A, _A, _A, _A, _A, _A, _A), jit=_JIT),
    Spec(propagate_adaptive, {"y0": _A, "phys": _A, "params": _A, "out": _A}, jit=_TOP),
)
#: functions the integrator calls whose results carry no derivative (step control)
PASSIVE = ("_doubling_error", "adaptive_budget")

_MODULE = None
_PATH: Path | None = None
#: one thread of a process writes, imports and compiles the generated module
_INIT = threading.RLock()


def source() -> str:
    """The generated tangent module's source."""
    return tangent_module(list(SPECS), PASSIVE)


def _folder() -> Path:
    base = os.environ.get("NUMBA_CACHE_DIR")
    folder = Path(base) if base else Path(tempfile.gettempdir()) / f"cadra-{os.getuid()}"
    folder = folder / "tangent"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _path() -> Path:
    """Where the generated module lives (written on first call in a process: by one thread,
    the fits of a multi-shot problem asking from several at once)."""
    global _PATH
    with _INIT:
        if _PATH is None:
            text = source()
            key = hashlib.sha256(text.encode()).hexdigest()[:16]
            path = _folder() / f"cadra_tangent_{key}.py"
            if not path.exists() or path.read_text() != text:
                tmp = path.with_suffix(f".{os.getpid()}-{threading.get_ident()}.tmp")
                tmp.write_text(text)
                os.replace(tmp, path)
            _PATH = path
    return _PATH


def module():
    """The generated module (imported, and compiled or loaded from numba's cache, on first
    use in a process).

    The first compile on a machine (per build of the sources) takes one to two minutes of
    one core: the tangent code is several times the float code. It runs under a file lock,
    so parallel processes (test workers, a campaign's workers) compile once and load the
    cached result; a marker then says the compiled code is there (:func:`ready`)."""
    if _MODULE is not None:     # loaded: every propagation asks, from every thread
        return _MODULE
    with _INIT:
        return _MODULE if _MODULE is not None else _load()


def _load():
    """:func:`module`'s first call in a process (under ``_INIT``)."""
    global _MODULE
    path = _path()
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = mod
    spec.loader.exec_module(mod)
    with FileLock(str(path.with_suffix(".lock"))):
        _warm(mod)
        path.with_suffix(".ready").touch()
        path.with_suffix(".compiling").unlink(missing_ok=True)
    _MODULE = mod
    return _MODULE


def ready() -> bool:
    """Whether the compiled tangent code can be had without compiling it: loaded in this
    process, or compiled on this machine for these sources (numba's cache holds it)."""
    return _MODULE is not None or _path().with_suffix(".ready").exists()


#: a background compile whose flag is older than this is taken for dead
_COMPILE_STALE_S = 1800.0
#: the intermediate's program: start the compiler in a session of its own, and leave
_LAUNCH = ("import subprocess, sys; subprocess.Popen([sys.executable, '-c', "
           "'from cadra.dynamics.tangent import module; module()'], "
           "stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, "
           "start_new_session=True)")


def compile_in_background() -> bool:
    """Start one process that compiles the tangent code into numba's cache, unless it is
    ready or another process is already at it (a flag file next to the module). Returns
    whether one was started. Until it is done, callers that cannot wait use complex step
    (:func:`cadra.fitting.sensitivity.predict_with_jacobian`, ``method="auto"``)."""
    if ready():
        return False
    flag = _path().with_suffix(".compiling")
    try:
        if time.time() - flag.stat().st_mtime < _COMPILE_STALE_S:
            return False
        flag.unlink(missing_ok=True)                   # a dead compile's flag
    except FileNotFoundError:
        pass
    try:
        os.close(os.open(flag, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return False                                    # another process got there first
    # launched through a short-lived intermediate that is waited for: the compiler is then
    # nobody's child here (no zombie, no Popen of a running child to warn when collected)
    subprocess.run([sys.executable, "-c", _LAUNCH], stdin=subprocess.DEVNULL,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    return True


def _warm(mod) -> None:
    """Compile (or load from numba's cache) the run for the argument types every caller
    passes: an empty run of a trivial model."""
    L = 1
    phys = np.zeros(N_PHYS)
    phys[P_MASS] = 1.0
    phys[P_INERTIA:P_INERTIA + 9] = np.eye(3).ravel()
    y0 = np.zeros(N_STATE)
    y0[6] = 1.0
    mod.propagate_adaptive_t(y0, np.zeros((N_STATE, L)), 0.0, np.zeros(0), 1e-3, 1e-8, 1e-8,
                             phys, np.zeros((N_PHYS, L)), np.array([HEADER], dtype=np.int64),
                             np.array([float(PROGRAM_FORMAT)]), np.ones(N_COEFFICIENTS + 1,
                                                                        dtype=np.int64),
                             np.zeros(1), np.zeros((1, L)), 0, 1, np.zeros((0, N_STATE)),
                             np.zeros((0, N_STATE, L)))


def propagate_tangent(y0, y0_t, t0, t_out, h_max, tol_pos, tol_ang, phys, phys_t, ops, args,
                      starts, params, params_t, plane, stack_size, out, out_t):
    """:func:`cadra.dynamics.integrate.propagate_adaptive` with derivative lanes: ``y0_t``
    (13, L), ``phys_t`` (N_PHYS, L) and ``params_t`` (n_params, L) seed the lanes; ``out_t``
    (n, 13, L) receives d(state)/d(lane) at each output time (``out`` the states, as the
    float run gives them). Returns the number of derivative evaluations (negative: the run
    was stopped, its outputs NaN). Releases the GIL."""
    return module().propagate_adaptive_t(y0, y0_t, t0, t_out, h_max, tol_pos, tol_ang, phys,
                                         phys_t, ops, args, starts, params, params_t, plane,
                                         stack_size, out, out_t)
