"""CADRA: ballistic-range data reduction.

Shadowgraphs -> positions and attitudes -> aerodynamic coefficients with honest
uncertainties, and a diagnosis of why a fit does not match the data (docs/api.md)::

    import cadra

    shot = cadra.simulate("sample_shots/specs/m2_2429.toml")    # flown and rendered
    stage1 = cadra.measure(shot)                                # images -> trajectory
    result = cadra.fit(stage1, "m2_m070")                       # trajectory -> coefficients
    print(result.report())

The calls of the whole job (:mod:`cadra.pipeline`): :func:`simulate`, :func:`measure` (and
:func:`measure_view` for one image), :func:`fit`, :func:`diagnose`, :func:`calibrate`,
:func:`plan` (what to fire next); the
readers :func:`load_model`, :func:`load_shot_data`, :func:`load_shots`. They are imported
when first used, so ``import cadra`` stays light.

Conventions (frames, angles, pixel origin, units) are defined once in ``docs/conventions.md``
and implemented in :mod:`cadra.conventions`.
"""

__version__ = "0.1.0"

from cadra._numba_cache import configure as _configure_numba_cache

_configure_numba_cache()

#: the top-level names and the module each lives in (imported on first use)
_LAZY = {
    "simulate": "cadra.pipeline", "measure": "cadra.pipeline",
    "measure_view": "cadra.pipeline", "fit": "cadra.pipeline", "diagnose": "cadra.pipeline",
    "calibrate": "cadra.pipeline", "plan": "cadra.pipeline",
    "load_shot_data": "cadra.flight", "load_shots": "cadra.flight", "ShotData": "cadra.flight",
    "FitResult": "cadra.fitting", "load_model": "cadra.aero",
}
_ALIASES = {"load_model": "resolve_model"}

__all__ = ["__version__", *sorted(_LAZY)]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), _ALIASES.get(name, name))
        globals()[name] = value
        return value
    raise AttributeError(f"module 'cadra' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
