"""The campaign database: SQLite in the campaign folder (schema: docs/campaign.md).

Only the client writes it (:mod:`cadra.campaign.run`); each write is one transaction, so a
run killed at any point leaves the database as it was after its last completed task. The
result tables hold the campaign as its manifest last asked for it: a task's rows are
replaced when the task (the same ``kind:name``) is rerun under a new key. The ``tasks``
table keeps every run of every key.

Any SQLite client reads it; :func:`read_tables` gives every table as a pandas DataFrame, and
:func:`query` runs SQL across several campaigns' databases (docs/campaign.md has examples).
"""

from __future__ import annotations

import os
import sqlite3
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import pandas as pd

FILENAME = "campaign.sqlite"

#: table -> its columns and their SQL types (docs/campaign.md); every result table also has
#: ``task_key``, the key of the task the row came from
SCHEMA: dict[str, dict[str, str]] = {
    "campaign": {"key": "TEXT PRIMARY KEY", "value": "TEXT"},
    "tasks": {"key": "TEXT", "kind": "TEXT", "name": "TEXT", "status": "TEXT",
              "started_utc": "TEXT", "finished_utc": "TEXT", "seconds": "REAL",
              "worker": "TEXT", "error": "TEXT", "result": "TEXT", "current": "INTEGER"},
    "shots": {"shot_id": "TEXT", "role": "TEXT", "body": "TEXT", "group_name": "TEXT",
              "status": "TEXT", "error": "TEXT", "mach": "REAL", "velocity_m_s": "REAL",
              "n_stations": "INTEGER", "stage1_report": "TEXT", "fit_report": "TEXT"},
    "coefficients": {"scope": "TEXT", "name": "TEXT", "model": "TEXT", "parameter": "TEXT",
                     "value": "REAL", "sigma": "REAL", "vary": "INTEGER", "mach": "REAL",
                     "alpha_rms_deg": "REAL", "sigma_rms_deg": "REAL",
                     "sigma_consider": "REAL"},
    "fits": {"scope": "TEXT", "name": "TEXT", "model": "TEXT", "status": "TEXT",
             "converged": "INTEGER", "chi2nu": "REAL", "dof": "INTEGER", "n_shots": "INTEGER",
             "shots": "TEXT", "note": "TEXT", "report": "TEXT"},
    "curves": {"group_name": "TEXT", "coefficient": "TEXT", "angle": "TEXT",
               "angle_deg": "REAL", "mach": "REAL", "value": "REAL", "sigma": "REAL"},
    "hold_study": {"group_name": "TEXT", "parameter": "TEXT", "held_value": "REAL",
                   "status": "TEXT", "converged": "INTEGER", "reduced_chi2": "REAL",
                   "theta_rms_deg": "REAL", "psi_rms_deg": "REAL"},
    "station_biases": {"facility": "TEXT", "station": "INTEGER", "x_m": "REAL",
                       "sigma_x_m": "REAL", "y_m": "REAL", "sigma_y_m": "REAL", "z_m": "REAL",
                       "sigma_z_m": "REAL", "time_s": "REAL", "sigma_time_s": "REAL",
                       "applied": "INTEGER"},
    "gap_verdicts": {"group_name": "TEXT", "verdict": "TEXT", "best_effect": "TEXT",
                     "best_p": "REAL", "chi2nu_before": "REAL", "chi2nu_after": "REAL",
                     "summary": "TEXT"},
    "bootstrap": {"group_name": "TEXT", "parameter": "TEXT", "value": "REAL",
                  "sigma_cov": "REAL", "sigma_boot": "REAL", "ratio": "REAL", "bias_sigma": "REAL",
                  "lower": "REAL", "upper": "REAL", "non_gaussian": "INTEGER", "n": "INTEGER",
                  "noise": "TEXT"},
    "file_hashes": {"path": "TEXT PRIMARY KEY", "size": "INTEGER", "mtime_ns": "INTEGER",
                    "sha256": "TEXT"},
}
#: the tables that hold results (each row carries its task's key)
RESULT_TABLES = ("shots", "coefficients", "fits", "curves", "hold_study", "station_biases",
                 "gap_verdicts", "bootstrap")
