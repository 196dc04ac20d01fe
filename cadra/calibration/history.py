"""Per-facility station bias history: an append-only record of sphere-calibration bias tables.

A :class:`BiasTable` is what a calibration estimated for each station of one facility: the
position bias (x, y, z in m, facility frame F, docs/conventions.md: what the station *adds* to
the measured position of the model's reference point) and the spark-time error (s), each with
its 1-sigma. The history of a facility is ``<root>/stations/<facility>/bias_history.jsonl``:
one JSON object per line, appended and never rewritten (docs/calibration.md, "Station
history"). A plain bias table for one fit (``cadra2 fit --bias-table FILE``) is a CSV with units
in the column names (:func:`save_bias_table`, :func:`load_bias_table`).

The history file is the record a facility keeps for years, so every read checks it fully:

* each line carries the SHA-256 of its canonical JSON (:func:`canonical_json`); a line whose
  hash does not match, or that is not JSON, is an error naming the line (never skipped);
* an entry naming another facility is refused, naming both;
* an append interrupted midway (power cut, full disk) leaves at most a partial *last* line,
  which :func:`load_history` reports as a warning and skips. The next append starts a new line
  (the fragment's bytes stay in place, never rewritten) and records the fragment's line number,
  length and SHA-256 in the new entry (``after_fragment``); a later read accepts that fragment
  only because the entry after it vouches for exactly those bytes.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from statistics import NormalDist

import numpy as np
import pandas as pd

from cadra.io.atomic import atomic_write_text

#: format key of a history entry (one line of ``bias_history.jsonl``)
HISTORY_FORMAT = "cadra-station-bias-1"
#: format key of a plain bias-table CSV (first header line)
TABLE_FORMAT = "cadra-station-bias-table-1"
#: history file name inside ``stations/<facility>/``
HISTORY_FILENAME = "bias_history.jsonl"
#: the four bias channels and their SI units (column suffixes at the file boundary)
CHANNELS = ("x", "y", "z", "time")
UNITS = ("m", "m", "m", "s")
BIAS_COLUMNS = tuple(f"bias_{c}_{u}" for c, u in zip(CHANNELS, UNITS, strict=True))
SIGMA_COLUMNS = tuple(f"sigma_{c}_{u}" for c, u in zip(CHANNELS, UNITS, strict=True))
TABLE_COLUMNS = ("station", *BIAS_COLUMNS, *SIGMA_COLUMNS)

_ENTRY_KEYS = frozenset({"format", "facility", "created_utc", "stations", *BIAS_COLUMNS,
                         *SIGMA_COLUMNS, "shots", "method", "note"})
_FACILITY_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


class StationHistoryError(ValueError):
    """A history file or bias table that cannot be trusted; the message names the file and line
    and says why. Nothing is written when an append is refused."""


# --------------------------------------------------------------------------- the table


@dataclass(frozen=True, eq=False)
class BiasTable:
    """Station biases of one facility, as estimated by one calibration.

    Attributes
    ----------
    facility : facility name (``facilities/<name>.toml``, e.g. ``"hffaf"``).
    created_utc : ISO 8601 UTC time of the estimate, e.g. ``"2026-11-22T21:30:00Z"``.
    stations : (n,) int, station ids, unique.
    bias : (n, 4) float, columns x_m, y_m, z_m, time_s: what the station adds to the measured
        position (m, facility frame F) and its spark-time error (s). 0 where not estimated.
    sigma : (n, 4) float, 1-sigma of ``bias`` in the same units; NaN where a channel was not
        estimated (the bias is then 0).
    shots : ids of the shots the estimate came from.
    method : free text: how the table was made.
    note : free text.

    The arrays are read-only copies; construction validates shapes, finiteness and the
    NaN-sigma / zero-bias rule and raises :class:`StationHistoryError` otherwise.
    """

    facility: str
    created_utc: str
    stations: np.ndarray
    bias: np.ndarray
    sigma: np.ndarray
    shots: tuple[str, ...]
    method: str = ""
    note: str = ""

    def __post_init__(self):
        _check_facility_name(self.facility)
        _parse_utc(self.created_utc)
        st = np.asarray(self.stations)
        if st.ndim != 1 or st.size == 0:
            raise StationHistoryError(f"stations: expected a non-empty 1-D array, got shape "
                                      f"{st.shape}")
        if not np.issubdtype(st.dtype, np.integer):
            if not (np.issubdtype(st.dtype, np.floating) and np.all(st == np.round(st))):
                raise StationHistoryError(f"stations: expected integer ids, got {st.dtype}")
        st = st.astype(np.int64)
        if np.unique(st).size != st.size:
            dup = sorted({int(s) for s in st if np.count_nonzero(st == s) > 1})
            raise StationHistoryError(f"stations: ids {dup} appear more than once")
        n = st.size
        bias = np.array(self.bias, dtype=float)
        sigma = np.array(self.sigma, dtype=float)
        for name, a in (("bias", bias), ("sigma", sigma)):
            if a.shape != (n, 4):
                raise StationHistoryError(f"{name}: expected shape ({n}, 4) "
                                          f"(x_m, y_m, z_m, time_s), got {a.shape}")
        if not np.all(np.isfinite(bias)):
            raise StationHistoryError("bias: non-finite values (use 0 with sigma NaN for a "
                                      "channel that was not estimated)")
        est = ~np.isnan(sigma)
        if np.any(np.isinf(sigma)) or np.any(sigma[est] <= 0):
            raise StationHistoryError("sigma: must be > 0 and finite, or NaN (not estimated)")
        bad = ~est & (bias != 0)
        if np.any(bad):
            i, j = np.argwhere(bad)[0]
            raise StationHistoryError(f"station {st[i]} {CHANNELS[j]}: sigma NaN (not "
                                      f"estimated) but bias {bias[i, j]!r} (must be 0)")
        shots = tuple(self.shots) if not isinstance(self.shots, str) else (self.shots,)
        if not all(isinstance(s, str) and s for s in shots):
            raise StationHistoryError(f"shots: expected non-empty strings, got {shots!r}")
        for name in ("method", "note"):
            if not isinstance(getattr(self, name), str):
                raise StationHistoryError(f"{name}: expected a string")
        for a in (st, bias, sigma):
            a.setflags(write=False)
        object.__setattr__(self, "stations", st)
        object.__setattr__(self, "bias", bias)
        object.__setattr__(self, "sigma", sigma)
        object.__setattr__(self, "shots", shots)

    @property
    def estimated(self) -> np.ndarray:
        """(n, 4) bool: channels that were estimated (finite sigma)."""
        return ~np.isnan(self.sigma)

    def row(self, station: int) -> int:
        """Row index of ``station`` (KeyError if absent)."""
        hit = np.flatnonzero(self.stations == int(station))
        if hit.size == 0:
            raise KeyError(f"{self.facility} bias table {self.created_utc}: no station "
                           f"{station}")
        return int(hit[0])


def _check_facility_name(name) -> None:
    if not isinstance(name, str) or not _FACILITY_RE.match(name):
        raise StationHistoryError(f"facility: expected a plain name such as 'hffaf' (letters, "
                                  f"digits, _ . -), got {name!r}")


def _parse_utc(text) -> datetime:
    if not isinstance(text, str):
        raise StationHistoryError(f"created_utc: expected an ISO 8601 string, got {text!r}")
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        raise StationHistoryError(f"created_utc: {text!r} is not ISO 8601 "
                                  f"(e.g. '2026-11-22T21:30:00Z')") from None
    if t.tzinfo is None or t.utcoffset().total_seconds() != 0:
        raise StationHistoryError(f"created_utc: {text!r} must be UTC ('...Z' or '+00:00')")
    return t


def utc_now() -> str:
    """The current time as ``YYYY-MM-DDTHH:MM:SS.ffffffZ``.

    Microseconds, so two estimates made one after the other (the same sphere shots calibrated
    twice within a second) are two tables, not one table recorded twice."""
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


# --------------------------------------------------------------------------- canonical JSON


def canonical_json(obj) -> str:
    """The canonical JSON text hashed by the history: keys sorted, no spaces (separators
    ``","`` and ``":"``), ASCII only, no NaN (a missing sigma is ``null``), floats in Python's
    shortest round-trip form."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                      allow_nan=False)


