"""Detection near the limit (issue 21, item 6): for each library effect, the size the gap
diagnosis detects in 90 % of trials, over the size at which the score test of the true effect
alone has 90 % power. The ratio is the diagnosis's efficiency (acceptance: at most 1.5).

Cases: the library-effect cases of tools/gap_cases.py (cg, inertia_asym, products, density,
crossflow, cm3, cmq2, cmM, station_bias, timing, scale) on the shots and sets
tools/validate_gap.py's ``run_trial`` uses: one M2 M0.70 sample shot (M1 M1.10 for
``M1_CASES``), three M2 shots for ``products``, ``cm3``, ``station_bias`` and ``scale`` (the
last two each at its own lateral offset, ``OFFSET_CASES``), the three sphere shots for
``timing``; a body effect in the set's first shot only, an aero term in every shot, a station
edit in every shot. Stage-one noise; the base model fitted; :func:`diagnose_gap` run blind
with its defaults (family-wise alpha 0.01).

Each trial:

1. The configuration is drawn as ``make_case`` draws it (shots, noise seeds, lateral
   offsets, the effect's axis, roll angle, station, sign): ``make_case`` runs with a
   ``draw`` hook that returns ``lo * u`` (``lo`` the case's own lower bound, in the case's
   own units: metres for cg, a fraction of Iyy for inertia and products, the cubic's
   fraction of the linear moment for cm3, ...) and consumes no random numbers, on a fresh
   generator from the trial's case seed each time, so every call gives the same
   configuration and the truth is linear in ``u``.
2. **The reference** (the score test of the true effect alone): the shots made with the
   effect at size u *without noise* and fitted with the base model; that fit's weighted
   residual r is the effect's signature orthogonal to what the base model absorbs (the mean
   of the residual the diagnosis scores). The candidate's weighted columns C and the fit's
   Jacobian J come from ``cadra.gap.score``'s own helpers (``_columns``, ``_stack``,
   ``_orth``; the candidate from ``cadra.gap.candidates.library``, built as
   ``diagnose_gap`` builds it), C is projected orthogonal to J, k is its rank, and the
   candidate's score test of k parameters alone (no other candidate, no multiplicity) at
   alpha = 0.01 has noncentrality ``lambda(u) = |P_C r|^2`` (P_C the projector on the
   projected columns; ``|P_perp C d|^2`` u^2 when the effect is exactly the candidate along
   d). ``lambda90(k)`` solves ``P(ncx2(k, lambda90) > chi2.isf(alpha, k)) = 0.9``; the
   reference size is the u with ``lambda(u) = lambda90(k)``: a fixed point of
   ``u <- u sqrt(lambda90 / lambda(u))``, from ``u = 0.1`` (dynamics, aero) or 1 (station
   effects), to 3 % (:data:`REF_TOLERANCE`; usually one or two noise-free fits).
   Why the residual of a nonlinear fit and not the simulator's signature d projected with
   J: most of a body or aero effect's signature is absorbed by the fit (a 0.1 mm cg
   offset moves a capsule's trim by degrees), and the part the fit cannot absorb is then
   ~1e-6 of it, far below the accuracy of a projection with a Jacobian taken elsewhere
   (one cg trial: |P_perp d|^2 = 3.3e5 per unit^2 by projection, 490 by the fit, which
   is what the data show). The residual of the fit needs no map from the simulator's body
   frame to the fit's either (a body of revolution's fitted roll is arbitrary,
   docs/gap.md).
3. Beside it: ``lambda_full = |r|^2`` (the test along the signature itself, k = 1) and
   ``coverage = lambda / lambda_full``, the part of the residual signature the library's
   candidate holds (about 1 for an effect in the library).
4. The effect is injected at ``u = sign * m * u_ref`` (u_ref the reference; ``s_ref`` =
   ``lo * u_ref`` in the case's units), ``m`` log-uniform in
   :data:`M_RANGE`, measured with the trial's noise, fitted without it and diagnosed.
   **Detected**: the injected effect is among the added effects (any round) or named as an
   alias of one.

**Which k.** The reference is the candidate's own test, with k its projected rank (1 for
density, timing, scale, a station bias, an aero term; 2 for a cg, inertia, products or
cross-flow pair in one shot; 6 for products in a set of three, per shot), not a k = 1 test
along the truth's signature. "The score test of the true effect alone" is the test the
diagnosis would run if the library held that one candidate: what is lost to everything
else (the ~90-candidate multiplicity, the F test, the BIC, nonlinear refits, the greedy
rounds, aliases) is what the ratio measures. A known direction is not something a
diagnosis can be given: a body of revolution's fitted roll is arbitrary, so the direction
of a body pair in the fit's frame is not known before the fit, nor the axis of a
cross-flow or which shot of a set carries a body effect. The k = 1 (known-direction,
``lambda_full``) figure is printed beside it (``detection_efficiency_known_direction``: the
same m90 against that smaller size) as the bound no test can beat.

**The detection curve.** P(detect | m) is fitted by maximum likelihood with one parameter:
the diagnosis behaves as the true effect's k-parameter test with an effective threshold
c, ``P(m) = P(ncx2(k, m^2 lambda90(k)) > c)``, parametrized by m90, the multiple of s_ref
detected in 90 % (``c = ncx2.isf(0.9, k, m90^2 lambda90(k))``; each trial with its own
k). At m90 = 1 the diagnosis is the single test. Efficiency = m90, with its 95 %
profile-likelihood interval (-2 log L within 3.84 of its minimum). The raw detection rate
per bin of m is printed beside it. With every trial detected (or none) m90 is only
bounded (the interval reaches the grid's end, :data:`M90_GRID`).

Usage:
    python tools/gap_detection.py [--trials 20] [--seed 21] [--cases cg,density,...]

Last line: a JSON object (``detection_efficiency_by_case``, ``detection_efficiency_max``,
``detection_trials_per_case``, ``detection_efficiency_interval_by_case``, ...);
:func:`detection_summary` returns the same dict for validate_gap.py.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import optimize, stats

sys.path.insert(0, str(Path(__file__).resolve().parent))
from gap_cases import (  # noqa: E402
    AERO_CASES,
    LATERAL_OFFSET_M,
    M1_CASES,
    M1_SHOTS,
    OFFSET_CASES,
    ROOT,
    SET_CASES,
    SHOTS,
    make_case,
    measure,
)

#: the library-effect cases (tools/gap_cases.py)
CASES = ["cg", "inertia_asym", "products", "density", "crossflow", "cm3", "cmq2", "cmM",
         "station_bias", "timing", "scale"]
#: station effects: exactly linear in their size (the signature's step is the unit draw)
LINEAR_CASES = ("station_bias", "timing", "scale")
#: the diagnosis's family-wise alpha (``diagnose_gap``'s default) and the power of the
#: reference
ALPHA = 0.01
POWER = 0.9
#: multiples of s_ref injected: log-uniform in this range (the curve's rise from 10 % to
#: 90 % spans about a factor 2 in m for k = 1)
M_RANGE = (0.6, 2.2)
#: bins of m for the raw detection rates
M_BINS = (0.6, 0.9, 1.2, 1.5, 2.2)
#: the grid of m90 searched by the maximum-likelihood fit
M90_GRID = (0.1, 10.0)
#: the first size (in units of the case's ``lo``) at which a dynamics or aero effect's
#: reference is taken, and the fixed-point iteration of the reference size (relative
#: tolerance, at most this many noise-free fits)
H_START = 0.1
REF_TOLERANCE = 0.03
REF_ITERATIONS = 4
#: likelihood-ratio level of the m90 interval (95 %, one parameter)
INTERVAL_LEVEL = 0.95


# --- statistics (pure; tests/test_gap_detection.py) ---------------------------------------

def lambda90(k: int, alpha: float = ALPHA, power: float = POWER) -> float:
    """The noncentrality at which a chi^2 test of k parameters at level ``alpha`` has
    ``power``: P(ncx2(k, lambda) > chi2.isf(alpha, k)) = power."""
    c = float(stats.chi2.isf(alpha, k))

    def f(lam):
        return float(stats.ncx2.sf(c, k, lam)) - power

    hi = 1.0
    while f(hi) < 0.0:
        hi *= 2.0
    return float(optimize.brentq(f, 1e-12, hi, xtol=1e-12, rtol=1e-13))


def orth(A: np.ndarray, rcond: float = 1e-10) -> np.ndarray:
    """An orthonormal basis of A's columns (``cadra.gap.score._orth``: the same rank cut)."""
    from cadra.gap.score import _orth

    return _orth(A, rcond)


