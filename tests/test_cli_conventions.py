"""The command lines keep the conventions of good Unix tools (docs/cli.md):
``--version``, a plain-text description and shown defaults on every subcommand, ``-q``/``-v``
everywhere, negative number lists, one status line, labelled fit phases, one ``value ±
sigma`` format, hints and plain warnings instead of ``nan ± nan``. Run in-process with
``main([...])`` on the real outputs."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import cadra
from cadra.cli.cadra1 import main as cadra1_main
from cadra.cli.cadra2 import main as cadra2_main
from cadra.io.trajectory import COLUMNS, write_trajectory
from cadra.numfmt import pm
from cadra.report.stage1 import station_lines
from cadra.studies.single import SINGLE_FIT_CHI2_WARN, check_single_fits
from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

SPECS = Path("sample_shots/specs")
SUBCOMMANDS = ("fit", "single", "holdone", "plan", "diagnose", "calibrate", "simulate",
               "models")


def option_blocks(text: str) -> dict[str, str]:
    """A help text's options: the first option string of each entry -> its whole entry (the
    option lines and the help under them, joined)."""
    blocks, key = {}, None
    for line in text.splitlines():
        m = re.match(r"^  (-[-\w]+)", line)
        if m:
            key = m.group(1)
            blocks[key] = line.strip()
        elif key is not None and line.startswith("    ") and line.strip():
            blocks[key] += " " + line.strip()
        elif not line.strip() or not line.startswith(" "):
            key = None
    return blocks


def description(text: str) -> str:
    """A subcommand's help description: the paragraph after the usage lines."""
    parts = [p for p in re.split(r"\n\s*\n", text) if p.strip()]
    return " ".join(parts[1].split())


def _help(capsys, run, argv) -> str:
    with pytest.raises(SystemExit) as exc:
        run(argv)
    assert exc.value.code == 0
    return capsys.readouterr().out


@pytest.fixture(scope="module")
def fine_shot(tmp_path_factory):
    """M2-2429 measured to stage one's micrometre precision (the fit then runs two phases)."""
    base = tmp_path_factory.mktemp("conventions")
    sim = simulate_shot(load_shot_spec(SPECS / "m2_2429.toml"))
    d = write_shot(sim, base / "m2_2429", images=False, progress=False)
    rng = np.random.default_rng(17)
    t, n, sp, sa = sim.truth, len(sim.truth), 2.5e-6, 0.002
    table = pd.DataFrame({
        "station": t["station"].to_numpy(), "t_s": t["t_s"].to_numpy(), "status": "ok",
        **{f"{c}_m": t[f"{c}_m"] + rng.normal(0, sp, n) for c in "xyz"},
        **{f"{c}_deg": t[f"{c}_deg"] + rng.normal(0, sa, n) for c in ("theta", "psi")},
        **{f"sigma_{c}_m": sp for c in "xyz"},
        **{f"sigma_{c}_deg": sa for c in ("theta", "psi")},
        "x_top_minus_side_m": 0.0, "x_consistency": 0.0, "reason": "", "warnings": ""})
    traj = base / "trajectory.csv"
    write_trajectory(traj, table.loc[:, list(COLUMNS)],
                     {"shot_id": sim.spec.shot_id, "shot_file": str((d / "shot.toml").resolve())})
    return base, traj


# --------------------------------------------------------------------------- version, help


@pytest.mark.parametrize("run, prog", [(cadra1_main, "cadra1"), (cadra2_main, "cadra2")])
def test_version(capsys, run, prog):
    assert _help(capsys, run, ["--version"]).strip() == f"{prog} {cadra.__version__}"


def test_top_level_help_is_plain_text(capsys):
    text = _help(capsys, cadra2_main, ["--help"])
    assert "``" not in text and "Stage two" in text and "Exit status" in text
    for name in SUBCOMMANDS:
        assert re.search(rf"^\s+{name}\s+\S", text, re.M), name   # each with its summary
    text1 = _help(capsys, cadra1_main, ["--help"])
    assert "``" not in text1 and "Exit status" in text1


