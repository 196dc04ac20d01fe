"""Forward-mode sensitivities: the integrator's generated tangent code against complex step.

Truth: complex step (each column from its own complex run of the float code, exact to
rounding) and, for the transform itself, derivatives by hand of small functions. The two
methods differentiate the same discrete scheme, so they agree to rounding wherever they take
the same path (the mounts' constrained equations included); across Table 4's max(...) kinks
complex step's real part takes its own path now and then, and the test says by how much.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from numba import njit

from cadra.channels import N_CHANNELS
from cadra.dynamics.forward_ad import Spec, TransformError, tangent_module
from cadra.dynamics.layout import N_PHYS, P_CG_OFFSET, P_INERTIA, P_WIND
from cadra.fitting.sensitivity import Integration, predict_states, predict_with_jacobian
from cadra.synthetic.simulate import load_shot_spec, simulate_shot

SPECS = "sample_shots/specs"


def _worst(J, ref):
    """Largest |J - ref| of each column over the column's largest |ref|."""
    scale = np.abs(ref).max(axis=(0, 1))
    return (np.abs(J - ref).max(axis=(0, 1)) / np.where(scale > 0, scale, 1.0)).max()


@pytest.fixture(scope="module")
def m1_2366():
    return simulate_shot(load_shot_spec(f"{SPECS}/m1_2366.toml"))


def _directions(n):
    d = np.zeros((5, N_PHYS))
    d[0, P_CG_OFFSET] = 1.0                         # axial cg offset
    d[1, P_CG_OFFSET + 2] = 1.0                     # lateral cg offset (moves the ref point)
    d[2, P_WIND + 1] = 1.0                          # cross wind
    d[3, P_INERTIA + 4] = 1.0                       # I_yy
    d[4, P_INERTIA + 1] = d[4, P_INERTIA + 3] = 1.0  # a product of inertia
    return d[:n]


def _both(shot, model, n_dirs=5):
    prog, params, phys = model.compile(), model.values(), shot.rigid.phys()
    k = len(shot.times_s) // 2
    args = (shot.states[k], shot.times_s[k], shot.times_s, phys, prog, params,
            shot.rigid.ref_from_cg_body_m(), np.arange(12), model.free_indices(),
            Integration(), _directions(n_dirs), True)
    return (predict_with_jacobian(*args, method="forward"),
            predict_with_jacobian(*args, method="complex"),
            predict_states(*args[:6], Integration()))


def test_forward_jacobian_equals_complex_step(m1_2366):
    """Table 4 M1 M1.10 made smooth (C_mq_A2 low enough that max(...) never switches, as in
    the finite-difference check): every column (12 locals, every free aero parameter, five
    physical directions) agrees with complex step to 1e-12 of its size (measured ~1e-14),
    and the predictions and states are the float run's, bit for bit."""
    shot = m1_2366
    model = shot.model.with_values({"Cmq_A2": -10.0})
    (pf, Jf, sf), (pc, Jc, sc), states = _both(shot, model)
    n_free = 12 + model.free_indices().size + 5
    assert Jf.shape == Jc.shape == (len(shot.times_s), N_CHANNELS, n_free)
    assert _worst(Jf, Jc) < 1e-12
    assert np.array_equal(sf, states)
    assert np.abs(pf - pc).max() < 1e-12


def test_forward_jacobian_across_table4_kinks(m1_2366):
    """Under Table 4 M1 M1.10 itself the record crosses the max(...) C_mq kink many times.
    The tangent run is the float run (its states bit for bit), so its Jacobian is the
    derivative of the very predictions the fit compares. Complex step decides each kink and
    each step on the real part of a complex computation, which differs from the float one in
    the last bits; near a kink that takes another branch or step now and then, so its path
    strays from the float run's (by ~1e-7 here) and its columns differ from the tangent's by
    ~1e-4 of their size: the same derivative of a slightly different discrete path."""
    shot = m1_2366
    (pf, Jf, sf), (pc, Jc, sc), states = _both(shot, shot.model)
    assert np.array_equal(sf, states)
    stray = np.abs(sc - states).max()
    assert stray > 1e-9                              # complex step's own path, not the float's
    assert _worst(Jf, Jc) < 1e-3


