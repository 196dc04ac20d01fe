"""What several test modules share: the suite runs from the repository root (the sample specs'
paths are relative to it) whichever folder pytest is started in, the capsule shot with an
offset centre of gravity that the fit's extras and its problem tests both fit, and the folder
of inputs (``work``) the output-safety tests aim their outputs at.

Shared harness code (simulated records, gap cases, trajectory writers, image fixtures) lives
in :mod:`cadra.validation`, which the tools use too; tests never import a tool or another
test."""

from __future__ import annotations

import os
import shutil
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    os.chdir(ROOT)


@pytest.fixture(scope="session")
def cg_offset_shot():
    """M2-2429 flown with its cg 0.2 mm off the axis (body z) and read, noise-free, with the
    nominal body (cg on the axis), sigmas 0.28 um and 0.0012 deg. Fields: ``cg_z`` (m),
    ``sim`` (the simulated shot), ``data`` (its ShotData), ``y0`` (the true state at the
    epoch station, about the true cg: a fit's start)."""
    from cadra.dynamics.effects import Effects
    from cadra.flight import shot_data_from_truth
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    cg_z = 2e-4
    spec = load_shot_spec("sample_shots/specs/m2_2429.toml")
    sim = simulate_shot(replace(spec, effects=Effects(cg_offset_body_m=(0.0, 0.0, cg_z))))
    nominal = sim.rigid.with_effects(Effects())
    sd = shot_data_from_truth(sim.truth, nominal, "M2-2429", "capsule",
                              sigma_position_m=2.8e-7, sigma_angle_rad=np.radians(0.0012))
    t = sim.truth.iloc[sd.epoch_index]
    y0 = np.array([t.x_cg_m, t.y_cg_m, t.z_cg_m, t.vx_m_s, t.vy_m_s, t.vz_m_s,
                   t.q0, t.q1, t.q2, t.q3, t.p_rad_s, t.q_rad_s, t.r_rad_s])
    return SimpleNamespace(cg_z=cg_z, sim=sim, data=sd, y0=y0)


def _trajectory(sim, shot_file: Path, out_dir: Path, rng) -> Path:
    """A stage-one folder for ``sim``: its exact truth plus seeded noise, written by
    tests/test_cadra2_cli.py's helper (no images needed, and the fit converges)."""
    from cadra.validation.truth_files import write_trajectory_file as trajectory_file

    out_dir.mkdir()
    trajectory_file(sim, shot_file, out_dir / "trajectory.csv", rng)
    return out_dir


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """One folder of inputs: a 2-station shot with images (``shot/``, for cadra1), whole
    M2-2429 and sphere shots without images with stage-one folders the fit and the
    calibration accept (``m2/``, ``m2_stage1/``, ``sphere/``, ``sphere_stage1/``: so the old
    code would have run to the end and written over them) and a 3-station spec
    (``specs/small.toml``)."""
    import dataclasses

    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    spec_m2 = ROOT / "sample_shots" / "specs" / "m2_2429.toml"
    base = tmp_path_factory.mktemp("safety")
    spec = dataclasses.replace(load_shot_spec(spec_m2), n_stations=2)
    write_shot(simulate_shot(spec), base / "shot", images=True, progress=False)
    rng = np.random.default_rng(17)
    for name, spec_file in (("m2", spec_m2), ("sphere", spec_m2.with_name("sphere_1.toml"))):
        sim = simulate_shot(load_shot_spec(spec_file))
        write_shot(sim, base / name, images=False, progress=False)
        _trajectory(sim, base / name / "shot.toml", base / f"{name}_stage1", rng)
    (base / "specs").mkdir()
    (base / "specs" / "small.toml").write_text("n_stations = 3\n" + spec_m2.read_text())
    return base


# -- a real headless browser (the campaign page's tests) ----------------------------------------


def _chromium() -> str:
    for name in ("chromium", "chromium-browser"):
        found = shutil.which(name)
        if found:
            return found
    pytest.fail("no Chromium on PATH (chromium or chromium-browser): the campaign page's "
                "browser test needs one (Debian: apt-get install chromium)", pytrace=False)


@pytest.fixture(scope="session")
def browser():
    """Debian's Chromium, headless, driven by Playwright. A missing browser or Playwright
    FAILS the test (never skips: CI must run the browser tests)."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError as exc:
        pytest.fail(f"playwright is not installed ({exc}): the campaign page's browser test "
                    "needs it", pytrace=False)
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=_chromium(),
                              args=["--no-sandbox", "--headless=new"])
        yield b
        b.close()


@pytest.fixture(scope="session")
def open_page():
    """``open_page(browser, url) -> (page, errors)``: a new page at ``url`` with every console
    error and page error collected in ``errors``."""

    def _open(browser, url):
        page = browser.new_page()
        errors = []
        page.on("console", lambda m: errors.append(f"console: {m.text}")
                if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(f"pageerror: {e}"))
        page.goto(url)
        return page, errors

    return _open
