"""The station history is never destroyed: no output, from the command line or Python,
replaces it or its folders, wherever its root comes from; a history that cannot be read is
refused in one line; its warnings reach the fit that applies it."""

from __future__ import annotations

import pytest

from cadra.atomic import UnsafeOutputError, atomic_output_dir, check_output_dir
from cadra.cli.cadra2 import main as cadra2


def _refused(argv, capsys) -> str:
    """Run ``cadra2 argv``: refused with status 1 and one line naming the output."""
    assert cadra2(argv) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "output" in err, err
    return err


def test_an_output_never_replaces_the_station_history(work, capsys, monkeypatch, tmp_path):
    """Calibrate once (entry 1 recorded), then aim outputs at the history's folder and its
    parents, with the root given, from the environment and not yet created: every one is
    refused before anything is written, and the history is byte for byte what it was."""
    from cadra.calibration.history import history_path

    root = tmp_path / "root"
    sphere = str(work / "sphere_stage1")
    assert cadra2(["calibrate", sphere, "-o", str(tmp_path / "cal1"), "--stations-root",
                   str(root), "-q"]) == 0
    hist = history_path(root, "hffaf")
    kept = hist.read_bytes()
    assert kept.count(b"\n") == 1
    capsys.readouterr()
    for out in (hist.parent, root / "stations"):
        for extra in (["--stations-root", str(root)], []):
            monkeypatch.setenv("CADRA_STATIONS_ROOT", str(root))
            _refused(["calibrate", sphere, "-o", str(out), *extra, "--overwrite"], capsys)
            assert hist.read_bytes() == kept
        _refused(["fit", str(work / "m2_stage1"), "--model", "m2_m070", "--bias-table",
                  "current", "-o", str(out), "--overwrite"], capsys)
        assert hist.read_bytes() == kept
    # a first calibration aimed at the folder its history is about to be created in
    fresh = tmp_path / "fresh"
    assert "holds the input" in _refused(["calibrate", sphere, "-o",
                                          str(fresh / "stations" / "hffaf"),
                                          "--stations-root", str(fresh)], capsys)
    assert not (fresh / "stations").exists()


def test_no_library_call_replaces_a_station_history(tmp_path):
    """The guard is in the writer itself: a folder holding a station history at any depth
    is never an output, with or without overwrite, whatever inputs were named."""
    from cadra.atomic import NEVER_REPLACED
    from cadra.calibration.history import HISTORY_FILENAME

    assert HISTORY_FILENAME in NEVER_REPLACED
    deep = tmp_path / "mine" / "stations" / "hffaf"
    deep.mkdir(parents=True)
    (deep / HISTORY_FILENAME).write_text("{}\n")
    for folder in (tmp_path / "mine", deep):
        with pytest.raises(UnsafeOutputError, match="station history"):
            check_output_dir(folder)
        with pytest.raises(UnsafeOutputError, match="station history"):
            with atomic_output_dir(folder, overwrite=True) as tmp:
                (tmp / "report.md").write_text("x")
    assert (deep / HISTORY_FILENAME).read_text() == "{}\n"


def test_a_station_history_that_is_a_folder_is_refused_in_one_line(work, tmp_path, capsys):
    root = tmp_path / "root"
    (root / "stations" / "hffaf" / "bias_history.jsonl").mkdir(parents=True)
    for argv in (["calibrate", str(work / "sphere_stage1")],
                 ["fit", str(work / "m2_stage1"), "--model", "m2_m070", "--bias-table",
                  "current"]):
        code = cadra2([*argv, "-o", str(tmp_path / "out"), "--stations-root", str(root)])
        err = capsys.readouterr().err.strip()
        assert code == 1 and len(err.splitlines()) == 1, err
        assert "cannot be read" in err and "it must be a file" in err
        assert not (tmp_path / "out").exists()


def test_fit_with_the_current_bias_table_passes_on_the_history_s_warnings(work, tmp_path,
                                                                         capsys):
    """A torn last line (an interrupted append) is skipped by the history's reader with a
    warning: the fit applying the latest complete entry says so on the console and in its
    report, instead of calling it the latest."""
    from cadra.calibration.history import history_path

    root = tmp_path / "root"
    assert cadra2(["calibrate", str(work / "sphere_stage1"), "-o", str(tmp_path / "cal"),
                   "--stations-root", str(root), "-q"]) == 0
    with open(history_path(root, "hffaf"), "ab") as fh:
        fh.write(b'{"format": "cadra-bias-table-1", "facil')         # torn mid-append
    capsys.readouterr()
    out = tmp_path / "fit"
    cadra2(["fit", str(work / "m2_stage1"), "--model", "m2_m070", "--bias-table", "current",
            "--stations-root", str(root), "--max-iterations", "3", "-o", str(out), "-q"])
    err = capsys.readouterr().err
    assert "the history warns" in err and "interrupted write" in err, err
    assert "latest complete entry (1" in (out / "report.md").read_text()