@pytest.mark.parametrize("name", SUBCOMMANDS + ("motion", "roll"))
def test_every_subcommand_has_a_description_and_shows_defaults(capsys, name):
    text = _help(capsys, cadra2_main, [name, "--help"])
    desc = description(text)
    assert len(desc) > 40 and "``" not in desc and ":func:" not in desc
    blocks = option_blocks(text)
    assert "-o" in blocks or name == "models"
    for opt, block in blocks.items():
        if opt in ("-h", "-q", "-v"):       # help; -q/-v: set on the top-level parser
            continue
        assert len(block.split()) > 2, f"{name} {opt}: no help"
        assert "(default" in block or "(required)" in block, \
            f"{name} {opt}: default not shown: {block}"
    if name in ("fit", "single", "holdone", "plan", "diagnose", "calibrate"):
        flat = " ".join(text.split())
        assert "--max-iterations MAX_ITERATIONS most Levenberg-Marquardt" in flat
        assert "(default: 60)" in flat and "(required)" in flat


def test_cadra1_options_show_defaults(capsys):
    flat = " ".join(_help(capsys, cadra1_main, ["--help"]).split())
    assert "--no-overlays skip the overlay PNGs (default: off)" in flat
    assert "(default: all cores" in flat and "-q, --quiet" in flat and "-v, --verbose" in flat


# --------------------------------------------------------------------------- models