def projected_noncentrality(J: np.ndarray, C: np.ndarray, d: np.ndarray) -> dict:
    """Noncentralities per unit size of a signature ``d`` (weighted, in sigmas) at a fit of
    weighted Jacobian ``J``: ``lambda_cand`` = |P_C d|^2 with P_C the projector on the
    candidate's columns ``C`` made orthogonal to J (the candidate's k-parameter score test),
    ``lambda_full`` = |P_perp d|^2 (a test along d itself), ``k`` the rank of the projected
    columns and ``coverage`` = lambda_cand / lambda_full."""
    Q = orth(J)
    Cp = C - Q @ (Q.T @ C)
    Qc = orth(Cp)
    dp = d - Q @ (Q.T @ d)
    lam_full = float(dp @ dp)
    proj = Qc.T @ dp
    lam_cand = float(proj @ proj)
    return {"k": int(Qc.shape[1]), "lambda_cand": lam_cand, "lambda_full": lam_full,
            "coverage": lam_cand / lam_full if lam_full > 0 else math.nan}


def detection_probability(m, k, m90: float, power: float = POWER, alpha: float = ALPHA):
    """P(detect) at multiples ``m`` of s_ref for a diagnosis that behaves as the k-parameter
    test with the threshold that puts its 90 % point (``power``) at ``m90``."""
    m = np.asarray(m, float)
    k = np.broadcast_to(np.asarray(k, int), m.shape)
    out = np.empty(m.shape)
    for kk in np.unique(k):
        lam = lambda90(int(kk), alpha, power)
        c = stats.ncx2.isf(power, kk, m90 ** 2 * lam)
        sel = k == kk
        out[sel] = stats.ncx2.sf(c, kk, m[sel] ** 2 * lam)
    return out


