"""Variance components (``cadra2 fit --variance-components``): per-channel sigma scales
estimated by the fit, against noise whose true scale per channel is known."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cadra.fitting import fit_shots
from cadra.flight import CHANNELS, shot_data_from_truth
from cadra.synthetic.simulate import load_shot_spec, simulate_shot

SPECS = "sample_shots/specs"
NAMES = ("x", "y", "z", "theta", "psi")


@pytest.fixture(scope="module")
def sims():
    return [simulate_shot(load_shot_spec(f"{SPECS}/{n}.toml"))
            for n in ("m2_2429", "m2_2427", "m2_2425")]


def _shots(sims, true_scale, seed):
    rng = np.random.default_rng(seed)
    out = []
    for sim in sims:
        sd = shot_data_from_truth(sim.truth, sim.rigid, sim.spec.shot_id, sim.body.kind,
                                  sigma_position_m=1e-4, sigma_angle_rad=np.radians(0.1))
        cols = [CHANNELS.index(n) for n in NAMES]       # the measured ones (no roll)
        noise = (rng.standard_normal((len(sd.t_s), len(NAMES))) * sd.sigma[:, cols]
                 * np.asarray(true_scale))
        meas = sd.meas.copy()
        meas[:, cols] += noise
        out.append(replace(sd, meas=meas))
    return out


def test_the_scales_the_noise_has_are_found(sims):
    true = np.array([1.5, 1.0, 1.0, 0.7, 1.0])      # x under-reported, theta over-reported
    shots = _shots(sims, true, 5)
    plain, _ = fit_shots(shots, sims[0].model)
    res, _ = fit_shots(shots, sims[0].model, variance_components=True)
    assert plain.converged and res.converged
    vc = res.options["variance_components"]
    for j, ch in enumerate(NAMES):
        f, sf = vc["factors"][ch], vc["factor_sigma"][ch]
        assert abs(f - true[j] ** 2) < 3 * sf, (ch, f, sf)
    assert vc["reduced_chi2_before"] == pytest.approx(plain.reduced_chi2, rel=1e-9)
    assert abs(res.reduced_chi2 - 1.0) < 0.05
    # the rescaled shots are the ones the fit's problem holds: its residuals use them
    x = NAMES.index("x")
    np.testing.assert_allclose(res.problem.shots[0].sigma[:, x],
                               shots[0].sigma[:, x] * vc["sigma_scale"]["x"], rtol=1e-12)
    # coefficient sigmas grow where x and z carry the information, shrink with theta
    assert not np.allclose(res.aero_sigma, plain.aero_sigma, rtol=0.02)


def test_honest_sigmas_are_left_alone(sims):
    shots = _shots(sims, np.ones(5), 6)
    plain, _ = fit_shots(shots, sims[0].model)
    res, _ = fit_shots(shots, sims[0].model, variance_components=True)
    vc = res.options["variance_components"]
    for ch in NAMES:
        assert abs(vc["factors"][ch] - 1.0) < 3 * vc["factor_sigma"][ch]
    # the values move by a small fraction of their sigma
    assert np.all(np.abs(res.aero_values - plain.aero_values) < 0.5 * plain.aero_sigma)


def test_cli_reports_the_scales(tmp_path, capsys):
    import json

    from cadra.cli.cadra2 import main
    from cadra.synthetic.simulate import write_shot
    from cadra.validation.truth_files import write_trajectory_file

    sim = simulate_shot(load_shot_spec(f"{SPECS}/m2_2429.toml"))
    d = write_shot(sim, tmp_path / "shot", images=False, progress=False)
    traj = write_trajectory_file(sim, d / "shot.toml", tmp_path / "t.csv",
                                 np.random.default_rng(2))
    out = tmp_path / "fit"
    assert main(["fit", str(traj), "--model", "m2_m070", "-o", str(out), "--no-plots",
                 "--variance-components"]) == 0
    assert "variance components: sigma scale x ×" in capsys.readouterr().out
    res = json.loads((out / "results.json").read_text())
    assert set(res["options"]["variance_components"]["factors"]) == set(NAMES)
    assert "### Variance components" in (out / "report.md").read_text(encoding="utf-8")
