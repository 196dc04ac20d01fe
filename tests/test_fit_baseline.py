"""Two implementations, one answer: CADRA's fitter against the SciPy reference fitter.

:func:`cadra.fitting.solver.fit` (adaptive RK4, complex-step sensitivities, block-arrow
Levenberg-Marquardt) and :func:`cadra.validation.fit_baseline.baseline_fit` (``solve_ivp``
DOP853 and ``least_squares`` with finite differences, sharing only the equations of motion and
the observation model) must find the same least-squares solution on the same data: shot M2-2429
(sample shot, seed 004 Table 4 M2 M0.70 truth) with film noise, four free aerodynamic
parameters and the 12 state unknowns.

The baseline's plain-Python right-hand side (``rhs="python"``: the equations of
:mod:`cadra.dynamics.eom` on Python floats, coefficients from the model's expression trees by
the numpy reference evaluator) must reproduce the compiled :func:`cadra.dynamics.eom.derivative`
to rounding, with every physics effect switched on.
"""

import math

import numpy as np
import pandas as pd
import pytest

from cadra.aero import load_bundled_model
from cadra.body import body_from_spec
from cadra.dynamics.effects import Effects
from cadra.dynamics.eom import air_data, derivative, rotation_fb
from cadra.dynamics.integrate import inverse3
from cadra.dynamics.layout import P_CG_OFFSET, P_INERTIA, P_WIND, P_WIND_GRAD
from cadra.dynamics.setup import plane_code
from cadra.fitting.sensitivity import apply_local, observables, predict
from cadra.fitting.solver import fit
from cadra.flight.data import FILM_SIGMAS, rigid_body_from_shot, shot_data_from_truth
from cadra.io.shotfile import load_shot
from cadra.validation.fit_baseline import baseline_fit, derivative_python, trajectory_ivp

SHOT_DIR = "sample_shots/m2_2429"
FREE = ("CD_A1", "CL_A1", "Cm_A1", "Cmq_A1")
STATE_COLUMNS = ["x_cg_m", "y_cg_m", "z_cg_m", "vx_m_s", "vy_m_s", "vz_m_s", "q0", "q1", "q2",
                 "q3", "p_rad_s", "q_rad_s", "r_rad_s"]


@pytest.fixture(scope="module")
def problem(request):
    root = request.config.rootpath
    shot = load_shot(root / SHOT_DIR / "shot.toml")
    truth = pd.read_csv(root / SHOT_DIR / "truth.csv")
    rng = np.random.default_rng(20240)
    sd = shot_data_from_truth(truth, rigid_body_from_shot(shot), shot.shot_id,
                              body_from_spec(shot.model).kind,
                              sigma_position_m=FILM_SIGMAS["position_m"],
                              sigma_angle_rad=FILM_SIGMAS["angle_rad"], rng=rng)
    y_true = truth.iloc[sd.epoch_index][STATE_COLUMNS].to_numpy(float)
    model = load_bundled_model("m2_m070")
    model = model.with_vary({n: n in FREE for n in model.names})
    u = np.r_[5e-4, -5e-4, 5e-4, 0.2, -0.2, 0.2, math.radians(0.2), -math.radians(0.2),
              math.radians(0.2), 0.2, -0.2, 0.2]
    start = model.with_values({n: model.parameter(n).value * 1.05 for n in FREE})
    return sd, model, start, apply_local(y_true, u)


def test_solve_ivp_trajectory_matches_cadra_prediction(problem):
    """The baseline's trajectory and CADRA's adaptive RK4 agree to far below the noise."""
    sd, model, _, y0 = problem
    t0 = sd.t_s[sd.epoch_index]
    args = (y0, t0, sd.t_s, sd.rigid.phys(), model.compile(), model.values())
    a = observables(trajectory_ivp(*args), sd.rigid.ref_from_cg_body_m())
    b = predict(*args, sd.rigid.ref_from_cg_body_m())
    assert np.max(np.abs(a[:, :3] - b[:, :3])) < 1e-9          # m (sigma 1e-4)
    assert np.max(np.abs(a[:, 3:] - b[:, 3:])) < 1e-7          # rad (sigma 1.7e-3)


def test_python_rhs_trajectory_matches_compiled(problem):
    """The plain-Python right-hand side gives solve_ivp the same trajectory as the compiled one
    (same equations to rounding, so the same steps)."""
    sd, model, _, y0 = problem
    t0 = sd.t_s[sd.epoch_index]
    args = (y0, t0, sd.t_s, sd.rigid.phys(), model.compile(), model.values())
    a = trajectory_ivp(*args)
    b = trajectory_ivp(*args, rhs="python", model=model)
    assert np.max(np.abs(a[:, :6] - b[:, :6])) < 1e-12          # m, m/s
    assert np.max(np.abs(a[:, 6:] - b[:, 6:])) < 1e-12          # quaternion, rad/s