def fit_m90(m, k, detected, power: float = POWER, alpha: float = ALPHA,
            level: float = INTERVAL_LEVEL, grid=M90_GRID, n_grid: int = 600) -> dict:
    """Maximum-likelihood m90 of :func:`detection_probability` from outcomes ``detected`` at
    multiples ``m`` (each trial with its own ``k``), and its profile-likelihood interval at
    ``level``. Returns ``m90``, ``lower``, ``upper``, ``censored`` (the maximum at an end of
    the grid: every trial detected or none), ``n``."""
    m = np.asarray(m, float)
    y = np.asarray(detected, bool)
    k = np.broadcast_to(np.asarray(k, int), m.shape)
    if m.size == 0:
        return {"m90": math.nan, "lower": math.nan, "upper": math.nan, "censored": True,
                "n": 0}
    g = np.geomspace(*grid, n_grid)
    lam = {int(kk): lambda90(int(kk), alpha, power) for kk in np.unique(k)}
    L = np.zeros(g.size)
    for kk, lk in lam.items():
        sel = k == kk
        c = stats.ncx2.isf(power, kk, g ** 2 * lk)                      # (grid,)
        p = stats.ncx2.sf(c[:, None], kk, (m[sel] ** 2 * lk)[None, :])  # (grid, trials)
        p = np.clip(p, 1e-12, 1 - 1e-12)
        L += np.where(y[sel][None, :], np.log(p), np.log1p(-p)).sum(axis=1)

    def nll(logm90):
        q = np.clip(detection_probability(m, k, math.exp(logm90), power, alpha),
                    1e-12, 1 - 1e-12)
        return -float(np.sum(np.where(y, np.log(q), np.log1p(-q))))

    i = int(np.argmax(L))
    censored = i in (0, g.size - 1)
    best, lmax = g[i], L[i]
    if not censored:
        r = optimize.minimize_scalar(nll, bounds=(math.log(g[i - 1]), math.log(g[i + 1])),
                                     method="bounded", options={"xatol": 1e-6})
        if r.success and -r.fun >= lmax:
            best, lmax = math.exp(r.x), -r.fun
    inside = g[2.0 * (lmax - L) <= stats.chi2.ppf(level, 1)]
    return {"m90": float(best), "lower": float(inside.min()), "upper": float(inside.max()),
            "censored": bool(censored), "n": int(m.size)}


