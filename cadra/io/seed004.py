"""Seed 004 (HFFAF Orion capsule tests) Tables 2 and 3 as data.

``cadra/data/seed004_shots.csv`` holds one row per shot (24 shots: M1 x12, M2 x10, M3 x2),
transcribed as printed; ``cadra/data/README.md`` gives the source lines and every suspicious
cell. Columns (units in the names; angles in the CEV convention, 180 deg = heat shield
forward, as the table prints them):

model, shot, d_cm, h_cm, mass_g, x_cg_from_base_cm, y_cg_cm, z_cg_cm, Ixx_g_cm2, Iyy_g_cm2,
Izz_g_cm2 (Table 2, model axes: x nose, y port, z up); mach, reynolds, velocity_m_s,
pressure_torr, temperature_k, density_kg_m3, alpha0_cev_deg, alpha_trim_cev_deg (Table 3);
notes.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from cadra import units

DATA_PATH = Path(__file__).resolve().parent.parent / "data" / "seed004_shots.csv"

COLUMNS = (
    "model", "shot", "d_cm", "h_cm", "mass_g", "x_cg_from_base_cm", "y_cg_cm", "z_cg_cm",
    "Ixx_g_cm2", "Iyy_g_cm2", "Izz_g_cm2", "mach", "reynolds", "velocity_m_s", "pressure_torr",
    "temperature_k", "density_kg_m3", "alpha0_cev_deg", "alpha_trim_cev_deg", "notes",
)


@lru_cache(maxsize=1)
def _read() -> pd.DataFrame:
    dtypes = {c: float for c in COLUMNS}
    dtypes.update(model=str, shot=int, notes=str)
    df = pd.read_csv(DATA_PATH, dtype=dtypes, keep_default_na=False)
    if tuple(df.columns) != COLUMNS:
        raise ValueError(f"{DATA_PATH}: unexpected columns {list(df.columns)}")
    return df


def load_seed004_table() -> pd.DataFrame:
    """Seed 004 Tables 2 and 3, one row per shot, in the paper's row order (a fresh copy)."""
    return _read().copy()


def seed004_row(shot: int) -> pd.Series:
    """The row of shot number ``shot`` (KeyError if it is not in the tables)."""
    df = _read()
    hit = df[df["shot"] == int(shot)]
    if hit.empty:
        raise KeyError(f"shot {shot} is not in seed 004 Tables 2/3")
    return hit.iloc[0].copy()


def seed004_shot_file(shot: int, stations: Sequence | None = None, *,
                      base_x_from_reference_m: float | None = None,
                      facility: str = "hffaf"):
    """A :class:`~cadra.io.shotfile.ShotFile` from a seed 004 Table 2/3 row (SI).

    Parameters
    ----------
    shot : shot number, e.g. 2429.
    stations : the shot's :class:`~cadra.io.shotfile.StationRecord` list (the tables have no
        spark times or images; a shot file needs at least one station to be saved).
    base_x_from_reference_m : model-axis x of the centre of the model base, measured from the
        body's reference point, m (``body.base_s_m``). Table 2 gives the cg from the base
        (``x_cg-b``); the shot file wants it from the reference point:
        ``x_cg = base_x_from_reference_m + x_cg_from_base``. If None it is taken from
        ``cadra.body.body_from_spec(model).base_s_m`` (imported lazily).
    facility : facility name or path to record.

    Notes
    -----
    y_cg and z_cg are copied as written (Table 2 z_cg = -0.173 cm is below the axis with the
    model upright; model axes are x nose, y port, z up). Table 2 lists Ixx, Iyy, Izz only: the
    tensor is diagonal (products of inertia not measured / zero).
    """
    from cadra.io.shotfile import MassProperties, ShotFile

    row = seed004_row(shot)
    model = {"kind": "capsule", "preset": str(row["model"]), "d_cm": float(row["d_cm"]),
             "h_cm": float(row["h_cm"])}
    if base_x_from_reference_m is None:
        from cadra.body import body_from_spec  # lazy: cadra.body is optional for this module

        base_x_from_reference_m = float(body_from_spec(model).base_s_m)
    cg = np.array([base_x_from_reference_m + units.cm_to_m(float(row["x_cg_from_base_cm"])),
                   units.cm_to_m(float(row["y_cg_cm"])), units.cm_to_m(float(row["z_cg_cm"]))])
    inertia = units.g_cm2_to_kg_m2(np.diag([float(row["Ixx_g_cm2"]), float(row["Iyy_g_cm2"]),
                                            float(row["Izz_g_cm2"])]))
    mass = MassProperties(mass_kg=units.g_to_kg(float(row["mass_g"])), cg_model_m=cg,
                          inertia_model_kg_m2=inertia)
    notes = f"seed 004 Tables 2/3, {row['model']} shot {int(row['shot'])}"
    if row["notes"]:
        notes += f"; table note: {row['notes']}"
    return ShotFile(shot_id=f"{row['model']}-{int(row['shot'])}", model=model, mass=mass,
                    pressure_pa=units.torr_to_pa(float(row["pressure_torr"])),
                    temperature_k=float(row["temperature_k"]), facility=facility,
                    stations=tuple(stations or ()), notes=notes, source_path=None,
                    nominal_velocity_m_s=float(row["velocity_m_s"]))


__all__ = ["COLUMNS", "DATA_PATH", "load_seed004_table", "seed004_row", "seed004_shot_file"]