def test_forward_jacobian_on_a_pitch_pivot_equals_complex_step():
    """The mounts' constrained equations (a pitch pivot ahead of the cg) differentiate as
    well: the locals the mount leaves free and the aero columns agree with complex step."""
    from cadra.aero import model_from_dict
    from cadra.dynamics.modes import TestMode
    from cadra.dynamics.setup import RigidBody
    from cadra.dynamics.trajectory import Launch

    body = RigidBody(mass_kg=0.096563,
                     inertia_body_kg_m2=np.diag([104.208, 81.024, 81.024]) * 1e-7,
                     d_m=0.03556, cg_from_ref_body_m=[-0.0044, 0.0, 0.0],
                     density_kg_m3=1.191, speed_of_sound_m_s=345.3, viscosity_pa_s=1.81e-5,
                     mode=TestMode(kind="pitch_pivot", stream_m_s=100.0,
                                   pivot_from_cg_body_m=(0.006, 0.0, 0.0)))
    model = model_from_dict({
        "format": "cadra.aero/1", "name": "pivot", "angle_plane": "sigma",
        "coefficients": {"CD": "CD0", "CL": "CLa*sin(sigma)", "Cm": "Cma*sin(sigma)",
                         "Cmq": "Cmq0"},
        "parameters": {k: {"value": v} for k, v in dict(CD0=0.3, CLa=1.5, Cma=-0.117,
                                                        Cmq0=-2.0).items()}})
    t = np.linspace(0.0, 0.2, 41)
    y0 = Launch(speed_m_s=0.0, theta_rad=0.02, q_rad_s=1.0).state(body)
    args = (y0, 0.0, t, body.phys(), model.compile(), model.values(),
            body.ref_from_cg_body_m(), np.array([6, 7, 8, 10]), model.free_indices(),
            Integration(), _directions(2))
    _, Jf = predict_with_jacobian(*args, method="forward")
    _, Jc = predict_with_jacobian(*args, method="complex")
    assert np.abs(Jc).max() > 0
    assert _worst(Jf, Jc) < 1e-12


# --- the transform itself ------------------------------------------------------------------


@njit
def _toy(x, p, out):
    a = x[0] * x[1] + np.sin(x[0]) / p[0]
    b = a if x[1].real > 0.0 else -a
    for i in range(2):
        out[i] = np.sqrt(b * b + 1.0) * x[i] ** 3.0
    out[2] = np.arctan(a) - np.exp(-x[1]) + np.log(p[0])


@njit
def _bad(x, out):
    out[0] = np.hypot(x[0], x[1])


def _load(text):
    ns: dict = {}
    exec(compile(text.replace("cache=True", "cache=False"), "<tangent>", "exec"), ns)
    return ns


def test_transform_differentiates_by_the_chain_rule():
    """A function of every construct the transform knows, against derivatives by hand."""
    text = tangent_module([Spec(_toy, {"x": "a", "p": "a", "out": "a"})])
    toy_t = _load(text)["_toy_t"]
    x, p = np.array([0.7, 1.3]), np.array([2.0])
    x_t = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])      # lanes: x0, x1, p0
    p_t = np.array([[0.0, 0.0, 1.0]])
    out, out_t = np.zeros(3), np.zeros((3, 3))
    toy_t(x, x_t, p, p_t, out, out_t)
    ref = np.zeros(3)
    _toy(x, p, ref)
    assert np.array_equal(out, ref)                           # the primal, bit for bit
    a = x[0] * x[1] + np.sin(x[0]) / p[0]
    da = np.array([x[1] + np.cos(x[0]) / p[0], x[0], -np.sin(x[0]) / p[0] ** 2])
    s = np.sqrt(a * a + 1.0)
    for i in range(2):
        dx3 = np.zeros(3)
        dx3[i] = 3.0 * x[i] ** 2
        want = a / s * da * x[i] ** 3 + s * dx3
        assert np.allclose(out_t[i], want, rtol=1e-14, atol=0)
    want = da / (1 + a * a) + np.array([0.0, np.exp(-x[1]), 0.0]) + np.array([0, 0, 1 / p[0]])
    assert np.allclose(out_t[2], want, rtol=1e-14, atol=0)


