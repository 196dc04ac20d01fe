"""Per-facility station bias history: an append-only record of sphere-calibration bias tables.

The history of a facility is ``<root>/stations/<facility>/bias_history.jsonl``: one JSON
object per line, one :class:`~cadra.calibration.table.BiasTable` each (the table, its canonical
JSON and its CSV live in :mod:`cadra.calibration.table`; re-exported here), appended and never
rewritten (docs/calibration.md, "Station history"). ``<root>`` is :func:`stations_root`: the
repository root unless the user names another (never the working directory by default).

The history file is the record a facility keeps for years, so every read checks it fully:

* each line carries the SHA-256 of its canonical JSON (:func:`canonical_json`); a line whose
  hash does not match, or that is not JSON, is an error naming the line (never skipped);
* an entry naming another facility is refused, naming both;
* an append interrupted midway (power cut, killed process) leaves at most a partial *last*
  line, which :func:`load_history` reports as a warning and skips. The next append starts a
  new line (the fragment's bytes stay in place, never rewritten) and records the fragment's
  line number, length and SHA-256 in the new entry (``after_fragment``); a later read accepts
  that fragment only because the entry after it vouches for exactly those bytes.

Appends are serialised by a lock file beside the history (``bias_history.jsonl.lock``,
`filelock`): :func:`append_compared` reads, dates, compares and appends under it, so
concurrent calibrations each compare with every earlier entry and are recorded in one order.
A write that fails (a full disk) is cut back off: the file is left as it was.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
from dataclasses import dataclass, replace
from datetime import timedelta
from pathlib import Path
from statistics import NormalDist

import numpy as np
import pandas as pd
from filelock import FileLock, Timeout

from cadra.calibration.table import (
    BIAS_COLUMNS,
    CHANNELS,
    HISTORY_FORMAT,
    SIGMA_COLUMNS,
    TABLE_COLUMNS,
    TABLE_FORMAT,
    UNITS,
    BiasTable,
    StationHistoryError,
    _check_facility_name,
    _entry_dict,
    _parse_utc,
    _sha256,
    _table_from_entry,
    bias_table_to_frame,
    canonical_json,
    frame_to_bias_table,
    load_bias_table,
    save_bias_table,
    table_sha256,
    utc_now,
)
from cadra.facility.reference import REPO_ROOT

#: history file name inside ``stations/<facility>/``
HISTORY_FILENAME = "bias_history.jsonl"
#: environment variable naming the stations root (the directory holding ``stations/``)
STATIONS_ROOT_ENV = "CADRA_STATIONS_ROOT"
#: seconds an append waits for another process's lock on the history before giving up
LOCK_TIMEOUT_S = 120.0

# --------------------------------------------------------------------------- history file


def stations_root(root: str | os.PathLike | None = None) -> Path:
    """The directory holding ``stations/``, never the working directory unless asked for.

    ``root`` if given (``"."`` is the working directory, by choice); else the environment
    variable ``CADRA_STATIONS_ROOT``; else the repository root, the folder holding
    ``facilities/`` (where a bare facility name such as ``hffaf`` resolves first,
    :func:`cadra.io.facility_file.resolve_facility_path`), so a facility's file and its station
    history sit side by side whatever folder a command runs in. docs/calibration.md, "Where
    the history lives".

    Raises
    ------
    StationHistoryError : none of the three applies (an installed package without its
        ``facilities/`` folder): the message says to name the root.
    """
    if root is not None and str(root) != "":
        return Path(root)
    env = os.environ.get(STATIONS_ROOT_ENV, "")
    if env:
        return Path(env)
    if (REPO_ROOT / "facilities").is_dir():
        return REPO_ROOT
    raise StationHistoryError(f"no station history location: {REPO_ROOT / 'facilities'} does "
                              f"not exist (an installed package); name the directory that "
                              f"holds stations/ with --stations-root or {STATIONS_ROOT_ENV}")


def history_dir(root: str | os.PathLike | None, facility: str) -> Path:
    """``<root>/stations/<facility>/``: where a facility's station history lives.

    Parameters
    ----------
    root : the directory holding ``stations/``; None means the default of
        :func:`stations_root` (``$CADRA_STATIONS_ROOT``, else the repository root).
    facility : facility name, e.g. ``"hffaf"``.
    """
    _check_facility_name(facility)
    return stations_root(root) / "stations" / facility


def history_path(root: str | os.PathLike | None, facility: str) -> Path:
    """``<root>/stations/<facility>/bias_history.jsonl``."""
    return history_dir(root, facility) / HISTORY_FILENAME


@dataclass(frozen=True)
class _Scan:
    tables: list
    hashes: list          # table_sha256 of each entry
    warnings: list
    size: int             # bytes in the file (0 if absent)
    terminated: bool      # the file is empty or ends with a newline
    fragment: dict | None  # the unterminated, non-JSON last line: line, bytes, sha256


class _NonFinite(str):
    """A JSON number beyond a float (``1e400``) or a non-standard constant (``NaN``,
    ``Infinity``), kept as its text so the entry holding it is named (:func:`_nonfinite_at`):
    the writer never produces one (canonical JSON has no inf or NaN)."""


def _keep_constant(name: str) -> _NonFinite:
    return _NonFinite(name)


def _no_duplicates(pairs):
    keys = [k for k, _ in pairs]
    if len(set(keys)) != len(keys):
        raise ValueError("duplicate keys")
    return dict(pairs)


def _finite_float(text: str) -> float | _NonFinite:
    """A JSON number as float; one beyond a float (``1e400``) stays its text."""
    x = float(text)
    return x if math.isfinite(x) else _NonFinite(text)


def _parse_line(raw: bytes):
    try:
        return json.loads(raw.decode("ascii"), parse_constant=_keep_constant,
                          parse_float=_finite_float, object_pairs_hook=_no_duplicates)
    except (UnicodeDecodeError, ValueError):
        return None


def _nonfinite_at(obj, key: str = "") -> tuple[str, str] | None:
    """The first non-finite number in a parsed entry: (its key path, e.g. ``bias_x_m[2]``, and
    its text), or None."""
    if isinstance(obj, _NonFinite):
        return key, str(obj)
    items = (obj.items() if isinstance(obj, dict)
             else ((f"[{i}]", v) for i, v in enumerate(obj)) if isinstance(obj, list) else ())
    for k, v in items:
        found = _nonfinite_at(v, f"{key}.{k}" if key and not k.startswith("[") else f"{key}{k}")
        if found:
            return found
    return None


def _scan(path: Path, facility: str) -> _Scan:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return _Scan([], [], [], 0, True, None)
    except (IsADirectoryError, PermissionError, OSError) as exc:   # a folder, a link loop
        raise StationHistoryError(f"{path}: the station history cannot be read "
                                  f"({exc.strerror or type(exc).__name__}); it must be a "
                                  f"file") from None
    terminated = data == b"" or data.endswith(b"\n")
    pieces = data.split(b"\n")
    if terminated:
        pieces = pieces[:-1]
    tables, hashes, warns = [], [], []
    pending = None        # (line number, bytes) of a terminated non-JSON line awaiting its voucher
    fragment = None
    n = len(pieces)
    for k, raw in enumerate(pieces, start=1):
        where = f"{path}: line {k}"
        last_open = k == n and not terminated
        obj = _parse_line(raw)
        if obj is None:
            if pending is not None:
                raise StationHistoryError(
                    f"{path}: line {pending[0]} is not valid JSON and no entry vouches for it "
                    f"(it looks like two interrupted appends in a row, or corruption); "
                    f"refusing to guess: inspect the file by hand")
            if last_open:
                fragment = {"line": k, "bytes": len(raw), "sha256": _sha256(raw)}
                warns.append(f"{where}: {len(raw)} bytes of an interrupted write (no final "
                             f"newline, not JSON): skipped; the next append starts a new line")
                continue
            pending = (k, raw)
            continue
        if not isinstance(obj, dict):
            raise StationHistoryError(f"{where}: not a JSON object (corrupted line)")
        bad = _nonfinite_at(obj)
        if bad is not None:
            raise StationHistoryError(f"{where} (entry {len(tables) + 1}): key {bad[0]}: "
                                      f"{bad[1]} is not a finite number (a bias or sigma must "
                                      f"be finite; null means a channel not estimated)")
        if obj.get("format") != HISTORY_FORMAT:
            raise StationHistoryError(f"{where}: format {obj.get('format')!r}, expected "
                                      f"{HISTORY_FORMAT!r}")
        stored = obj.pop("sha256", None)
        if not isinstance(stored, str):
            raise StationHistoryError(f"{where}: no sha256 (corrupted or hand-edited line)")
        if _sha256(canonical_json(obj)) != stored:
            raise StationHistoryError(f"{where}: sha256 mismatch: the line was altered after "
                                      f"it was written (corruption or a hand edit); refusing")
        ack = obj.pop("after_fragment", None)
        if pending is not None:
            pk, praw = pending
            want = {"line": pk, "bytes": len(praw), "sha256": _sha256(praw)}
            if ack != want:
                raise StationHistoryError(
                    f"{path}: line {pk}: corrupted line (not valid JSON, and the entry on line "
                    f"{k} does not vouch for it as an interrupted write); refusing to guess")
            warns.append(f"{path}: line {pk}: {len(praw)} bytes of an earlier interrupted "
                         f"write (vouched for by line {k}): skipped")
            pending = None
        elif ack is not None:
            raise StationHistoryError(f"{where}: the entry vouches for an interrupted write on "
                                      f"line {ack.get('line') if isinstance(ack, dict) else ack}"
                                      f", which is not there (lines removed or reordered)")
        if obj.get("facility") != facility:
            raise StationHistoryError(
                f"{where}: the entry is for facility {obj.get('facility')!r}, but this is the "
                f"history of facility {facility!r} ({path}); refusing to mix facilities")
        table = _table_from_entry(obj, where)
        if tables and _parse_utc(table.created_utc) < _parse_utc(tables[-1].created_utc):
            raise StationHistoryError(f"{where}: created_utc {table.created_utc} is earlier "
                                      f"than the entry before it ({tables[-1].created_utc})")
        if last_open:
            warns.append(f"{where}: complete entry without a final newline (accepted; the next "
                         f"append starts a new line)")
        tables.append(table)
        hashes.append(table_sha256(table))
    if pending is not None:
        raise StationHistoryError(
            f"{path}: line {pending[0]}: not valid JSON and followed by a newline, so it is not "
            f"the partial last line of an interrupted write (corruption, or an append "
            f"interrupted right after its first byte); refusing to guess: inspect by hand")
    return _Scan(tables, hashes, warns, len(data), terminated, fragment)


def load_history(stations_root: str | os.PathLike | None,
                 facility: str) -> tuple[list[BiasTable], list[str]]:
    """Read and verify a facility's station history.

    Parameters
    ----------
    stations_root : the directory holding ``stations/`` (see :func:`history_dir`).
    facility : facility name.

    Returns
    -------
    (entries, warnings) : the bias tables in file order (oldest first; an empty list if there
        is no history yet) and warnings (a partial last line of an interrupted write, skipped).

    Raises
    ------
    StationHistoryError : a line that is neither a verified entry nor a recognised interrupted
        write (message names the line), an entry for another facility, or entries out of
        time order.
    """
    s = _scan(history_path(stations_root, facility), facility)
    return s.tables, s.warnings


@contextlib.contextmanager
def _history_lock(path: Path, timeout_s: float):
    """Hold ``<history>.lock`` (filelock: ``flock`` on POSIX, ``msvcrt`` on Windows) while the
    history is read, compared and appended; every append takes it, so two appends never
    interleave and each sees the entries before it. Readers do not take it (a read during an
    append sees at most a partial last line, which it skips with a warning)."""
    new_dir = not path.parent.exists()
    path.parent.mkdir(parents=True, exist_ok=True)
    if new_dir:
        _fsync_dir(path.parent.parent)
    lock = FileLock(f"{path}.lock", timeout=timeout_s)
    try:
        lock.acquire()
    except Timeout:
        raise TimeoutError(errno.ETIMEDOUT, f"{path}: the history's lock ({path.name}.lock) "
                           f"was held by another process for {timeout_s:g} s; nothing was "
                           f"appended") from None
    try:
        yield
    finally:
        lock.release()


def _write_all(fd: int, data: bytes) -> None:
    """``os.write`` until all of ``data`` is written (the seam a full-disk test replaces)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _write_entry(path: Path, table: BiasTable, s: _Scan) -> int:
    """Append the entry line for ``table`` to ``path`` (scanned as ``s`` under the lock) and
    fsync it; on any failure cut the file back to its old length, so it is left as it was.
    Returns the entry's number (1-based)."""
    d = _entry_dict(table)
    if s.fragment is not None:
        d["after_fragment"] = s.fragment
    line = canonical_json({**d, "sha256": _sha256(canonical_json(d))})
    payload = (b"" if s.terminated else b"\n") + line.encode("ascii") + b"\n"
    existed = path.exists()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_BINARY", 0),
                 0o666)
    try:
        size = os.fstat(fd).st_size
        if size != s.size:
            raise StationHistoryError(f"{path}: changed while locked ({s.size} -> {size} "
                                      f"bytes: a writer that ignores {path.name}.lock?); "
                                      f"nothing appended")
        try:
            _write_all(fd, payload)
            os.fsync(fd)
        except BaseException:
            with contextlib.suppress(OSError):   # leave the file exactly as it was
                os.ftruncate(fd, size)
                os.fsync(fd)
                if not existed:
                    os.unlink(path)
            raise
    finally:
        os.close(fd)
    if size == 0:
        _fsync_dir(path.parent)
    return len(s.tables) + 1


