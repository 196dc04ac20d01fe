"""A Ctrl-C that lands in the instant between creating a temporary (or its lock file) and the
``try`` that removes it leaves nothing behind (cadra.atomic._signals_held).

The signal is sent by the process to itself right after the creation it must not cut off, so
the test is deterministic: before the signals were held there, these runs left a ``.tmp``
folder or a ``.tmp.lock`` file beside the output (as a Ctrl-C from the command line
occasionally did)."""

from __future__ import annotations

import os
import signal
import sys
import tempfile

import pytest

from cadra.atomic import atomic_output_dir, atomic_write_text

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


@pytest.fixture
def python_sigint():
    """Python's own SIGINT handler (a test runner's worker may ignore SIGINT)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def _interrupt_after(function, when=lambda *a, **k: True):
    def wrapped(*args, **kwargs):
        result = function(*args, **kwargs)
        if when(*args, **kwargs):
            os.kill(os.getpid(), signal.SIGINT)   # acted on at the next bytecode boundary
        return result
    return wrapped


def _left_beside(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _is_lock(path, *args, **kwargs) -> bool:
    return str(path).endswith(".lock")


def _write_folder(out):
    with atomic_output_dir(out) as tmp:
        (tmp / "a.txt").write_text("x")


def _write_file(out):
    atomic_write_text(out, "x\n")


@pytest.mark.parametrize("write, create", [(_write_folder, "mkdtemp"),
                                           (_write_file, "mkstemp")])
@pytest.mark.parametrize("step", ["temporary", "lock"])
def test_ctrl_c_just_after_a_write_starts_leaves_nothing(tmp_path, monkeypatch, python_sigint,
                                                        step, write, create):
    if step == "temporary":
        monkeypatch.setattr(tempfile, create, _interrupt_after(getattr(tempfile, create)))
    else:
        monkeypatch.setattr(os, "open", _interrupt_after(os.open, _is_lock))
    with pytest.raises(KeyboardInterrupt):
        write(tmp_path / "out")
    assert not (tmp_path / "out").exists()
    assert _left_beside(tmp_path) == []


def test_ctrl_c_between_the_two_renames_of_an_overwrite(tmp_path, monkeypatch, python_sigint):
    """The previous output is moved aside, then the new one into place: a Ctrl-C between
    the two is acted on after both, so the output is the whole new one (never missing,
    never the old one half-removed) and nothing else is left."""
    out = tmp_path / "out"
    with atomic_output_dir(out) as tmp:
        (tmp / "a.txt").write_text("old")
    monkeypatch.setattr(os, "replace", _interrupt_after(
        os.replace, lambda src, dst: os.path.basename(dst) == "d"))   # moved aside
    with pytest.raises(KeyboardInterrupt):
        with atomic_output_dir(out, overwrite=True) as tmp:
            (tmp / "a.txt").write_text("new")
    assert (out / "a.txt").read_text() == "new"
    assert _left_beside(tmp_path) == []


def test_held_signals_are_acted_on_once_and_handlers_restored(python_sigint):
    from cadra.atomic import _signals_held

    with pytest.raises(KeyboardInterrupt):
        with _signals_held():
            os.kill(os.getpid(), signal.SIGINT)
            reached = True                      # the signal did not cut the block
    assert reached
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


SWALLOWED = """
import gc, os, signal, sys
from pathlib import Path
from cadra.atomic import atomic_output_dir, atomic_write_text
from cadra.cli._format import console_main

class Collected:
    def __del__(self):   # where numba's compiler collects llvmlite objects
        os.kill(os.getpid(), signal.SIG{sig})   # lands inside the finalizer

def body(argv):
    out = Path(argv[0])
    Collected()          # collected at once: its finalizer runs, the signal lands there
    gc.collect()
    {write}
    print("finished")
    return 0

sys.exit(console_main("demo", body, sys.argv[1:]))
"""


@pytest.mark.parametrize("sig, status, line", [("INT", 130, "demo: interrupted"),
                                                ("TERM", 143, "demo: terminated")])
@pytest.mark.parametrize("write", [
    "atomic_write_text(out / 'a.txt', 'x')",
    "with atomic_output_dir(out / 'd') as tmp:\n        (tmp / 'f.txt').write_text('x')",
    "raise RuntimeError('no compiled object yet')"])   # a library the stop left half-done
def test_a_stop_a_finalizer_swallowed_still_stops_the_command(tmp_path, sig, status, line,
                                                              write):
    """Python drops an exception raised inside a ``__del__``: a Ctrl-C landing in a finalizer
    (numba's compiler collects llvmlite objects often; a CI run saw one) was lost, and the
    command wrote its outputs and exited 0, or failed with the error of a library the stop had
    left half-done (numba's cache: "no compiled object yet"). The stop is recorded and raised
    before the output is committed and in place of that error: one line, the signal's status,
    nothing written."""
    import subprocess

    code = SWALLOWED.replace("{sig}", sig).replace("{write}", write)
    run = subprocess.run([sys.executable, "-c", code, str(tmp_path / "out")],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == status, run.stderr
    assert run.stderr.strip().splitlines() == [line], run.stderr
    assert "finished" not in run.stdout
    out = tmp_path / "out"
    assert not out.exists() or sorted(os.listdir(out)) == []