def rate_by_bin(m, detected, bins=M_BINS) -> list:
    """Raw detection rate per bin of m: [(lo, hi, n, rate), ...]."""
    m = np.asarray(m, float)
    y = np.asarray(detected, bool)
    out = []
    for lo, hi in zip(bins[:-1], bins[1:], strict=True):
        sel = (m >= lo) & ((m < hi) if hi < bins[-1] else (m <= hi))
        out.append((lo, hi, int(sel.sum()), float(y[sel].mean()) if sel.any() else math.nan))
    return out


# --- the reference of one trial ------------------------------------------------------------

def mach_of(shots) -> float:
    """The mean Mach number of the shots as ``diagnose_gap`` computes it (for the library)."""
    from cadra.channels import POSITION

    return float(np.mean([np.median(np.linalg.norm(np.diff(s.meas[:, POSITION], axis=0), axis=1)
                                    / np.diff(s.t_s)) / s.rigid.speed_of_sound_m_s
                          for s in shots]))


def library_candidate(name: str, model, shots):
    """The library's candidate ``name`` as ``diagnose_gap`` builds the library for ``shots``."""
    from cadra.gap.candidates import library

    stations = sorted({int(st) for s in shots for st in s.stations})
    for c in library(model, stations, mach_of(shots)):
        if c.name == name:
            return c
    raise KeyError(f"no candidate {name!r} in the library")


def reference_noncentrality(result, shots, cand, size: float = 1.0, integ=None) -> dict:
    """:func:`projected_noncentrality` per unit ``size``^2 of the residual of ``result``, a
    fit without the effect of noise-free ``shots`` made with the effect at ``size``: that
    residual is the effect's signature orthogonal to what the fit absorbs (the mean of the
    residual the diagnosis scores). The candidate's columns, the fit's Jacobian and the
    weighted residual come from ``cadra.gap.score``'s own helpers (unweighted rows masked),
    as the diagnosis scores them."""
    from cadra.fitting.sensitivity import Integration
    from cadra.gap.score import _cand_matrix, _columns, _stack

    per = _columns(result, shots, [cand], integ or Integration())
    J, r = _stack(per, result.model.free_indices().size + len(result.extras))
    C = _cand_matrix(per, cand.name)
    return projected_noncentrality(J, C, r / size)


# --- one trial -----------------------------------------------------------------------------

