"""Seed 004's analysis studies (cadra.studies.single) against independent truth.

- single fits of shots flown with an exactly linear model recover that model (the simulator's
  own values) and the amplitude measures equal the simulator's truth table;
- with Table 4 M1 M1.10 as truth, the quasi-linear C_m_alpha and C_mq of single fits move with
  sigma_rms as the equivalent linearisation of the Table 4 forms over the true motion predicts;
- a hold-one study is minimal, with chi^2 ~ 0 and the others recovered, at the true value, and
  its chi^2 profile has the curvature 1 / sigma^2 of the free fit's covariance;
- the straight-line summary matches numpy's weighted polyfit.
"""

from __future__ import annotations

import math
import pickle
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cadra.aero import load_bundled_model
from cadra.dynamics.setup import propagate_states
from cadra.fitting.solver import fit
from cadra.flight.data import FILM_SIGMAS, shot_data_from_truth
from cadra.report.studies import plot_hold_one, plot_quasi_linear
from cadra.studies.holdone import hold_one_study
from cadra.studies.single import (
    aero_angle_history,
    linear_template_for,
    quasi_linear_summary,
    single_fit,
    single_fits,
)
from cadra.synthetic.simulate import load_shot_spec, rigid_body, simulate_shot, spec_from_dict

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "sample_shots" / "specs"
#: a small, a medium and a large-amplitude M1 M1.10 shot of seed 004 (sigma_rms ~4, 24, 29 deg)
M1_SHOTS = ("m1_2384", "m1_2388", "m1_2366")
#: truth of the exactly linear model (linear_template_sigma), away from its starting values
LINEAR_TRUTH = {"CD_0": 1.25, "CL_a": -1.40, "Cm_a": -0.100, "Cmq_0": -0.5}


def _shot_data(sim):
    return shot_data_from_truth(sim.truth, sim.rigid, sim.spec.shot_id, sim.body.kind,
                                sigma_position_m=FILM_SIGMAS["position_m"],
                                sigma_angle_rad=FILM_SIGMAS["angle_rad"])


def _linear_sim(name):
    data = tomllib.loads((SPECS / f"{name}.toml").read_text())
    data["aero_model"] = "linear_template_sigma"
    data["aero_values"] = dict(LINEAR_TRUTH)
    return simulate_shot(spec_from_dict(data))


@pytest.fixture(scope="module")
def linear_shots():
    sims = [_linear_sim(n) for n in M1_SHOTS]
    return sims, [_shot_data(s) for s in sims]


@pytest.fixture(scope="module")
def table4_shots():
    sims = [simulate_shot(load_shot_spec(SPECS / f"{n}.toml")) for n in M1_SHOTS]
    return sims, [_shot_data(s) for s in sims]


_TRUTH_STATES: dict = {}


def truth_state(shot, model):
    """An ``initial_states`` callable (module level, so it pickles): the simulator's state."""
    return _TRUTH_STATES[shot.shot_id]


def _start_states(sims, shots):
    return [sim.states[sd.epoch_index] for sim, sd in zip(sims, shots, strict=True)]


# --------------------------------------------------------------------------- step 1


def test_single_fits_recover_an_exactly_linear_truth(linear_shots):
    sims, shots = linear_shots
    model = linear_template_for(shots[0])
    assert model.name == "linear_template_sigma"
    for k, v in LINEAR_TRUTH.items():          # the fit must move: it starts elsewhere
        assert abs(model.parameter(k).value - v) > 0.05 * abs(v)
    table = single_fits(shots, model, _start_states(sims, shots))
    assert list(table["shot_id"]) == [s.shot_id for s in shots]
    assert table["converged"].all()
    for (_, row), sim in zip(table.iterrows(), sims, strict=True):
        for name, true in LINEAR_TRUTH.items():
            # noise-free: within the solver's own convergence step (0.01 sigma)
            assert abs(row[name] - true) < 0.01 * row[f"{name}_sigma"], (row.shot_id, name)
        assert row["reduced_chi2"] < 1e-3
        # amplitude measures along the fitted trajectory = the simulator's truth table
        # (the fit converges to 0.01 sigma, so its trajectory is within ~0.01 of the angle
        # sigma of the truth)
        t = sim.truth
        tol = 0.01 * math.degrees(FILM_SIGMAS["angle_rad"])
        assert row["sigma_rms_deg"] == pytest.approx(np.sqrt(np.mean(t["sigma_deg"] ** 2)),
                                                     abs=tol)
        assert row["alpha_rms_deg"] == pytest.approx(np.sqrt(np.mean(t["alpha_deg"] ** 2)),
                                                     abs=tol)   # alpha_ref-free model: about 0
        assert row["alpha_std_deg"] == pytest.approx(np.std(t["alpha_deg"]), abs=tol)
        assert row["alpha_mean_deg"] == pytest.approx(np.mean(t["alpha_deg"]), abs=tol)
        assert row["beta_rms_deg"] == pytest.approx(np.sqrt(np.mean(t["beta_deg"] ** 2)),
                                                    abs=tol)
        assert row["sigma_max_deg"] == pytest.approx(t["sigma_deg"].max(), abs=tol)
        assert row["mach_mean"] == pytest.approx(t["mach"].mean(), rel=1e-7)
    # the shots span a wide range of amplitude
    assert table["sigma_rms_deg"].min() < 5 and table["sigma_rms_deg"].max() > 20
    # no nonlinearity: the quasi-linear C_m_alpha lies on a flat line through the truth
    s = quasi_linear_summary(table, "Cm_a", "sigma_rms_deg")
    assert s["n"] == 3 and s["line_consistent"] is True
    assert abs(s["slope"]) < 0.1 * s["slope_sigma"]
    assert abs(s["intercept"] - LINEAR_TRUTH["Cm_a"]) < 0.1 * s["intercept_sigma"]


