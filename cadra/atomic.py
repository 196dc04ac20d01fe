"""Atomic file and directory writes: a reader never sees a half-written output.

Every writer in CADRA validates first and writes last, through these helpers: the data go to a
temporary file (or directory) beside the target, are flushed to disk, and are moved into place
with :func:`os.replace`, which is atomic on POSIX and Windows for a path on the same file
system. Existing outputs are refused unless ``overwrite=True``.

Every output folder holds :data:`OUTPUT_MARKER`, and ``--overwrite`` replaces only such a
folder: a folder of the user's is never replaced, whatever the option says.

Inputs are never destroyed: :func:`check_output_dir` is the one guard every command runs
before it writes; it refuses (:class:`UnsafeOutputError`) an output folder that is, or holds,
one of the command's inputs, the current working folder or one of its parents, or an
existing file — links and ``..`` resolved first. Whatever the inputs named, an existing
folder holding a file CADRA keeps for good (:data:`NEVER_REPLACED`: a facility's station
history) is never an output, so no call, from the command line or Python, replaces it.

Temporary siblings are named ``.NAME.cadra-PID@HOST-XXXXXXXX.tmp`` (and ``.old`` for the
previous output while it is swapped out), so a run killed before its cleanup (SIGKILL, power
loss) leaves something recognisable: the next run that writes the same output removes the
siblings whose writer is gone — :func:`clean_stale_temps` — and leaves every other file
alone. Whether the writer is gone is asked of a lock, not of its process id: the writer holds
an exclusive lock on ``<temporary>.lock`` while it writes (POSIX ``flock``, which the kernel
drops when the process dies), so a live writer in another PID namespace (a container) keeps
its temporary. A temporary without a lock file (a writer killed in the instant between
creating it and locking it, or another platform) falls back to the process id on this host.
A ``.old`` folder whose output is missing (killed in the middle of the swap) is moved back
into place, not deleted.

A Ctrl-C or SIGTERM leaves nothing either: creating a temporary and entering the ``try``
that removes it, removing a lock file, and the two renames of an overwrite are never cut
apart by a signal (:func:`_signals_held` acts on it at the end of those few statements). A
signal that lands during the overwrite's renames is acted on after them: the output is then
the whole new one.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import socket
import sys
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

try:
    import fcntl
except ImportError:   # Windows: the process id decides (never guessed there: kept)
    fcntl = None


class UnsafeOutputError(ValueError):
    """An output path that would destroy an input, the working folder or a file."""


#: the file every output folder holds (written last, with the folder): ``--overwrite``
#: replaces only a folder that holds it (or an empty one), never a folder of the user's
OUTPUT_MARKER = ".cadra-output"

#: names of files CADRA keeps for good (a facility's station history, appended to under a
#: lock and never rewritten): a folder holding one, at any depth, is never an output
NEVER_REPLACED = frozenset({"bias_history.jsonl"})


def _kept_file_in(folder: Path) -> Path | None:
    """The first :data:`NEVER_REPLACED` file at any depth of ``folder`` (links not
    followed), or None."""
    for here, _dirs, files in os.walk(folder):
        for name in files:
            if name in NEVER_REPLACED:
                return Path(here) / name
    return None


def _read_umask() -> int:
    """The process's umask (read once, at import: setting it to read it is not thread-safe)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: temporary files are created private (0600); outputs get the mode a plain open() would give
_UMASK = _read_umask()


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname())[:32] or "host"


def _temp_prefix(path: Path) -> str:
    """The prefix of this process's temporary siblings of ``path``."""
    return f".{path.name}.cadra-{os.getpid()}@{_host()}-"


