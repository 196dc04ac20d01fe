"""``cadra2 fit --reference``: pulls and a joint chi^2 against a reference."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from cadra.cli.cadra2 import main
from cadra.fitting.reference import Reference, compare_with_reference
from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot
from cadra.validation.truth_files import write_trajectory_file

SPECS = Path("sample_shots/specs")


def test_pulls_and_joint_chi2_against_independent_arithmetic():
    rng = np.random.default_rng(3)
    names = ["a", "b", "c", "d"]
    A = rng.normal(size=(4, 4))
    C = A @ A.T + 0.5 * np.eye(4)             # correlated fit covariance
    values = np.array([1.0, -2.0, 0.5, 3.0])
    ref = Reference("r", {"a": 0.8, "b": -2.5, "c": 0.1}, {"a": 0.3, "b": 0.0, "c": 0.2})
    cmp = compare_with_reference(names, values, C, ref)
    assert cmp.not_compared == ("d",)
    d = values[:3] - np.array([0.8, -2.5, 0.1])
    total = C[:3, :3] + np.diag([0.09, 0.0, 0.04])
    np.testing.assert_allclose(cmp.table["pull"], d / np.sqrt(np.diag(total)), rtol=1e-12)
    chi2 = float(d @ np.linalg.solve(total, d))
    assert cmp.chi2 == pytest.approx(chi2, rel=1e-10) and cmp.dof == 3
    assert cmp.p == pytest.approx(stats.chi2.sf(chi2, 3), rel=1e-8)
    # with the reference's own covariance (a folder), its correlations count
    rc = pd.DataFrame(np.diag([0.09, 0.01, 0.04]) + 0.005, index=["a", "b", "c"],
                      columns=["a", "b", "c"])
    cmp2 = compare_with_reference(names, values, C, Reference("r", ref.values, ref.sigmas, rc))
    total2 = C[:3, :3] + rc.to_numpy()
    assert cmp2.chi2 == pytest.approx(float(d @ np.linalg.solve(total2, d)), rel=1e-10)


@pytest.fixture(scope="module")
def two_fits(tmp_path_factory):
    base = tmp_path_factory.mktemp("ref")
    rng = np.random.default_rng(7)
    out = {}
    for name in ("m2_2429", "m2_2427"):
        sim = simulate_shot(load_shot_spec(SPECS / f"{name}.toml"))
        d = write_shot(sim, base / name, images=False, progress=False)
        out[name] = (sim, write_trajectory_file(sim, d / "shot.toml", base / f"{name}.csv",
                                               rng))
    first = base / "fit_2429"
    assert main(["fit", str(out["m2_2429"][1]), "--model", "m2_m070", "-o", str(first),
                 "-q", "--no-plots", "--reference", "m2_m070"]) == 0
    second = base / "fit_2427"
    assert main(["fit", str(out["m2_2427"][1]), "--model", "m2_m070", "-o", str(second),
                 "-q", "--reference", str(first)]) == 0
    return out, first, second


def test_reference_model_gives_the_pulls_against_the_truth(two_fits):
    out, first, _ = two_fits
    truth = out["m2_2429"][0].model
    res = json.loads((first / "results.json").read_text())
    pulls = pd.read_csv(first / "reference_pulls.csv").set_index("parameter")
    free = [n for n, p in res["parameters"].items() if not p["held"]]
    assert sorted(pulls.index) == sorted(free)
    for n in free:
        p = res["parameters"][n]
        assert pulls.loc[n, "pull"] == pytest.approx(
            (p["value"] - truth.parameter(n).value) / p["sigma"], rel=1e-6)
        assert pulls.loc[n, "reference_sigma"] == 0
    assert res["reference"]["dof"] == len(free)
    report = (first / "report.md").read_text(encoding="utf-8")
    assert "## Against the reference" in report and "Joint χ² of agreement" in report


def test_an_earlier_fit_folder_as_reference_uses_its_sigmas(two_fits):
    _, first, second = two_fits
    a = json.loads((second / "results.json").read_text())["parameters"]
    b = json.loads((first / "results.json").read_text())["parameters"]
    pulls = pd.read_csv(second / "reference_pulls.csv").set_index("parameter")
    for n in pulls.index:
        expect = (a[n]["value"] - b[n]["value"]) / np.hypot(a[n]["sigma"], b[n]["sigma"])
        assert pulls.loc[n, "pull"] == pytest.approx(expect, rel=1e-6)
    # both are fits of the same truth: they agree (the joint test, correlations counted)
    assert json.loads((second / "results.json").read_text())["reference"]["p"] > 1e-3
    assert (second / "plots" / "coefficients.png").is_file()


@pytest.mark.parametrize("what", ["missing", "empty_dir"])
def test_a_bad_reference_is_refused_before_the_fit(two_fits, tmp_path, capsys, what):
    out, _, _ = two_fits
    ref = tmp_path / "nothing"
    if what == "empty_dir":
        ref.mkdir()
    code = main(["fit", str(out["m2_2429"][1]), "--model", "m2_m070", "-o",
                 str(tmp_path / "o"), "-q", "--no-plots", "--reference", str(ref)])
    err = capsys.readouterr().err
    assert code == 1 and str(ref) in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()