def test_initial_states_callable_and_shipping(linear_shots):
    sims, shots = linear_shots
    model = load_bundled_model("linear_template_sigma")
    for sim, sd in zip(sims, shots, strict=True):
        _TRUTH_STATES[sd.shot_id] = sim.states[sd.epoch_index]
    by_call = single_fits(shots[1:2], model, truth_state)
    by_list = single_fits(shots[1:2], model, [truth_state(shots[1], model)])
    pd.testing.assert_frame_equal(by_call.drop(columns="message"),
                                  by_list.drop(columns="message"))
    # what a scheduler ships: the per-shot function and its arguments pickle
    for obj in (single_fit, single_fits, hold_one_study, truth_state, shots[0], model):
        assert pickle.loads(pickle.dumps(obj)) is not None
    with pytest.raises(ValueError, match="initial states"):
        single_fits(shots, model, [truth_state(shots[0], model)])


def test_linear_template_for_lifting_body():
    spec = load_shot_spec(SPECS / "m2_2429.toml")
    truth = pd.read_csv(ROOT / "sample_shots" / "m2_2429" / "truth.csv")
    sd = shot_data_from_truth(truth, rigid_body(spec), spec.shot_id, "capsule",
                              sigma_position_m=1e-4, sigma_angle_rad=1e-3)
    assert linear_template_for(sd).name == "linear_template_alpha_beta"


def _equivalent_linear(sim, sd, n=801):
    """Equivalent linearisation of the truth model over the true motion (the describing
    function of an oscillator): C_m_alpha_eff = <C_m(sigma) sin sigma> / <sin^2 sigma> and
    C_mq_eff = <C_mq(sigma) (q^2 + r^2)> / <q^2 + r^2> (rate-weighted, as the damping work)."""
    m = sim.model
    k = sd.epoch_index
    tt = np.linspace(sd.t_s[0], sd.t_s[-1], n)
    states = propagate_states(sim.states[k], sd.t_s[k], tt, sim.rigid.phys(), m.compile(),
                              m.values(), 2.5e-5)
    h = aero_angle_history(sd, states)
    c = m.evaluate(h["alpha"], h["beta"], h["sigma"], h["mach"])
    s = np.sin(h["sigma"])
    w = states[:, 11] ** 2 + states[:, 12] ** 2
    return float(np.sum(c["Cm"] * s) / np.sum(s * s)), float(np.sum(c["Cmq"] * w) / np.sum(w))