#: what export writes and the report reads
PUBLIC_TABLES = ("tasks", *RESULT_TABLES)
#: each table's rows in a fixed order (a run finishes tasks in any order)
ORDER = {"campaign": "key", "tasks": "rowid", "shots": "shot_id",
         "coefficients": "scope, name, parameter", "fits": "scope, name",
         "curves": "group_name, coefficient, angle, angle_deg",
         "hold_study": "group_name, parameter, held_value",
         "station_biases": "facility, station", "gap_verdicts": "group_name",
         "bootstrap": "group_name, parameter",
         "file_hashes": "path"}


def _create(conn: sqlite3.Connection) -> None:
    for table, cols in SCHEMA.items():
        extra = ", task_key TEXT" if table in RESULT_TABLES else ""
        body = ", ".join(f"{c} {t}" for c, t in cols.items())
        conn.execute(f"CREATE TABLE IF NOT EXISTS {table} ({body}{extra})")
        # a database an older CADRA wrote gains the columns added since (NULL in its rows)
        have = {row[1] for row in conn.execute(f"PRAGMA table_info({table})")}
        for c, t in cols.items():
            if c not in have:
                conn.execute(f"ALTER TABLE {table} ADD COLUMN {c} {t}")
    conn.execute("CREATE INDEX IF NOT EXISTS tasks_key ON tasks (key)")


class CampaignDB:
    """The campaign folder's database, opened for writing by the one client."""

    def __init__(self, folder: str | os.PathLike):
        self.path = Path(folder) / FILENAME
        self.conn = sqlite3.connect(self.path, timeout=30.0)
        self.conn.execute("PRAGMA journal_mode=WAL")
        with self.conn:
            _create(self.conn)

    def close(self) -> None:
        self.conn.close()

    # ------------------------------------------------------------------ properties

    def set(self, **values) -> None:
        with self.conn:
            self.conn.executemany("INSERT OR REPLACE INTO campaign VALUES (?, ?)",
                                  [(k, str(v)) for k, v in values.items()])

    def get(self, key: str, default: str | None = None) -> str | None:
        row = self.conn.execute("SELECT value FROM campaign WHERE key = ?", (key,)).fetchone()
        return row[0] if row else default

    # ------------------------------------------------------------------ file hashes

    def hasher(self, compute):
        """``compute(path) -> sha256`` cached by (path, size, mtime): an image read once is not
        read again until it changes."""

        def cached(path) -> str:
            p = Path(path).resolve()
            st = p.stat()
            row = self.conn.execute("SELECT size, mtime_ns, sha256 FROM file_hashes WHERE "
                                    "path = ?", (str(p),)).fetchone()
            if row and row[0] == st.st_size and row[1] == st.st_mtime_ns:
                return row[2]
            digest = compute(p)
            with self.conn:
                self.conn.execute("INSERT OR REPLACE INTO file_hashes VALUES (?, ?, ?, ?)",
                                  (str(p), st.st_size, st.st_mtime_ns, digest))
            return digest

        return cached

    # ------------------------------------------------------------------ tasks

    def done(self, key: str) -> str | None:
        """The stored result of a task key that finished, or None."""
        row = self.conn.execute("SELECT result FROM tasks WHERE key = ? AND status = 'done' "
                                "ORDER BY rowid DESC LIMIT 1", (key,)).fetchone()
        return row[0] if row else None

    def mark_current(self, keys: Iterable[str]) -> None:
        keys = list(keys)
        with self.conn:
            self.conn.execute("UPDATE tasks SET current = 0")
            self.conn.executemany("UPDATE tasks SET current = 1 WHERE key = ?",
                                  [(k,) for k in keys])

    def started(self, key: str, kind: str, name: str, utc: str) -> None:
        with self.conn:
            self.conn.execute("INSERT INTO tasks (key, kind, name, status, started_utc, "
                              "current) VALUES (?, ?, ?, 'submitted', ?, 1)",
                              (key, kind, name, utc))

    def finished(self, outcome, finished_utc: str, result: str | None) -> None:
        with self.conn:
            self.conn.execute(
                "UPDATE tasks SET status = ?, started_utc = ?, finished_utc = ?, seconds = ?, "
                "worker = ?, error = ?, result = ? WHERE key = ? AND status = 'submitted'",
                ("done" if outcome.ok else "failed", outcome.started_utc, finished_utc,
                 outcome.seconds, outcome.worker, outcome.error, result, outcome.key))

    def interrupted(self) -> int:
        """Mark tasks a stopped run left 'submitted' as 'interrupted'; returns how many."""
        with self.conn:
            return self.conn.execute("UPDATE tasks SET status = 'interrupted' WHERE "
                                     "status = 'submitted'").rowcount

    # ------------------------------------------------------------------ results

    def replace(self, table: str, where: Mapping[str, str], rows: Sequence[Mapping],
                task_key: str | None) -> None:
        """Delete ``table``'s rows matching ``where`` and insert ``rows`` (one transaction)."""
        cols = list(SCHEMA[table]) + ["task_key"]
        cond = " AND ".join(f"{c} = ?" for c in where) or "1"
        with self.conn:
            self.conn.execute(f"DELETE FROM {table} WHERE {cond}", tuple(where.values()))
            self.conn.executemany(
                f"INSERT INTO {table} ({', '.join(cols)}) VALUES "
                f"({', '.join('?' for _ in cols)})",
                [tuple(_plain(r.get(c)) for c in cols[:-1]) + (task_key,) for r in rows])


