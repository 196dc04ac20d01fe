"""CADRA: ballistic-range data reduction.

Stage one (``cadra1``) measures model position and attitude from shadowgraphs; stage two
(``cadra2``) identifies aerodynamic coefficients by 6-DOF least-squares differential correction.
The simulator (:mod:`cadra.synthetic`) and the fitter share one dynamics
and one aerodynamic-model code path.

Conventions (frames, angles, pixel origin, units) are defined once in ``docs/conventions.md``
and implemented in :mod:`cadra.conventions`.
"""

__version__ = "0.1.0"

from cadra._numba_cache import configure as _configure_numba_cache

_configure_numba_cache()