def test_transform_refuses_what_it_cannot_differentiate():
    with pytest.raises(TransformError, match="hypot"):
        tangent_module([Spec(_bad, {"x": "a", "out": "a"})])
    with pytest.raises(TransformError, match="no parameter"):
        tangent_module([Spec(_bad, {"y": "a"})])


def test_the_first_compile_runs_once_in_the_background(tmp_path, monkeypatch):
    """Until the tangent code is compiled on the machine, "auto" asks for one background
    compile: one process however many ask, another after a dead one's flag goes stale, none
    once the code is ready."""
    from cadra.dynamics import tangent

    started = []
    monkeypatch.setattr(tangent, "_MODULE", None)
    monkeypatch.setattr(tangent, "_PATH", tmp_path / "cadra_tangent_0.py")
    monkeypatch.setattr(tangent.subprocess, "run", lambda *a, **k: started.append(a))
    assert not tangent.ready()
    assert tangent.compile_in_background() and len(started) == 1
    assert not tangent.compile_in_background() and len(started) == 1     # one at work
    flag = tmp_path / "cadra_tangent_0.compiling"
    old = flag.stat().st_mtime - 2 * tangent._COMPILE_STALE_S
    os.utime(flag, (old, old))                                            # it died
    assert tangent.compile_in_background() and len(started) == 2
    (tmp_path / "cadra_tangent_0.ready").touch()
    assert tangent.ready() and not tangent.compile_in_background() and len(started) == 2


def test_threads_asking_for_the_generated_module_at_once_write_it_once(tmp_path, monkeypatch):
    """A multi-shot fit's shots ask for the tangent code from several threads at its first
    fit in a process: one writes the generated module, the others wait for it (two threads
    of a process wrote the same temporary, and the second's rename failed: a validation run
    stopped with FileNotFoundError)."""
    import threading
    import time

    from cadra.dynamics import tangent

    monkeypatch.setattr(tangent, "_PATH", None)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    replace = os.replace

    def slow_replace(src, dst):          # widen the window between writing and renaming
        time.sleep(0.05)
        replace(src, dst)

    monkeypatch.setattr(tangent.os, "replace", slow_replace)
    start, paths, errors = threading.Barrier(6), [], []

    def ask():
        start.wait()
        try:
            paths.append(tangent._path())
        except OSError as exc:
            errors.append(exc)

    threads = [threading.Thread(target=ask) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == [] and len(set(paths)) == 1 and paths[0].exists()
    assert [p.name for p in (tmp_path / "tangent").iterdir()] == [paths[0].name]


def test_the_environment_chooses_what_auto_means(tmp_path, monkeypatch):
    """CADRA_SENSITIVITIES forces a method for every fit of a process (no background compile
    when it says complex); unset, a process keeps the method it first chose, even once the
    compile is done; a value it does not know is refused, naming the variable."""
    from cadra.dynamics import tangent
    from cadra.fitting import sensitivity

    started = []
    monkeypatch.setattr(tangent, "_MODULE", None)
    monkeypatch.setattr(tangent, "_PATH", tmp_path / "cadra_tangent_0.py")
    monkeypatch.setattr(tangent.subprocess, "run", lambda *a, **k: started.append(a))
    monkeypatch.setattr(sensitivity, "_RESOLVED", None)
    monkeypatch.setenv(sensitivity.METHOD_ENV, "complex")
    assert sensitivity.process_method() == "complex" and not started
    monkeypatch.setenv(sensitivity.METHOD_ENV, "Forward")
    assert sensitivity.process_method() == "forward" and not started
    monkeypatch.setenv(sensitivity.METHOD_ENV, "")
    assert sensitivity.process_method() == "complex" and len(started) == 1   # not ready yet
    (tmp_path / "cadra_tangent_0.ready").touch()                          # compiled now
    assert sensitivity.process_method() == "complex" and len(started) == 1   # kept
    monkeypatch.setenv(sensitivity.METHOD_ENV, "adjoint")
    with pytest.raises(ValueError, match="CADRA_SENSITIVITIES"):
        sensitivity.process_method()
