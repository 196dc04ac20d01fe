"""The numba cache folder: keyed by the compiled sources, nothing written inside the package.

:mod:`cadra._numba_cache` replaced a guard that deleted the package's cache files whenever a
jitted source changed (a read-only install or two processes importing at once could break on
it). These tests check the key, the choice of base folder, and that importing cadra and running
compiled code in a fresh process writes numba's files to the keyed folder only.
"""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from cadra import _numba_cache as nc


def _tree(tmp_path: Path) -> Path:
    root = tmp_path / "pkg"
    (root / "sub").mkdir(parents=True)
    (root / "sub" / "kernel.py").write_text(
        "import numba\n\n@numba.njit\ndef f(x):\n    return x\n")
    (root / "plain.py").write_text("X = 1\n")
    return root


def test_key_follows_the_compiled_sources_only(tmp_path):
    root = _tree(tmp_path)
    k0 = nc.sources_key(root)
    (root / "plain.py").write_text("X = 2\n")                    # no numba: same key
    assert nc.sources_key(root) == k0
    (root / "sub" / "kernel.py").write_text("import numba\n\n@numba.njit\ndef f(x):\n"
                                             "    return x + 1\n")
    k1 = nc.sources_key(root)
    assert k1 != k0
    (root / "other.py").write_text("import numba\n")            # a new compiled module
    assert nc.sources_key(root) not in (k0, k1)


def test_base_order_fallback_and_inherited_folder(tmp_path):
    root = _tree(tmp_path)
    key = nc.sources_key(root)
    first = tmp_path / "cadra_cache"
    env = {"CADRA_CACHE_DIR": str(first), "HOME": str(tmp_path)}
    assert nc.cache_folder(env, root) == first / key
    # a base that cannot be a folder (a file is in the way): the next candidate is used
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    env = {"CADRA_CACHE_DIR": str(blocker / "below"), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    assert nc.cache_folder(env, root) == tmp_path / "xdg" / "cadra" / "numba" / key
    # a worker process inherits NUMBA_CACHE_DIR = <base>/<key>: the same folder, not nested
    env = {"NUMBA_CACHE_DIR": str(first / key)}
    assert nc.cache_folder(env, root) == first / key


def test_other_keys_pruned_only_when_stale_and_cadra_s(tmp_path):
    """Only a stale folder CADRA provably made (named like a key, holding the marker) is
    removed; a user's folder, another project's numba cache or an unmarked key-named folder
    under the same base stays, however old."""
    root = _tree(tmp_path)
    base = tmp_path / "base"
    old, recent = base / ("a" * 20), base / ("b" * 20)
    unmarked = base / ("c" * 20)
    thesis = base / "thesis"
    for d in (old, recent, unmarked, thesis):
        d.mkdir(parents=True)
    for d in (old, recent):
        (d / nc.MARKER).touch()
    (thesis / "chapter1.tex").write_text("precious")
    t_old = 1e9                                                    # 2001
    for d in (old, unmarked, thesis):
        os.utime(d, (t_old, t_old))
    folder = nc.cache_folder({"CADRA_CACHE_DIR": str(base)}, root)
    assert (folder / nc.MARKER).is_file()
    assert not old.exists() and recent.exists()
    assert unmarked.exists() and (thesis / "chapter1.tex").read_text() == "precious"


def test_fresh_process_caches_outside_the_package(tmp_path):
    """Import cadra and run a compiled function in a new process: numba's index and data
    files appear in the keyed folder of the given base and none in the package."""
    pkg = Path(nc.__file__).resolve().parent
    before = {p for p in pkg.rglob("*.nb[ic]")}
    script = textwrap.dedent("""
        import numpy as np
        import cadra, os
        from cadra.dynamics.integrate import inverse3
        out = np.empty((3, 3))
        inverse3(np.diag([2.0, 4.0, 5.0]), out)
        assert abs(out[1, 1] - 0.25) < 1e-15
        print(os.environ["NUMBA_CACHE_DIR"])
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR",
                                                            "CADRA_CACHE_DIR")}
    env["CADRA_CACHE_DIR"] = str(tmp_path / "base")
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    run = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                         text=True, cwd=tmp_path, check=True)
    folder = Path(run.stdout.strip().splitlines()[-1])
    assert folder.parent == tmp_path / "base"
    assert folder.name == nc.sources_key()
    assert any(folder.rglob("integrate.inverse3-*.nbi"))
    assert {p for p in pkg.rglob("*.nb[ic]")} == before
