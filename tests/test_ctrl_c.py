"""A Ctrl-C is never lost (docs/cli.md): a command started by a parent that ignores SIGINT or
has it blocked (a pool's worker, a shell's background job, a test runner's worker) still ends
at a Ctrl-C with one line and status 130, and writes nothing. Without taking SIGINT back at
its start (cadra.cli._format.take_ctrl_c) such a command ran to its end and exited 0."""

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "sample_shots" / "specs" / "m2_2429.toml"


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("inherited", ["ignored", "blocked"])
def test_ctrl_c_reaches_a_command_whose_parent_ignored_or_blocked_it(tmp_path, inherited):
    def preexec():
        if inherited == "ignored":
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        else:
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})

    out = tmp_path / "sim"
    proc = subprocess.Popen([sys.executable, "-m", "cadra.cli.cadra2", "simulate", str(SPEC),
                             "-o", str(out), "-q"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=preexec)
    t_end = time.monotonic() + 180
    while not [p for p in tmp_path.iterdir() if p.name.startswith(".sim.")]:   # writing
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < t_end, "timed out"
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert stderr.strip().splitlines() == ["cadra2: interrupted"]
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
