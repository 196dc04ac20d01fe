"""The trajectory measurement file: stage one's output, stage two's input (docs/stage1.md).

A CSV file, one row per station, units in the column names, preceded by ``# key: value``
metadata lines (shot id, shot file, facility, producer). Angles are degrees in the file and
radians inside CADRA; the conversion happens here and nowhere else.

Columns (in this order):

======================  ====================================================================
``station``             station id (facility file)
``t_s``                 spark time from the shot file, s
``status``              ``ok``, ``warning`` (measured; see ``warnings``) or ``failed``
``x_m, y_m, z_m``       reference point of the body in the facility frame F, m
``theta_deg, psi_deg``  inclinations of the nose axis to the x-y plane (+ up) and to the
                        x-z plane (+ port), deg (docs/conventions.md); empty for a sphere
``phi_deg``             roll angle about the nose axis, deg (aircraft 3-2-1 roll; continuous
                        along the shot or wrapped, either is read); empty where not measured
                        (a body of revolution). Optional: a file may leave out ``phi_deg`` and
                        ``sigma_phi_deg`` (files written before the roll channel)
``sigma_*``             1-sigma of each of the above (same unit)
``x_top_minus_side_m``  x seen by the top view minus x seen by the side view, m
``x_consistency``       that difference over its sigma
``reason``              why a station failed
``warnings``            what to know about a measured station (``;``-separated)
======================  ====================================================================

Missing values (a failed station, a sphere's angles) are empty cells (NaN). Loading refuses,
naming the station and the column: text where a number belongs, ``inf``, a sigma that is not
> 0 beside a value, and magnitudes no range produces (:data:`LIMITS`).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.atomic import atomic_write_text
from cadra.channels import OBSERVED, to_si, trajectory_sigma_columns, trajectory_value_columns

FORMAT = "cadra-trajectory-1"

#: every column a file may have, in file order; the value and sigma columns come from the
#: channel registry (:mod:`cadra.channels`: a channel added there is a column pair here)
ALL_COLUMNS = (
    "station", "t_s", "status",
    *trajectory_value_columns(),
    *trajectory_sigma_columns(),
    "x_top_minus_side_m", "x_consistency", "reason", "warnings",
)
#: an optional channel's columns (the roll, ``phi_deg`` and ``sigma_phi_deg``): written when a
#: table measures it, read as "not measured" when a file leaves them out
OPTIONAL_COLUMNS = tuple(c for ch in OBSERVED if ch.optional
                         for c in (ch.value_column, ch.sigma_column))
#: the columns every file has
COLUMNS = tuple(c for c in ALL_COLUMNS if c not in OPTIONAL_COLUMNS)
STATUSES = ("ok", "warning", "failed")
#: largest plausible magnitude of each numeric column, file units (larger is a unit slip or
#: a corrupted file): positions 10 km, angles 180 deg, times 3600 s (a wind-tunnel record's
#: frames; the shot file holds a range's spark times to 10 s); a
#: roll carried continuously along a shot may run to many turns (1e7 deg: 20,000 rad/s for
#: 10 s)
LIMITS = {"t_s": 3600.0, "x_top_minus_side_m": 1e4, "x_consistency": 1e12,
          **{c.value_column: (1e7 if c.periodic else 180.0 if c.file_unit == "deg" else 1e4)
             for c in OBSERVED},
          **{c.sigma_column: (180.0 if c.file_unit == "deg" else 1e4) for c in OBSERVED}}


class TrajectoryFileError(ValueError):
    """A trajectory file that cannot be right; the message names the column or line."""


@dataclass(frozen=True)
class Trajectory:
    """A loaded trajectory measurement: ``table`` (SI: angles converted to rad in columns
    ``theta_rad``, ``psi_rad``, ``sigma_theta_rad``, ``sigma_psi_rad``) and ``meta``."""

    table: pd.DataFrame
    meta: dict

    @property
    def measured(self) -> pd.DataFrame:
        """Rows with a measurement (status ok or warning)."""
        return self.table[self.table["status"] != "failed"]


def header_value(text: str) -> str:
    """A metadata value as its ``# key: value`` line holds it: as it is, unless it would break
    the line or not read back the same (a line break of any kind in a path, surrounding
    blanks, a leading quote): then as a JSON string (:func:`read_header_value`)."""
    if text != text.strip() or text.startswith('"') or text.splitlines() not in ([], [text]):
        return json.dumps(text)
    return text


def read_header_value(text: str) -> str:
    """The value of a ``# key: value`` line (:func:`header_value`'s inverse)."""
    if text.startswith('"'):
        try:
            value = json.loads(text)
        except ValueError:
            return text
        if isinstance(value, str):
            return value
    return text


