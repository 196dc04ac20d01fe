"""No input ever destroyed, and clean faults.

Every command that writes refuses an output folder that is, or holds, one of its inputs (links
and ``..`` resolved), the working folder, or an input file, with or without ``--overwrite``:
the input tree hashes the same before and after, and the one-line message names both. Ctrl-C
exits 130 with one line and no partial output; a SIGKILLed run's temporary folder is cleaned by
the next run; a SIGKILLed ``cadra1`` leaves no pool worker behind.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cadra.atomic import (
    UnsafeOutputError,
    atomic_output_dir,
    check_output_dir,
    clean_stale_temps,
    stale_temps,
)
from cadra.cli.cadra1 import main as cadra1
from cadra.cli.cadra2 import main as cadra2
from cadra.imaging.shot import measure_shot
from cadra.io.trajectory import load_trajectory
from cadra.report.stage1 import write_stage1

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "sample_shots" / "specs" / "m2_2429.toml"
POSIX = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def tree_hash(root: Path) -> str:
    """sha256 over every path, file content and link target under ``root``."""
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        h.update(str(p.relative_to(root)).encode())
        if p.is_symlink():
            h.update(os.readlink(p).encode())
        elif p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


#: per command: the stage-one folder it accepts and its other options (calibrate never
#: touches the repository's station history, whatever the code does)
def _command(command: str, work: Path) -> tuple[Path, list[str]]:
    if command == "calibrate":
        return work / "sphere_stage1", ["--no-history", "--stations-root", str(work / "hist")]
    extra = {"holdone": ["--param", "Cm_A1", "--values", "1,2"]}.get(command, [])
    model = [] if command == "single" else ["--model", "m2_m070"]
    return work / "m2_stage1", [*model, *extra, "--max-iterations", "20"]


def _refused(run, argv, culprit: str, capsys, work: Path, code: int) -> str:
    before = tree_hash(work)
    assert run(argv) == code
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert culprit in err and "output" in err, err
    assert tree_hash(work) == before
    return err


# -- cadra2: an output that is or holds an input -------------------------------------------

ALL = ["fit", "single", "holdone", "plan", "calibrate", "diagnose"]


@pytest.mark.parametrize("command", ALL)
@pytest.mark.parametrize("overwrite", [True, False])
def test_cadra2_output_is_the_stage_one_folder(work, capsys, command, overwrite):
    stage1, options = _command(command, work)
    argv = [command, str(stage1), *options, "-o", str(stage1),
            *(["--overwrite"] if overwrite else [])]
    err = _refused(cadra2, argv, "is the input", capsys, work, 1)
    assert err.startswith(f"cadra2 {command}: output {stage1}")


@pytest.mark.parametrize("command", ALL)
def test_cadra2_output_holding_the_inputs(work, capsys, command):
    stage1, options = _command(command, work)
    shot = stage1.parent / stage1.name.replace("_stage1", "")
    # the folder holding the stage-one folder and the shot
    _refused(cadra2, [command, str(stage1), *options, "-o", str(work), "--overwrite"],
             "holds the input", capsys, work, 1)
    # the folder of --shot
    _refused(cadra2, [command, str(stage1), *options, "--shot", str(shot / "shot.toml"),
                      "-o", str(shot), "--overwrite"], "shot.toml", capsys, work, 1)


def test_cadra2_output_is_the_images_of_the_shot(work, capsys):
    stage1 = work / "shot_stage1"
    if not stage1.exists():
        write_stage1(measure_shot(work / "shot" / "shot.toml", workers=1, progress=False,
                                  overlays=False), stage1)
    _refused(cadra2, ["fit", str(stage1), "--model", "m2_m070", "-o",
                      str(work / "shot" / "images"), "--overwrite"], "st01_", capsys, work, 1)


def test_cadra2_output_holding_the_station_history(work, capsys, monkeypatch):
    hist = work / "hist_root"
    (hist / "stations" / "hffaf").mkdir(parents=True, exist_ok=True)
    (hist / "stations" / "hffaf" / "bias_history.jsonl").write_text("")
    monkeypatch.setenv("CADRA_STATIONS_ROOT", str(hist))        # calibrate's default root
    _refused(cadra2, ["calibrate", str(work / "sphere_stage1"), "-o", str(hist / "stations"),
                      "--overwrite"], "is the input", capsys, work, 1)
    _refused(cadra2, ["fit", str(work / "m2_stage1"), "--model", "m2_m070", "--bias-table",
                      "current", "--stations-root", str(hist), "-o", str(hist),
                      "--overwrite"], "holds the input", capsys, work, 1)


def test_cadra2_output_names_an_input_file(work, capsys):
    traj = work / "m2_stage1" / "trajectory.csv"
    _refused(cadra2, ["fit", str(traj), "--model", "m2_m070", "-o", str(traj), "--overwrite"],
             f"is the input {traj}", capsys, work, 1)
    assert traj.is_file()
    spec = work / "specs" / "small.toml"
    _refused(cadra2, ["simulate", str(spec), "-o", str(spec), "--overwrite", "--no-images"],
             f"is the input {spec}", capsys, work, 1)
    _refused(cadra2, ["simulate", str(spec), "-o", str(work / "specs"), "--overwrite",
                      "--no-images"], "holds the input", capsys, work, 1)
    assert spec.is_file()


# -- cadra1 ------------------------------------------------------------------------------------

def test_cadra1_output_holding_its_inputs(work, capsys):
    shot = work / "shot" / "shot.toml"
    for out, culprit in [(work / "shot", "holds the input"),
                         (work / "shot" / "images", "holds the input"),
                         (work / "shot" / "images" / "st01_top.png", "is the input")]:
        _refused(cadra1, [str(shot), "-o", str(out), "--overwrite", "-q", "--workers", "1"],
                 culprit, capsys, work, 2)
    truth = work / "shot" / "truth.csv"
    _refused(cadra1, [str(shot), "-o", str(truth), "--truth", str(truth), "--overwrite",
                      "-q"], "is the input", capsys, work, 2)


# -- the same folder by another spelling -------------------------------------------------------

def test_other_spellings_of_an_input_folder(work, capsys, tmp_path, monkeypatch):
    link = tmp_path / "link"
    link.symlink_to(work / "shot", target_is_directory=True)
    shot = work / "shot" / "shot.toml"
    for out in (str(link), f"{work}/stage1/../shot", f"{work}/./shot/"):
        err = _refused(cadra1, [str(shot), "-o", out, "--overwrite", "-q"], "holds the input",
                       capsys, work, 2)
        assert str(Path(out)) in err
    # the current folder, and its parent, by any spelling
    monkeypatch.chdir(work / "shot")
    for out in (".", "./", "../shot"):
        _refused(cadra2, ["fit", str(work / "m2_stage1"), "--model", "m2_m070", "-o", out,
                          "--overwrite"], "output", capsys, work, 1)
        _refused(cadra1, ["shot.toml", "-o", out, "--overwrite", "-q"], "output", capsys,
                 work, 2)
    _refused(cadra2, ["simulate", str(work / "specs" / "small.toml"), "-o", "..",
                      "--overwrite", "--no-images"], "holds the current working folder",
             capsys, work, 1)
    assert not [p for p in work.rglob(".*") if ".cadra-" in p.name and p.name != ".cadra-output"]


def test_guard_library_function(tmp_path):
    (tmp_path / "in").mkdir()
    f = tmp_path / "in" / "a.txt"
    f.write_text("x")
    assert check_output_dir(tmp_path / "in" / "new", [f], cwd=tmp_path) == \
        (tmp_path / "in" / "new").resolve()               # a new folder inside an input one
    for out in (tmp_path / "in", f, tmp_path, tmp_path / "in" / ".." / "in"):
        with pytest.raises(UnsafeOutputError, match="input|working"):
            check_output_dir(out, [f], cwd=tmp_path)
    with pytest.raises(UnsafeOutputError, match="existing file"):
        check_output_dir(tmp_path / "in" / "a.txt", [], cwd=tmp_path / "in")
    # an input reached through a link counts under the link's folder too
    (tmp_path / "links").mkdir()
    (tmp_path / "links" / "a.txt").symlink_to(f)
    with pytest.raises(UnsafeOutputError, match="holds the input"):
        check_output_dir(tmp_path / "links", [tmp_path / "links" / "a.txt"], cwd=tmp_path / "in")


def test_new_output_inside_an_input_folder_is_fine(work, capsys):
    out = work / "specs" / "new_shot"
    assert cadra2(["simulate", str(work / "specs" / "small.toml"), "-o", str(out),
                   "--no-images", "-q"]) == 0
    assert (out / "shot.toml").is_file() and (work / "specs" / "small.toml").is_file()


# -- stale temporaries of killed runs ----------------------------------------------------------

def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_temps_cleaned_only_when_ours_and_dead(tmp_path):
    from cadra.atomic import _host

    out = tmp_path / "out"
    dead, host = _dead_pid(), _host()
    stale_tmp = tmp_path / f".out.cadra-{dead}@{host}-abcd1234.tmp"
    stale_old = tmp_path / f".out.cadra-{dead}@{host}-efgh5678.old"
    alive = tmp_path / f".out.cadra-{os.getppid()}@{host}-abcd1234.tmp"   # a running process
    other_host = tmp_path / f".out.cadra-{dead}@elsewhere-abcd1234.tmp"
    foreign = [tmp_path / ".out.abcd1234.tmp", tmp_path / ".other.cadra-1@x-abcd1234.tmp",
               tmp_path / ".out.cadra-1@x-abcd1234.txt"]
    for p in (stale_tmp, stale_old / "d", alive, other_host, *foreign):
        p.mkdir(parents=True)
    (stale_old / "d" / "report.md").write_text("the previous output")
    (stale_old / "d" / ".cadra-output").write_text("kind: output\n")   # a CADRA output
    assert stale_temps(out) == sorted([stale_tmp, stale_old])
    # the run was killed between its two renames: the previous output is moved back
    assert sorted(clean_stale_temps(out)) == sorted([stale_tmp, stale_old])
    assert (out / "report.md").read_text() == "the previous output"
    assert not stale_tmp.exists() and not stale_old.exists()
    assert alive.exists() and other_host.exists() and all(p.exists() for p in foreign)
    # an ordinary write cleans them too (and names its own temporary with its PID)
    (tmp_path / f".out.cadra-{dead}@{host}-zzzz9999.tmp").mkdir()
    with atomic_output_dir(out, overwrite=True) as tmp:
        assert f".cadra-{os.getpid()}@" in tmp.name
    assert not (tmp_path / f".out.cadra-{dead}@{host}-zzzz9999.tmp").exists()


def test_stale_temporary_files_of_single_file_writes(tmp_path):
    from cadra.atomic import _host, atomic_write_text

    dead, host = _dead_pid(), _host()
    stale = tmp_path / f".a.csv.cadra-{dead}@{host}-abcd1234.tmp"
    stale.write_text("half written")
    keep = tmp_path / ".a.csv.abcd1234.tmp"                 # not CADRA's naming: kept
    keep.write_text("someone's")
    atomic_write_text(tmp_path / "a.csv", "x\n")
    assert not stale.exists() and keep.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [keep.name, "a.csv"]


def _wait_for(predicate, timeout_s: float, proc=None):
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        value = predicate()
        if value:
            return value
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"process ended early with {proc.returncode}: "
                        f"{proc.stderr.read() if proc.stderr else ''}")
        time.sleep(0.02)
    pytest.fail("timed out")


def _temps(out: Path) -> list[Path]:
    return [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]


def _cadra2_proc(*argv) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "cadra.cli.cadra2", *argv], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@POSIX
def test_sigkill_then_rerun_cleans_the_stale_temporary(work, tmp_path):
    out = tmp_path / "sim"
    proc = _cadra2_proc("simulate", str(SPEC), "-o", str(out), "-q")   # 16 stations: ~30 s
    stale = _wait_for(lambda: _temps(out), 120, proc)
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    def tmps(found):   # the temporary itself (its lock file may or may not be seen yet)
        return [p for p in found if p.suffix != ".lock"]
    assert tmps(_temps(out)) == tmps(stale) and not out.exists()   # what a SIGKILL leaves
    assert cadra2(["simulate", str(work / "specs" / "small.toml"), "-o", str(out),
                   "--no-images", "-q"]) == 0
    assert (out / "shot.toml").is_file()
    assert _temps(out) == []


@POSIX
@pytest.mark.parametrize("sig, code, word", [(signal.SIGINT, 130, "interrupted"),
                                             (signal.SIGTERM, 143, "terminated")])
def test_ctrl_c_or_sigterm_cadra2_one_line_nothing_written(tmp_path, sig, code, word):
    """Ctrl-C and SIGTERM (a scheduler's stop) alike: one line, nothing written, no hidden
    temporary left."""
    out = tmp_path / "sim"
    proc = _cadra2_proc("simulate", str(SPEC), "-o", str(out), "-q")
    _wait_for(lambda: _temps(out), 120, proc)                   # it is writing
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == code
    assert stderr.strip().splitlines() == [f"cadra2: {word}"], stderr
    assert not out.exists() and _temps(out) == []


#: cadra2 simulate, where the signal lands inside a constructor: the half-built object's
#: finalizer fails later (as llvmlite's OutputString did when SIGTERM cut it off)
HALF_BUILT = """
import os, signal, sys
import cadra.synthetic.simulate as sim
SIG = int(sys.argv.pop(1))
class HalfBuilt:
    def __init__(self):
        os.kill(os.getpid(), SIG)                    # the signal arrives here ...
        self._ptr = None                             # ... so this is never set
    def __del__(self):
        if self._ptr is not None:
            pass
def simulate_shot(spec):
    keep = HalfBuilt()
    raise AssertionError("not reached")
sim.simulate_shot = simulate_shot
from cadra.cli.cadra2 import main
sys.exit(main(sys.argv[1:]))
"""


@POSIX
@pytest.mark.parametrize("sig, code, word", [(signal.SIGINT, 130, "interrupted"),
                                             (signal.SIGTERM, 143, "terminated")])
def test_an_interrupted_constructor_adds_no_traceback_to_the_one_line(tmp_path, sig, code,
                                                                      word):
    out = tmp_path / "sim"
    proc = subprocess.run([sys.executable, "-c", HALF_BUILT, str(int(sig)), "simulate",
                           str(SPEC), "-o", str(out), "-q"], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == code, proc.stderr
    assert proc.stderr.strip().splitlines() == [f"cadra2: {word}"], proc.stderr
    assert not out.exists()


# -- cadra1: Ctrl-C and a killed parent with pool workers --------------------------------------

#: cadra1's own main, with each station slowed down so the signal lands while the pool works
SLOW_CADRA1 = """
import sys, time
import cadra.imaging.shot as shot
measure = shot.measure_station
def slow(*args, **kwargs):
    time.sleep(3.0)
    return measure(*args, **kwargs)
shot.measure_station = slow
from cadra.cli.cadra1 import main
sys.exit(main(sys.argv[1:]))
"""


def _children(pid: int) -> list[int]:
    kids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                kids.append(int(d.name))
    return kids


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (ProcessLookupError, FileNotFoundError):
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"        # a zombie has exited


def _slow_cadra1(work: Path, out: Path, stderr=subprocess.PIPE) -> subprocess.Popen:
    # a session of its own: a terminal's Ctrl-C reaches the whole process group
    return subprocess.Popen([sys.executable, "-c", SLOW_CADRA1, str(work / "shot" / "shot.toml"),
                             "-o", str(out), "-q", "--workers", "2", "--no-overlays"],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=stderr, text=True,
                            start_new_session=True)


linux_only = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")


@linux_only
@pytest.mark.parametrize("sig, code, word", [(signal.SIGINT, 130, "interrupted"),
                                             (signal.SIGTERM, 143, "terminated")])
def test_ctrl_c_or_sigterm_cadra1_with_workers(work, tmp_path, sig, code, word):
    """To the whole process group, as a terminal's Ctrl-C or a scheduler's stop reaches it:
    one line, nothing written, every worker gone (a worker does not inherit the parent's
    SIGTERM handler, so the pool can end it)."""
    out = tmp_path / "st1"
    proc = _slow_cadra1(work, out)
    workers = _wait_for(lambda: len(_children(proc.pid)) >= 2 and _children(proc.pid), 60,
                        proc)
    time.sleep(0.3)                                             # the tasks are running
    os.killpg(proc.pid, sig)                                    # parent and workers
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == code
    assert stderr.strip().splitlines() == [f"cadra1: {word}"], stderr
    assert not out.exists() and _temps(out) == []
    _wait_for(lambda: not any(_alive(p) for p in workers), 10)


@linux_only
def test_killed_cadra1_leaves_no_worker(work, tmp_path):
    out = tmp_path / "st1"
    proc = _slow_cadra1(work, out, stderr=subprocess.DEVNULL)   # an orphan would hold a pipe
    workers = _wait_for(lambda: len(_children(proc.pid)) >= 2 and _children(proc.pid), 60,
                        proc)
    time.sleep(0.3)
    proc.kill()
    assert proc.wait() == -signal.SIGKILL
    _wait_for(lambda: not any(_alive(p) for p in workers), 10)
    assert not out.exists()


# -- cadra2 fit: Ctrl-C and SIGKILL while it fits ----------------------------------------------

#: cadra2's own main, with every trajectory integration slowed down (and the first one
#: announced by a marker file) so the signal lands while the fit is iterating
SLOW_CADRA2 = """
import sys, time
from pathlib import Path
import cadra.fitting.problem as problem
marker = Path(sys.argv[1])
integrate = problem.predict_with_jacobian
def slow(*args, **kwargs):
    marker.touch()
    time.sleep(0.5)
    return integrate(*args, **kwargs)
problem.predict_with_jacobian = slow
from cadra.cli.cadra2 import main
sys.exit(main(sys.argv[2:]))
"""


def _slow_fit(work: Path, out: Path, marker: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", SLOW_CADRA2, str(marker), "fit",
                             str(work / "m2_stage1"), "--model", "m2_m070", "-o", str(out),
                             "-q", "--no-plots"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@POSIX
def test_ctrl_c_during_cadra2_fit_exits_130_and_writes_nothing(work, tmp_path):
    out, marker = tmp_path / "fit", tmp_path / "fitting"
    before = tree_hash(work)
    proc = _slow_fit(work, out, marker)
    _wait_for(marker.exists, 120, proc)                         # it is iterating
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert stderr.strip().splitlines() == ["cadra2: interrupted"], stderr
    assert not out.exists() and _temps(out) == []
    assert tree_hash(work) == before


@POSIX
def test_sigkill_during_cadra2_fit_leaves_nothing_and_a_rerun_succeeds(work, tmp_path):
    out, marker = tmp_path / "fit", tmp_path / "fitting"
    before = tree_hash(work)
    proc = _slow_fit(work, out, marker)
    _wait_for(marker.exists, 120, proc)
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert not out.exists() and _temps(out) == []               # nothing partial
    assert tree_hash(work) == before
    assert cadra2(["fit", str(work / "m2_stage1"), "--model", "m2_m070", "-o", str(out), "-q",
                   "--no-plots"]) == 0
    assert (out / "report.md").is_file() and _temps(out) == []


def test_outputs_get_the_mode_of_a_plain_open(tmp_path, monkeypatch):
    """The temporary files behind atomic writes are private (0600); what lands is not."""
    import cadra.atomic as atomic

    monkeypatch.setattr(atomic, "_UMASK", 0o027)  # read once at import: set both alike
    mask = os.umask(0o027)
    try:
        plain = tmp_path / "plain.txt"
        plain.write_text("x")
        written = atomic.atomic_write_text(tmp_path / "a.txt", "x")
        with atomic.atomic_output_dir(tmp_path / "d") as tmp:
            (tmp / "f.txt").write_text("x")
    finally:
        os.umask(mask)
    assert written.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777 == 0o640
    assert (tmp_path / "d").stat().st_mode & 0o777 == 0o750


def test_a_looping_link_among_the_images_fails_its_station_only(work, tmp_path, capsys):
    """An image that is a symbolic link to itself: its station fails with that reason, the
    other is measured, no traceback (the output guard resolving it used to raise)."""
    import shutil

    shot = tmp_path / "shot"
    shutil.copytree(work / "shot", shot)
    loop = shot / "images" / "st01_top.png"
    loop.unlink()
    loop.symlink_to(loop.name)
    assert cadra1([str(shot / "shot.toml"), "-o", str(tmp_path / "out"), "-q",
                   "--workers", "1", "--no-overlays"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and "symbolic link" in err
    t = load_trajectory(tmp_path / "out" / "trajectory.csv").table.set_index("station")
    assert t.loc[1, "status"] == "failed" and "symbolic link" in t.loc[1, "reason"]
    assert t.loc[2, "status"] != "failed"


@POSIX
def test_a_live_writer_keeps_its_temporary_whatever_its_process_id(tmp_path):
    """A writer in another PID namespace (a container) has a process id this one cannot see:
    its temporary is kept while it holds its lock, and cleaned, lock file too, once the lock
    is free (the kernel frees it when the writer dies). A lock file left by a writer killed
    after its rename goes too."""
    import fcntl

    from cadra.atomic import _host

    out = tmp_path / "out"
    dead, host = _dead_pid(), _host()
    temp = tmp_path / f".out.cadra-{dead}@{host}-live1234.tmp"
    temp.mkdir()
    lock = tmp_path / (temp.name + ".lock")
    fd = os.open(lock, os.O_CREAT | os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)                  # the live writer, elsewhere
    try:
        assert stale_temps(out) == []
        assert clean_stale_temps(out) == [] and temp.exists() and lock.exists()
    finally:
        os.close(fd)                                # the writer dies
    assert stale_temps(out) == [temp]
    assert clean_stale_temps(out) == [temp]
    assert not temp.exists() and not lock.exists()
    orphan = tmp_path / f".out.cadra-{dead}@{host}-gone5678.tmp.lock"
    orphan.write_text("")
    clean_stale_temps(out)
    assert not orphan.exists()
    # a write holds its lock while it runs and leaves no lock file behind
    with atomic_output_dir(out) as tmp:
        assert (tmp_path / (tmp.name + ".lock")).exists()
        assert stale_temps(out) == []
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def _disk_full(*args, **kwargs):
    import errno

    raise OSError(errno.ENOSPC, "No space left on device",
                  "/somewhere/.out.cadra-1@host-abcd1234.tmp/plots/residuals.png")


def test_a_full_disk_loses_no_fit_and_names_the_output(work, tmp_path, capsys, monkeypatch):
    """The disk fills while the fit's outputs are written: the finished result is printed
    (even under -q), one line names the output the user gave (not the hidden temporary),
    status 1; simulate alike. (A read-only folder cannot be tested as root; the same
    OSError path.)"""
    import cadra.report.fit
    import cadra.synthetic.simulate

    monkeypatch.setattr(cadra.report.fit, "write_fit_outputs", _disk_full)
    out = tmp_path / "fit"
    code = cadra2(["fit", str(work / "m2_stage1"), "--model", "m2_m070", "--max-iterations",
                   "3", "-o", str(out), "-q"])
    cap = capsys.readouterr()
    assert code == 1
    assert f"could not write {out}: No space left on device" in cap.err
    assert ".cadra-" not in cap.err and "Traceback" not in cap.err
    assert "Cm_A1" in cap.out                         # the result, not lost
    monkeypatch.setattr(cadra.synthetic.simulate, "write_shot", _disk_full)
    out = tmp_path / "sim"
    assert cadra2(["simulate", str(work / "specs" / "small.toml"), "-o", str(out),
                   "--no-images", "-q"]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"cadra2 simulate: could not write {out}: No space left on device " \
                  "(nothing written)", err


def test_a_multi_fit_of_different_bodies_is_refused_at_once(work, capsys):
    """A capsule and a sphere under one model: refused before any fitting, naming both
    (it ran ~30 s to "not converged")."""
    code = cadra2(["fit", str(work / "m2_stage1"), str(work / "sphere_stage1"), "--model",
                   "m2_m070", "-o", str(work / "never"), "-q"])
    err = capsys.readouterr().err
    assert code == 1 and "different bodies" in err and "capsule" in err and "sphere" in err
    assert not (work / "never").exists()


def test_a_shot_file_naming_a_missing_facility_is_warned_about(work, tmp_path, capsys):
    import shutil

    shot = tmp_path / "m2"
    shutil.copytree(work / "m2", shot, ignore=shutil.ignore_patterns("images"))
    text = (shot / "shot.toml").read_text()
    (shot / "shot.toml").write_text(text.replace('facility = "hffaf"', 'facility = "hfaff"'))
    stage1 = tmp_path / "m2_stage1"
    shutil.copytree(work / "m2_stage1", stage1)
    cadra2(["fit", str(stage1), "--shot", str(shot / "shot.toml"), "--model", "m2_m070",
            "--max-iterations", "2", "-o", str(tmp_path / "fit"), "-q", "--no-plots"])
    err = capsys.readouterr().err
    assert "the facility 'hfaff' the shot file names is not found" in err, err


def test_overwrite_replaces_only_an_output_of_its_own_kind(work, tmp_path, capsys):
    """A simulated shot's folder (CADRA's, with its images) given to fit with --overwrite is
    refused: a fit replaces a fit, never a shot or a stage-one folder."""
    from cadra.atomic import output_kind

    shot = tmp_path / "sim"
    assert cadra2(["simulate", str(work / "specs" / "small.toml"), "-o", str(shot),
                   "--no-images", "-q"]) == 0
    assert output_kind(shot) == "shot"
    before = tree_hash(shot)
    assert cadra2(["fit", str(work / "m2_stage1"), "--model", "m2_m070", "-o", str(shot),
                   "--overwrite", "-q"]) == 1
    err = capsys.readouterr().err
    assert "is CADRA's shot output, not a fit output" in err, err
    assert tree_hash(shot) == before
    assert cadra2(["simulate", str(work / "specs" / "small.toml"), "-o", str(shot),
                   "--no-images", "-q", "--overwrite"]) == 0        # its own kind: replaced


def _masks_in_worker(queue):
    """A pool initializer: the worker's blocked signals as forked, then after its set-up."""
    from cadra.imaging import shot as shot_module

    before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    shot_module._worker_init(os.getppid())
    after = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    queue.put((signal.SIGTERM in before, signal.SIGINT in before,
               signal.SIGTERM in after, signal.SIGINT in after))


@linux_only
def test_pool_workers_take_no_signal_before_their_own_handlers():
    """A worker forked while the pool is made (or to replace one) holds SIGINT and SIGTERM
    until it has set its own handlers: a terminate that meets it half-started must not raise
    the command line's exception in it (a traceback on stderr). The parent's mask is back."""
    import multiprocessing as mp

    from cadra.imaging.shot import _pool_held_signals

    ctx = mp.get_context("fork")
    queue = ctx.SimpleQueue()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    with _pool_held_signals():
        pool = ctx.Pool(1, initializer=_masks_in_worker, initargs=(queue,))
    with pool:
        got = queue.get()
    assert got == (True, True, False, False)
    assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == mask