def _sha256(text: str | bytes) -> str:
    return hashlib.sha256(text.encode("ascii") if isinstance(text, str) else text).hexdigest()


def _entry_dict(table: BiasTable) -> dict:
    d = {"format": HISTORY_FORMAT, "facility": table.facility,
         "created_utc": table.created_utc, "stations": [int(s) for s in table.stations],
         "shots": list(table.shots), "method": table.method, "note": table.note}
    for j, col in enumerate(BIAS_COLUMNS):
        d[col] = [float(v) for v in table.bias[:, j]]
    for j, col in enumerate(SIGMA_COLUMNS):
        d[col] = [None if math.isnan(v) else float(v) for v in table.sigma[:, j]]
    return d


def table_sha256(table: BiasTable) -> str:
    """SHA-256 of the table's content (its history entry without ``after_fragment``): equal
    for two tables with identical facility, time, numbers, shots, method and note."""
    return _sha256(canonical_json(_entry_dict(table)))


def _table_from_entry(d: dict, where: str) -> BiasTable:
    missing = sorted(_ENTRY_KEYS - set(d))
    if missing:
        raise StationHistoryError(f"{where}: missing keys {missing}")
    unknown = sorted(set(d) - _ENTRY_KEYS - {"after_fragment"})
    if unknown:
        raise StationHistoryError(f"{where}: unknown keys {unknown}")
    n = len(d["stations"]) if isinstance(d["stations"], list) else -1
    cols = []
    for col in (*BIAS_COLUMNS, *SIGMA_COLUMNS):
        v = d[col]
        if not isinstance(v, list) or len(v) != n:
            raise StationHistoryError(f"{where}: {col} must be a list of {n} values (one per "
                                      f"station)")
        if not all(x is None or (isinstance(x, int | float) and not isinstance(x, bool))
                   for x in v):
            raise StationHistoryError(f"{where}: {col} holds non-numbers")
        if col in BIAS_COLUMNS and any(x is None for x in v):
            raise StationHistoryError(f"{where}: {col} holds null (a bias not estimated is 0)")
        cols.append([math.nan if x is None else float(x) for x in v])
    if not all(isinstance(s, int) and not isinstance(s, bool) for s in d["stations"]):
        raise StationHistoryError(f"{where}: stations must be integers")
    if not isinstance(d["shots"], list):
        raise StationHistoryError(f"{where}: shots must be a list of strings")
    arr = np.array(cols, dtype=float).reshape(8, n).T
    try:
        return BiasTable(facility=d["facility"], created_utc=d["created_utc"],
                         stations=np.array(d["stations"], dtype=np.int64), bias=arr[:, :4],
                         sigma=arr[:, 4:], shots=tuple(d["shots"]), method=d["method"],
                         note=d["note"])
    except StationHistoryError as exc:
        raise StationHistoryError(f"{where}: {exc}") from None