@pytest.mark.slow
def test_baseline_and_cadra_find_the_same_solution(problem):
    """The reference fitter (scipy least_squares over solve_ivp) and CADRA's fit reach the same
    minimum. Slow (the reference fitter is the slow thing the benchmark measures):
    tools/bench_cadra2.py runs the same comparison and records it
    (baseline_vs_cadra_single_max_sigma, docs/validation.md)."""
    sd, model, start, y0 = problem
    res = fit([sd], start, [y0])
    base = baseline_fit([sd], start, [y0])
    assert res.converged and base.success
    assert res.aero_names == base.aero_names == FREE
    # same minimum: values within 1 % of a sigma, the same chi^2, the same sigmas
    assert np.max(np.abs(base.aero_values - res.aero_values) / res.aero_sigma) < 0.01
    assert base.chi2 == pytest.approx(res.chi2, rel=1e-5)
    np.testing.assert_allclose(base.aero_sigma, res.aero_sigma, rtol=0.02)
    y_fit, y_base = res.shots[0].state, base.states[0]
    local_sigma = res.shots[0].local_sigma
    assert np.max(np.abs(y_base[:6] - y_fit[:6]) / local_sigma[:6]) < 0.01
    assert np.max(np.abs(y_base[10:] - y_fit[10:]) / local_sigma[9:]) < 0.01


def _compiled_derivative(y, phys, model, params):
    prog = model.compile()
    I = phys[P_INERTIA:P_INERTIA + 9].reshape(3, 3).copy()
    Iinv = np.empty((3, 3))
    inverse3(I, Iinv)
    dy = np.empty(13)
    derivative(y, phys, I, Iinv, prog.ops, prog.args, prog.starts, params,
               plane_code(model.angle_plane), np.empty((3, 3)), np.empty(3), np.empty(8),
               np.empty(3), np.empty(3), np.empty(9), prog.new_stack(), dy)
    return dy


def _with_magnus(model):
    """``model`` (a total-angle one) with Magnus force and moment terms (CC, Cn) and a roll
    moment in the aerodynamic roll angle phi (its every quadrant: the states are turned)."""
    from cadra.aero import AeroModel, Parameter

    cl = model.coefficients.get("Cl", "0")
    return AeroModel(model.name, model.angle_plane,
                     {**model.coefficients, "CC": "CNpa*p_hat*sin(sigma)",
                      "Cn": "CMpa*p_hat*sin(sigma)",
                      "Cl": f"{cl} + Cl4*sin(4*phi)*sin(sigma) + Cl1*phi"},
                     model.parameters + (Parameter("CNpa", 0.6), Parameter("CMpa", -0.3),
                                         Parameter("Cl4", 0.05), Parameter("Cl1", 0.01)))


@pytest.mark.parametrize(("shot_dir", "model_name"), [("sample_shots/m2_2429", "m2_m070"),
                                                      ("sample_shots/m1_2366", "m1_m110"),
                                                      ("sample_shots/m1_2366", "m1_m110+magnus")])
def test_python_rhs_matches_compiled_derivative(request, shot_dir, model_name):
    """Plain-Python RHS == numba derivative to 1e-12 relative, every component, with the cg
    offset, wind, wind gradient, density gradient and inertia effects on, at six states of
    truth.csv turned by a few degrees and given large random rates, with the aero parameters
    moved by up to 10 % (both angle planes; the alpha_beta states lie on both sides of Cm's
    kink at alpha_ref), and at zero incidence (the sigma plane's degenerate normal-force
    direction)."""
    root = request.config.rootpath
    shot = load_shot(root / shot_dir / "shot.toml")
    truth = pd.read_csv(root / shot_dir / "truth.csv")
    model = load_bundled_model(model_name.split("+")[0])
    if model_name.endswith("+magnus"):
        model = _with_magnus(model)
    effects = Effects(cg_offset_body_m=(2e-4, -3e-4, 1.5e-4),
                      inertia_delta_body_kg_m2=((1e-8, 2e-9, 0.0), (2e-9, -1e-8, 0.0),
                                                (0.0, 0.0, 5e-9)),
                      density_gradient_per_m=1e-4, wind_facility_m_s=(1.5, -2.0, 0.7),
                      wind_gradient_facility_per_s=(2e-3, -1e-3, 5e-4))
    phys = rigid_body_from_shot(shot).with_effects(effects).phys()
    assert np.all(phys[P_WIND:P_CG_OFFSET + 3] != 0)  # wind, gradients, cg offset all on
    rng = np.random.default_rng(8)
    params = model.values() * rng.uniform(0.9, 1.1, model.values().size)
    states = []
    for i in rng.choice(len(truth), 6, replace=False):
        y = truth.iloc[i][STATE_COLUMNS].to_numpy(float)
        u = np.r_[np.zeros(6), rng.normal(0, math.radians(4), 3), rng.normal(0, 30, 3)]
        states.append(apply_local(y, u))
    # zero incidence: air-relative velocity along x_b (the first column of R_FB)
    y = states[0].copy()
    qw, qx, qy, qz = y[6:10]
    x_b = np.array([1 - 2 * (qy * qy + qz * qz), -2 * (qx * qy + qw * qz),
                    -2 * (qx * qz - qw * qy)])
    y[3:6] = phys[P_WIND:P_WIND + 3] + phys[P_WIND_GRAD:P_WIND_GRAD + 3] * y[0] + 250.0 * x_b
    states.append(y)
    alphas = []
    for y in states:
        want = _compiled_derivative(y, phys, model, params)
        got = derivative_python(y, phys, model, params)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
        R, variables = np.empty((3, 3)), np.empty(8)
        rotation_fb(y, R)
        air_data(y, phys, R, np.empty(3), variables)
        alphas.append(variables[0])
    assert abs(alphas[-1]) < 1e-12
    if model.angle_plane == "alpha_beta":       # both branches of Cm's where(alpha < alpha_ref)
        alpha_ref = model.parameter("alpha_ref").value
        assert min(alphas) < alpha_ref < max(alphas)