def _stale_pattern(path: Path) -> re.Pattern:
    return re.compile(rf"\.{re.escape(path.name)}\.cadra-(?P<pid>\d+)@(?P<host>[A-Za-z0-9-]+)"
                      r"-[A-Za-z0-9_]{6,}\.(?P<kind>tmp|old)")


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie counts as gone; unknown counts as alive)."""
    if pid == os.getpid():
        return True
    if sys.platform == "win32":  # os.kill would terminate it: never guess there
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    try:  # Linux: a killed child nobody has waited for yet is a zombie
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat.rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def _lock_of(temp: Path) -> Path:
    return temp.with_name(temp.name + ".lock")


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM for the few statements inside: a signal that arrives there is
    acted on at the end of the block, as it would have been at its arrival.

    A Python signal handler raises at the next bytecode boundary, so a Ctrl-C landing between
    creating a temporary (or its lock file) and the ``try`` that removes it would leave it
    behind. Creating and recording a temporary, and removing a lock, are done inside this
    block. Only the main thread can set handlers; elsewhere the block holds nothing."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held, previous = [], {}

    def hold(signum, frame):
        held.append(signum)

    try:
        for signum in (signal.SIGINT, signal.SIGTERM):
            handler = signal.getsignal(signum)
            if callable(handler):       # ignored or default: nothing to defer
                previous[signum] = signal.signal(signum, hold)
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for signum in held:
            previous[signum](signum, None)   # raises KeyboardInterrupt (or Terminated)


#: stop requests (a Ctrl-C's KeyboardInterrupt, SIGTERM's) that a finalizer swallowed: Python
#: drops an exception raised inside a ``__del__`` (numba's compiler collects llvmlite objects
#: often), so a signal landing there was lost and the command ran on to write its outputs.
#: :func:`watch_swallowed_stops` records them; no output is committed after one
#: (:func:`raise_swallowed_stop`).
_SWALLOWED: list[BaseException] = []


def watch_swallowed_stops() -> None:
    """Record a stop request (a :class:`KeyboardInterrupt`) that Python drops because it was
    raised inside a finalizer; other such reports go to the hook as before. Idempotent."""
    hook = sys.unraisablehook
    if getattr(hook, "_cadra_records_stops", False):
        return

    def record(unraisable):
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            _SWALLOWED.append(unraisable.exc_value)
        else:
            hook(unraisable)

    record._cadra_records_stops = True
    sys.unraisablehook = record


def raise_swallowed_stop() -> None:
    """Raise the stop request a finalizer swallowed (:func:`watch_swallowed_stops`), if any:
    called before an output is committed, and by a command when its work returns."""
    if _SWALLOWED:
        exc = _SWALLOWED[0]
        _SWALLOWED.clear()
        raise exc


@contextlib.contextmanager
def _locked(temp: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``temp``'s lock file while the block writes ``temp`` (the
    kernel drops it if this process dies); the lock file is removed at the end, whatever
    interrupts the block (:func:`_signals_held` around its creation and removal)."""
    if fcntl is None:
        yield
        return
    lock, fd = _lock_of(temp), None
    try:
        with _signals_held():
            fd = os.open(lock, os.O_CREAT | os.O_RDWR, 0o600)
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        with _signals_held():
            with contextlib.suppress(FileNotFoundError):
                os.unlink(lock)
            if fd is not None:
                os.close(fd)


def _writer_alive(temp: Path, pid: int) -> bool:
    """Whether the writer of ``temp`` still runs: its lock is held (any PID namespace), or,
    without a lock file, process ``pid`` of this host runs."""
    lock = _lock_of(temp)
    if fcntl is None or not lock.exists():
        return _alive(pid)
    try:
        fd = os.open(lock, os.O_RDWR)
    except OSError:
        return _alive(pid)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True            # held: its writer is alive
    finally:
        os.close(fd)
    return False


def stale_temps(path: str | os.PathLike) -> list[Path]:
    """CADRA's temporary siblings of ``path`` left by a process of this host that is gone."""
    path = Path(path)
    pattern, host = _stale_pattern(path), _host()
    found = []
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return []
    for entry in entries:
        if not entry.name.startswith(f".{path.name}.cadra-"):
            continue
        m = pattern.fullmatch(entry.name)
        if m and m["host"] == host and not _writer_alive(path.parent / entry.name,
                                                           int(m["pid"])):
            found.append(path.parent / entry.name)
    return sorted(found)


def _orphan_locks(path: Path) -> list[Path]:
    """Lock files of CADRA's temporaries of ``path`` whose temporary is gone and whose
    writer is too (killed between its rename and the lock's removal)."""
    pattern, host, out = _stale_pattern(path), _host(), []
    with contextlib.suppress(OSError):
        for entry in os.scandir(path.parent):
            if not entry.name.endswith(".lock"):
                continue
            m = pattern.fullmatch(entry.name[:-len(".lock")])
            temp = path.parent / entry.name[:-len(".lock")]
            if (m and m["host"] == host and not os.path.lexists(temp)
                    and not _writer_alive(temp, int(m["pid"]))):
                out.append(path.parent / entry.name)
    return out


