"""Angular-motion analysis: pure functions over angle histories (docs/motion.md).

Epicyclic and tricyclic fits by differential corrections (10- and 12-constant forms, the
nonrolling-axis correction), 1-DOF pitch fits, overlapping sectional fits, the
Kryloff-Bogoliuboff nonlinear reduction, linear-theory coefficients from the fitted arms,
Murphy's cubic correlator, the Nonplanar Ratio, the cg transfer and seed 001's pure-roll
(roll lock-in) reduction by differential corrections (docs/pureroll.md). Plain numpy in, frozen
dataclasses out; no file I/O (their text reports: :mod:`cadra.report.motion`). May import only
numpy, scipy, cadra.conventions, cadra.units and cadra.numfmt.
"""

from cadra.motion.alias import AliasBand, Dealiased, dealias_arms
from cadra.motion.coefficients import (
    CgSeriesFit,
    FlightConditions,
    LinearCoefficients,
    MomentDerivatives,
    SwerveFit,
    fit_cg_series,
    lift_from_swerve,
    linear_coefficients,
    pitch_coefficients,
    planar_coefficients,
    transfer_cg,
)
from cadra.motion.epicyclic import Arm, EpicyclicFit, Layout, MotionFitError, fit_epicyclic
from cadra.motion.kb import KBResult, kb_pitch_reduction, kb_reduction
from cadra.motion.nonplanar import (
    CubicCorrelator,
    NonplanarRatio,
    cubic_correlator,
    nonplanar_ratio,
    nonplanar_ratio_of_fit,
)
from cadra.motion.nonrolling import fixed_plane_angles, nonrolling_angle, nonrolling_rate
from cadra.motion.pitch import PitchFit, fit_pitch
from cadra.motion.pureroll import (
    RollCoefficients,
    RollFit,
    energy_balance_amplitude,
    limit_cycle_amplitude_eq31,
    mdc_fit,
    pure_roll_coefficients,
)
from cadra.motion.sectional import Sections, sectional_epicyclic, sectional_pitch

__all__ = [
    "AliasBand", "Arm", "CgSeriesFit", "CubicCorrelator", "Dealiased", "EpicyclicFit",
    "FlightConditions", "KBResult",
    "Layout", "LinearCoefficients", "MomentDerivatives", "MotionFitError", "NonplanarRatio",
    "PitchFit", "RollCoefficients", "RollFit", "Sections", "SwerveFit",
    "cubic_correlator", "dealias_arms", "energy_balance_amplitude", "fit_cg_series",
    "fit_epicyclic", "fit_pitch",
    "fixed_plane_angles", "kb_pitch_reduction", "kb_reduction", "lift_from_swerve",
    "limit_cycle_amplitude_eq31", "linear_coefficients", "mdc_fit", "nonplanar_ratio",
    "nonplanar_ratio_of_fit", "nonrolling_angle", "nonrolling_rate", "pitch_coefficients",
    "planar_coefficients", "pure_roll_coefficients", "sectional_epicyclic", "sectional_pitch",
    "transfer_cg",
]
