"""Angular-motion analysis: pure functions over angle histories (docs/motion.md).

Epicyclic and tricyclic fits by differential corrections (10- and 12-constant forms, the
nonrolling-axis correction), 1-DOF pitch fits, overlapping sectional fits, the
Kryloff-Bogoliuboff nonlinear reduction, linear-theory coefficients from the fitted arms,
Murphy's cubic correlator, the Nonplanar Ratio and the cg transfer. Plain numpy in, frozen
dataclasses out; no file I/O. May import only the numerical core (numpy, scipy,
cadra.conventions, cadra.units, cadra.numfmt).
"""

from cadra.motion.epicyclic import Arm, EpicyclicFit, Layout, MotionFitError, fit_epicyclic
from cadra.motion.nonrolling import fixed_plane_angles, nonrolling_angle, nonrolling_rate

__all__ = [
    "Arm", "EpicyclicFit", "Layout", "MotionFitError", "fit_epicyclic",
    "fixed_plane_angles", "nonrolling_angle", "nonrolling_rate",
]