def clean_stale_temps(path: str | os.PathLike) -> list[Path]:
    """Remove the stale temporary siblings of ``path`` (:func:`stale_temps`); return them.

    A stale ``.old`` folder holding the previous output (``.../d``) while ``path`` is missing
    is moved back to ``path`` first: the run was killed between its two renames.
    """
    path = Path(path)
    removed = []
    for stale in stale_temps(path):
        try:
            if stale.is_dir() and not stale.is_symlink():
                if stale.name.endswith(".old") and (stale / "d").exists() \
                        and not os.path.lexists(path):
                    os.replace(stale / "d", path)
                shutil.rmtree(stale)
            else:
                stale.unlink()
        except FileNotFoundError:  # another run cleaned it first
            pass
        with contextlib.suppress(FileNotFoundError):
            os.unlink(_lock_of(stale))
        removed.append(stale)
    for lock in _orphan_locks(path):
        with contextlib.suppress(FileNotFoundError):
            os.unlink(lock)
    return removed


def _spelled(given: str | os.PathLike, resolved: Path) -> str:
    """``given``, followed by its resolved form when that reads differently."""
    return f"{given}" if Path(os.path.abspath(given)) == resolved else f"{given} (= {resolved})"


def _resolved(p: Path) -> Path:
    """``p`` with links and ``..`` resolved; a link loop (which cannot be resolved) as its
    absolute spelling, so the guard still compares it."""
    try:
        return p.resolve()
    except (RuntimeError, OSError):   # a symbolic link loop
        return Path(os.path.abspath(p))


def _input_forms(p: Path) -> set[Path]:
    """Where an input lives: its target and, for a link, the link itself."""
    forms = {_resolved(p)}
    absolute = Path(os.path.abspath(p))
    if absolute.name:
        forms.add(_resolved(absolute.parent) / absolute.name)
    return forms


def output_kind(folder: str | os.PathLike) -> str | None:
    """The kind of output CADRA wrote in ``folder`` (``"fit"``, ``"stage one"``, ...: its
    :data:`OUTPUT_MARKER`'s first line), ``""`` for a marker of no known kind, None if the
    folder holds no marker."""
    marker = Path(folder) / OUTPUT_MARKER
    try:
        text = marker.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None if not marker.exists() else ""
    first = text.splitlines()[0].strip() if text.strip() else ""
    return first.removeprefix("kind: ") if first.startswith("kind: ") else ""


def check_output_dir(out: str | os.PathLike, inputs: Iterable[str | os.PathLike] = (), *,
                     cwd: str | os.PathLike | None = None, kind: str | None = None) -> Path:
    """Refuse an output folder that writing (with or without overwrite) would destroy.

    Refused, with :class:`UnsafeOutputError` (a ``ValueError``) naming the output and the
    culprit: an output that *is* an input (file or folder), *holds* an input at any depth, is
    the current working folder or one of its parents, the file system's root, or an existing
    file. Links and ``..`` are resolved first (:meth:`pathlib.Path.resolve`), so another
    spelling of the same folder is caught; an input reached through a link counts under both
    the link's folder and the target's. A new output folder *inside* an input folder is fine.
    An existing folder that holds a :data:`NEVER_REPLACED` file (a station history) at any
    depth is refused whatever the inputs, and so is an existing folder, not empty, that CADRA
    did not write (no :data:`OUTPUT_MARKER`): ``--overwrite`` replaces CADRA's own outputs,
    never a folder of the user's; with ``kind``, only an output of that kind (a fit never
    replaces a stage-one folder or a simulated shot).

    Parameters
    ----------
    out : the output folder the command will write (atomically).
    inputs : every file or folder the command reads.
    cwd : the working folder (default: the process's).

    Returns
    -------
    The resolved output path.
    """
    out_r = Path(out).resolve()
    here = Path(os.getcwd() if cwd is None else cwd).resolve()
    shown = _spelled(out, out_r)
    if not out_r.name:
        raise UnsafeOutputError(f"output {shown} is the file system's root; choose another")
    if out_r == here:
        raise UnsafeOutputError(f"output {shown} is the current working folder; choose a "
                                "new folder (inputs are never overwritten)")
    if out_r in here.parents:
        raise UnsafeOutputError(f"output {shown} holds the current working folder {here}; "
                                "choose a new folder")
    for p in inputs:
        for form in _input_forms(Path(p)):
            if form == out_r or out_r in form.parents:
                how = "is" if form == out_r else "holds"
                raise UnsafeOutputError(f"output {shown} {how} the input {p}; choose a new "
                                        "folder (inputs are never overwritten)")
    if out_r.exists() and not out_r.is_dir():
        raise UnsafeOutputError(f"output {shown} is an existing file, not a folder; choose "
                                "a new folder")
    kept = _kept_file_in(out_r) if out_r.is_dir() else None
    if kept is not None:
        raise UnsafeOutputError(f"output {shown} holds {kept}, a station history CADRA never "
                                "replaces; choose a new folder")
    if out_r.is_dir() and not (out_r / OUTPUT_MARKER).is_file() and any(out_r.iterdir()):
        raise UnsafeOutputError(f"output {shown} is a folder CADRA did not write (no "
                                f"{OUTPUT_MARKER} in it); CADRA replaces only its own output "
                                "folders, even with --overwrite: choose a new folder")
    found = output_kind(out_r) if out_r.is_dir() else None
    if kind is not None and found is not None and found != kind:
        raise UnsafeOutputError(f"output {shown} is CADRA's {found or 'other'} output, not a "
                                f"{kind} output; --overwrite replaces only an output of its "
                                "own kind: choose a new folder")
    return out_r


