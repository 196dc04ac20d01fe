"""Two implementations, one answer: CADRA's fitter against the SciPy reference fitter.

:func:`cadra.fitting.solver.fit` (adaptive RK4, complex-step sensitivities, block-arrow
Levenberg-Marquardt) and :func:`cadra.fitting.baseline.baseline_fit` (``solve_ivp`` DOP853 and
``least_squares`` with finite differences, sharing only the equations of motion and the
observation model) must find the same least-squares solution on the same data: shot M2-2429
(sample shot, seed 004 Table 4 M2 M0.70 truth) with film noise, four free aerodynamic
parameters and the 12 state unknowns.
"""

import math

import numpy as np
import pandas as pd
import pytest

from cadra.aero import load_bundled_model
from cadra.body import body_from_spec
from cadra.fitting.baseline import baseline_fit, trajectory_ivp
from cadra.fitting.data import FILM_SIGMAS, rigid_body_from_shot, shot_data_from_truth
from cadra.fitting.sensitivity import apply_local, observables, predict
from cadra.fitting.solver import fit
from cadra.io.shotfile import load_shot

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


def test_baseline_and_cadra_find_the_same_solution(problem):
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