# --------------------------------------------------------------------------- history file


def history_dir(root: str | os.PathLike | None, facility: str) -> Path:
    """``<root>/stations/<facility>/``: where a facility's station history lives.

    Parameters
    ----------
    root : the directory holding ``stations/`` (the repository or working directory root);
        None means the current working directory.
    facility : facility name, e.g. ``"hffaf"``.
    """
    _check_facility_name(facility)
    return (Path.cwd() if root is None else Path(root)) / "stations" / facility


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


def _reject_constant(name):
    raise ValueError(f"{name} is not allowed")


def _no_duplicates(pairs):
    keys = [k for k, _ in pairs]
    if len(set(keys)) != len(keys):
        raise ValueError("duplicate keys")
    return dict(pairs)


def _parse_line(raw: bytes):
    try:
        return json.loads(raw.decode("ascii"), parse_constant=_reject_constant,
                          object_pairs_hook=_no_duplicates)
    except (UnicodeDecodeError, ValueError):
        return None


def _scan(path: Path, facility: str) -> _Scan:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return _Scan([], [], [], 0, True, None)
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
def _locked(fh):
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows: single-writer by convention
        yield
        return
    fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
    try:
        yield
    finally:
        fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def append_entry(table: BiasTable, stations_root: str | os.PathLike | None) -> Path:
    """Append ``table`` to ``<stations_root>/stations/<facility>/bias_history.jsonl``.

    The existing file is verified first (:func:`load_history`; any error refuses the append
    and nothing is written). The new line (with its SHA-256) is written in one ``write`` call
    in append mode, flushed and fsynced; the file is never rewritten. After a partial last
    line (an interrupted write) the new entry starts on a new line and records the fragment
    (``after_fragment``: line, bytes, sha256) so later reads accept it.

    Parameters
    ----------
    table : the bias table; its ``facility`` chooses the history.
    stations_root : the directory holding ``stations/`` (see :func:`history_dir`).

    Returns
    -------
    The history file's path.

    Raises
    ------
    StationHistoryError : the history is corrupt or belongs to another facility, the table is
        older than the latest entry, or the same table is already recorded.
    """
    path = history_path(stations_root, table.facility)
    new_dir = not path.parent.exists()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "ab") as fh, _locked(fh):
        s = _scan(path, table.facility)
        digest = table_sha256(table)
        if digest in s.hashes:
            k = s.hashes.index(digest)
            raise StationHistoryError(f"{path}: this table (created {table.created_utc}) is "
                                      f"already entry {k + 1}; not appending it twice")
        if s.tables and _parse_utc(table.created_utc) < _parse_utc(s.tables[-1].created_utc):
            raise StationHistoryError(
                f"{path}: table created {table.created_utc} is older than the latest entry "
                f"({s.tables[-1].created_utc}); the history is kept in time order")
        d = _entry_dict(table)
        if s.fragment is not None:
            d["after_fragment"] = s.fragment
        line = canonical_json({**d, "sha256": _sha256(canonical_json(d))})
        payload = (b"" if s.terminated else b"\n") + line.encode("ascii") + b"\n"
        fh.write(payload)
        fh.flush()
        os.fsync(fh.fileno())
    if new_dir or s.size == 0:
        _fsync_dir(path.parent)
    return path


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


