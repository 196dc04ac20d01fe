"""Held values with an uncertainty (cadra.fitting.consider) against independent truth.

Two M1 M1.10 shots flown with an exactly linear model (linear_template_sigma at known
values), read noise-free with film-level sigmas, fitted with C_mq held at the truth:

- the consider covariance with the held value's sigma set to what the free fit gives it is the
  free fit's covariance (the block inverse of the free fit's normal matrix: an identity of
  linear algebra, so they agree to the solver's convergence);
- the sensitivity d(free)/d(held) is the slope of real refits held at the truth +- one sigma
  (converged tightly, central differences), to 1e-3;
- ``--hold NAME=VALUE+-SIGMA`` and a model file's ``sigma`` reach the parameter, in the file's
  unit, and a hold without an uncertainty is exact.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from cadra.aero import load_bundled_model, model_from_dict
from cadra.fitting import FitOptions
from cadra.fitting.consider import consider
from cadra.fitting.inputs import apply_holds
from cadra.fitting.solver import fit
from cadra.flight.data import FILM_SIGMAS, shot_data_from_truth
from cadra.synthetic.simulate import simulate_shot, spec_from_dict

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "sample_shots" / "specs"
TRUTH = {"CD_0": 1.25, "CL_a": -1.40, "Cm_a": -0.100, "Cmq_0": -0.5}
OTHERS = ("CD_0", "CL_a", "Cm_a")


@pytest.fixture(scope="module")
def shots():
    sims, data = [], []
    for name in ("m1_2388", "m1_2366"):
        spec = tomllib.loads((SPECS / f"{name}.toml").read_text())
        spec["aero_model"] = "linear_template_sigma"
        spec["aero_values"] = dict(TRUTH)
        sim = simulate_shot(spec_from_dict(spec))
        sims.append(sim)
        data.append(shot_data_from_truth(sim.truth, sim.rigid, sim.spec.shot_id, sim.body.kind,
                                         sigma_position_m=FILM_SIGMAS["position_m"],
                                         sigma_angle_rad=FILM_SIGMAS["angle_rad"]))
    states = [s.states[d.epoch_index] for s, d in zip(sims, data, strict=True)]
    model = load_bundled_model("linear_template_sigma").with_values(TRUTH)
    free = fit(data, model, states)
    assert free.converged
    return data, states, model, free


def test_consider_with_the_free_fits_sigma_is_the_free_fits_covariance(shots):
    data, states, model, free = shots
    s_free = free.sigma("Cmq_0")
    held = model.with_vary({"Cmq_0": False}).with_sigmas({"Cmq_0": s_free})
    res = fit(data, held, states)
    assert res.converged
    ca = consider(res)
    assert ca.held == ("Cmq_0",)
    i_free = [free.param_names.index(n) for n in OTHERS]
    i_held = [ca.names.index(n) for n in OTHERS]
    want = free.covariance[np.ix_(i_free, i_free)]
    got = ca.covariance[np.ix_(i_held, i_held)]
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4 * np.sqrt(
        np.outer(np.diag(want), np.diag(want))).max())
    # the conditional sigmas are smaller: the hold's uncertainty is what they lacked
    table = ca.table().set_index("parameter")
    assert (table.loc[list(OTHERS), "sigma_consider"]
            > table.loc[list(OTHERS), "sigma_conditional"]).all()
    assert set(table["dominant_held"]) == {"Cmq_0"}
    # consider^2 = conditional^2 + (S sigma_c)^2, each parameter
    S = ca.sensitivity_table().loc[list(OTHERS), "Cmq_0"].to_numpy()
    np.testing.assert_allclose(table.loc[list(OTHERS), "sigma_consider"] ** 2,
                               table.loc[list(OTHERS), "sigma_conditional"] ** 2
                               + (S * s_free) ** 2, rtol=1e-10)


def test_the_sensitivity_is_the_slope_of_real_refits(shots):
    data, states, model, free = shots
    s = free.sigma("Cmq_0")
    held = model.with_vary({"Cmq_0": False}).with_sigmas({"Cmq_0": s})
    ca = consider(fit(data, held, states))
    # refits converged far past the solver's default stop (chi^2 steps below 1e-4: the
    # parameters within 1 % of their sigma, while the hold moves CL_a by 2 % of its sigma):
    # steps to 1e-9 sigma, and a remaining Gauss-Newton step that no trial can take counted
    # as converged below 1e-5 sigma, the adaptive integrator's noise floor here (its step
    # choices move chi^2 by ~1e-11: a step of 4e-6 sigma was seen that no trial could take,
    # with either method of sensitivities); 1e-5 sigma of the parameters is < 5e-4 of the
    # slope below
    tight = FitOptions(step_tol_sigma=1e-9, noise_tol_sigma=1e-5, max_iterations=50)
    lo, hi = (fit(data, held.with_values({"Cmq_0": TRUTH["Cmq_0"] + d}), states,
                  options=tight) for d in (-s, s))
    assert lo.converged and hi.converged
    sens = ca.sensitivity_table()["Cmq_0"]
    for name in OTHERS:
        slope = (hi.value(name) - lo.value(name)) / (2 * s)
        assert sens[name] == pytest.approx(slope, rel=1e-3), name


def test_a_fit_without_held_uncertainties_has_no_consider_analysis(shots):
    *_, free = shots
    assert consider(free) is None


def test_hold_with_an_uncertainty_from_the_command_line_and_the_model_file():
    model = load_bundled_model("m1_m110")
    m = apply_holds(model, hold=["Cmq_A2=3.65+-0.75"])
    p = m.parameter("Cmq_A2")
    assert (p.vary, p.value, p.sigma) == (False, 3.65, 0.75)
    assert apply_holds(model, hold=["Cmq_A2=3.65±0.75"]).parameter("Cmq_A2").sigma == 0.75
    # a new value without an uncertainty is exact; a bare hold keeps the model's sigma
    assert apply_holds(m, hold=["Cmq_A2=3.0"]).parameter("Cmq_A2").sigma == 0.0
    assert apply_holds(m, hold=["Cmq_A2"]).parameter("Cmq_A2").sigma == 0.75
    with pytest.raises(ValueError, match="not a number"):
        apply_holds(model, hold=["Cmq_A2=3.65+-wide"])
    # in the file's unit: an angle held in degrees has its sigma in degrees
    model = load_bundled_model("m2_m070")
    d = model.to_dict()
    angle = next(n for n, e in d["parameters"].items() if e.get("unit") == "deg")
    m = apply_holds(model, hold=[f"{angle}=20+-2"])
    assert m.parameter(angle).sigma == pytest.approx(np.radians(2.0), rel=1e-12)
    # the model file carries it both ways, in the file's unit
    d = m.to_dict()
    assert d["parameters"][angle]["sigma"] == pytest.approx(2.0, rel=1e-12)
    back = model_from_dict(d, source="test")
    assert back.parameter(angle).sigma == m.parameter(angle).sigma
    d["parameters"][angle]["sigma"] = -1.0
    with pytest.raises(ValueError, match=f"parameters.{angle}: sigma must be"):
        model_from_dict(d, source="test")


def test_the_report_says_what_a_hold_does(shots, tmp_path):
    """The report's table shows the consider sigma, the conditional beside it, and says
    which free parameters the hold's ±σ moves; a hold without an uncertainty is exact."""
    from cadra.report.fit import report_markdown, results_dict

    data, states, model, free = shots
    held = model.with_vary({"Cmq_0": False}).with_sigmas({"Cmq_0": 0.2})
    res = fit(data, held, states)
    text = report_markdown(res, data)
    assert "σ conditional" in text and "### What the holds do" in text
    assert "held Cmq_0 = -0.5 ± 0.2 (SI) moves" in text
    ca = res.consider
    i = ca.names.index("Cm_a")
    d = results_dict(res, data)
    assert d["parameters"]["Cm_a"]["sigma_consider"] == pytest.approx(ca.sigma[i])
    assert d["parameters"]["Cmq_0"]["held_sigma"] == 0.2
    assert set(d["consider_sensitivity"]["Cm_a"]) == {"Cmq_0"}
    # the console report (what cadra2 fit prints) says the same
    console = res.report()
    assert "the consider sigma" in console and "Cmq_0 = -0.5 ± 0.2" in console
    assert f"conditional {res.sigma('Cm_a'):.2g}" in console
    exact = fit(data, model.with_vary({"Cmq_0": False}), states)
    assert "consider" not in exact.report()
    assert exact.consider is None
    text = report_markdown(exact, data)
    assert "Cmq_0 = -0.5 (exact)" in text and "σ conditional" not in text


