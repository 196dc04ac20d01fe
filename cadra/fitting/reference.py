"""A fit against a reference: the last campaign's coefficients, a bundled model, a truth.

Range engineers compare every new fit with the last one. :func:`load_reference` reads the
reference, and :func:`compare_with_reference` gives, per free parameter the reference also
has, the difference and its pull, plus one joint chi^2 of agreement.

A reference can be one of three things:

- **a model** (a bundled name or a model file): values only; pulls use the fit's sigma alone;
- **a folder written by ``cadra2 fit``**: its ``model_fitted.toml`` gives the values and its
  ``results.json`` the sigmas; its ``covariance.csv``, when present, gives the covariance,
  so the joint chi^2 counts the reference's correlations too;
- **a plain ``results.json``** of such a folder.

The pull of parameter k is ``(fit - ref) / sqrt(sigma_fit^2 + sigma_ref^2)``. The joint
chi^2 is ``d^T (C_fit + C_ref)^-1 d`` over the compared parameters, with its degrees of
freedom and p-value. It is the honest test, because the coefficients of one fit are
correlated and their pulls are not independent.

Everything here is a pure function of plain data.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

__all__ = ["Reference", "ReferenceComparison", "compare_with_reference", "load_reference"]


@dataclass(frozen=True)
class Reference:
    """Reference values (SI, by parameter name), optional sigmas and covariance, and a label.

    ``model`` is the reference as an aero model, for the coefficient plots.
    """

    label: str
    values: dict
    sigmas: dict
    covariance: pd.DataFrame | None = None
    model: object | None = None


@dataclass(frozen=True)
class ReferenceComparison:
    """``table``: one row per compared parameter. ``chi2``, ``dof`` and ``p`` are the joint
    test of agreement. ``not_compared`` lists the fit's free parameters the reference lacks."""

    label: str
    table: pd.DataFrame
    chi2: float
    dof: int
    p: float
    not_compared: tuple[str, ...]


def _load_folder_sigmas(results_path: Path) -> tuple[dict, dict]:
    """(values, sigmas) of the free parameters in a results.json."""
    try:
        data = json.loads(results_path.read_text(encoding="utf-8"))
        params = data["parameters"]
        values, sigmas = {}, {}
        for name, p in params.items():
            values[name] = float(p["value"])
            if p.get("sigma") is not None:
                sigmas[name] = float(p["sigma"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{results_path}: not a cadra2 results.json ({exc})") from None
    return values, sigmas


def load_reference(spec: str | os.PathLike) -> Reference:
    """Read a reference (module doc). Raises ``ValueError`` (naming the file) for anything
    that is not one, ``FileNotFoundError`` for a path that does not exist."""
    from cadra.aero import load_model, resolve_model

    path = Path(spec)
    if path.is_dir():
        results = path / "results.json"
        fitted = path / "model_fitted.toml"
        if not results.is_file():
            raise ValueError(f"{path}: a reference folder must hold the results.json of a "
                             "cadra2 fit")
        values, sigmas = _load_folder_sigmas(results)
        model = load_model(fitted) if fitted.is_file() else None
        cov = None
        if (path / "covariance.csv").is_file():
            try:
                cov = pd.read_csv(path / "covariance.csv", index_col=0)
            except (OSError, ValueError) as exc:
                raise ValueError(f"{path / 'covariance.csv'}: {exc}") from None
        return Reference(str(path), values, sigmas, cov, model)
    if path.suffix == ".json":
        if not path.is_file():
            raise FileNotFoundError(f"{path}: reference not found")
        values, sigmas = _load_folder_sigmas(path)
        return Reference(str(path), values, sigmas)
    model = resolve_model(str(spec))
    return Reference(str(spec), {p.name: p.value for p in model.parameters}, {}, None, model)


def compare_with_reference(names, values, covariance, reference: Reference
                           ) -> ReferenceComparison:
    """Compare a fit's free parameters (``names``, ``values``, their ``covariance``, SI) with
    ``reference``. Parameters the reference does not have are listed, not compared."""
    names = list(names)
    values = np.asarray(values, float)
    C = np.asarray(covariance, float)[: len(names), : len(names)]
    idx = [i for i, n in enumerate(names) if n in reference.values]
    cmp_names = [names[i] for i in idx]
    ref = np.array([reference.values[n] for n in cmp_names])
    ref_sig = np.array([reference.sigmas.get(n, 0.0) for n in cmp_names])
    d = values[idx] - ref
    Cf = C[np.ix_(idx, idx)]
    Cr = np.diag(ref_sig ** 2)
    if reference.covariance is not None:
        rc = reference.covariance
        have = [n for n in cmp_names if n in rc.index and n in rc.columns]
        if len(have) == len(cmp_names):
            Cr = rc.loc[cmp_names, cmp_names].to_numpy(float)
    total = Cf + Cr
    sig = np.sqrt(np.maximum(np.diag(total), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        pull = np.where(sig > 0, d / sig, np.nan)
    table = pd.DataFrame({
        "parameter": cmp_names, "fit": values[idx], "sigma": np.sqrt(np.diag(Cf)),
        "reference": ref, "reference_sigma": ref_sig, "difference": d,
        "difference_percent": np.where(ref != 0, 100.0 * d / np.where(ref != 0, ref, 1.0),
                                       np.nan),
        "pull": pull})
    if len(idx):
        w, V = np.linalg.eigh(total)
        keep = w > 1e-12 * max(w.max(), 0.0)
        proj = V[:, keep].T @ d
        chi2 = float(np.sum(proj ** 2 / w[keep]))
        dof = int(keep.sum())
        p = float(stats.chi2.sf(chi2, dof)) if dof else math.nan
    else:
        chi2, dof, p = math.nan, 0, math.nan
    not_compared = tuple(n for n in names if n not in reference.values)
    return ReferenceComparison(reference.label, table, chi2, dof, p, not_compared)