def test_quasi_linear_trends_follow_table4_m1(table4_shots):
    """Seed 004 step 1 on Table 4 M1 M1.10 truth: C_m = (A1 + A3 s^2 + A4 s^4) s with
    s = sin sigma, so d(C_m / s)/d(s^2) = A3 + 2 A4 s^2 is negative below
    s^2 = -A3 / (2 A4) (sigma ~ 28 deg) and positive above: the quasi-linear C_m_alpha first
    falls, then turns back up, with amplitude. C_mq = max(A1, A2 + A3 s^2) falls from its
    peak to the asymptote: the quasi-linear C_mq falls with sigma_rms along a curve."""
    sims, shots = table4_shots
    model = load_bundled_model("linear_template_sigma")
    table = single_fits(shots, model, _start_states(sims, shots))
    assert table["converged"].all()
    order = np.argsort(table["sigma_rms_deg"].to_numpy())
    assert list(order) == [0, 1, 2]          # M1_SHOTS is listed by amplitude
    pred = np.array([_equivalent_linear(sim, sd) for sim, sd in zip(sims, shots, strict=True)])
    cma = table["Cm_a"].to_numpy()
    cmq = table["Cmq_0"].to_numpy()
    # Table 4 itself: the sign change of d(C_m / s)/d(s^2) lies between the shots' amplitudes
    p = sims[0].model.parameter
    turn = math.degrees(math.asin(math.sqrt(-p("Cm_A3").value / (2 * p("Cm_A4").value))))
    assert 20 < turn < 35
    # C_m_alpha: the changes between successive amplitudes have the predicted signs
    # (down, then up) and sizes within half of the prediction
    for i in (0, 1):
        d_fit, d_pred = cma[i + 1] - cma[i], pred[i + 1, 0] - pred[i, 0]
        assert np.sign(d_fit) == np.sign(d_pred) == (-1 if i == 0 else 1)
        assert abs(d_fit - d_pred) < 0.5 * abs(d_pred)
    # C_mq: destabilising (peak) at small amplitude, near the asymptote at large ones
    assert cmq[0] > cmq[1] > cmq[2]
    assert np.all(np.sign(np.diff(pred[:, 1])) == -1)
    span = p("Cmq_A2").value - p("Cmq_A1").value
    assert np.all(np.abs(cmq - pred[:, 1]) < 0.1 * span)
    # a straight line in sigma_rms does not describe C_mq: the points define a curve
    s = quasi_linear_summary(table, "Cmq_0", "sigma_rms_deg")
    assert s["line_consistent"] is False and s["p_value"] < 1e-6
    assert s["slope"] < 0


# --------------------------------------------------------------------------- step 2


def test_quasi_linear_summary_matches_weighted_polyfit():
    rng = np.random.default_rng(4)
    x = np.array([2.0, 5.0, 7.5, 11.0, 16.0, 25.0])
    sig = np.array([0.3, 0.2, 0.25, 0.1, 0.15, 0.05])
    y = 3.0 - 0.12 * x + rng.standard_normal(x.size) * sig
    table = pd.DataFrame({"shot_id": [f"S{i}" for i in range(x.size)], "status": "converged",
                          "amp": x, "C": y, "C_sigma": sig})
    table.loc[len(table)] = ["bad", "stalled", 1.0, 99.0, 0.1]
    table.loc[len(table)] = ["undetermined", "converged", 1.0, 5.0, math.inf]
    s = quasi_linear_summary(table, "C", "amp")
    assert s["n"] == 6
    assert [e[0] for e in s["excluded"]] == ["bad", "undetermined"]
    (b, a), cov = np.polyfit(x, y, 1, w=1 / sig, cov="unscaled")
    assert s["slope"] == pytest.approx(b, rel=1e-12)
    assert s["intercept"] == pytest.approx(a, rel=1e-12)
    assert s["slope_sigma"] == pytest.approx(math.sqrt(cov[0, 0]), rel=1e-10)
    assert s["intercept_sigma"] == pytest.approx(math.sqrt(cov[1, 1]), rel=1e-10)
    assert s["cov_slope_intercept"] == pytest.approx(cov[0, 1], rel=1e-10)
    chi2 = float(np.sum(((y - a - b * x) / sig) ** 2))
    assert s["chi2"] == pytest.approx(chi2, rel=1e-10) and s["dof"] == 4
    assert s["mean"] == pytest.approx(np.average(y, weights=sig**-2), rel=1e-12)
    assert s["line_consistent"] is (s["p_value"] >= 0.05)
    # a curve: the same points bent by a parabola far beyond their errors
    table["C"] = table["C"] + 0.02 * (table["amp"] - 12.0) ** 2
    bent = quasi_linear_summary(table, "C", "amp")
    assert bent["line_consistent"] is False
    # two points: a line fits exactly, nothing left to test it
    two = quasi_linear_summary(table.iloc[:2], "C", "amp")
    assert two["dof"] == 0 and two["line_consistent"] is None and math.isnan(two["p_value"])
    with pytest.raises(KeyError, match="Cxx"):
        quasi_linear_summary(table, "Cxx", "amp")


def test_plots(tmp_path):
    table = pd.DataFrame({"shot_id": ["a", "b", "c"], "status": "converged",
                          "sigma_rms_deg": [4.0, 20.0, 29.0], "Cmq_0": [3.0, 0.2, 0.0],
                          "Cmq_0_sigma": [0.1, 0.01, 0.01]})
    fig = plot_quasi_linear(table, "Cmq_0", "sigma_rms_deg")
    fig.savefig(tmp_path / "ql.png")
    hold = pd.DataFrame({"held": "Cmq_0", "value": [-0.7, -0.5, -0.3],
                         "status": ["converged", "converged", "stalled"],
                         "chi2": [9.0, 0.0, 9.0], "theta_rms_deg": [0.4, 0.0, 0.4],
                         "psi_rms_deg": [0.1, 0.0, 0.1], "sigma_rms_deg": [0.4, 0.0, 0.4],
                         "x_rms_m": [1e-4, 0, 1e-4], "Cm_a": [-0.1, -0.1, -0.1],
                         "Cm_a_sigma": [1e-4] * 3, "Cm_a_sigma_scaled": [1e-4] * 3,
                         "CD_0": [1.3] * 3, "CD_0_sigma": [1e-4] * 3})
    fig2 = plot_hold_one(hold)
    assert len([a for a in fig2.axes if a.get_visible()]) == 3
    fig2.savefig(tmp_path / "hold.png")
    import matplotlib.pyplot as plt

    plt.close(fig)
    plt.close(fig2)