def append_entry(table: BiasTable, stations_root: str | os.PathLike | None, *,
                 timeout_s: float = LOCK_TIMEOUT_S) -> Path:
    """Append ``table``, as dated, to ``<stations_root>/stations/<facility>/bias_history.jsonl``.

    Under the history's lock (:data:`LOCK_TIMEOUT_S`) the existing file is verified
    (:func:`load_history`; any error refuses the append and nothing is written), then the new
    line (with its SHA-256) is appended and fsynced; a failed write (a full disk) is cut back
    off, leaving the file as it was. After a partial last line left by an interrupted process
    the new entry starts on a new line and records the fragment (``after_fragment``: line,
    bytes, sha256) so later reads accept it. A calibration records its estimate with
    :func:`append_compared`, which dates it under the lock; this function keeps the table's
    own date and so refuses a table older than the latest entry.

    Parameters
    ----------
    table : the bias table; its ``facility`` chooses the history.
    stations_root : the directory holding ``stations/`` (see :func:`stations_root`).
    timeout_s : how long to wait for another append's lock.

    Returns
    -------
    The history file's path.

    Raises
    ------
    StationHistoryError : the history is corrupt or belongs to another facility, the table is
        older than the latest entry, or the same table is already recorded.
    OSError : the write failed (the file is unchanged) or the lock was not obtained in time
        (``TimeoutError``).
    """
    path = history_path(stations_root, table.facility)
    with _history_lock(path, timeout_s):
        s = _scan(path, table.facility)
        _check_new(path, table, s)
        _write_entry(path, table, s)
    return path