def _plain(v):
    """A value SQLite stores (numpy scalars to Python; NaN to NULL)."""
    if v is None:
        return None
    if hasattr(v, "item"):
        v = v.item()
    if isinstance(v, float) and v != v:
        return None
    if isinstance(v, bool):
        return int(v)
    return v


def read_tables(folder: str | os.PathLike, tables: Sequence[str] = PUBLIC_TABLES
                ) -> dict[str, pd.DataFrame]:
    """Every public table of a campaign folder's database as a DataFrame (read only)."""
    path = Path(folder) / FILENAME
    if not path.is_file():
        raise FileNotFoundError(f"{folder}: no campaign database ({FILENAME}) here")
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        return {t: pd.read_sql_query(f"SELECT * FROM {t} ORDER BY {ORDER[t]}", conn)
                for t in tables}
    finally:
        conn.close()


def query(sql: str, folders: Sequence[str | os.PathLike], params: Sequence = ()
          ) -> pd.DataFrame:
    """Run ``sql`` over the union of several campaigns' tables.

    Each folder's database is attached read-only; the SQL sees, for each public table, a view
    of the same name holding every campaign's rows with a ``campaign`` column (the folder's
    name), e.g. ``SELECT campaign, name, value, sigma FROM coefficients WHERE parameter =
    'Cmq_A1'``."""
    conn = sqlite3.connect("file::memory:", uri=True)
    try:
        names = []
        for k, folder in enumerate(folders):
            path = Path(folder) / FILENAME
            if not path.is_file():
                raise FileNotFoundError(f"{folder}: no campaign database ({FILENAME}) here")
            conn.execute(f"ATTACH DATABASE ? AS c{k}", (f"file:{path}?mode=ro",))
            names.append((f"c{k}", Path(folder).name))
        for t in PUBLIC_TABLES:
            union = " UNION ALL ".join(f"SELECT ? AS campaign, * FROM {a}.{t}"
                                       for a, _ in names)
            conn.execute(f"CREATE TEMP VIEW {t} AS {union}".replace(
                "?", "'{}'").format(*[n.replace("'", "''") for _, n in names]))
        return pd.read_sql_query(sql, conn, params=list(params))
    finally:
        conn.close()


__all__ = ["FILENAME", "PUBLIC_TABLES", "RESULT_TABLES", "SCHEMA", "CampaignDB", "query",
           "read_tables"]