# --- the Bayesian alternative: the held parameter free under a Gaussian prior -------------


def test_a_gaussian_prior_combines_with_the_data_as_two_gaussians(shots):
    """Noise-free data put the free fit at the truth with sigma s; a prior one s above it
    with sigma s gives the posterior mean half-way and sigma s / sqrt 2 (the product of two
    Gaussians), and the other parameters' covariance drops by the regression on it:
    P_oo - P_oc P_co / (s^2 + s_p^2)."""
    data, states, model, free = shots
    s = free.sigma("Cmq_0")
    mu = TRUTH["Cmq_0"] + s
    res = fit(data, model.with_priors({"Cmq_0": (mu, s)}), states,
              options=FitOptions(step_tol_sigma=1e-4))
    assert res.converged and res.n_priors == 1
    assert res.dof == free.dof + 1
    assert abs(res.value("Cmq_0") - (TRUTH["Cmq_0"] + 0.5 * s)) < 0.01 * s
    assert res.sigma("Cmq_0") == pytest.approx(s / np.sqrt(2.0), rel=2e-3)
    # the prior's own chi^2 share: ((mu - posterior) / s)^2 = 1/4
    assert res.prior_chi2 == pytest.approx(0.25, rel=0.02)
    i = [free.param_names.index(n) for n in OTHERS]
    c = free.param_names.index("Cmq_0")
    P = free.covariance
    want = P[np.ix_(i, i)] - np.outer(P[i, c], P[c, i]) / (2.0 * s * s)
    j = [res.param_names.index(n) for n in OTHERS]
    np.testing.assert_allclose(res.covariance[np.ix_(j, j)], want, rtol=2e-3,
                               atol=2e-3 * np.sqrt(np.outer(np.diag(want),
                                                            np.diag(want))).max())