def test_models_lists_the_bundled_models(capsys):
    assert cadra2_main(["models"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("m2_m070 "))
    assert row.split()[1:5] == ["M2", "M0.70", "alpha_beta", "15"]
    assert "Seed 004 Table 4, M2 lifting capsule" in row
    assert all(m in out for m in ("sphere", "linear_template_sigma", "m1_m110"))
    assert cadra2_main(["models", "-q"]) == 0
    assert capsys.readouterr().out.count("\n") == 1       # the result line only
    assert cadra2_main(["models", "-v"]) == 0
    assert "free: CD_0" in capsys.readouterr().out


# --------------------------------------------------------------------------- -q and -v


_MINIMAL = {"fit": ["t.csv", "--model", "m", "-o", "o"], "single": ["t.csv", "-o", "o"],
            "holdone": ["t.csv", "--model", "m", "--param", "p", "--values", "1", "-o", "o"],
            "diagnose": ["t.csv", "--model", "m", "-o", "o"], "calibrate": ["t.csv", "-o", "o"],
            "plan": ["t.csv", "--model", "m", "-o", "o"],
            "simulate": ["spec.toml", "-o", "o"], "models": []}


@pytest.mark.parametrize("name", SUBCOMMANDS)
def test_quiet_and_verbose_accepted_everywhere(name, tmp_path, monkeypatch, capsys):
    """-q and -v before or after the subcommand: never a usage error (status 2); the inputs
    here do not exist, so each command refuses them (1), or lists the models (0)."""
    monkeypatch.chdir(tmp_path)
    expected = 0 if name == "models" else 1
    for flag in ("-q", "--quiet", "-v", "--verbose"):
        assert cadra2_main([name, *_MINIMAL[name], flag]) == expected, (name, flag)
        assert cadra2_main([flag, name, *_MINIMAL[name]]) == expected, (flag, name)
    assert cadra2_main([name, *_MINIMAL[name]]) == expected
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:          # the two together are a usage error
        cadra2_main([name, *_MINIMAL[name], "-q", "-v"])
    assert exc.value.code == 2


def test_quiet_before_the_subcommand_is_not_reset(capsys):
    """``cadra2 -q models``: the top-level -q holds (the subcommand's parser does not reset
    it), as ``cadra2 models -q`` does; -v likewise."""
    for argv in (["-q", "models"], ["models", "-q"]):
        assert cadra2_main(argv) == 0
        assert capsys.readouterr().out.count("\n") == 1
    for argv in (["-v", "models"], ["models", "-v"]):
        assert cadra2_main(argv) == 0
        assert "free: CD_0" in capsys.readouterr().out


def test_cadra1_quiet_and_verbose(capsys):
    shot = "sample_shots/m2_2429/shot.toml"
    for flag in ("-q", "-v"):
        assert cadra1_main(["--check", shot, flag]) == 1     # images are not committed
    with pytest.raises(SystemExit) as exc:
        cadra1_main(["--check", shot, "-q", "-v"])
    assert exc.value.code == 2


# --------------------------------------------------------------------------- negative lists


def test_holdone_takes_negative_values(tmp_path, capsys):
    """``--values -1.0,-1.5`` is a value list, not an option: the command line parses (the
    missing trajectory is then refused, status 1, not a usage error, status 2); a lone
    option after --values is still a usage error."""
    base = ["holdone", str(tmp_path / "t.csv"), "--model", "m2_m070", "--param", "Cm_A1",
            "-o", str(tmp_path / "out")]
    assert cadra2_main([*base, "--values", "-1.0,-1.5"]) == 1
    assert "no trajectory file" in capsys.readouterr().err
    assert cadra2_main([*base, "--values", "1,2"]) == 1
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cadra2_main([*base, "--values", "-q"])
    assert exc.value.code == 2


# --------------------------------------------------------------------------- value ± sigma


def test_one_format_for_value_and_sigma():
    assert pm(-1.5532, 0.183) == "-1.55 ± 0.18"
    assert pm(0.81234, 0.0123, "deg") == "0.812 ± 0.012 deg"
    assert pm(1.25, float("nan")) == "1.25 (σ not determined)"
    assert pm(float("nan"), float("nan")) == "not determined"
    assert "nan" not in pm(float("nan"), 0.1)


# --------------------------------------------------------------------------- the fit


def test_fit_one_status_line_and_two_labelled_phases(fine_shot, capsys):
    base, traj = fine_shot
    out = base / "fit"
    assert cadra2_main(["fit", str(traj), "--model", "m2_m070", "-o", str(out),
                        "--no-plots"]) == 0
    cap = capsys.readouterr()
    lines = cap.out.splitlines()
    status = [line for line in lines if line.startswith(("converged", "max_iterations",
                                                         "stalled", "failed"))]
    assert len(status) == 1 and status[0].startswith("converged: ")
    assert "converged: converged" not in cap.out
    assert "chi^2/nu = " in status[0] and "film-level sigmas" in status[0]
    # one progress bar per phase, each labelled
    assert "fit (film-level sigmas)" in cap.err and "fit (stage-one sigmas)" in cap.err
    assert "cadra2 fit:" not in cap.err
    # the console and the report say why chi^2 jumps
    assert any(line.startswith("two phases: fit (film-level sigmas)") for line in lines)
    assert "because the weights change" in cap.out
    report = (out / "report.md").read_text()
    assert "two phases" in report and "jumps between the phases" in report
    # every value ± sigma in the one format
    row = next(line for line in lines if line.startswith("Cm_A1 "))
    assert re.match(r"Cm_A1\s+-?\d+\.\d+ ± \d+\.\d+(\s|$)", row.strip())

    # -q: no progress bars, the status line only
    assert cadra2_main(["fit", str(traj), "--model", "m2_m070", "-o", str(base / "fit_q"),
                        "--no-plots", "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.out.count("\n") == 1 and cap.out.startswith("converged: ")
    assert cap.err == ""
    # -v: more detail (chi^2 history, per-shot residual rms)
    assert cadra2_main(["fit", str(traj), "--model", "m2_m070", "-o", str(base / "fit_v"),
                        "--no-plots", "-v"]) == 0
    out_v = capsys.readouterr().out
    assert "chi^2 history:" in out_v and "residual rms" in out_v
    assert len(out_v.splitlines()) > len(lines)


def test_fit_warnings_go_to_stderr_and_survive_quiet(fine_shot, capsys):
    """chi^2/nu far above 1 is said on stderr, with or without -q (it was stdout, and -q hid
    it). The data: the fine shot with its sigmas halved (chi^2/nu ~ 4, p(chi^2) far below
    1e-6): a poor minimum, with its worst channel and station and exit status 1; stdout
    holds no "converged" line."""
    from cadra.io.trajectory import load_trajectory

    base, traj = fine_shot
    loaded = load_trajectory(traj)
    table = loaded.table.loc[:, list(COLUMNS)].copy()
    for c in table.columns:
        if c.startswith("sigma_"):
            table[c] = table[c] / 2
    tight = base / "tight" / "trajectory.csv"
    tight.parent.mkdir()
    write_trajectory(tight, table, loaded.meta)
    for quiet in (True, False):
        out = base / f"tight_fit_{quiet}"
        assert cadra2_main(["fit", str(tight), "--model", "m2_m070", "-o", str(out),
                            "--no-plots", *(["-q"] if quiet else [])]) == 1
        cap = capsys.readouterr()
        poor = [line for line in cap.err.splitlines()
                if line.startswith("cadra2 fit: CONVERGED TO A POOR MINIMUM")]
        assert poor and "p(chi^2) = " in poor[0] and "carries" in poor[0], cap.err
        assert "station" in poor[0] and "warning" not in cap.out
        assert not cap.out.startswith("converged: ")
        assert (cap.out == "") == quiet


# --------------------------------------------------------------------------- single


def test_single_on_one_shot_says_why_not_nan(fine_shot, capsys):
    base, traj = fine_shot
    out = base / "single"
    cadra2_main(["single", str(traj), "-o", str(out)])
    cap = capsys.readouterr()
    assert "nan ± nan" not in cap.out and "nan +- nan" not in cap.out
    assert "quasi-linear trends not computed" in cap.out
    # the warning itself: stderr, one line, prefixed with the command
    assert "cadra2 single: warning: quasi-linear trends not computed" in cap.err
    assert "at least two" in cap.err and "warning" not in cap.out.replace("warning(s)", "")
    report = (out / "report.md").read_text()
    assert "nan ± nan" not in report and "quasi-linear trends not computed" in report
    status = [line for line in cap.out.splitlines() if line.startswith("single: ")]
    assert len(status) == 1 and "not computed" in status[0]


def test_single_warnings_survive_quiet(fine_shot, capsys):
    """-q hides progress and chatter, never a warning on the result: the one-shot quasi-linear
    warning was not printed at all under -q (it sat inside the not-quiet block, on stdout)."""
    base, traj = fine_shot
    cadra2_main(["single", str(traj), "-o", str(base / "single_q"), "-q"])
    cap = capsys.readouterr()
    warned = [line for line in cap.err.splitlines() if ": warning: " in line]
    assert len(warned) == 2   # one shot; the linear model does not fit it (chi^2/nu >> 1)
    assert warned[0].startswith("cadra2 single: warning: quasi-linear trends not computed")
    assert "at least two" in warned[0]
    assert re.match(r"cadra2 single: warning: M2-2429: chi\^2/nu = \S+, far above 1", warned[1])
    assert [line for line in cap.out.splitlines() if line.startswith("single: ")] == \
        cap.out.splitlines()   # stdout: the status line only


def test_single_fit_warnings_flag_meaningless_sigmas():
    table = pd.DataFrame({"shot_id": ["A", "B", "C"], "converged": [True, True, False],
                          "status": ["converged", "converged", "max_iterations"],
                          "message": ["", "", "not converged after 60 iterations"],
                          "reduced_chi2": [1.1, 5e3, 2.0]})
    checks = check_single_fits(table)
    w = checks.messages
    assert checks.trends and not checks.trends_note               # two converged shots
    assert any(x.startswith("B: chi^2/nu = 5e+03, far above 1") and "not meaningful" in x
               for x in w)
    assert any(x.startswith("C: fit max_iterations") for x in w)
    assert not any(x.startswith("A:") for x in w)
    assert SINGLE_FIT_CHI2_WARN > 1
    one = check_single_fits(table.iloc[:1])
    assert not one.trends and one.trends_note.startswith("quasi-linear trends not computed")
    assert one.messages[0] == one.trends_note


# --------------------------------------------------------------------------- cadra1 --check


def test_check_hints_how_images_are_rendered(capsys):
    shot = "sample_shots/m2_2429/shot.toml"
    assert cadra1_main(["--check", shot]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) <= 6                                   # summarised, not 32 lines
    assert any("python tools/make_sample_shots.py --images m2_2429" in line
               and "cadra2 simulate SPEC -o DIR" in line for line in err)
    assert cadra1_main(["--check", shot, "-v"]) == 1
    err = capsys.readouterr().err
    assert err.count("no image listed") == 32 and "make_sample_shots.py" in err


def test_cadra1_verbose_stations_use_the_one_format():
    """``cadra1 -v`` prints each measured station as value ± sigma (mm, deg) with :func:`pm`
    (:func:`cadra.report.stage1.station_lines`); a failed station is left to its FAILED
    line."""
    t = pd.DataFrame({"station": [1, 2], "status": ["ok", "failed"],
                      "x_m": [1.2345671, np.nan], "y_m": [0.0012, np.nan],
                      "z_m": [-0.0031, np.nan], "theta_deg": [2.51234, np.nan],
                      "psi_deg": [-0.41, np.nan], "sigma_x_m": [3.1e-7, np.nan],
                      "sigma_y_m": [2.5e-7, np.nan], "sigma_z_m": [2.5e-7, np.nan],
                      "sigma_theta_deg": [0.0012, np.nan], "sigma_psi_deg": [0.0012, np.nan]})
    out = station_lines(t)
    assert out == ["  station  1: x 1234.56710 ± 0.00031 mm, y 1.20000 ± 0.00025 mm, "
                   "z -3.10000 ± 0.00025 mm, theta 2.5123 ± 0.0012 deg, "
                   "psi -0.4100 ± 0.0012 deg"]


def test_closed_stdout_is_quiet():
    """``cadra2 models | head -0``: the reader went away; exit 141 (128 + SIGPIPE) with no
    traceback, as a good filter does."""
    import subprocess
    import sys

    p = subprocess.Popen([sys.executable, "-m", "cadra.cli.cadra2", "models"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    p.stderr.close()
    assert p.wait() == 141
    assert "Traceback" not in err and "BrokenPipe" not in err


def test_calibrate_warnings_survive_quiet(tmp_path, capsys):
    """A calibration warning (one sphere shot: timing biases not estimated) was printed on
    stdout and hidden by -q; now stderr, with -q, and stdout keeps the one status line."""
    from cadra.validation.truth_files import sphere_trajectory as _trajectory

    traj = _trajectory(tmp_path / "stage1")
    assert cadra2_main(["calibrate", str(traj), "--stations-root", str(tmp_path), "-o",
                        str(tmp_path / "out"), "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.err.startswith("cadra2 calibrate: warning: timing biases not estimated: the "
                              "shots' speeds differ by 0 %")
    assert cap.out.splitlines() == [
        f"recorded in {tmp_path / 'stations' / 'hffaf' / 'bias_history.jsonl'} as entry 1 "
        "(compared with the 0 before it)"]


@pytest.mark.parametrize("encoding", ["ascii", "latin-1"])
def test_a_terminal_that_cannot_show_a_character_gets_plain_text(encoding):
    """``±``, ``α`` and ``—`` on a terminal that cannot encode them (PYTHONIOENCODING, an
    ISO-8859-1 locale): plain-text stand-ins, never a traceback."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, PYTHONIOENCODING=encoding)
    run = subprocess.run([sys.executable, "-m", "cadra.cli.cadra2", "models"], env=env,
                         capture_output=True, timeout=120)
    assert run.returncode == 0, run.stderr.decode(encoding, "replace")
    assert b"Traceback" not in run.stderr
    out = run.stdout.decode(encoding)
    assert "sphere" in out and "--" in out and "—" not in out


@pytest.mark.parametrize("argv, option", [
    (["fit", "t", "-o", "o", "--model", "m", "--max-iterations", "-5"], "--max-iterations"),
    (["fit", "t", "-o", "o", "--model", "m", "--sigma-time-s", "-1"], "--sigma-time-s"),
    (["fit", "t", "-o", "o", "--model", "m", "--min-sigma-angle-deg", "nan"],
     "--min-sigma-angle-deg"),
    (["fit", "t", "-o", "o", "--model", "m", "--min-sigma-position-m", "1e300"],
     "--min-sigma-position-m"),
    (["diagnose", "t", "-o", "o", "--model", "m", "--alpha", "2"], "--alpha"),
    (["calibrate", "t", "-o", "o", "--threshold-sigma", "0"], "--threshold-sigma"),
    (["motion", "t", "-o", "o", "--window", "1"], "--window"),
    (["motion", "t", "-o", "o", "--spin", "inf"], "--spin"),
    (["roll", "t", "-o", "o", "--alpha-deg", "120"], "--alpha-deg"),
])
def test_a_numeric_option_out_of_range_is_a_usage_error(argv, option, capsys):
    """Negative, non-finite or absurd numbers are refused at once (status 2), naming the
    option and what it must be, before anything is read."""
    with pytest.raises(SystemExit) as exc:
        cadra2_main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}: must be" in err, err


def test_cadra1_workers_must_be_positive(capsys):
    with pytest.raises(SystemExit) as exc:
        cadra1_main(["shot.toml", "--workers", "0"])
    assert exc.value.code == 2 and "argument --workers: must be a whole number >= 1" in \
        capsys.readouterr().err