def atomic_write_bytes(path: str | os.PathLike, data: bytes, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically.

    Parameters
    ----------
    path : target file; its parent directory is created if needed.
    data : the complete contents.
    overwrite : replace an existing file (default: refuse with :class:`FileExistsError`).

    Returns
    -------
    The target path. On any error nothing is left at ``path`` (nor a temporary file).
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite (pass overwrite=True)")
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory")
    path.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temps(path)
    tmp = None
    try:
        with _signals_held():   # a Ctrl-C here is raised inside the try, which removes tmp
            fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=".tmp",
                                       dir=path.parent)
        with _locked(Path(tmp)), os.fdopen(fd, "wb") as fh:
            if hasattr(os, "fchmod"):
                os.fchmod(fh.fileno(), 0o666 & ~_UMASK)
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
            if not overwrite and path.exists():  # appeared while we were writing
                raise FileExistsError(f"{path} exists; refusing to overwrite (pass "
                                      "overwrite=True)")
            raise_swallowed_stop()
            os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str, overwrite: bool = False,
                      encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`)."""
    return atomic_write_bytes(path, text.encode(encoding), overwrite=overwrite)


@contextlib.contextmanager
def atomic_output_dir(path: str | os.PathLike, overwrite: bool = False,
                      kind: str = "output") -> Iterator[Path]:
    """Build a directory of outputs in a temporary sibling and move it into place at the end.

    ::

        with atomic_output_dir("out/m2_2429") as tmp:
            (tmp / "shot.toml").write_text(...)
            ...
        # out/m2_2429 now exists, complete; on an exception it does not exist (or is unchanged)

    Parameters
    ----------
    path : the final directory.
    overwrite : replace an existing directory at the end (default: refuse up front with
        :class:`FileExistsError`). The old directory is removed only after the new one is
        complete.

    The path is resolved first (a link to a folder replaces the folder, the link stays); the
    current working folder, its parents and an existing file are refused
    (:func:`check_output_dir`, which commands call with their inputs before they start).
    Stale temporary siblings of killed runs are removed first (:func:`clean_stale_temps`).
    """
    given = path
    path = check_output_dir(path, kind=kind)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{given} exists; refusing to overwrite (pass overwrite=True)")
    path.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temps(path)
    tmp = old = None
    try:
        with _signals_held():   # a Ctrl-C here is raised inside the try, which removes tmp
            tmp = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".tmp",
                                        dir=path.parent))
        with _locked(tmp):
            os.chmod(tmp, 0o777 & ~_UMASK)  # mkdtemp's folder is private (0700)
            yield tmp
            (tmp / OUTPUT_MARKER).write_text(f"kind: {kind}\nwritten by CADRA: --overwrite "
                                             f"replaces it with another {kind} output\n",
                                             encoding="utf-8")
            raise_swallowed_stop()
            if path.exists():
                if not overwrite:
                    raise FileExistsError(f"{given} exists; refusing to overwrite")
                with _signals_held():
                    old = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".old",
                                                dir=path.parent))
                with _locked(old):
                    with _signals_held():    # the two renames are never cut apart
                        os.replace(path, old / "d")  # move aside, swap in, delete the old
                        try:
                            os.replace(tmp, path)
                        except BaseException:
                            os.replace(old / "d", path)
                            raise
                    shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and os.path.lexists(path):   # the previous output is not in it
            shutil.rmtree(old, ignore_errors=True)
        raise


__all__ = ["NEVER_REPLACED", "OUTPUT_MARKER", "UnsafeOutputError", "atomic_output_dir",
           "output_kind",
           "atomic_write_bytes", "atomic_write_text", "check_output_dir", "clean_stale_temps",
           "stale_temps"]