def run_detection_trial(case: str, rng, tmpdir, m_range=M_RANGE, alpha: float = ALPHA,
                        power: float = POWER) -> dict:
    """One trial of ``case`` (module doc): the reference size, the injection at a random
    multiple of it, the diagnosis; a dict row."""
    from cadra.dynamics.effects import Effects
    from cadra.fitting import fit_shots
    from cadra.gap.score import diagnose_gap
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    t_start = time.perf_counter()
    pool = M1_SHOTS if case in M1_CASES else SHOTS
    group = SET_CASES.get(case)
    if group is None:
        names = [pool[int(rng.integers(len(pool)))]]
    elif isinstance(group, int):
        names = [str(n) for n in rng.choice(pool, size=group, replace=False)]
    else:
        names = list(group)
    specs = [load_shot_spec(ROOT / "sample_shots" / "specs" / f"{n}.toml") for n in names]
    case_seed = int(rng.integers(1 << 62))
    sign = float(rng.choice([-1.0, 1.0]))
    m = float(np.exp(rng.uniform(math.log(m_range[0]), math.log(m_range[1]))))
    seeds = [int(rng.integers(1 << 31)) for _ in specs]
    offsets = [tuple(float(v) for v in rng.uniform(-LATERAL_OFFSET_M, LATERAL_OFFSET_M, 2))
               if case in OFFSET_CASES else (0.0, 0.0) for _ in specs]
    clean_sims = [simulate_shot(s) for s in specs]
    nominal = [cs.rigid.with_effects(Effects()) for cs in clean_sims]
    model = clean_sims[-1].model
    lo_seen = []

    def case_at(u):
        def draw(_rng, lo, _hi):
            lo_seen.append(lo)
            return lo * u
        # the same generator each call: the same file name for an aero model, so each call
        # writes into a directory of its own
        return make_case(case, np.random.default_rng(case_seed), specs,
                         tempfile.mkdtemp(dir=tmpdir), draw=draw)

    def data_at(u, noisy):
        spec_e, edit, expected, truth, _ = case_at(u)
        shots = []
        for k, spec in enumerate(specs):
            # as run_trial: a body effect in the first shot only, an aero term in every
            # shot, a measurement edit in every shot
            se = (spec_e if k == 0 else replace(spec, aero_model=spec_e.aero_model)
                  if case in AERO_CASES else spec)
            sim = simulate_shot(se) if se is not spec else clean_sims[k]
            shots.append(measure(sim, nominal[k], spec, seeds[k] if noisy else None, edit,
                                 offsets[k]))
        return shots, expected, truth

    # the reference size: fixed point of u = sqrt(lambda90(k) / lambda_cand(u)), the
    # noncentrality taken from the fit of the noise-free shots with the effect at u
    u = 1.0 if case in LINEAR_CASES else H_START
    cand = ref = None
    done, n_iter = False, 0
    while n_iter < REF_ITERATIONS:
        n_iter += 1
        free, expected, _ = data_at(sign * u, False)
        res0, _ = fit_shots(free, model)
        cand = cand or library_candidate(expected, model, free)
        ref = reference_noncentrality(res0, free, cand, u)
        if ref["k"] == 0 or not ref["lambda_cand"] > 0:
            break
        u_new = math.sqrt(lambda90(ref["k"], alpha, power) / ref["lambda_cand"])
        done = abs(math.log(u_new / u)) < math.log(1.0 + REF_TOLERANCE)
        u = u_new
        if done:
            break
    row = {"case": case, "shot": "+".join(names), "m": m, "expected": expected, **ref,
           "ref_iterations": n_iter, "ref_settled": bool(done)}
    if ref["k"] == 0 or not ref["lambda_cand"] > 0:
        row.update({"valid": False, "seconds": time.perf_counter() - t_start})
        return row
    lam90 = lambda90(ref["k"], alpha, power)
    u_ref = u
    # the same size for a test along the signature itself (k = 1: direction known)
    u_ref1 = math.sqrt(lambda90(1, alpha, power) / ref["lambda_full"])
    lo = lo_seen[0]
    shots, _, truth = data_at(sign * m * u_ref, True)
    res, _ = fit_shots(shots, model)
    dg = diagnose_gap(res, shots, model, alpha=alpha)
    added = [a["effect"] for a in dg.added]
    detected = any(a["effect"] == expected or expected in tuple(a.get("aliases", ()))
                   for a in dg.added)
    first = {}
    if dg.ranking is not None and len(dg.ranking) and "candidate" in dg.ranking:
        hit = dg.ranking[dg.ranking["candidate"] == expected]
        if len(hit):
            first = {"dchi2_first_round": float(hit.iloc[0]["dchi2"]),
                     "p_adjusted_first_round": float(hit.iloc[0].get("p_adjusted", math.nan))}
    row.update({"valid": True, "lambda90": lam90, "s_ref": lo * u_ref, "s_ref_known": lo * u_ref1,
                "ref_ratio_known": u_ref / u_ref1, "truth": {k: float(v) for k, v in
                                                              truth.items()},
                "detected": bool(detected), "added": added,
                "wrong": bool(added and not detected), "fit_status": res.status,
                "verdict": dg.verdict, **first, "seconds": time.perf_counter() - t_start})
    return row