# --------------------------------------------------------------------------- plain CSV table


def bias_table_to_frame(table: BiasTable) -> pd.DataFrame:
    """The table as a DataFrame with columns :data:`TABLE_COLUMNS` (station, bias_x_m, ...,
    sigma_time_s; SI, NaN sigma = not estimated); facility, created_utc, shots, method and
    note in ``attrs``."""
    df = pd.DataFrame({"station": table.stations.astype(np.int64)})
    for j, col in enumerate(BIAS_COLUMNS):
        df[col] = table.bias[:, j]
    for j, col in enumerate(SIGMA_COLUMNS):
        df[col] = table.sigma[:, j]
    df.attrs.update({"facility": table.facility, "created_utc": table.created_utc,
                     "shots": list(table.shots), "method": table.method, "note": table.note})
    return df


def frame_to_bias_table(df: pd.DataFrame, facility: str, created_utc: str | None = None,
                        shots=(), method: str = "", note: str = "") -> BiasTable:
    """A :class:`BiasTable` from a DataFrame with columns :data:`TABLE_COLUMNS` (exactly those,
    any order; units are in the names, so a column in other units is refused as unknown).

    ``created_utc`` None means now (:func:`utc_now`).
    """
    cols = [str(c) for c in df.columns]
    missing = [c for c in TABLE_COLUMNS if c not in cols]
    unknown = [c for c in cols if c not in TABLE_COLUMNS]
    if missing or unknown:
        raise StationHistoryError(f"bias table columns: missing {missing}, unknown {unknown}; "
                                  f"expected {list(TABLE_COLUMNS)} (SI, units in the names)")
    try:
        values = df[[*BIAS_COLUMNS, *SIGMA_COLUMNS]].to_numpy(dtype=float)
    except (TypeError, ValueError) as exc:
        raise StationHistoryError(f"bias table: non-numeric values ({exc})") from None
    return BiasTable(facility=facility, created_utc=created_utc or utc_now(),
                     stations=df["station"].to_numpy(), bias=values[:, :4],
                     sigma=values[:, 4:], shots=tuple(shots), method=method, note=note)