def _check_new(path: Path, table: BiasTable, s: _Scan) -> None:
    digest = table_sha256(table)
    if digest in s.hashes:
        k = s.hashes.index(digest)
        raise StationHistoryError(f"{path}: this table (created {table.created_utc}) is "
                                  f"already entry {k + 1}; not appending it twice")
    if s.tables and _parse_utc(table.created_utc) < _parse_utc(s.tables[-1].created_utc):
        raise StationHistoryError(
            f"{path}: table created {table.created_utc} is older than the latest entry "
            f"({s.tables[-1].created_utc}); the history is kept in time order")


@dataclass(frozen=True)
class Appended:
    """What :func:`append_compared` recorded.

    Attributes
    ----------
    path : the history file.
    entry : the new entry's number in the file (1-based; ``len(history) + 1``).
    table : the table as recorded: ``created_utc`` is the time taken under the lock.
    history : the entries before it, as read and verified under the lock (oldest first).
    comparison : :func:`compare` of ``table`` with ``history``.
    warnings : the history's warnings (a skipped fragment of an interrupted write).
    """

    path: Path
    entry: int
    table: BiasTable
    history: list
    comparison: pd.DataFrame
    warnings: list


def append_compared(table: BiasTable, stations_root: str | os.PathLike | None = None, *,
                    threshold_sigma: float = 3.0, family_alpha: float = 0.05,
                    timeout_s: float = LOCK_TIMEOUT_S) -> Appended:
    """Record a new estimate: under the history's lock, read, date, compare and append.

    Concurrent calibrations of one facility are serialised by the lock, so each compares its
    estimate with every entry recorded before it and none is refused as "older than the
    latest entry": the entry is dated *under the lock* (``created_utc`` = now, or 1 µs after
    the latest entry if the clock reads earlier: a clock stepped back, another machine's
    clock), which makes file order, time order and lock order one order.

    Parameters
    ----------
    table : the estimate; its ``created_utc`` is replaced by the time of recording.
    stations_root : the directory holding ``stations/`` (None: :func:`stations_root`).
    threshold_sigma, family_alpha : as in :func:`compare`.
    timeout_s : how long to wait for another append's lock.

    Returns
    -------
    :class:`Appended` (the recorded table, the history it was compared with, the comparison).

    Raises
    ------
    StationHistoryError, OSError : as :func:`append_entry`; nothing is appended.
    """
    path = history_path(stations_root, table.facility)
    with _history_lock(path, timeout_s):
        s = _scan(path, table.facility)
        now = _parse_utc(utc_now())
        if s.tables:
            now = max(now, _parse_utc(s.tables[-1].created_utc) + timedelta(microseconds=1))
        table = replace(table, created_utc=now.strftime("%Y-%m-%dT%H:%M:%S.%fZ"))
        comparison = compare(table, s.tables, threshold_sigma=threshold_sigma,
                             family_alpha=family_alpha)
        _check_new(path, table, s)
        entry = _write_entry(path, table, s)
    return Appended(path, entry, table, list(s.tables), comparison, list(s.warnings))


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError, AttributeError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def current_table(history: list[BiasTable]) -> BiasTable | None:
    """The latest entry of a history (its last line; the file is in time order), or None."""
    return history[-1] if history else None


