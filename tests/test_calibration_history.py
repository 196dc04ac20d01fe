"""Station bias history (cadra/calibration/history.py, docs/calibration.md "Station history").

Truth here is independent of the code under test: the entry hash is recomputed with hashlib
from the documented canonical-JSON rule, interrupted writes are made by writing half of a real
line by hand, and compare()'s false-alarm rates are checked against the normal distribution
(scipy) over seeded random draws of unbiased stations.
"""

from __future__ import annotations

import hashlib
import io
import json
import shutil

import numpy as np
import pytest
from scipy.stats import norm

from cadra.calibration.history import (
    BiasTable,
    StationHistoryError,
    append_entry,
    bias_table_to_frame,
    compare,
    current_table,
    family_false_alarm,
    family_threshold,
    frame_to_bias_table,
    history_dir,
    history_path,
    load_bias_table,
    load_history,
    save_bias_table,
    utc_now,
)

FAC = "hffaf"
N = 16


def make_table(seed=0, created="2026-11-22T21:30:00Z", facility=FAC, bias=None, sigma=None,
               shots=("m2_2425", "m2_2426")):
    rng = np.random.default_rng(seed)
    st = np.arange(1, N + 1)
    if sigma is None:
        sigma = np.tile([2e-4, 1e-4, 1e-4, 5e-8], (N, 1)) * rng.uniform(0.8, 1.2, (N, 4))
        sigma[0, 3] = np.nan           # station 1 timing not estimated (reference clock)
    if bias is None:
        bias = rng.normal(0.0, 1.0, (N, 4)) * np.nan_to_num(sigma)
    bias = np.where(np.isnan(sigma), 0.0, bias)
    return BiasTable(facility=facility, created_utc=created, stations=st, bias=bias,
                     sigma=sigma, shots=tuple(shots), method="test, zero-sum constraint",
                     note="line 1\nline 2 \"quoted\"")


def same(a: BiasTable, b: BiasTable) -> bool:
    return (a.facility == b.facility and a.created_utc == b.created_utc
            and np.array_equal(a.stations, b.stations) and np.array_equal(a.bias, b.bias)
            and np.array_equal(a.sigma, b.sigma, equal_nan=True) and a.shots == b.shots
            and a.method == b.method and a.note == b.note)


def line_of(table: BiasTable, tmp_path) -> bytes:
    """The exact line append_entry writes for ``table`` on a fresh history."""
    root = tmp_path / "scratch"
    shutil.rmtree(root, ignore_errors=True)
    return append_entry(table, root).read_bytes()


# --------------------------------------------------------------------------- round trip


def test_round_trip_and_documented_hash(tmp_path):
    t = make_table()
    path = append_entry(t, tmp_path)
    assert path == tmp_path / "stations" / FAC / "bias_history.jsonl"
    assert history_dir(tmp_path, FAC) == tmp_path / "stations" / FAC
    hist, warns = load_history(tmp_path, FAC)
    assert warns == [] and len(hist) == 1 and same(hist[0], t)
    raw = path.read_bytes()
    assert raw.endswith(b"\n") and raw.count(b"\n") == 1
    obj = json.loads(raw)
    assert obj["format"] == "cadra-station-bias-1" and obj["facility"] == FAC
    assert obj["sigma_time_s"][0] is None and obj["bias_time_s"][0] == 0.0
    assert obj["bias_x_m"] == [float(v) for v in t.bias[:, 0]]
    stored = obj.pop("sha256")
    canon = json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    assert hashlib.sha256(canon.encode()).hexdigest() == stored


def test_no_history_yet(tmp_path):
    assert load_history(tmp_path, FAC) == ([], [])
    assert current_table([]) is None


def test_append_twice_in_order(tmp_path):
    t1, t2 = make_table(1), make_table(2, created="2026-12-01T08:00:00Z")
    append_entry(t1, tmp_path)
    append_entry(t2, tmp_path)
    hist, warns = load_history(tmp_path, FAC)
    assert warns == [] and len(hist) == 2
    assert same(hist[0], t1) and same(hist[1], t2) and same(current_table(hist), t2)


