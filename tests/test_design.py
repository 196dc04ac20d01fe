"""What to fire next (cadra.fitting.information, cadra.studies.candidates, .design).

Checked against independent answers:

- the information of a fit problem inverts to the covariance the solver reported (a
  different computation: the full normal matrix, locals included);
- a candidate with the template's own launch flies the template's flight;
- a second copy of a single shot halves every variance (sigma / sqrt 2: linear least
  squares with the data doubled);
- the predicted sigmas after a candidate are the sigmas a refit with that shot added reports
  (noise-free data at the current estimate: the linearisation is then exact at the point);
- more stations never add less information;
- ``cadra2 plan`` writes its report, tables and plot, and refuses what it cannot plan.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from cadra.fitting.information import covariance_sigmas, problem_information
from cadra.fitting.solver import fit
from cadra.flight.data import FILM_SIGMAS
from cadra.studies.candidates import Candidate, CandidateSpace, candidate_shot
from cadra.studies.design import planner
from cadra.validation.stage2_bench import SINGLE, make_problem


@pytest.fixture(scope="module")
def fitted():
    rng = np.random.default_rng([2024, 12, 6])
    sds, ys, model, _, _ = make_problem(SINGLE, rng, FILM_SIGMAS)
    res = fit(sds, model, ys)
    assert res.converged
    return res


@pytest.fixture(scope="module")
def plan_m2(fitted):
    return planner(fitted, targets=("Cmq_A1", "Cm_A1"))


def test_the_information_inverts_to_the_solvers_covariance(fitted):
    ns = fitted.problem.n_shared
    cov, sig = covariance_sigmas(problem_information(fitted.problem))
    np.testing.assert_allclose(sig, fitted.aero_sigma, rtol=1e-6)
    np.testing.assert_allclose(cov, fitted.covariance[:ns, :ns], rtol=1e-5,
                               atol=1e-9 * np.abs(fitted.covariance[:ns, :ns]).max())


def test_a_prior_adds_its_information(fitted):
    """A prior of sigma s on a parameter adds 1/s^2 on its diagonal: the posterior sigma of
    that parameter alone follows 1/sigma^2 = 1/sigma_data^2 + 1/s^2 when it is uncorrelated;
    in general, the Schur complement of the rest."""
    name = "Cnr_A1"
    s = float(fitted.sigma(name))
    prob = fitted.problem
    with_prior = prob.model.with_priors({name: (prob.model.parameter(name).value, s)})
    from dataclasses import replace

    info0 = problem_information(prob)
    info1 = problem_information(replace(prob, model=with_prior))
    i = list(fitted.aero_names).index(name)
    diff = info1 - info0
    assert diff[i, i] == pytest.approx(1.0 / s**2, rel=1e-12)
    assert np.count_nonzero(np.abs(diff) > 1e-12 / s**2) == 1


def test_a_candidate_with_the_templates_launch_flies_the_templates_flight(plan_m2):
    t = plan_m2.template
    cp = candidate_shot(t, t.base, plan_m2.problem)
    ours, theirs = cp.predict()[0], t.problem.predict()[0]
    # far below the film sigmas (0.1 mm, 0.1 deg): the same flight
    assert np.abs(ours[:, :3] - theirs[:, :3]).max() < 1e-6
    assert np.abs(ours[:, 3:5] - theirs[:, 3:5]).max() < 1e-7
    dt = (cp.shots[0].t_s - cp.shots[0].t_s[0]) - (t.shot.t_s - t.shot.t_s[0])
    assert np.abs(dt).max() < 1e-8


def test_a_second_copy_of_a_single_shot_halves_every_variance(plan_m2):
    row = plan_m2.evaluate(plan_m2.template.base)
    ratio = np.array([row[f"sigma_{n}"] for n in plan_m2.names]) / plan_m2.sigma_now
    # the copy's sigmas are the group's median per channel (x's timing share varies a
    # little with the speed along the shot): sqrt(1/2) to a per cent
    np.testing.assert_allclose(ratio, math.sqrt(0.5), rtol=0.01)
    assert row["objective"] == pytest.approx(0.5, rel=0.02)


def test_predicted_sigmas_are_what_a_refit_with_the_shot_reports(fitted, plan_m2):
    c = Candidate(**{**plan_m2.template.base.as_dict(), "angle_deg": 5.0, "rate_deg_s": 150.0,
                     "stations": 12})
    row = plan_m2.evaluate(c)
    cp = candidate_shot(plan_m2.template, c, plan_m2.problem)
    shots = list(fitted.problem.shots) + list(cp.shots)
    states = list(fitted.problem.epoch_states) + list(cp.epoch_states)
    refit = fit(shots, fitted.model, states)
    assert refit.converged
    predicted = np.array([row[f"sigma_{n}"] for n in refit.aero_names])
    np.testing.assert_allclose(refit.aero_sigma, predicted, rtol=1e-3)
    # and the shot is worth firing: every target narrows
    for n in plan_m2.targets:
        assert row[f"sigma_{n}"] < plan_m2.sigma_now[plan_m2.names.index(n)]


def test_more_stations_never_add_less_information(plan_m2):
    space = CandidateSpace(plan_m2.template.base, {"stations": (4, 16)})
    rows = [plan_m2.evaluate(c) for c in space.grid(13)]
    table = pd.DataFrame(rows).sort_values("stations")
    assert list(table["stations"]) == list(range(4, 17))
    assert (np.diff(table["objective"]) < 0).all()


def test_the_plan_searches_beyond_its_sample(plan_m2):
    base = plan_m2.template.base
    space = CandidateSpace(base, {"angle_deg": (0.0, 35.0), "rate_deg_s": (0.0, 250.0)})
    res = plan_m2.plan(space, 12, refine=1, refine_evaluations=15, n_best=3)
    assert res.n_sample == 12 and 0 < res.n_refine <= 15
    assert res.best["objective"].iloc[0] <= res.sampled["objective"].min()
    assert res.best["objective"].is_monotonic_increasing
    assert ((res.table["angle_deg"] >= 0) & (res.table["angle_deg"] <= 35)).all()
    lo, hi = res.best[["flown_min_deg", "flown_max_deg"]].iloc[0]
    assert 0.0 <= lo <= hi < 90.0
    text = res.report()
    assert "moves:" in text and "Cmq_A1" in text


def test_bad_plans_are_refused(fitted):
    with pytest.raises(ValueError, match="not a free unknown"):
        planner(fitted, targets=("Cmq_A3",))
    with pytest.raises(ValueError, match="criterion"):
        planner(fitted, criterion="E")
    with pytest.raises(ValueError, match="no candidate dimension"):
        CandidateSpace(planner(fitted).template.base, {"speed": (1, 2)})
    with pytest.raises(ValueError, match="low <= high"):
        CandidateSpace(planner(fitted).template.base, {"mach": (0.7, 0.5)})
    p = planner(fitted, targets=("Cmq_A1",))
    with pytest.raises(ValueError, match="station count"):
        candidate_shot(p.template, Candidate(**{**p.template.base.as_dict(), "stations": 40}))


def test_a_held_parameter_can_be_planned_for(fitted):
    """Freed for the plan, a held parameter is an unknown the group's data may or may not
    determine; its sigma is finite here (Cmq_A3 shapes the peak the shot flies through)."""
    p = planner(fitted, targets=("Cmq_A3",), free=("Cmq_A3",))
    i = p.names.index("Cmq_A3")
    assert np.isfinite(p.sigma_now[i]) and p.sigma_now[i] > 0


def test_cadra2_plan_writes_its_report(work, tmp_path, capsys):
    from cadra.cli.cadra2 import main

    out = tmp_path / "plan"
    argv = ["plan", str(work / "m2_stage1"), "--model", "m2_m070", "-o", str(out),
            "--angle-deg", "0:30", "--rate-deg-s", "0:200", "--target", "Cmq_A1",
            "--candidates", "8", "--refine", "1", "--shots", "2", "-q"]
    assert main(argv) == 0
    for f in ("report.md", "candidates.csv", "best.csv", "sigmas.csv", "plan.png",
              "sequence.csv"):
        assert (out / f).is_file(), f
    seq = pd.read_csv(out / "sequence.csv")
    assert list(seq["shot"]) == [1, 2]
    assert seq["sigma_Cmq_A1"].iloc[1] < seq["sigma_Cmq_A1"].iloc[0]
    assert "Shots one after another" in (out / "report.md").read_text()
    capsys.readouterr()
    assert main([*argv[:4], "-o", str(tmp_path / "other"), "--target", "nope", "-q"]) == 1
    err = capsys.readouterr().err
    assert "nope" in err and "free" in err
    assert not (tmp_path / "other").exists()