def trajectory_to_csv(table: pd.DataFrame, meta: dict) -> str:
    """CSV text (with the ``#`` metadata header) of a table with :data:`COLUMNS`, and an
    optional channel's two columns (:data:`OPTIONAL_COLUMNS`) where the table has a value in
    them (a body of revolution's file is as it was before the roll channel)."""
    missing = [c for c in COLUMNS if c not in table]
    if missing:
        raise TrajectoryFileError(f"trajectory table lacks columns {missing}")
    written = [c for ch in OBSERVED if ch.optional
               if ch.value_column in table
               and pd.to_numeric(table[ch.value_column], errors="coerce").notna().any()
               for c in (ch.value_column, ch.sigma_column)]
    missing = [c for c in written if c not in table]
    if missing:
        raise TrajectoryFileError(f"trajectory table lacks columns {missing}")
    columns = [c for c in ALL_COLUMNS if c in COLUMNS or c in written]
    head = [f"# format: {FORMAT}"]
    for k, v in meta.items():
        head.append(f"# {k}: {header_value(str(v))}")
    body = table.loc[:, columns].to_csv(index=False, float_format="%.10g",
                                             lineterminator="\n")
    return "\n".join(head) + "\n" + body


def write_trajectory(path: str | os.PathLike, table: pd.DataFrame, meta: dict,
                     overwrite: bool = False) -> Path:
    """Write atomically (refuses to overwrite unless told)."""
    return atomic_write_text(path, trajectory_to_csv(table, meta), overwrite=overwrite)


