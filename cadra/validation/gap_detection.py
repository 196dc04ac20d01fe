"""The gap diagnosis's detection efficiency: detection near the limit, per library effect.

For each library effect, the size the gap diagnosis detects in 90 % of trials, over the size
at which the score test of the true effect alone has 90 % power. The ratio is the
diagnosis's efficiency (acceptance: at most 1.5).

Cases: the library-effect cases of :mod:`cadra.validation.gap_cases` (cg, inertia_asym,
products, density, crossflow, cm3, cmq2, cmM, station_bias, timing, scale) on the shots and
sets :func:`cadra.validation.gap_trials.run_trial` uses: one M2 M0.70 sample shot (M1 M1.10 for
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

The statistics (the reference's power, the detection curve and its fit) are
:mod:`cadra.validation.gap_power`. :func:`detection_summary` returns the figures
(``detection_efficiency_max``, ``detection_efficiency_by_case``, ...) that
``tools/gap_detection.py`` prints and ``tools/validate_gap.py`` joins to its own.
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import replace

import numpy as np

from cadra.validation.gap_cases import (
    AERO_CASES,
    LATERAL_OFFSET_M,
    M1_CASES,
    M1_SHOTS,
    OFFSET_CASES,
    SET_CASES,
    SHOTS,
    make_case,
    shot_spec,
)
from cadra.validation.gap_measure import measure
from cadra.validation.gap_power import (
    ALPHA,
    POWER,
    fit_m90,
    lambda90,
    projected_noncentrality,
    rate_by_bin,
)

__all__ = ["CASES", "H_START", "LINEAR_CASES", "M_RANGE", "REF_ITERATIONS", "REF_TOLERANCE",
           "case_figures", "case_line", "detection_summary", "library_candidate", "mach_of",
           "reference_noncentrality", "run_detection_trial", "scan", "summarize"]

#: the library-effect cases (:mod:`cadra.validation.gap_cases`)
CASES = ["cg", "inertia_asym", "products", "density", "crossflow", "cm3", "cmq2", "cmM",
         "station_bias", "timing", "scale"]
#: station effects: exactly linear in their size (the signature's step is the unit draw)
LINEAR_CASES = ("station_bias", "timing", "scale")
#: multiples of s_ref injected: log-uniform in this range (the curve's rise from 10 % to
#: 90 % spans about a factor 2 in m for k = 1)
M_RANGE = (0.6, 2.2)
#: the first size (in units of the case's ``lo``) at which a dynamics or aero effect's
#: reference is taken, and the fixed-point iteration of the reference size (relative
#: tolerance, at most this many noise-free fits)
H_START = 0.1
REF_TOLERANCE = 0.03
REF_ITERATIONS = 4


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


def run_detection_trial(case: str, rng, tmpdir, m_range=M_RANGE, alpha: float = ALPHA,
                        power: float = POWER) -> dict:
    """One trial of ``case`` (module doc): the reference size, the injection at a random
    multiple of it, the diagnosis; a dict row."""
    from cadra.dynamics.effects import Effects
    from cadra.fitting import fit_shots
    from cadra.gap.score import diagnose_gap
    from cadra.synthetic.simulate import simulate_shot

    t_start = time.perf_counter()
    pool = M1_SHOTS if case in M1_CASES else SHOTS
    group = SET_CASES.get(case)
    if group is None:
        names = [pool[int(rng.integers(len(pool)))]]
    elif isinstance(group, int):
        names = [str(n) for n in rng.choice(pool, size=group, replace=False)]
    else:
        names = list(group)
    specs = [shot_spec(n) for n in names]
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
            # as the gap validation's trials: a body effect in the first shot only, an aero
            # term in every shot, a measurement edit in every shot
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
    """The scan's summary (``detection_efficiency_max`` etc.): :func:`summarize` of
    :func:`scan`."""
    return summarize(scan(list(cases), trials, seed, progress), trials)


def case_line(case: str, rows) -> str:
    """The summary line of one case's trials: m90 and its interval, the known-direction
    efficiency, the rate per bin of m, the reference's k, coverage and size."""
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