# --------------------------------------------------------------------------- step 3


def test_hold_one_study_minimum_at_truth(linear_shots):
    sims, shots = linear_shots
    sims, shots = sims[1:], shots[1:]          # two shots with motion: a small multi-fit
    start = load_bundled_model("linear_template_sigma")
    states = _start_states(sims, shots)
    true = LINEAR_TRUTH["Cmq_0"]
    values = [true + 0.2, true - 0.4, true, true - 0.2, true + 0.4]      # any order
    table = hold_one_study(shots, start, states, "Cmq_0", values)
    assert list(table["value"]) == sorted(values)
    assert table["converged"].all()
    assert "Cmq_0" not in table.columns and set(table["held"]) == {"Cmq_0"}
    chi2 = table["chi2"].to_numpy()
    i0 = int(np.argmin(np.abs(table["value"].to_numpy() - true)))
    assert i0 == 2 and chi2[i0] < 1e-3
    assert np.all(np.diff(chi2[:i0 + 1]) < 0) and np.all(np.diff(chi2[i0:]) > 0)
    at = table.iloc[i0]
    for name in ("CD_0", "CL_a", "Cm_a"):
        assert abs(at[name] - LINEAR_TRUTH[name]) < 0.01 * at[f"{name}_sigma"]
    assert at["theta_rms_deg"] < 1e-4 and at["sigma_rms_deg"] < 1e-4
    assert table.iloc[0]["sigma_rms_deg"] > 0.1
    # the chi^2 profile is (v - v_true)^2 / sigma_v^2, sigma_v from the free fit's covariance
    free = fit(shots, start, states)
    sv = free.sigma("Cmq_0")
    for dv in (-0.2, 0.2):
        row = table.iloc[int(np.argmin(np.abs(table["value"].to_numpy() - (true + dv))))]
        assert row["chi2"] == pytest.approx((dv / sv) ** 2, rel=0.02)
    with pytest.raises(KeyError, match="no parameter"):
        hold_one_study(shots, start, states, "Cmq_A2", [1.0])


@pytest.mark.slow
def test_hold_one_fig15_m1_peak_width_trade():
    """Seed 004 Fig. 15 on Table 4 M1 M1.10 truth, all seven shots, noise-free: holding the
    C_mq peak A2 away from the truth (3.65), the fit narrows the peak (A3 more negative) for a
    higher peak and widens it for a lower one ("if the peak value estimate is too high or too
    low, the width of the peak becomes narrower or wider"), a lower peak gives a more negative
    large-angle asymptote A1 (Fig. 15b: -1.35 for 2.4 against -1.06 for 2.9-4.4), and the fit
    is best at the truth. About 15 s."""
    specs = [load_shot_spec(p) for p in sorted(SPECS.glob("m1_*.toml"))]
    # the M1 M1.10 group's seven (the M1 M1.25 group's shots fly another model)
    sims = [simulate_shot(s) for s in specs if s.aero_model == "m1_m110"]
    assert len(sims) == 7
    shots = [_shot_data(s) for s in sims]
    model = sims[0].model
    values = [2.4, 2.9, 3.65, 4.4]
    table = hold_one_study(shots, model, _start_states(sims, shots), "Cmq_A2", values)
    assert table["converged"].all()
    i0 = values.index(3.65)
    chi2 = table["chi2"].to_numpy()
    assert int(np.argmin(chi2)) == i0 and chi2[i0] < 1e-3
    assert np.all(np.diff(table["Cmq_A3"].to_numpy()) < 0)
    assert np.all(np.diff(table["Cmq_A1"].to_numpy()) > 0)
    rms = table["sigma_rms_deg"].to_numpy()
    assert int(np.argmin(rms)) == i0 and rms[i0] < 1e-3


def test_the_lowest_chi2_of_a_hold_one_study_is_a_converged_one():
    """A failed refit reports chi^2 0 (or its start's): it is never the study's best."""
    import pandas as pd

    from cadra.studies.holdone import lowest_converged

    table = pd.DataFrame({"value": [1.0, 2.0, 3.0], "converged": [True, False, True],
                          "chi2": [120.0, 0.0, 95.0]})
    assert lowest_converged(table) == 3.0
    table["converged"] = False
    assert lowest_converged(table) is None
