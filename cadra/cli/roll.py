"""``cadra2 roll``: seed 003's global segmented fit of pure-roll records (docs/segmented_roll.md).

A finned model on a roll bearing at a fixed angle of attack (a shot file whose
``[test_mode]`` is ``roll_bearing``) measured in its roll angle phi, frame by frame (a
trajectory file with ``phi_deg``; theta and psi optional). The records are cut into segments
as the paper does (one oscillation cycle from a zero-rate peak, 180 deg of roll in speed-up,
360 deg in steady spin), each with its own initial roll angle and rate, and fitted with one
shared coefficient set (:func:`cadra.fitting.segmented.segmented_fit`: the local fit, then
the paper's stepwise global fit). Writes ``report.md``, seed 003's Tables 2 and 3
(``table2``, ``table3``, ``paper_table3``), ``segments`` (bias, rms and runs of sign per
segment) and ``steady_spins`` as CSV and markdown, and ``roll_fit.png`` (Figs. 5-6 layout).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from cadra.cli._format import HelpFormatter, add_verbosity

PROG = "cadra2 roll"
_REFUSED = (ValueError, KeyError, FileNotFoundError)


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``cadra2 roll`` on ``cadra2``'s subparsers."""
    p = sub.add_parser(
        "roll", help="seed 003's global segmented fit of pure-roll records",
        description="Seed 003's (ROMOF) global nonlinear least-squares fit of the rolling "
        "motion of a finned model on a roll bearing: the records cut into segments, each with "
        "its own initial roll angle and rate, one coefficient set for all, fitted in the "
        "paper's steps (its start set, then the others 3-4 at a time) from equation-error "
        "starting values. Writes report.md, Tables 2 and 3 (coefficients, sigmas, "
        "signal/noise, correlations), the segments' bias, rms and runs of sign, the steady "
        "spins of the fitted coefficients, and roll_fit.png; docs/segmented_roll.md.",
        formatter_class=HelpFormatter)
    add_verbosity(p, top=False)
    p.set_defaults(func=run)
    p.add_argument("trajectories", nargs="+",
                   help="trajectory.csv files of the roll records (or their directories)")
    p.add_argument("-o", "--output", required=True, help="output directory (must not exist)")
    p.add_argument("--shot", action="append",
                   help="shot file of each trajectory, same order (default: the one the "
                        "trajectory file names)")
    p.add_argument("--model", default="seed003_romof",
                   help="aero model (bundled name or file) whose Cl is linear in the "
                        "stepped coefficients")
    p.add_argument("--alpha-deg", type=float, default=None,
                   help="the bearing's angle of attack, deg (default: from the measured "
                        "theta and psi)")
    p.add_argument("--window", type=int, default=11,
                   help="frames of the smoothing filter that finds the zero-rate peaks")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    return p


def _refused(exc: Exception) -> int:
    msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
    print(f"{PROG}: {msg}", file=sys.stderr)
    return 1


def bearing_alpha(shots, alpha_deg: float | None) -> float:
    """The bearing's angle of attack (rad): ``alpha_deg`` when given, else the angle between
    the mean measured nose axis and the stream (+x of F)."""
    from cadra import channels
    from cadra.conventions import axis_from_inclinations

    if alpha_deg is not None:
        if not (0.0 < alpha_deg < 90.0):
            raise ValueError(f"--alpha-deg: {alpha_deg:g} is not an angle of attack in (0, 90)")
        return math.radians(alpha_deg)
    th, ps = channels.NAMES.index("theta"), channels.NAMES.index("psi")
    axes = [axis_from_inclinations(m[th], m[ps]) for s in shots for m in s.meas
            if np.isfinite(m[th]) and np.isfinite(m[ps])]
    if not axes:
        raise ValueError("the records measure no nose axis (theta, psi): give --alpha-deg")
    a = np.mean(axes, axis=0)
    a /= np.linalg.norm(a)
    if abs(a[1]) > math.sin(math.radians(0.5)):
        raise ValueError(f"the measured axis is {math.degrees(math.asin(a[1])):.2f} deg out of "
                         "the vertical plane: the segments' states put it in that plane; "
                         "give --alpha-deg to accept that")
    return math.acos(float(np.clip(a[0], -1.0, 1.0)))