def test_refuses_older_and_duplicate_entries(tmp_path):
    append_entry(make_table(1, created="2026-12-01T08:00:00Z"), tmp_path)
    before = history_path(tmp_path, FAC).read_bytes()
    with pytest.raises(StationHistoryError, match="older than the latest"):
        append_entry(make_table(2, created="2026-11-01T08:00:00Z"), tmp_path)
    with pytest.raises(StationHistoryError, match="already entry 1"):
        append_entry(make_table(1, created="2026-12-01T08:00:00Z"), tmp_path)
    assert history_path(tmp_path, FAC).read_bytes() == before


def test_same_numbers_estimated_twice_now_are_two_entries(tmp_path):
    # the same sphere shots calibrated twice within one second (CI did this): two estimates,
    # two entries in time order, not a duplicate refusal
    a = make_table(1, created=utc_now())
    b = make_table(1, created=utc_now())
    assert a.created_utc != b.created_utc and a.created_utc.endswith("Z")
    append_entry(a, tmp_path)
    append_entry(b, tmp_path)
    hist, _ = load_history(tmp_path, FAC)
    assert [t.created_utc for t in hist] == [a.created_utc, b.created_utc]


# --------------------------------------------------------------------------- damage


def test_interrupted_write_then_append(tmp_path):
    t1 = make_table(1, created="2026-11-01T00:00:00Z")
    t2 = make_table(2, created="2026-11-02T00:00:00Z")
    t3 = make_table(3, created="2026-11-03T00:00:00Z")
    t4 = make_table(4, created="2026-11-04T00:00:00Z")
    path = append_entry(t1, tmp_path)
    line2 = line_of(t2, tmp_path)
    with open(path, "ab") as fh:                       # power cut half way through line 2
        fh.write(line2[: len(line2) // 2])
    damaged = path.read_bytes()
    hist, warns = load_history(tmp_path, FAC)
    assert len(hist) == 1 and same(hist[0], t1)
    assert len(warns) == 1 and "line 2" in warns[0] and "interrupted" in warns[0]

    append_entry(t3, tmp_path)
    raw = path.read_bytes()
    assert raw.startswith(damaged)                     # the fragment is kept, never rewritten
    assert raw[len(damaged):len(damaged) + 1] == b"\n"  # ... and not glued onto
    hist, warns = load_history(tmp_path, FAC)
    assert [h.created_utc for h in hist] == [t1.created_utc, t3.created_utc]
    assert same(hist[1], t3)
    assert len(warns) == 1 and "line 2" in warns[0]

    append_entry(t4, tmp_path)
    hist, _ = load_history(tmp_path, FAC)
    assert len(hist) == 3 and same(hist[2], t4)


def test_complete_entry_without_final_newline(tmp_path):
    t1, t2 = make_table(1), make_table(2, created="2026-12-01T00:00:00Z")
    path = append_entry(t1, tmp_path)
    path.write_bytes(path.read_bytes()[:-1])          # only the newline was lost
    hist, warns = load_history(tmp_path, FAC)
    assert len(hist) == 1 and same(hist[0], t1) and len(warns) == 1
    append_entry(t2, tmp_path)
    hist, warns = load_history(tmp_path, FAC)
    assert len(hist) == 2 and same(hist[1], t2) and warns == []


def _three_entries(tmp_path):
    for k in range(3):
        append_entry(make_table(k, created=f"2026-11-0{k + 1}T00:00:00Z"), tmp_path)
    return history_path(tmp_path, FAC)


def test_corrupted_middle_line_is_an_error(tmp_path):
    path = _three_entries(tmp_path)
    lines = path.read_bytes().split(b"\n")
    lines[1] = lines[1][: len(lines[1]) // 2]        # the second half of line 2 lost
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(StationHistoryError, match=r"line 2\b.*corrupted"):
        load_history(tmp_path, FAC)
    before = path.read_bytes()
    with pytest.raises(StationHistoryError, match=r"line 2\b"):
        append_entry(make_table(9, created="2027-01-01T00:00:00Z"), tmp_path)
    assert path.read_bytes() == before


def test_hash_mismatch_is_an_error(tmp_path):
    path = _three_entries(tmp_path)
    lines = path.read_bytes().split(b"\n")
    obj = json.loads(lines[1])
    obj["bias_y_m"][4] += 1e-3                        # still valid JSON, stale hash
    lines[1] = json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(StationHistoryError, match=r"line 2: sha256 mismatch"):
        load_history(tmp_path, FAC)


def test_unvouched_terminated_fragment_is_an_error(tmp_path):
    path = append_entry(make_table(1), tmp_path)
    with open(path, "ab") as fh:
        fh.write(b'{"bias_time_s":[0.0,1.2\n')           # a fragment someone terminated
    with pytest.raises(StationHistoryError, match=r"line 2"):
        load_history(tmp_path, FAC)


def test_other_facility_is_refused(tmp_path):
    other = append_entry(make_table(1, facility="otherrange"), tmp_path / "b")
    target = history_path(tmp_path, FAC)
    target.parent.mkdir(parents=True)
    shutil.copy(other, target)
    with pytest.raises(StationHistoryError, match=r"'otherrange'.*'hffaf'"):
        load_history(tmp_path, FAC)
    with pytest.raises(StationHistoryError, match=r"'otherrange'.*'hffaf'"):
        append_entry(make_table(2, created="2027-01-01T00:00:00Z"), tmp_path)


def test_table_validation():
    sigma = np.full((N, 4), 1e-4)
    sigma[3, 1] = np.nan
    bias = np.zeros((N, 4))
    bias[3, 1] = 1e-4
    with pytest.raises(StationHistoryError, match="station 4 y: sigma NaN"):
        BiasTable(FAC, "2026-11-22T21:30:00Z", np.arange(1, N + 1), bias, sigma, ())
    with pytest.raises(StationHistoryError, match="UTC"):
        make_table(created="2026-11-22T21:30:00+01:00")
    with pytest.raises(StationHistoryError, match="shape"):
        BiasTable(FAC, "2026-11-22T21:30:00Z", np.arange(3), np.zeros((3, 3)),
                  np.ones((3, 3)), ())


# --------------------------------------------------------------------------- compare


def _pair(rng, sig0, sig1):
    """An earlier and a new estimate of unbiased, unmoved stations (true bias 0)."""
    est = ~np.isnan(sig0)
    b0 = np.where(est, rng.normal(size=sig0.shape) * np.nan_to_num(sig0), 0.0)
    b1 = np.where(est, rng.normal(size=sig1.shape) * np.nan_to_num(sig1), 0.0)
    return b0, b1


def test_compare_flags_a_real_move_only():
    sig = np.full((N, 4), 1e-4)
    b0 = np.zeros((N, 4))
    b1 = b0.copy()
    sd = np.hypot(sig[0, 0], sig[0, 0])
    b1[2, 0] += 5.0 * sd        # station 3 x moved by 5 sigma of the difference
    b1[6, 1] += 0.5 * sd        # station 7 y by 0.5 sigma
    b1[9, 2] = 10 * sig[9, 2]   # station 10 z: a 10-sigma bias (and a 7-sigma move)
    old = make_table(bias=b0, sigma=sig, created="2026-11-01T00:00:00Z")
    new = make_table(bias=b1, sigma=sig, created="2026-12-01T00:00:00Z", shots=("a", "b"))
    df = compare(new, [old])
    row = df.set_index(["station", "channel"])
    assert row.loc[(3, "x"), "z_move"] == pytest.approx(5.0)
    assert row.loc[(3, "x"), "moved"] and row.loc[(3, "x"), "moved_family"]
    assert row.loc[(7, "y"), "z_move"] == pytest.approx(0.5)
    assert not row.loc[(7, "y"), "moved"] and not row.loc[(7, "y"), "moved_family"]
    assert row.loc[(10, "z"), "biased_family"] and row.loc[(10, "z"), "z_bias"] == 10.0
    assert set(df.index[df["moved"]]) == set(df.index[df["moved_family"]])
    assert df["moved"].sum() == 2 and df["biased"].sum() == 2   # 10 z; 3 x is 7.07 sigma
    assert df.attrs["n_move_tests"] == 64 and df.attrs["previous_created_utc"] == old.created_utc
    assert df.attrs["warnings"] == []
    # comparing with a history that already holds the new table uses the entry before it
    again = compare(new, [old, new])
    assert again.attrs["previous_created_utc"] == old.created_utc


def test_compare_without_history_and_shared_shots():
    t = make_table()
    df = compare(t, [])
    assert df["z_move"].isna().all() and not df["moved"].any()
    assert df.attrs["n_move_tests"] == 0 and df.attrs["n_bias_tests"] == 63
    t2 = make_table(5, created="2027-01-01T00:00:00Z")   # same shots as t
    assert "too small" in compare(t2, [t]).attrs["warnings"][0]


def test_family_threshold_is_sidak():
    m, a = 64, 0.05
    z = family_threshold(m, a)
    # independent: chance that none of m |N(0,1)| exceeds z is 1 - a
    assert (1 - 2 * norm.sf(z)) ** m == pytest.approx(1 - a, rel=1e-12)
    assert family_false_alarm(64, 3.0) == pytest.approx(1 - (1 - 2 * norm.sf(3.0)) ** 64)


def test_false_flag_rates_over_unbiased_draws():
    """2000 comparisons of an unchanged, unbiased facility: the fraction raising any
    family-wise flag is family_alpha, the fraction raising any per-test 3-sigma flag is
    1 - (1 - 2 Q(3))**m, both within 3.5 binomial standard deviations."""
    rng = np.random.default_rng(20261122)
    n_draw, alpha = 2000, 0.05
    sig0 = np.tile([2e-4, 1e-4, 1e-4, 5e-8], (N, 1)) * rng.uniform(0.5, 2.0, (N, 4))
    sig1 = np.tile([2e-4, 1e-4, 1e-4, 5e-8], (N, 1)) * rng.uniform(0.5, 2.0, (N, 4))
    sig0[0, 3] = sig1[0, 3] = np.nan                  # 63 tests per comparison
    m = 63
    counts = dict.fromkeys(("moved_family", "moved", "biased_family", "biased"), 0)
    for k in range(n_draw):
        b0, b1 = _pair(rng, sig0, sig1)
        old = make_table(bias=b0, sigma=sig0, created="2026-11-01T00:00:00Z", shots=("a",))
        new = make_table(bias=b1, sigma=sig1, created="2026-12-01T00:00:00Z", shots=("b",))
        df = compare(new, [old], family_alpha=alpha)
        if k == 0:
            assert df.attrs["n_move_tests"] == m and df.attrs["n_bias_tests"] == m
        for key in counts:
            counts[key] += bool(df[key].any())
    p3 = 1 - (1 - 2 * norm.sf(3.0)) ** m
    for key, p in (("moved_family", alpha), ("biased_family", alpha), ("moved", p3),
                   ("biased", p3)):
        tol = 3.5 * np.sqrt(n_draw * p * (1 - p))
        assert abs(counts[key] - n_draw * p) < tol, (key, counts[key], n_draw * p, tol)


# --------------------------------------------------------------------------- CSV table


def test_csv_round_trip_and_refusals(tmp_path):
    t = make_table(7)
    path = save_bias_table(t, tmp_path / "bias.csv")
    text = path.read_text()
    assert text.startswith("# format: cadra-station-bias-table-1\n# facility: hffaf\n"
                           "# created_utc: 2026-11-22T21:30:00Z\n")
    assert same(load_bias_table(path), t)
    with pytest.raises(FileExistsError):
        save_bias_table(t, path)
    save_bias_table(make_table(8), path, overwrite=True)
    assert same(load_bias_table(path), make_table(8))
    df = bias_table_to_frame(t)
    assert list(df.columns[:3]) == ["station", "bias_x_m", "bias_y_m"]
    assert same(frame_to_bias_table(df, FAC, t.created_utc, t.shots, t.method, t.note), t)
    bad = tmp_path / "bad.csv"
    bad.write_text(text.replace("bias_x_m", "bias_x_mm"))
    with pytest.raises(StationHistoryError, match="bias_x_mm"):
        load_bias_table(bad)
    bad.write_text("\n".join(line for line in text.splitlines() if "facility" not in line))
    with pytest.raises(StationHistoryError, match="facility"):
        load_bias_table(bad)


# --------------------------------------------------------------------------- plot


def test_plot_returns_figure():
    from matplotlib.figure import Figure

    from cadra.report.calibration import plot_biases

    old = make_table(1, created="2026-10-01T00:00:00Z")
    mid = make_table(2, created="2026-11-01T00:00:00Z")
    b = mid.bias.copy()
    b[4, 0] += 1e-2                                      # a big move at station 5
    new = make_table(bias=b, sigma=mid.sigma, created="2026-12-01T00:00:00Z")
    fig = plot_biases(new, [old, mid])
    assert isinstance(fig, Figure) and len(fig.axes) == 4
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert "2026-10-01" in labels and "moved (family-wise)" in labels
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    assert buf.getvalue()[:8] == b"\x89PNG\r\n\x1a\n"

