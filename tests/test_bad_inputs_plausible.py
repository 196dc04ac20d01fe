"""Plausibility checks where a unit slip is likely, and non-finite numbers refused by location
(issue 17, item 3): the inertia tensor's magnitude, a station bias's size, a history number
beyond a float, and the model's diameter against the image scale at load time. Each test
asserts the message names the culprit (key, station and channel, line and entry)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from cadra.io.shotfile import ShotFileError, load_shot

ROOT = Path(__file__).resolve().parents[1]
SPHERE = ROOT / "sample_shots" / "sphere_1" / "shot.toml"
M2 = ROOT / "sample_shots" / "m2_2429" / "shot.toml"


def _write(tmp_path: Path, text: str, name: str = "shot.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# --- inertia tensor -------------------------------------------------------------------------


@pytest.mark.parametrize("tensor, culprit", [
    ("[[1e308, 1e308, 0.0], [1e308, 1e308, 0.0], [0.0, 0.0, 13.153]]", "[0][0] = 1e+308"),
    ("[[13.153, 0.0, 0.0], [0.0, 13.153, -1e308], [0.0, -1e308, 13.153]]", "[1][2] = -1e+308"),
    ("[[13.153, 0.0, 0.0], [0.0, 13.153, 0.0], [0.0, 0.0, 2e9]]", "[2][2] = 2e+09"),
])
def test_inertia_beyond_plausible_is_refused_before_the_numerics(tmp_path, tensor, culprit):
    """Components like 1e308 overflowed in the symmetry and eigenvalue checks (RuntimeWarning,
    an error under this suite's warnings-as-errors); now refused by magnitude first."""
    text = SPHERE.read_text().replace(
        "[[13.153, 0.0, 0.0], [0.0, 13.153, 0.0], [0.0, 0.0, 13.153]]", tensor)
    p = _write(tmp_path, text)
    with pytest.raises(ShotFileError, match=re.escape(
            f"{p}: mass.inertia_g_cm2: component {culprit} g cm^2 is not a model's moment of "
            "inertia (|I| <= 1e+09 g cm^2, 100 kg at 1 m; check the unit)")):
        load_shot(p)


def test_inertia_components_beyond_plausible(tmp_path):
    text = SPHERE.read_text().replace(
        "inertia_g_cm2 = [[13.153, 0.0, 0.0], [0.0, 13.153, 0.0], [0.0, 0.0, 13.153]]",
        "Ixx_g_cm2 = 1e308\nIyy_g_cm2 = 1e308\nIzz_g_cm2 = 13.0\nIxy_g_cm2 = 1e308")
    p = _write(tmp_path, text)
    with pytest.raises(ShotFileError, match=re.escape(
            f"{p}: mass.Ixx_g_cm2/Iyy_g_cm2/Izz_g_cm2: component [0][0] = 1e+308 g cm^2 is not")):
        load_shot(p)


def test_validate_inertia_raises_no_warning():
    from cadra.io.shotfile import validate_inertia

    with np.errstate(all="raise"):
        for big in (1e308, -1e308, 1e200, 1.5e9):
            with pytest.raises(ShotFileError, match="is not a model's moment of inertia"):
                validate_inertia(np.full((3, 3), big), "k")
        validate_inertia(np.diag([1e9, 1e9, 1e9]), "k")  # the bound itself is accepted