def load_trajectory(path: str | os.PathLike) -> Trajectory:
    """Read and validate a trajectory file; angles become radians."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FileNotFoundError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise TrajectoryFileError(f"{path}: not a text file (not UTF-8 at byte {exc.start})"
                                  ) from None
    meta = {}
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        key, _, value = line[1:].partition(":")
        meta[key.strip()] = read_header_value(value.strip())
    if meta.get("format") != FORMAT:
        raise TrajectoryFileError(f"{path}: not a CADRA trajectory file (format "
                                  f"{meta.get('format')!r}, expected {FORMAT!r})")
    import io

    table = _read_csv(io.StringIO(text), path, comment="#", keep_default_na=True, dtype=str)
    for ch in OBSERVED:       # an optional channel's columns may be left out: not measured
        if ch.optional and ch.value_column not in table and ch.sigma_column not in table:
            table[ch.value_column] = ""
            table[ch.sigma_column] = ""
    return trajectory_from_table(table, meta, path)


def trajectory_from_table(table: pd.DataFrame, meta: dict | None = None,
                          source: str | os.PathLike = "trajectory table") -> Trajectory:
    """A stage-one table in memory (:data:`ALL_COLUMNS`, file units: what
    :func:`station_rows` makes and a trajectory file holds) validated as
    :func:`load_trajectory` validates a file, with the SI columns added: the hand-off from
    stage one to stage two without a file. ``source`` names the table in messages."""
    table = table.copy()
    for ch in OBSERVED:       # an optional channel's columns may be left out: not measured
        if ch.optional and ch.value_column not in table and ch.sigma_column not in table:
            table[ch.value_column] = np.nan
            table[ch.sigma_column] = np.nan
    missing = [c for c in ALL_COLUMNS if c not in table]
    if missing:
        raise TrajectoryFileError(f"{source}: missing column(s) {missing}")
    if table.empty:
        raise TrajectoryFileError(f"{source}: no stations (a header without rows)")
    for c in ("reason", "warnings", "status"):
        table[c] = table[c].fillna("").astype(str)
    bad = sorted(set(table["status"]) - set(STATUSES))
    if bad:
        raise TrajectoryFileError(f"{source}: column status has unknown value(s) {bad}")
    table = _numeric(table.reset_index(drop=True), source)
    if table["station"].duplicated().any():
        st = int(table.loc[table["station"].duplicated(), "station"].iloc[0])
        raise TrajectoryFileError(f"{source}: station {st} listed twice")
    for ch in OBSERVED:       # SI columns beside the file's (theta_rad beside theta_deg)
        if ch.si_column != ch.value_column:
            table[ch.si_column] = to_si(table[ch.value_column], ch.file_unit)
            table[ch.si_sigma_column] = to_si(table[ch.sigma_column], ch.file_unit)
    return Trajectory(table=table, meta=dict(meta or {}))


def _read_csv(source, path, **kwargs) -> pd.DataFrame:
    """``pd.read_csv(source, **kwargs)``, its failures as one :class:`TrajectoryFileError`
    naming ``path`` (parser errors, empty data and bad UTF-8 are ValueErrors)."""
    try:
        return pd.read_csv(source, **kwargs)
    except (ValueError, OSError) as exc:
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise TrajectoryFileError(f"{path}: not a CSV table ({why})") from None


#: columns a truth table (``--truth``: a simulated shot's ``truth.csv``) must have
TRUTH_COLUMNS = tuple(c.value_column for c in OBSERVED if not c.optional)


def load_truth(path: str | os.PathLike) -> pd.DataFrame:
    """A truth table to draw beside a measurement (``cadra1 --truth``): a CSV file with
    :data:`TRUTH_COLUMNS` (others are kept; an optional channel's column, ``phi_deg``, is
    read when there, as NaN when not). :class:`TrajectoryFileError` naming the file,
    and the row and column of a value that is not a number."""
    path = Path(path)
    if not path.is_file():
        raise TrajectoryFileError(f"{path}: truth table not found")
    table = _read_csv(path, path)
    missing = [c for c in TRUTH_COLUMNS if c not in table]
    if missing:
        raise TrajectoryFileError(f"{path}: truth table lacks column(s) {missing}")
    if table.empty:
        raise TrajectoryFileError(f"{path}: truth table has no rows")
    for ch in OBSERVED:
        if ch.optional and ch.value_column not in table:
            table[ch.value_column] = np.nan
    for c in (ch.value_column for ch in OBSERVED):
        col = table[c]
        if col.dtype == object:  # integers beyond int64 are Python ints: as text, they are inf
            col = col.map(lambda v: v if isinstance(v, float) else str(v))
        num = pd.to_numeric(col, errors="coerce")
        bad = (num.isna() & table[c].notna()) | np.isinf(num)
        if bad.any():
            i = int(bad.to_numpy().argmax())
            v = table[c].iloc[i]
            v = v.item() if isinstance(v, np.generic) else v  # inf, not np.float64(inf)
            raise TrajectoryFileError(f"{path}: row {i + 1}, column {c}: {v!r} is not a finite "
                                      f"number")
        table[c] = num.astype(float)
    return table


def _numeric(table: pd.DataFrame, path: Path) -> pd.DataFrame:
    """The numeric columns as numbers, refusing text, ``inf``, implausible magnitudes and
    sigmas that are not > 0 beside a value; the message names the station and the column."""
    def fail(row, column, what):
        st = str(raw["station"].iloc[row]).strip()
        raise TrajectoryFileError(f"{path}: station {st}, column {column}: {what}")

    raw = table
    table = table.copy()
    for c in ALL_COLUMNS:
        if c in ("status", "reason", "warnings"):
            continue
        if not pd.api.types.is_numeric_dtype(raw[c]):    # text, as a file holds it
            text = raw[c].str.strip()
            num = pd.to_numeric(text, errors="coerce")
            notnum = num.isna() & text.notna() & (text.str.lower() != "nan") & (text != "")
            if notnum.any():
                i = int(notnum.to_numpy().argmax())
                fail(i, c, f"{raw[c].iloc[i]!r} is not a number")
        else:                              # numbers, as a table in memory holds them
            num = pd.to_numeric(raw[c], errors="coerce")
        table[c] = num.astype(float)
    st = table["station"].to_numpy()
    ok = np.isfinite(st) & (st >= 1) & (st == np.round(st)) & (st < 1e9)
    if not ok.all():
        i = int((~ok).argmax())
        raise TrajectoryFileError(f"{path}: row {i + 1}, column station: {raw['station'].iloc[i]!r}"
                                  " is not a station id (an integer >= 1)")
    table["station"] = table["station"].astype(int)
    measured = (table["status"] != "failed").to_numpy()
    for c, limit in LIMITS.items():
        v = table[c].to_numpy()
        with np.errstate(invalid="ignore"):
            bad = np.isinf(v) | (np.abs(v) > limit)
        if bad.any():
            i = int(bad.argmax())
            what = ("is not finite (an empty cell is 'not measured')" if np.isinf(v[i])
                    else f"|{v[i]:g}| > {limit:g} is implausible (check the unit)")
            fail(i, c, f"{raw[c].iloc[i]} {what}")
    t = table["t_s"].to_numpy()
    if (measured & np.isnan(t)).any():
        fail(int((measured & np.isnan(t)).argmax()), "t_s", "no spark time for a measured "
             "station")
    for ch in OBSERVED:
        v, s = table[ch.value_column].to_numpy(), table[ch.sigma_column].to_numpy()
        with np.errstate(invalid="ignore"):
            bad = measured & np.isfinite(v) & ~(s > 0)
        if bad.any():
            i = int(bad.argmax())
            what = "is empty" if np.isnan(s[i]) else f"{s[i]:g} is not a sigma (must be > 0)"
            fail(i, ch.sigma_column, f"{what}: a measured {ch.value_column} needs its sigma "
                                     "(leave the value and its sigma empty for 'not measured')")
    return table


def station_rows(results, times_s: dict) -> pd.DataFrame:
    """Table rows (:data:`ALL_COLUMNS`) from :class:`cadra.imaging.station.StationResult` s
    (the roll from a pose's ``phi_rad`` / ``sigma_phi_rad`` where it has them)."""
    rows = []
    for r in results:
        p = r.pose
        row = {"station": r.station, "t_s": times_s.get(r.station, math.nan),
               "status": r.status, "reason": r.reason, "warnings": "; ".join(r.warnings)}
        if p is not None:
            row.update(x_m=p.x_m, y_m=p.y_m, z_m=p.z_m,
                       theta_deg=math.degrees(p.theta_rad), psi_deg=math.degrees(p.psi_rad),
                       sigma_x_m=p.sigma_x_m, sigma_y_m=p.sigma_y_m, sigma_z_m=p.sigma_z_m,
                       sigma_theta_deg=math.degrees(p.sigma_theta_rad),
                       sigma_psi_deg=math.degrees(p.sigma_psi_rad),
                       phi_deg=math.degrees(getattr(p, "phi_rad", math.nan)),
                       sigma_phi_deg=math.degrees(getattr(p, "sigma_phi_rad", math.nan)),
                       x_top_minus_side_m=p.x_top_minus_side_m,
                       x_consistency=p.x_consistency_sigma)
        rows.append(row)
    table = pd.DataFrame(rows)
    for c in ALL_COLUMNS:
        if c not in table:
            table[c] = math.nan
    return table.loc[:, list(ALL_COLUMNS)].sort_values("station").reset_index(drop=True)
