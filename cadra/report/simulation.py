"""What ``cadra2 simulate`` says of a flown shot: one line, and the truth table's main columns
(the files are :func:`cadra.synthetic.simulate.write_shot`'s)."""

from __future__ import annotations

#: the truth columns shown by ``cadra2 simulate -v``
TRUTH_COLUMNS = ("station", "t_s", "x_m", "y_m", "z_m", "theta_deg", "psi_deg", "mach",
                 "alpha_deg", "beta_deg")


def summary_line(shot) -> str:
    """Stations, the x span, and the Mach, alpha and beta ranges of a simulated shot."""
    t = shot.truth
    return (f"{shot.spec.shot_id}: {len(t)} stations, x {t.x_m.iloc[0]:.3f}.."
            f"{t.x_m.iloc[-1]:.3f} m, Mach {t.mach.min():.3f}..{t.mach.max():.3f}, "
            f"alpha {t.alpha_deg.min():+.2f}..{t.alpha_deg.max():+.2f} deg, "
            f"beta {t.beta_deg.min():+.2f}..{t.beta_deg.max():+.2f} deg")


def truth_text(shot) -> str:
    """The truth table's :data:`TRUTH_COLUMNS` as text."""
    t = shot.truth
    return t[[c for c in TRUTH_COLUMNS if c in t]].to_string(index=False)


__all__ = ["TRUTH_COLUMNS", "summary_line", "truth_text"]