def records_of(shots):
    """A :class:`~cadra.fitting.segmented.RollRecord` of each roll-bearing shot."""
    from cadra import channels
    from cadra.fitting.segmented import RollRecord

    k = channels.NAMES.index("phi")
    out = []
    for s in shots:
        name = s.source.get("trajectory_file", s.shot_id)
        if s.rigid.mode.kind != "roll_bearing":
            raise ValueError(f"{name}: a {s.rigid.mode.kind!r} record; cadra2 roll fits roll "
                             "bearings (the shot file's [test_mode] kind = 'roll_bearing')")
        ok = np.isfinite(s.meas[:, k])
        if ok.sum() < 8:
            raise ValueError(f"{name}: {int(ok.sum())} frame(s) with a measured roll (phi); "
                             "a roll record needs at least 8")
        out.append(RollRecord(s.shot_id, s.t_s[ok], np.unwrap(s.meas[ok, k]),
                              float(np.median(s.sigma[ok, k]))))
    r0 = shots[0].rigid
    for s in shots[1:]:
        if (s.rigid.mode != r0.mode or not np.allclose(s.rigid.phys(), r0.phys())):
            raise ValueError(f"{s.shot_id}: another body, air or bearing than "
                             f"{shots[0].shot_id}'s; one segmented fit is one flight "
                             "condition")
    return out


def run(args) -> int:
    """``cadra2 roll`` (module doc); returns the exit status."""
    from cadra.aero import resolve_model
    from cadra.fitting.segmented import (
        plot_segmented_fit,
        seed003_tables,
        segmented_fit,
        steady_spins,
        write_tables,
    )
    from cadra.flight.load import load_shots
    from cadra.io.atomic import atomic_output_dir

    quiet = bool(getattr(args, "quiet", False))
    try:
        if args.window < 5 or args.window % 2 == 0:
            raise ValueError(f"--window: an odd number of frames >= 5, got {args.window}")
        model = resolve_model(args.model)
        shots, _ = load_shots(args.trajectories, args.shot)
        alpha = bearing_alpha(shots, args.alpha_deg)
        records = records_of(shots)
        fit = segmented_fit(records, model, shots[0].rigid, alpha, window=args.window)
    except _REFUSED as exc:
        return _refused(exc)
    tables = seed003_tables(fit)
    res = fit.result
    out = Path(args.output)
    with atomic_output_dir(out, overwrite=args.overwrite) as tmp:
        write_tables(tables, tmp)
        plot_segmented_fit(fit, tmp / "roll_fit.png")
        (tmp / "report.md").write_text(report_markdown(fit, tables, records, alpha),
                                       encoding="utf-8")
    for note in fit.notes:
        print(f"{PROG}: warning: {note}", file=sys.stderr)
    spins = steady_spins(res.model)
    spun = ", ".join(f"{v:+.4f}" + ("" if st else " (unstable)")
                     for v, st in zip(spins["p_hat"], spins["stable"], strict=True))
    print(f"roll: {len(records)} record(s), {len(fit.segments)} segments, {res.status}, "
          f"chi^2/dof {res.reduced_chi2:.3f}; steady spins p_hat: {spun or 'none'}")
    if not quiet:
        print(f"wrote {out}/ (report.md, table2, table3, paper_table3, segments, steady_spins "
              "(.csv, .md), roll_fit.png)")
    return 0 if res.converged else 1        # the best point is written, marked so


def report_markdown(fit, tables, records, alpha_rad: float) -> str:
    from cadra.fitting.segmented import markdown_table

    res = fit.result
    lines = ["# Segmented roll fit (seed 003, ROMOF)", "",
             f"Records: {', '.join(r.name for r in records)}; bearing angle of attack "
             f"{math.degrees(alpha_rad):.3f} deg; {len(fit.segments)} segments; fit "
             f"{res.status}, chi^2/dof {res.reduced_chi2:.4f} ({res.dof} dof). Steps: "
             + "; ".join(", ".join(s) for s in fit.step_names) + ".", ""]
    if fit.notes:
        lines += ["**Notes:** " + "; ".join(fit.notes), ""]
    for title, key in (("Coefficients (seed 003 Table 2 layout)", "table2"),
                       ("Correlations (Table 3 layout)", "table3"),
                       ("Steady spins of the fitted coefficients", "steady_spins"),
                       ("Segments: bias, rms, runs of sign", "segments")):
        lines += [f"## {title}", "", markdown_table(tables[key]), ""]
    return "\n".join(lines)


__all__ = ["add_parser", "bearing_alpha", "records_of", "report_markdown", "run"]
