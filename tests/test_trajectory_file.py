"""The trajectory measurement file: round trip, units, refusals."""

import math

import numpy as np
import pandas as pd
import pytest

from cadra.io.trajectory import (
    COLUMNS,
    TrajectoryFileError,
    load_trajectory,
    trajectory_to_csv,
    write_trajectory,
)


def _table():
    rows = []
    for k in (1, 2, 3):
        rows.append({"station": k, "t_s": 0.0064 * (k - 1), "status": "ok",
                     "x_m": 1.524 * (k - 1), "y_m": 1e-3, "z_m": -2e-3, "theta_deg": 10.0 + k,
                     "psi_deg": -1.5, "sigma_x_m": 3e-7, "sigma_y_m": 3e-7, "sigma_z_m": 4e-7,
                     "sigma_theta_deg": 0.0015, "sigma_psi_deg": 0.0015,
                     "x_top_minus_side_m": 1e-7, "x_consistency": 0.3, "reason": "",
                     "warnings": ""})
    rows[1].update(status="failed", reason="top view: missing image file", x_m=math.nan)
    return pd.DataFrame(rows)


def test_round_trip_converts_angles_once(tmp_path):
    p = write_trajectory(tmp_path / "t.csv", _table(), {"shot_id": "X-1"})
    tr = load_trajectory(p)
    assert tr.meta["shot_id"] == "X-1"
    t = tr.table
    assert list(t.columns[: len(COLUMNS)]) == list(COLUMNS)
    assert t.loc[0, "theta_rad"] == pytest.approx(math.radians(11.0), rel=1e-12)
    assert t.loc[2, "sigma_psi_rad"] == pytest.approx(math.radians(0.0015), rel=1e-9)
    assert t.loc[1, "status"] == "failed" and "missing image" in t.loc[1, "reason"]
    assert np.isnan(t.loc[1, "x_m"]) and len(tr.measured) == 2
    with pytest.raises(FileExistsError):
        write_trajectory(p, _table(), {})


def test_refusals(tmp_path):
    text = trajectory_to_csv(_table(), {})
    bad = tmp_path / "bad.csv"
    bad.write_text(text.replace("# format: cadra-trajectory-1", "# format: other"))
    with pytest.raises(TrajectoryFileError, match="not a CADRA trajectory"):
        load_trajectory(bad)
    bad.write_text(text.replace(",ok,", ",maybe,", 1))
    with pytest.raises(TrajectoryFileError, match="status"):
        load_trajectory(bad)
    bad.write_text(text.replace("sigma_z_m", "sigma_z"))
    with pytest.raises(TrajectoryFileError, match="sigma_z_m"):
        load_trajectory(bad)


def test_a_measured_value_without_its_sigma_is_refused(tmp_path):
    """A measured value whose sigma cell is blank or NaN is not dropped silently: the file is
    refused, naming the station and the column (both empty is 'not measured')."""
    table = _table()
    for blank in (np.nan, ""):
        t = table.copy()
        t["sigma_y_m"] = t["sigma_y_m"].astype(object)
        t.loc[0, "sigma_y_m"] = blank
        path = tmp_path / "t.csv"
        path.write_text(trajectory_to_csv(t, {}))
        with pytest.raises(TrajectoryFileError,
                           match="station 1, column sigma_y_m: is empty: a measured y_m"):
            load_trajectory(path)
    t = table.copy()
    t.loc[0, ["y_m", "sigma_y_m"]] = np.nan        # both empty: not measured, accepted
    path.write_text(trajectory_to_csv(t, {}))
    assert np.isnan(load_trajectory(path).table.loc[0, "y_m"])


def test_a_line_break_in_a_path_does_not_break_the_header(tmp_path):
    """A shot file's path holding a newline, a carriage return or a Unicode line separator
    (legal on POSIX) reads back exactly, and the rows are intact; plain values are written
    as they were."""
    odd = {"shot_file": "/data/run 7\nshot.toml", "facility_file": "a\rb\u2028c.toml",
           "note": ' "quoted" ', "plain": "/data/shot.toml"}
    path = tmp_path / "t.csv"
    write_trajectory(path, _table(), odd)
    back = load_trajectory(path)
    assert {k: back.meta[k] for k in odd} == odd
    assert len(back.table) == 3
    assert "# plain: /data/shot.toml\n" in path.read_text()
