"""The channel registry (cadra.channels) and the layering it serves.

Truth: the trajectory file format of docs/stage1.md (its column names, degrees in the file)
and stage two's fixed channel order x, y, z, theta, psi, phi (docs/fitting.md).
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cadra import channels as C

ROOT = Path(__file__).resolve().parents[1]


def test_registry_matches_the_documented_channels():
    assert C.NAMES == ("x", "y", "z", "theta", "psi", "phi")
    assert C.UNITS == ("m", "m", "m", "rad", "rad", "rad")
    assert [c.value_column for c in C.OBSERVED] == ["x_m", "y_m", "z_m", "theta_deg",
                                                     "psi_deg", "phi_deg"]
    assert [c.sigma_column for c in C.OBSERVED] == ["sigma_x_m", "sigma_y_m", "sigma_z_m",
                                                     "sigma_theta_deg", "sigma_psi_deg",
                                                     "sigma_phi_deg"]
    assert [c.name for c in C.OBSERVED if c.periodic] == ["phi"]
    assert [c.name for c in C.OBSERVED if c.optional] == ["phi"]
    assert C.channel("theta").si_column == "theta_rad"
    assert C.channel("psi").display_scale == 180.0 / math.pi
    assert C.channel("x").display_scale == 1.0
    assert list(C.POSITION) == [0, 1, 2] and list(C.ANGLE) == [3, 4, 5]
    assert list(C.AXIS) == [3, 4] and list(C.ROLL) == [5]
    with pytest.raises(ValueError):
        C.POSITION[0] = 5                    # read-only
    with pytest.raises(KeyError, match="unknown channel"):
        C.channel("roll")
    with pytest.raises(ValueError, match="not a angle unit"):
        C.Channel("phi", "angle", "m", "deg", "φ")


def test_old_names_are_aliases_of_the_registry():
    from cadra.flight import data
    from cadra.io.trajectory import COLUMNS
    from cadra.report.fit import CHANNEL_OUTPUT_UNITS

    assert data.CHANNELS == C.NAMES and data.N_CHANNELS == 6
    assert data.CHANNEL_UNITS == C.UNITS
    assert CHANNEL_OUTPUT_UNITS == {"x": ("m", 1.0), "y": ("m", 1.0), "z": ("m", 1.0),
                                    "theta": ("deg", 180.0 / math.pi),
                                    "psi": ("deg", 180.0 / math.pi),
                                    "phi": ("deg", 180.0 / math.pi)}
    assert COLUMNS[3:13] == ("x_m", "y_m", "z_m", "theta_deg", "psi_deg", "sigma_x_m",
                             "sigma_y_m", "sigma_z_m", "sigma_theta_deg", "sigma_psi_deg")
    from cadra.io.trajectory import ALL_COLUMNS, OPTIONAL_COLUMNS

    assert OPTIONAL_COLUMNS == ("phi_deg", "sigma_phi_deg")
    assert ALL_COLUMNS[3:15] == ("x_m", "y_m", "z_m", "theta_deg", "psi_deg", "phi_deg",
                                 "sigma_x_m", "sigma_y_m", "sigma_z_m", "sigma_theta_deg",
                                 "sigma_psi_deg", "sigma_phi_deg")


def test_trajectory_file_angles_become_radians(tmp_path):
    from cadra.io.trajectory import COLUMNS, load_trajectory, write_trajectory

    row = dict.fromkeys(COLUMNS, np.nan)
    row.update(station=3, t_s=0.01, status="ok", x_m=1.5, y_m=0.002, z_m=-0.001,
               theta_deg=90.0, psi_deg=-45.0, sigma_x_m=1e-4, sigma_y_m=1e-4,
               sigma_z_m=1e-4, sigma_theta_deg=0.1, sigma_psi_deg=0.1, reason="",
               warnings="")
    write_trajectory(tmp_path / "t.csv", pd.DataFrame([row]), {"shot_id": "S"})
    t = load_trajectory(tmp_path / "t.csv").table
    assert t["theta_rad"].iloc[0] == pytest.approx(math.pi / 2, rel=1e-15)
    assert t["psi_rad"].iloc[0] == pytest.approx(-math.pi / 4, rel=1e-15)
    assert t["sigma_theta_rad"].iloc[0] == pytest.approx(math.radians(0.1), rel=1e-15)
    assert t["x_m"].iloc[0] == 1.5


def test_to_si_and_back():
    assert C.to_si(np.array([180.0]), "deg")[0] == math.pi
    assert C.from_si(np.array([math.pi]), "deg")[0] == 180.0
    assert C.to_si(2.0, "mm") == 0.002
    assert C.from_si(0.5, "m") == 0.5


def _imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
    return out


def test_stage_two_does_not_import_upward_or_in_a_circle():
    """No module of the fit, the gap or the calibration imports the synthetic side, stage
    one or the CLIs (lazily or not); the plots do not import the report."""
    for folder in ("fitting", "gap", "calibration"):
        for path in sorted((ROOT / "cadra" / folder).glob("*.py")):
            bad = {m for m in _imports(path)
                   if m.split(".")[:2] in (["cadra", "synthetic"], ["cadra", "measure"],
                                           ["cadra", "cli"])}
            assert not bad, f"{path.name} imports {bad}"
    assert "cadra.report.fit" not in _imports(ROOT / "cadra" / "report" / "fit_plots.py")
