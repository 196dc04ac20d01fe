"""The gap diagnosis' second step: one verdict from every test, a diagnosis that always runs,
the range air's shared forms, and held parameters under test.

Truth: shots simulated WITH an effect (or with a measurement edit, or with a held parameter at
another value), measured with stage-one-like noise, fitted WITHOUT it; the diagnosis is not
told what was injected.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from cadra.aero import load_bundled_model
from cadra.dynamics.effects import Effects
from cadra.fitting import FitOptions, fit_shots
from cadra.flight import shot_data_from_truth
from cadra.gap import verdict as vd
from cadra.gap.candidates import library, same_term
from cadra.gap.score import diagnose_gap
from cadra.synthetic.simulate import load_shot_spec, simulate_shot

SP = 2.8e-7                      # m, stage one's capsule precision
SA = np.radians(0.0012)          # rad


def _shots(names, effects=None, seed=3, edit=None, model=None, offsets=None):
    out, sim_model = [], None
    for k, name in enumerate(names):
        spec = load_shot_spec(f"sample_shots/specs/{name}.toml")
        sim = simulate_shot(replace(spec, effects=effects or Effects(),
                                    aero_model=model or spec.aero_model))
        truth = sim.truth.copy()
        if offsets is not None:
            truth["y_m"] += offsets[k][0]
            truth["z_m"] += offsets[k][1]
        sd = shot_data_from_truth(truth, sim.rigid.with_effects(Effects()), spec.shot_id,
                                  "capsule", sigma_position_m=SP, sigma_angle_rad=SA,
                                  rng=np.random.default_rng(seed + k))
        if edit is not None:
            sd = replace(sd, meas=edit(sd.meas.copy()))
        out.append(sd)
        sim_model = sim.model
    return out, sim_model


def test_a_one_station_angle_misfit_in_every_shot_is_found_where_the_global_test_passes():
    """Station 9's theta off by 4 sigma in each of three shots: the global chi^2 alone passes
    (p > 0.01), the cross-shot test finds it, and the verdict says so, with the offset's
    size within 2 sigma of the truth."""
    bias = 4.0 * SA

    def edit(m):
        m[8, 3] += bias
        return m

    shots, model = _shots(["m2_2425", "m2_2427", "m2_2429"], edit=edit)
    res, _ = fit_shots(shots, load_bundled_model("m2_m070"))
    assert res.converged
    assert stats.chi2.sf(res.chi2, res.dof) > 0.01          # the global test alone passes
    dg = diagnose_gap(res, shots)
    assert dg.unexplained
    assert "unexplained, at station 9 theta" in dg.verdict
    assert "same sign in every shot" in dg.verdict
    assert [(c["station"], c["channel"]) for c in dg.set_aside] == [(9, "theta")]
    name = vd.offset_name(dg.set_aside[0])
    v, s = dg.fit_after.value(name), dg.fit_after.sigma(name)
    assert abs(v - bias) <= 2 * s
    # no library effect is pinned on it
    assert not dg.added


def test_every_test_counted_keeps_a_null_set_clean_and_the_levels_add_up():
    shots, model = _shots(["m2_2426", "m2_2428"], seed=11)
    res, _ = fit_shots(shots, model)
    dg = diagnose_gap(res, shots)
    assert not dg.added and not dg.unexplained, dg.verdict
    ev = dg.evidence
    assert set(ev["family"]) == set(vd.SHARES)
    # each family's tests share its part of alpha (Bonferroni): p_adjusted = p n / share
    for fam, grp in ev.groupby("family"):
        row = grp.iloc[-1]
        expect = min(1.0, row["p_value"] * len(grp) / vd.SHARES[fam])
        assert row["p_adjusted"] == pytest.approx(expect, rel=1e-12)
    assert sum(vd.SHARES.values()) == pytest.approx(1.0)


def test_a_fit_short_of_convergence_is_continued_and_diagnosed():
    """A cg offset; the fit given is stopped after 2 iterations a phase (chi^2 4771.0, its
    minimum 4767.0; with the lambda search 3 already converge): the diagnosis continues it,
    says so, and finds the offset with its size."""
    shots, model = _shots(["m2_2429"], effects=Effects(cg_offset_body_m=(0.0, 0.0, 2e-4)))
    res, _ = fit_shots(shots, model, options=FitOptions(max_iterations=2))
    assert not res.converged
    dg = diagnose_gap(res, shots)
    assert dg.added and dg.added[0]["effect"] == "lateral cg offset"
    z, sz = dg.added[0]["size"][1], dg.added[0]["sigma"][1]
    assert abs(z - 2e-4) <= 2 * sz
    assert "had not converged" in dg.verdict or "did not converge" in dg.verdict
    assert dg.fit_given.converged


@pytest.mark.slow
def test_the_range_airs_shared_gradient_is_one_parameter_and_wins_over_the_per_shot_form():
    """Slow (three M1 shots diagnosed); tools/validate_gap.py's ``shared_density`` case runs it
    over many draws and records the rate it is named first (docs/validation.md)."""
    g = 4e-6
    shots, model = _shots(["m1_2366", "m1_2379", "m1_2388"],
                          effects=Effects(density_gradient_per_m=g), seed=5)
    res, _ = fit_shots(shots, model)
    dg = diagnose_gap(res, shots)
    first = dg.added[0]
    assert first["effect"] == "shared density gradient", dg.verdict
    assert first["params"] == ("drho_dx_over_rho_per_m",)
    assert abs(first["size"][0] - g) <= 2 * first["sigma"][0]
    assert first["form"]["chosen"] == "shared by the set"
    assert "density gradient" not in first["aliases"]
    assert "shared by the set" in dg.verdict


def test_a_held_parameter_the_data_reject_is_flagged_with_the_parameters_it_moves():
    """A model that holds M2's CL_A2 at 1 where the data have -1: freeing it is the
    effect (a parameter held at 0, a term left out, is not offered: the library's aero
    terms ask that question)."""
    base = load_bundled_model("m2_m070").with_values({"CL_A2": 1.0})
    truth = base.with_values({"CL_A2": -1.0})
    import tempfile
    from pathlib import Path

    from cadra.aero import save_model

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "truth.toml"
        save_model(truth, path)
        shots, _ = _shots(["m2_2425", "m2_2433"], model=str(path), seed=9)
    res, _ = fit_shots(shots, base)
    dg = diagnose_gap(res, shots, base)
    held = [a for a in dg.added if a["effect"] == "held CL_A2"]
    assert held, dg.verdict
    a = held[0]
    assert abs(a["size"][0] - (-1.0)) <= 2 * a["sigma"][0]
    assert a["held_value"] == 1.0
    assert "held CL_A2 = 1 is inconsistent with these data" in dg.verdict
    assert dg.held_inconsistent == ("CL_A2",)
    names = [c.name for c in library(load_bundled_model("m2_m070"), [1], 0.7)]
    assert "held Cmq_A3" in names and "held CL_A2" not in names


def test_a_held_blank_cell_that_is_a_library_term_is_offered_once():
    """M1 M1.10 holds Cm_A2 (M - M_ref) sin(sigma) at 0: the library's Mach dependence of C_m
    about M_ref is that very term."""
    m1 = load_bundled_model("m1_m110")
    names = [c.name for c in library(m1, [1, 2, 3], 1.08, n_shots=2)]
    assert "held Cm_A2" not in names and "Mach dependence of Cm" in names
    assert "held Cmq_A2" in names and "held M_ref" not in names
    assert "shared density gradient" in names and "shared cross-flow" in names
    assert "shared density gradient" not in [c.name for c in library(m1, [1], 1.08)]
    # and the test can tell a different term: Cmq_A2 is not the Mach term
    lib = {c.name: c for c in library(m1, [1], 1.08)}
    assert not same_term(m1, lib["held Cmq_A2"], lib["Mach dependence of Cm"], 1.10)


def test_an_underdetermined_fit_is_not_diagnosed():
    """No degrees of freedom (more unknowns than measurements; chi^2/dof NaN): refused with
    the counts, where a verdict was given on nothing."""
    from types import SimpleNamespace

    from cadra.gap.score import diagnose_gap

    fit = SimpleNamespace(dof=-17, chi2=0.0, n_observations=10, n_free=27)
    with pytest.raises(ValueError, match="10 measurements for 27 unknowns"):
        diagnose_gap(fit, [])
    fit = SimpleNamespace(dof=40, chi2=float("nan"), n_observations=67, n_free=27)
    with pytest.raises(ValueError, match="underdetermined"):
        diagnose_gap(fit, [])


def test_a_freed_hold_that_leaves_a_misfit_standing_or_has_an_alias_is_not_blamed_alone():
    """The verdict names a held value inconsistent only when freeing it leaves no misfit
    standing and no other candidate explains as much (docs/gap.md, "Held parameters")."""
    from types import SimpleNamespace

    from cadra.gap.verdict import compose

    def held(aliases=()):
        return {"effect": "held Cmq_A2", "kind": "held", "params": ("Cmq_A2",),
                "size": [1.17], "sigma": [0.18], "interval_2sigma": None,
                "held_value": 3.24, "aliases": tuple(aliases), "moved": [("Cmq_A3", 11.0)],
                "refit_status": "converged"}

    quiet = pd.DataFrame({"family": ["global"], "significant": [False], "p_value": [0.4]})
    fit = SimpleNamespace(param_names=(), reduced_chi2=1.02)
    cell = {"station": 7, "channel": "theta", "n": 1, "mean_sigma": 9.0, "same_sign": True,
            "p_adjusted": 1e-9}
    a = held()
    text, unexplained = compose([a], [], [], quiet, fit, "", 3.1, None)
    assert not unexplained and a["held_verdict"] == "inconsistent"
    assert "held Cmq_A2 = 3.24 is inconsistent with these data" in text
    a = held()
    text, unexplained = compose([a], [], [cell], quiet, fit, "", 3.1, None)
    assert unexplained and a["held_verdict"] == "misfit_standing"
    assert "is inconsistent" not in text and "not shown inconsistent" in text
    assert "station 7 theta" in text
    a = held(aliases=["Mach dependence of Cm"])
    text, _ = compose([a], [], [], quiet, fit, "", 3.1, None)
    assert a["held_verdict"] == "indistinguishable"
    assert "either held Cmq_A2 = 3.24" in text and "Mach dependence of Cm" in text
