"""Campaigns checked against the truth they were flown with (tools/validate_campaign.py) and
timed (tools/bench_campaign.py).

:func:`group_recovery` compares every group's multi-fit with the aerodynamic model its shots
were flown with (each specification's ``aero_model`` with its ``aero_values``): per free
parameter the fitted value, its sigma, the truth and the pull. :func:`synthetic_manifest`
writes a campaign of N synthetic shots of mixed bodies (capsules in groups of five, sphere
calibration shots, bullets) for the benchmark.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.campaign import load_manifest, read_tables

ROOT = Path(__file__).resolve().parents[2]
SPECS = ROOT / "sample_shots" / "specs"


def flown_model(entry):
    """The aerodynamic model a specification's shot was flown with (SI values)."""
    from cadra.aero import resolve_model
    from cadra.io.spec_file import spec_from_dict

    spec = spec_from_dict(dict(entry.spec),
                          source_path=Path(entry.spec_path) if entry.spec_path else None)
    model = resolve_model(spec.aero_model,
                          Path(spec.source_path).parent if spec.source_path else None)
    return model.with_values(spec.aero_values) if spec.aero_values else model


def group_recovery(folder: str | os.PathLike, manifest) -> pd.DataFrame:
    """Per group and free parameter: ``group``, ``parameter``, ``value``, ``sigma``,
    ``truth``, ``pull`` ((value - truth) / sigma), ``within_2sigma``; groups whose shots were
    flown with different models are skipped (no one truth)."""
    m = load_manifest(manifest) if not hasattr(manifest, "groups") else manifest
    coef = read_tables(folder)["coefficients"]
    rows = []
    for g in m.groups:
        truths = [flown_model(m.shot(s)) for s in g.shots]
        values = [t.values() for t in truths]
        if any(len(v) != len(values[0]) or not np.array_equal(v, values[0]) for v in values):
            continue
        truth = truths[0]
        fit = coef[(coef["scope"] == "group") & (coef["name"] == g.name) & (coef["vary"] == 1)]
        for r in fit.itertuples():
            t = truth.parameter(r.parameter).value
            pull = (r.value - t) / r.sigma if r.sigma and r.sigma > 0 else math.nan
            rows.append({"group": g.name, "parameter": r.parameter, "value": r.value,
                         "sigma": r.sigma, "truth": t, "pull": pull,
                         "within_2sigma": bool(abs(pull) <= 2.0)})
    return pd.DataFrame(rows)


# -- the benchmark's campaign ----------------------------------------------------------------

#: the bodies of the benchmark's campaign, in the order they are dealt, and their specs
MIX = (("capsule", "m2_2429"), ("capsule", "m2_2425"), ("sphere", "sphere_1"),
       ("capsule", "m2_2427"), ("capsule", "m2_2428"), ("sphere", "sphere_2"),
       ("capsule", "m2_2426"), ("bullet", "m80_1"), ("capsule", "m2_2431"),
       ("sphere", "sphere_3"))
#: capsules per group
GROUP_SIZE = 5


def synthetic_manifest(folder: str | os.PathLike, n_shots: int, *, tag: int = 0) -> Path:
    """A campaign of ``n_shots`` synthetic shots dealt from :data:`MIX` (each a sample
    specification with its own seed, so every shot is new), the capsules in groups of
    :data:`GROUP_SIZE` with the M2 M0.70 model, the spheres as calibration shots, the bullets
    fitted alone. ``tag`` changes every seed (a different campaign of the same size)."""
    import tomllib

    import tomli_w

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shots, capsules = [], []
    for k in range(n_shots):
        body, name = MIX[k % len(MIX)]
        spec = tomllib.loads((SPECS / f"{name}.toml").read_text(encoding="utf-8"))
        sid = f"{body}-{k + 1:04d}"
        spec.update(shot_id=sid, seed=100_000 * (tag + 1) + k)
        entry = {"id": sid, "spec": spec}
        if body == "sphere":
            entry["role"] = "sphere"
        if body == "capsule":
            capsules.append(sid)
        shots.append(entry)
    groups = [{"name": f"capsules {j // GROUP_SIZE + 1}", "model": "m2_m070",
               "shots": capsules[j:j + GROUP_SIZE]}
              for j in range(0, len(capsules), GROUP_SIZE) if capsules[j:j + GROUP_SIZE]]
    path = folder / "campaign.toml"
    path.write_bytes(tomli_w.dumps({"name": f"bench-{n_shots}", "shots": shots,
                                    "groups": groups}).encode("utf-8"))
    return path


__all__ = ["GROUP_SIZE", "MIX", "flown_model", "group_recovery", "synthetic_manifest"]