def test_a_wide_prior_is_a_free_fit_and_a_tight_one_a_hold(shots):
    data, states, model, free = shots
    s = free.sigma("Cmq_0")
    wide = fit(data, model.with_priors({"Cmq_0": (TRUTH["Cmq_0"] + 3 * s, 1e4 * s)}), states)
    assert wide.value("Cmq_0") == pytest.approx(free.value("Cmq_0"), abs=0.01 * s)
    assert wide.sigma("Cmq_0") == pytest.approx(s, rel=1e-3)
    at = TRUTH["Cmq_0"] + 2 * s
    tight = fit(data, model.with_priors({"Cmq_0": (at, 1e-4 * s)}), states)
    held = fit(data, model.with_vary({"Cmq_0": False}).with_values({"Cmq_0": at}), states)
    assert tight.value("Cmq_0") == pytest.approx(at, abs=1e-3 * s)
    for n in OTHERS:
        assert tight.value(n) == pytest.approx(held.value(n), abs=0.01 * held.sigma(n))
        assert tight.sigma(n) == pytest.approx(held.sigma(n), rel=1e-3)


def test_priors_from_the_command_line_and_the_model_file():
    from cadra.fitting.priors import holds_as_priors

    m = load_bundled_model("m1_m110")
    # NAME alone: the held value and the model's own sigma (0.433: seed 004's range)
    bayes = apply_holds(m, prior=["Cmq_A2"])
    p = bayes.parameter("Cmq_A2")
    assert p.vary and p.prior == pytest.approx(3.65) and p.sigma == pytest.approx(0.433)
    assert holds_as_priors(m).parameter("Cmq_A2") == p
    q = apply_holds(load_bundled_model("m2_m070"), prior=["alpha_ref=10+-2"]
                    ).parameter("alpha_ref")
    assert q.prior == pytest.approx(np.radians(10.0)) and q.sigma == pytest.approx(np.radians(2))
    with pytest.raises(ValueError, match="VALUE\\+-SIGMA"):
        apply_holds(m, prior=["Cmq_A2=3.65"])
    with pytest.raises(ValueError, match="uncertainty"):
        apply_holds(m, prior=["Cm_A1"])
    # the file keeps the prior in its unit, and a prior needs its sigma
    d = bayes.to_dict()
    assert d["parameters"]["Cmq_A2"]["prior"] == pytest.approx(3.65)
    again = model_from_dict(d, "again")
    assert again.parameter("Cmq_A2") == p
    d["parameters"]["Cmq_A2"].pop("sigma")
    with pytest.raises(ValueError, match="prior needs its sigma"):
        model_from_dict(d, "bad")