# --------------------------------------------------------------------------- comparison


def family_threshold(n_tests: int, family_alpha: float) -> float:
    """|z| above which one of ``n_tests`` independent N(0, 1) statistics is flagged so that the
    chance of *any* false flag among them is exactly ``family_alpha`` (Sidak):
    ``Phi^-1(1 - (1 - (1 - family_alpha)**(1 / n_tests)) / 2)``. For 64 tests and 0.05: 3.35."""
    if n_tests <= 0:
        return math.inf
    if not 0 < family_alpha < 1:
        raise ValueError(f"family_alpha must be in (0, 1), got {family_alpha}")
    per_test = -math.expm1(math.log1p(-family_alpha) / n_tests)   # 1 - (1-a)^(1/m)
    return NormalDist().inv_cdf(1 - per_test / 2)


def family_false_alarm(n_tests: int, threshold_sigma: float) -> float:
    """Chance that at least one of ``n_tests`` independent N(0, 1) statistics exceeds
    ``threshold_sigma`` in magnitude: ``1 - (1 - 2 (1 - Phi(t)))**n``. For 64 tests at 3 sigma:
    0.159."""
    p = 2 * (1 - NormalDist().cdf(threshold_sigma))
    return -math.expm1(n_tests * math.log1p(-p))


def compare(new: BiasTable, history: list[BiasTable], *, threshold_sigma: float = 3.0,
            family_alpha: float = 0.05) -> pd.DataFrame:
    """Compare a new bias table with the latest one of a history, station by station.

    Two questions per station and channel, each as a per-test z, a per-test flag at
    ``threshold_sigma`` and a family-wise flag:

    * moved: ``z_move = (bias - previous_bias) / sqrt(sigma**2 + previous_sigma**2)``;
    * biased: ``z_bias = bias / sigma`` (the bias is significantly non-zero).

    With 16 stations x 4 channels = 64 tests, a per-test 3-sigma threshold flags at least one
    channel of an unchanged facility in ~16% of comparisons (:func:`family_false_alarm`). The
    ``*_family`` flags use the Sidak threshold (:func:`family_threshold`) for the number of
    tests actually made, so an unchanged facility raises *any* family-wise flag in
    ``family_alpha`` of comparisons (5% by default; 3.35 sigma for 64 tests). Use ``moved`` to
    list candidates, ``moved_family`` to decide that the facility changed.

    The z values assume the two estimates are independent (no shared shots; a warning in
    ``attrs["warnings"]`` otherwise) and ignore the correlation between stations that the
    estimate's gauge introduces.

    Parameters
    ----------
    new : the new table.
    history : earlier tables, oldest first (:func:`load_history`). The latest entry that is not
        ``new`` itself is the reference; an empty history leaves the move columns NaN/False.
    threshold_sigma : per-test threshold on |z|.
    family_alpha : family-wise false-alarm probability of the ``*_family`` flags.

    Returns
    -------
    DataFrame, one row per station and channel (station order of ``new``, channels x, y, z,
    time): station, channel, unit, bias, sigma, z_bias, biased, biased_family, previous_bias,
    previous_sigma, difference, sigma_difference, z_move, moved, moved_family. Values in SI
    (``unit``: m or s). ``attrs`` holds the thresholds, the numbers of tests, the reference
    entry's created_utc, the documented false-alarm rates and warnings.
    """
    if threshold_sigma <= 0:
        raise ValueError(f"threshold_sigma must be > 0, got {threshold_sigma}")
    digest = table_sha256(new)
    prev = None
    for t in reversed(history):
        if t.facility != new.facility:
            raise StationHistoryError(f"compare: history entry {t.created_utc} is for facility "
                                      f"{t.facility!r}, the new table for {new.facility!r}")
        if table_sha256(t) != digest:
            prev = t
            break
    warns = []
    n = new.stations.size
    pb = np.full((n, 4), np.nan)
    ps = np.full((n, 4), np.nan)
    if prev is not None:
        for i, st in enumerate(new.stations):
            hit = np.flatnonzero(prev.stations == st)
            if hit.size:
                pb[i] = np.where(prev.estimated[hit[0]], prev.bias[hit[0]], np.nan)
                ps[i] = prev.sigma[hit[0]]
            else:
                warns.append(f"station {st}: not in the previous table ({prev.created_utc})")
        shared = sorted(set(new.shots) & set(prev.shots))
        if shared:
            warns.append(f"shots {shared} are in both estimates: they are correlated and the "
                         f"move z values are too small")
    b = np.where(new.estimated, new.bias, np.nan)
    s = new.sigma
    with np.errstate(invalid="ignore"):
        z_bias = b / s
        diff = b - pb
        sd = np.hypot(s, ps)
        z_move = diff / sd
    n_bias = int(np.count_nonzero(np.isfinite(z_bias)))
    n_move = int(np.count_nonzero(np.isfinite(z_move)))
    t_bias = family_threshold(n_bias, family_alpha)
    t_move = family_threshold(n_move, family_alpha)
    with np.errstate(invalid="ignore"):
        az_b, az_m = np.abs(z_bias), np.abs(z_move)
        flags = {"biased": az_b > threshold_sigma, "biased_family": az_b > t_bias,
                 "moved": az_m > threshold_sigma, "moved_family": az_m > t_move}
    df = pd.DataFrame({
        "station": np.repeat(new.stations, 4),
        "channel": np.tile(CHANNELS, n),
        "unit": np.tile(UNITS, n),
        "bias": b.ravel(), "sigma": s.ravel(), "z_bias": z_bias.ravel(),
        "biased": flags["biased"].ravel(), "biased_family": flags["biased_family"].ravel(),
        "previous_bias": pb.ravel(), "previous_sigma": ps.ravel(), "difference": diff.ravel(),
        "sigma_difference": sd.ravel(), "z_move": z_move.ravel(),
        "moved": flags["moved"].ravel(), "moved_family": flags["moved_family"].ravel(),
    })
    df.attrs.update({
        "facility": new.facility, "created_utc": new.created_utc,
        "previous_created_utc": None if prev is None else prev.created_utc,
        "threshold_sigma": threshold_sigma, "family_alpha": family_alpha,
        "n_move_tests": n_move, "n_bias_tests": n_bias,
        "family_threshold_move": t_move, "family_threshold_bias": t_bias,
        "per_test_family_false_alarm_move": family_false_alarm(n_move, threshold_sigma),
        "per_test_family_false_alarm_bias": family_false_alarm(n_bias, threshold_sigma),
        "warnings": warns,
    })
    return df

__all__ = [
    "BIAS_COLUMNS", "CHANNELS", "HISTORY_FILENAME", "HISTORY_FORMAT", "LOCK_TIMEOUT_S",
    "SIGMA_COLUMNS", "STATIONS_ROOT_ENV", "TABLE_COLUMNS", "TABLE_FORMAT", "UNITS", "Appended",
    "BiasTable", "StationHistoryError", "append_compared", "append_entry",
    "bias_table_to_frame", "canonical_json", "compare", "current_table", "family_false_alarm",
    "family_threshold", "frame_to_bias_table", "history_dir", "history_path", "load_bias_table",
    "load_history", "save_bias_table", "stations_root", "table_sha256", "utc_now",
]