# --- the scan and its summary --------------------------------------------------------------

def scan(cases=CASES, trials: int = 20, seed: int = 21, progress: bool = True) -> dict:
    """{case: [row, ...]}: ``trials`` trials per case; each case has its own random stream
    (``[seed, index in CASES]``), so a subset of the cases reproduces the full scan's."""
    def iterate(n, desc):
        if not progress:
            return range(n)
        from tqdm import tqdm

        return tqdm(range(n), desc=desc, unit="trial", leave=False)

    per = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            rng = np.random.default_rng([seed, CASES.index(case)])
            rows = []
            for _ in iterate(trials, case):
                try:
                    rows.append(run_detection_trial(case, rng, tmp))
                except Exception as exc:      # noqa: BLE001  (counted and printed, not hidden)
                    rows.append({"case": case, "valid": False, "error": repr(exc)[:300]})
            per[case] = rows
    return per


def case_figures(rows) -> dict:
    """The detection curve of one case's rows: m90 and its interval, the known-direction
    efficiency, the raw rate per bin, the reference's k and coverage."""
    ok = [r for r in rows if r.get("valid")]
    m = [r["m"] for r in ok]
    y = [r["detected"] for r in ok]
    k = [r["k"] for r in ok]
    fit = fit_m90(m, k, y)
    known = float(np.median([r["ref_ratio_known"] for r in ok])) if ok else math.nan
    return {"fit": fit, "known_factor": known, "bins": rate_by_bin(m, y),
            "k": sorted({int(v) for v in k}),
            "coverage_min": min((r["coverage"] for r in ok), default=math.nan),
            "s_ref_median": float(np.median([r["s_ref"] for r in ok])) if ok else math.nan,
            "rate": float(np.mean(y)) if ok else math.nan,
            "wrong": float(np.mean([r["wrong"] for r in ok])) if ok else math.nan,
            "n_valid": len(ok), "errors": sum("error" in r for r in rows),
            "unsettled": sum(not r.get("ref_settled", True) for r in ok),
            "seconds_median": (float(np.median([r["seconds"] for r in ok])) if ok
                               else math.nan)}