def save_bias_table(table: BiasTable, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write a plain bias-table CSV (atomic; refuses an existing file unless ``overwrite``).

    Header lines ``# format: cadra-station-bias-table-1``, ``# facility: <name>``,
    ``# created_utc: <time>``, then ``# shots:``, ``# method:``, ``# note:`` with JSON values,
    then the CSV (columns :data:`TABLE_COLUMNS`, full float precision, empty = NaN).
    """
    head = [f"# format: {TABLE_FORMAT}", f"# facility: {table.facility}",
            f"# created_utc: {table.created_utc}", f"# shots: {json.dumps(list(table.shots))}",
            f"# method: {json.dumps(table.method)}", f"# note: {json.dumps(table.note)}"]
    body = bias_table_to_frame(table).to_csv(index=False, lineterminator="\n")
    return atomic_write_text(path, "\n".join(head) + "\n" + body, overwrite=overwrite)


def load_bias_table(path: str | os.PathLike) -> BiasTable:
    """Read a bias-table CSV written by :func:`save_bias_table` (or by hand in that layout:
    the ``# facility:`` and ``# created_utc:`` lines are required, the others optional)."""
    path = Path(path)
    lines = path.read_text(encoding="utf-8").splitlines()
    meta, k = {}, 0
    while k < len(lines) and lines[k].startswith("#"):
        key, sep, value = lines[k][1:].partition(":")
        if not sep:
            raise StationHistoryError(f"{path}: line {k + 1}: expected '# key: value'")
        meta[key.strip()] = value.strip()
        k += 1
    fmt = meta.get("format", TABLE_FORMAT)
    if fmt != TABLE_FORMAT:
        raise StationHistoryError(f"{path}: format {fmt!r}, expected {TABLE_FORMAT!r}")
    for key in ("facility", "created_utc"):
        if key not in meta:
            raise StationHistoryError(f"{path}: no '# {key}: ...' header line")
    extra = {}
    for key, default in (("shots", []), ("method", ""), ("note", "")):
        try:
            extra[key] = json.loads(meta[key]) if key in meta else default
        except ValueError:
            raise StationHistoryError(f"{path}: '# {key}:' must be a JSON value") from None
    from io import StringIO

    df = pd.read_csv(StringIO("\n".join(lines[k:])))
    try:
        return frame_to_bias_table(df, meta["facility"], meta["created_utc"],
                                   shots=tuple(extra["shots"]), method=extra["method"],
                                   note=extra["note"])
    except StationHistoryError as exc:
        raise StationHistoryError(f"{path}: {exc}") from None


__all__ = [
    "BIAS_COLUMNS", "CHANNELS", "HISTORY_FILENAME", "HISTORY_FORMAT", "SIGMA_COLUMNS",
    "TABLE_COLUMNS", "TABLE_FORMAT", "UNITS", "BiasTable", "StationHistoryError",
    "append_entry", "bias_table_to_frame", "canonical_json", "compare", "current_table",
    "family_false_alarm", "family_threshold", "frame_to_bias_table", "history_dir",
    "history_path", "load_bias_table", "load_history", "save_bias_table", "table_sha256",
    "utc_now",
]
