"""Station bias tables: what one sphere calibration estimated for each station of a facility.

A :class:`BiasTable` holds, per station, the position bias (x, y, z in m, facility frame F,
docs/conventions.md: what the station *adds* to the measured position of the model's reference
point) and the spark-time error (s), each with its 1-sigma. This module defines the table, its
validation, the canonical JSON and SHA-256 of a history entry (the line format of the station
history, :mod:`cadra.calibration.history`) and the plain bias-table CSV of one fit
(``cadra2 fit --bias-table FILE``: :func:`save_bias_table`, :func:`load_bias_table`).
docs/calibration.md, "The bias table".
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.atomic import atomic_write_text

#: format key of a history entry (one line of ``bias_history.jsonl``)
HISTORY_FORMAT = "cadra-station-bias-1"
#: format key of a plain bias-table CSV (first header line)
TABLE_FORMAT = "cadra-station-bias-table-1"
#: the four bias channels and their SI units (column suffixes at the file boundary)
CHANNELS = ("x", "y", "z", "time")
UNITS = ("m", "m", "m", "s")
BIAS_COLUMNS = tuple(f"bias_{c}_{u}" for c, u in zip(CHANNELS, UNITS, strict=True))
SIGMA_COLUMNS = tuple(f"sigma_{c}_{u}" for c, u in zip(CHANNELS, UNITS, strict=True))
TABLE_COLUMNS = ("station", *BIAS_COLUMNS, *SIGMA_COLUMNS)
#: largest plausible |bias| of each channel (SI, CHANNELS' order): 0.1 m of position (a
#: station misplaced by 10 cm no longer sees the model where it expects it) and 1 ms of spark
#: time (metres of flight at range speeds). Larger is a unit slip or a broken estimate
#: (docs/calibration.md)
BIAS_MAX = (0.1, 0.1, 0.1, 1e-3)

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
            if not np.issubdtype(st.dtype, np.floating):
                raise StationHistoryError(f"stations: expected integer ids, got {st.dtype}")
            with np.errstate(invalid="ignore"):
                bad = ~(np.isfinite(st) & (st == np.round(st)) & (np.abs(st) < 2**62))
            if np.any(bad):
                i = int(np.argmax(bad))
                raise StationHistoryError(f"stations: row {i + 1}: {float(st[i])!r} is not a "
                                          f"station id (an integer)")
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
            i, j = np.argwhere(~np.isfinite(bias))[0]
            raise StationHistoryError(f"station {st[i]} {CHANNELS[j]}: bias "
                                      f"{float(bias[i, j])!r} is not finite (use 0 with sigma "
                                      f"NaN for a channel that was not estimated)")
        big = np.abs(bias) > np.array(BIAS_MAX)
        if np.any(big):
            i, j = np.argwhere(big)[0]
            raise StationHistoryError(f"station {st[i]} {CHANNELS[j]}: bias {bias[i, j]:g} "
                                      f"{UNITS[j]} is not a plausible station bias (|bias| <= "
                                      f"{BIAS_MAX[j]:g} {UNITS[j]}; check the unit)")
        est = ~np.isnan(sigma)
        with np.errstate(invalid="ignore"):
            bad_sigma = np.isinf(sigma) | (est & ~(sigma > 0))
        if np.any(bad_sigma):
            i, j = np.argwhere(bad_sigma)[0]
            raise StationHistoryError(f"station {st[i]} {CHANNELS[j]}: sigma "
                                      f"{float(sigma[i, j])!r} must be > 0 and finite, or NaN "
                                      f"(not estimated)")
        bad = ~est & (bias != 0)
        if np.any(bad):
            i, j = np.argwhere(bad)[0]
            raise StationHistoryError(f"station {st[i]} {CHANNELS[j]}: sigma NaN (not "
                                      f"estimated) but bias {float(bias[i, j])!r} (must be 0)")
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
        huge = [i for i, x in enumerate(v) if isinstance(x, int) and abs(x) > 2**1023]
        if huge:   # beyond a float: float() would raise OverflowError
            raise StationHistoryError(f"{where}: {col}[{huge[0]}]: an integer of "
                                      f"{len(str(abs(v[huge[0]])))} digits is not a bias")
        if col in BIAS_COLUMNS and any(x is None for x in v):
            raise StationHistoryError(f"{where}: {col} holds null (a bias not estimated is 0)")
        cols.append([math.nan if x is None else float(x) for x in v])
    if not all(isinstance(s, int) and not isinstance(s, bool) for s in d["stations"]):
        raise StationHistoryError(f"{where}: stations must be integers")
    big = [s for s in d["stations"] if not 0 <= s < 2**62]
    if big:    # beyond int64: numpy would raise OverflowError
        raise StationHistoryError(f"{where}: stations: {big[0]} is not a station id (an "
                                  f"integer >= 0)")
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


def _numeric_column(column: pd.Series, name: str) -> np.ndarray:
    """``column`` as floats (empty = NaN); a cell that is not a number is an error naming its
    row (1-based, data rows) and column. Integers beyond a float become inf (refused later,
    naming the station) rather than an ``OverflowError``."""
    if pd.api.types.is_numeric_dtype(column) and not pd.api.types.is_bool_dtype(column):
        return column.to_numpy(dtype=float)
    text = column.map(lambda v: v if isinstance(v, float) else str(v).strip())
    num = pd.to_numeric(text, errors="coerce")
    blank = text.map(lambda v: isinstance(v, str) and v.lower() in ("", "nan"))
    bad = num.isna() & column.notna() & ~blank.astype(bool)
    if bad.any():
        i = int(bad.to_numpy().argmax())
        raise StationHistoryError(f"row {i + 1}, column {name}: {column.iloc[i]!r} is not a "
                                  f"number")
    return num.to_numpy(dtype=float)


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
    columns = {c: _numeric_column(df[c], c) for c in TABLE_COLUMNS}
    values = np.column_stack([columns[c] for c in (*BIAS_COLUMNS, *SIGMA_COLUMNS)])
    stations = columns["station"]
    if np.isnan(stations).any():
        i = int(np.argmax(np.isnan(stations)))
        raise StationHistoryError(f"row {i + 1}, column station: empty (a station id is "
                                  f"needed)")
    return BiasTable(facility=facility, created_utc=created_utc or utc_now(),
                     stations=stations, bias=values[:, :4],
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
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise StationHistoryError(f"{path}: not a text file (not UTF-8: byte "
                                  f"0x{exc.object[exc.start]:02x} at position {exc.start})"
                                  ) from None
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

    try:
        df = pd.read_csv(StringIO("\n".join(lines[k:])))
    except (ValueError, pd.errors.ParserError) as exc:  # EmptyDataError is a ValueError
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise StationHistoryError(f"{path}: not a CSV table after the header lines ({why})"
                                  ) from None
    try:
        return frame_to_bias_table(df, meta["facility"], meta["created_utc"],
                                   shots=tuple(extra["shots"]), method=extra["method"],
                                   note=extra["note"])
    except StationHistoryError as exc:
        raise StationHistoryError(f"{path}: {exc}") from None


__all__ = [
    "BIAS_COLUMNS", "CHANNELS", "HISTORY_FORMAT", "SIGMA_COLUMNS", "TABLE_COLUMNS",
    "TABLE_FORMAT", "UNITS", "BiasTable", "StationHistoryError", "bias_table_to_frame",
    "canonical_json", "frame_to_bias_table", "load_bias_table", "save_bias_table",
    "table_sha256", "utc_now",
]