def summarize(per: dict, trials: int) -> dict:
    """The JSON summary of a scan (module doc)."""
    figs = {c: case_figures(rows) for c, rows in per.items()}
    eff = {c: f["fit"]["m90"] for c, f in figs.items()}
    finite = [v for v in eff.values() if math.isfinite(v)]
    secs = [r["seconds"] for rows in per.values() for r in rows if r.get("valid")]
    return {
        "detection_efficiency_max": max(finite) if finite else math.nan,
        "detection_efficiency_by_case": eff,
        # the acceptance read off the intervals: the largest 95 % upper bound (a case whose
        # trials were all detected has only that bound; its m90 is the grid's end)
        "detection_efficiency_upper_max": max(
            (f["fit"]["upper"] for f in figs.values() if math.isfinite(f["fit"]["upper"])),
            default=math.nan),
        "detection_efficiency_interval_by_case": {
            c: [f["fit"]["lower"], f["fit"]["upper"]] for c, f in figs.items()},
        "detection_efficiency_censored_by_case": {c: f["fit"]["censored"]
                                                  for c, f in figs.items()},
        "detection_efficiency_known_direction_by_case": {
            c: f["fit"]["m90"] * f["known_factor"] for c, f in figs.items()},
        "detection_rate_by_case": {c: f["rate"] for c, f in figs.items()},
        "detection_rate_by_bin_by_case": {c: [[lo, hi, n, r] for lo, hi, n, r in f["bins"]]
                                          for c, f in figs.items()},
        "detection_wrong_effect_rate_by_case": {c: f["wrong"] for c, f in figs.items()},
        "detection_reference_k_by_case": {c: f["k"] for c, f in figs.items()},
        "detection_coverage_min_by_case": {c: f["coverage_min"] for c, f in figs.items()},
        "detection_s_ref_median_by_case": {c: f["s_ref_median"] for c, f in figs.items()},
        "detection_trials_per_case": trials,
        "detection_valid_trials_by_case": {c: f["n_valid"] for c, f in figs.items()},
        "detection_errors_by_case": {c: f["errors"] for c, f in figs.items()},
        # trials whose reference size had not settled to REF_TOLERANCE in REF_ITERATIONS fits
        "detection_reference_unsettled_by_case": {c: f["unsettled"] for c, f in figs.items()},
        "detection_alpha": ALPHA,
        "detection_m_range": list(M_RANGE),
        "detection_seconds_per_trial": float(np.median(secs)) if secs else math.nan,
    }


def detection_summary(cases=CASES, trials: int = 20, seed: int = 21,
                      progress: bool = True) -> dict:
    """The scan's JSON summary (``detection_efficiency_max`` etc.) for tools/validate_gap.py."""
    return summarize(scan(list(cases), trials, seed, progress), trials)


def case_line(case: str, rows) -> str:
    f = case_figures(rows)
    fit = f["fit"]
    bins = ", ".join(f"[{lo:.1f}, {hi:.1f}) {r:.2f} of {n}" if n else f"[{lo:.1f}, {hi:.1f}) -"
                     for lo, hi, n, r in f["bins"])
    return (f"{case:13s} m90 {fit['m90']:.2f} [{fit['lower']:.2f}, {fit['upper']:.2f}]"
            f"{' (censored)' if fit['censored'] else ''} x s_ref (k {f['k']}; known direction "
            f"{fit['m90'] * f['known_factor']:.2f}), detected {f['rate']:.2f} of "
            f"{f['n_valid']} (per m bin: {bins}), another effect instead {f['wrong']:.2f}, "
            f"coverage min {f['coverage_min']:.3f}, s_ref median {f['s_ref_median']:.3g} "
            f"(case units), {f['seconds_median']:.1f} s/trial"
            + (f", {f['errors']} errors" if f["errors"] else ""))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--seed", type=int, default=21)
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--verbose", action="store_true", help="print every trial")
    args = parser.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        parser.error(f"unknown cases {unknown}; choose from {CASES}")
    t0 = time.perf_counter()
    per = scan(cases, args.trials, args.seed)
    for case, rows in per.items():
        print(case_line(case, rows))
        for r in rows:
            if "error" in r:
                print(f"    error: {r['error']}")
            elif args.verbose or (r.get("valid") and not r["detected"] and r["m"] > 1.5):
                print(f"    {r['shot']} m {r['m']:.2f} k {r['k']} detected "
                      f"{r.get('detected')} (first-round dchi2 "
                      f"{r.get('dchi2_first_round', math.nan):.1f}, p_adj "
                      f"{r.get('p_adjusted_first_round', math.nan):.2g}; m^2 lambda90 "
                      f"{r['m'] ** 2 * r.get('lambda90', math.nan):.1f}): "
                      f"{r.get('verdict', '')[:160]}")
    summary = summarize(per, args.trials)
    summary["detection_total_seconds"] = time.perf_counter() - t0
    print(json.dumps(summary, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
