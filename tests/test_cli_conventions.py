"""The command lines keep the conventions of good Unix tools (issue 17 item 5, docs/cli.md):
``--version``, a plain-text description and shown defaults on every subcommand, ``-q``/``-v``
everywhere, negative number lists, one status line, labelled fit phases, one ``value ±
sigma`` format, hints and plain warnings instead of ``nan ± nan``. Run in-process with
``main([...])`` on the real outputs."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import cadra
from cadra.cli import cadra1, cadra2
from cadra.cli._format import join_number_lists
from cadra.fitting.studies import SINGLE_FIT_CHI2_WARN, single_fit_warnings
from cadra.io.trajectory import COLUMNS, write_trajectory
from cadra.numfmt import pm
from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

SPECS = Path("sample_shots/specs")
SUBCOMMANDS = ("fit", "single", "holdone", "diagnose", "calibrate", "simulate", "models")


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


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


@pytest.mark.parametrize("run, prog", [(cadra1.main, "cadra1"), (cadra2.main, "cadra2")])
def test_version(capsys, run, prog):
    assert _help(capsys, run, ["--version"]).strip() == f"{prog} {cadra.__version__}"


def test_top_level_help_is_plain_text(capsys):
    text = _help(capsys, cadra2.main, ["--help"])
    assert "``" not in text and "Stage two" in text and "Exit status" in text
    for name in SUBCOMMANDS:
        assert re.search(rf"^\s+{name}\s+\S", text, re.M), name   # each with its summary
    text1 = _help(capsys, cadra1.main, ["--help"])
    assert "``" not in text1 and "Exit status" in text1


@pytest.mark.parametrize("name", SUBCOMMANDS)
def test_every_subcommand_has_a_description_and_shows_defaults(capsys, name):
    sub = _subparsers(cadra2.build_parser())[name]
    assert sub.description and "``" not in sub.description and ":func:" not in sub.description
    text = _help(capsys, cadra2.main, [name, "--help"])
    assert sub.description.split()[0] in text
    for action in sub._actions:
        if not action.option_strings or isinstance(action, argparse._HelpAction):
            continue
        assert action.help, f"{name} {action.option_strings}: no help"
        rendered = sub.formatter_class(name)._get_help_string(action)
        shown = ("(default" in rendered or "(required)" in rendered
                 or action.default is argparse.SUPPRESS)           # -q/-v: set on the top
        assert shown, f"{name} {action.option_strings}: default not shown"
    if name in ("fit", "single", "holdone", "diagnose", "calibrate"):
        flat = " ".join(text.split())
        assert "--max-iterations MAX_ITERATIONS most Levenberg-Marquardt" in flat
        assert "(default: 60)" in flat and "(required)" in flat


def test_cadra1_options_show_defaults(capsys):
    flat = " ".join(_help(capsys, cadra1.main, ["--help"]).split())
    assert "--no-overlays skip the overlay PNGs (default: off)" in flat
    assert "(default: all cores" in flat and "-q, --quiet" in flat and "-v, --verbose" in flat


# --------------------------------------------------------------------------- models


def test_models_lists_the_bundled_models(capsys):
    assert cadra2.main(["models"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("m2_m070 "))
    assert row.split()[1:5] == ["M2", "M0.70", "alpha_beta", "15"]
    assert "Seed 004 Table 4, M2 lifting capsule" in row
    assert all(m in out for m in ("sphere", "linear_template_sigma", "m1_m110"))
    assert cadra2.main(["models", "-q"]) == 0
    assert capsys.readouterr().out.count("\n") == 1       # the result line only
    assert cadra2.main(["models", "-v"]) == 0
    assert "free: CD_0" in capsys.readouterr().out


# --------------------------------------------------------------------------- -q and -v


_MINIMAL = {"fit": ["t.csv", "--model", "m", "-o", "o"], "single": ["t.csv", "-o", "o"],
            "holdone": ["t.csv", "--model", "m", "--param", "p", "--values", "1", "-o", "o"],
            "diagnose": ["t.csv", "--model", "m", "-o", "o"], "calibrate": ["t.csv", "-o", "o"],
            "simulate": ["spec.toml", "-o", "o"], "models": []}


@pytest.mark.parametrize("name", SUBCOMMANDS)
def test_quiet_and_verbose_accepted_everywhere(name):
    parser = cadra2.build_parser()
    for flag, quiet, verbose in (("-q", True, False), ("--quiet", True, False),
                                 ("-v", False, True), ("--verbose", False, True)):
        after = parser.parse_args([name, *_MINIMAL[name], flag])
        before = parser.parse_args([flag, name, *_MINIMAL[name]])   # not reset by the sub
        for args in (after, before):
            assert (args.quiet, args.verbose) == (quiet, verbose)
    plain = parser.parse_args([name, *_MINIMAL[name]])
    assert (plain.quiet, plain.verbose) == (False, False)


def test_cadra1_quiet_and_verbose(capsys):
    shot = "sample_shots/m2_2429/shot.toml"
    for flag in ("-q", "-v"):
        assert cadra1.main(["--check", shot, flag]) == 1     # images are not committed
    with pytest.raises(SystemExit) as exc:
        cadra1.main(["--check", shot, "-q", "-v"])
    assert exc.value.code == 2


# --------------------------------------------------------------------------- negative lists


def test_negative_number_lists():
    assert join_number_lists(["holdone", "--values", "-1.0,-1.5", "-q"], ("--values",)) == [
        "holdone", "--values=-1.0,-1.5", "-q"]
    # an option or a positive list is left alone
    assert join_number_lists(["--values", "-q"], ("--values",)) == ["--values", "-q"]
    assert join_number_lists(["--values", "1,2"], ("--values",)) == ["--values", "1,2"]


def test_holdone_takes_negative_values(monkeypatch, tmp_path):
    seen = {}
    monkeypatch.setattr(cadra2, "_holdone", lambda args: seen.setdefault("values",
                                                                         args.values) and 0)
    rc = cadra2.main(["holdone", str(tmp_path / "t.csv"), "--model", "m2_m070", "--param",
                      "Cm_A1", "--values", "-1.0,-1.5", "-o", str(tmp_path / "out")])
    assert rc == 0
    assert [float(v) for v in seen["values"].split(",")] == [-1.0, -1.5]


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
    assert cadra2.main(["fit", str(traj), "--model", "m2_m070", "-o", str(out),
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
    assert re.fullmatch(r"Cm_A1\s+-?\d+\.\d+ ± \d+\.\d+", row.strip())

    # -q: no progress bars, the status line only
    assert cadra2.main(["fit", str(traj), "--model", "m2_m070", "-o", str(base / "fit_q"),
                        "--no-plots", "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.out.count("\n") == 1 and cap.out.startswith("converged: ")
    assert cap.err == ""
    # -v: more detail (chi^2 history, per-shot residual rms)
    assert cadra2.main(["fit", str(traj), "--model", "m2_m070", "-o", str(base / "fit_v"),
                        "--no-plots", "-v"]) == 0
    out_v = capsys.readouterr().out
    assert "chi^2 history:" in out_v and "residual rms" in out_v
    assert len(out_v.splitlines()) > len(lines)


# --------------------------------------------------------------------------- single


def test_single_on_one_shot_says_why_not_nan(fine_shot, capsys):
    base, traj = fine_shot
    out = base / "single"
    cadra2.main(["single", str(traj), "-o", str(out)])
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
    cadra2.main(["single", str(traj), "-o", str(base / "single_q"), "-q"])
    cap = capsys.readouterr()
    warned = [line for line in cap.err.splitlines() if ": warning: " in line]
    assert len(warned) == 2   # one shot; the linear model does not fit it (chi^2/nu >> 1)
    assert warned[0].startswith("cadra2 single: warning: quasi-linear trends not computed")
    assert "at least two" in warned[0]
    assert re.match(r"cadra2 single: warning: M2-2429: chi\^2/nu = \S+, far above 1", warned[1])
    assert [line for line in cap.out.splitlines() if line.startswith("single: ")] == \
        cap.out.splitlines()   # stdout: the status line only


@pytest.mark.parametrize("quiet", [True, False])
def test_fit_warnings_go_to_stderr_and_survive_quiet(capsys, quiet):
    """chi^2/nu far above 1 and the result's own warnings (a parameter at a bound): stderr,
    with or without -q (they were stdout, and -q hid them)."""
    from types import SimpleNamespace

    result = SimpleNamespace(
        status="converged", message="converged: step below tolerance", options={},
        iterations=7, chi2=880.0, dof=10, reduced_chi2=88.0, elapsed_s=0.5, converged=True,
        warnings=("CD_A1 = 2 is at a bound [0, 2]",), aero_names=("CD_A1",),
        aero_values=np.array([2.0]), aero_sigma=np.array([0.01]), history=[88.0], shots=())
    cadra2._print_summary(result, argparse.Namespace(quiet=quiet, verbose=False))
    cap = capsys.readouterr()
    assert cap.err.splitlines() == [
        "cadra2 fit: warning: chi^2/nu = 88 > 2: the sigmas or the model do not describe the "
        "data; use the scaled or coloured sigmas (report.md)",
        "cadra2 fit: warning: CD_A1 = 2 is at a bound [0, 2]"]
    assert "warning" not in cap.out
    assert cap.out.splitlines()[0].startswith("converged: step below tolerance; chi^2/nu")
    assert len(cap.out.splitlines()) == (1 if quiet else 3)


def test_single_fit_warnings_flag_meaningless_sigmas():
    table = pd.DataFrame({"shot_id": ["A", "B", "C"], "converged": [True, True, False],
                          "status": ["converged", "converged", "max_iterations"],
                          "message": ["", "", "not converged after 60 iterations"],
                          "reduced_chi2": [1.1, 5e3, 2.0]})
    w = single_fit_warnings(table)
    assert not any(x.startswith("quasi-linear") for x in w)      # two converged shots
    assert any(x.startswith("B: chi^2/nu = 5e+03, far above 1") and "not meaningful" in x
               for x in w)
    assert any(x.startswith("C: fit max_iterations") for x in w)
    assert not any(x.startswith("A:") for x in w)
    assert SINGLE_FIT_CHI2_WARN > 1
    assert single_fit_warnings(table.iloc[:1])[0].startswith("quasi-linear trends not computed")


# --------------------------------------------------------------------------- cadra1 --check


def test_check_hints_how_images_are_rendered(capsys):
    shot = "sample_shots/m2_2429/shot.toml"
    assert cadra1.main(["--check", shot]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) <= 6                                   # summarised, not 32 lines
    assert any("python tools/make_sample_shots.py --images m2_2429" in line
               and "cadra2 simulate SPEC -o DIR" in line for line in err)
    assert cadra1.main(["--check", shot, "-v"]) == 1
    err = capsys.readouterr().err
    assert err.count("no image listed") == 32 and "make_sample_shots.py" in err


def test_cadra1_verbose_stations_use_the_one_format(capsys):
    """``cadra1 -v`` prints each measured station as value ± sigma (mm, deg) with :func:`pm`;
    a failed station is left to its FAILED line."""
    t = pd.DataFrame({"station": [1, 2], "status": ["ok", "failed"],
                      "x_m": [1.2345671, np.nan], "y_m": [0.0012, np.nan],
                      "z_m": [-0.0031, np.nan], "theta_deg": [2.51234, np.nan],
                      "psi_deg": [-0.41, np.nan], "sigma_x_m": [3.1e-7, np.nan],
                      "sigma_y_m": [2.5e-7, np.nan], "sigma_z_m": [2.5e-7, np.nan],
                      "sigma_theta_deg": [0.0012, np.nan], "sigma_psi_deg": [0.0012, np.nan]})
    cadra1._print_stations(t)
    out = capsys.readouterr().out.splitlines()
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
    from test_bad_inputs_plausible import _trajectory

    traj = _trajectory(tmp_path / "stage1")
    assert cadra2.main(["calibrate", str(traj), "--stations-root", str(tmp_path), "-o",
                        str(tmp_path / "out"), "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.err.startswith("cadra2 calibrate: warning: timing biases not estimated: the "
                              "shots' speeds differ by 0 %")
    assert cap.out.splitlines() == [
        f"recorded in {tmp_path / 'stations' / 'hffaf' / 'bias_history.jsonl'} as entry 1 "
        "(compared with the 0 before it)"]
