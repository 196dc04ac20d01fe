"""Facility: the range's stations, views, optics and fiducial wires (docs/facility_file.md).

``load_facility("hffaf")`` reads ``facilities/hffaf.toml``. The geometry and data objects are
:mod:`cadra.facility.reference`; the file format (``load_facility``, ``facility_from_dict``,
``FacilityFileError``) is :mod:`cadra.io.facility_file`, re-exported here.
"""

from cadra.facility.reference import (
    AffineFit,
    Facility,
    ReferenceMark,
    Station,
    View,
    Wire,
    affine_inverse,
    apply_affine,
    fit_affine_to_wires,
    nominal_image_to_plane,
)

#: names of :mod:`cadra.io.facility_file` offered here (imported on first use: that module
#: imports :mod:`cadra.facility.reference`).
#: Transition shim, to be deleted: it is this package's one import of cadra.io, which the import
#: contract "the numerical core imports no formats" (pyproject.toml) refuses. It stays while
#: cadra/measure/shot.py, cadra/measure/station.py, tests/test_wires.py and
#: tests/test_projection.py import these names from here rather than cadra.io.facility_file.
_FILE_FORMAT_NAMES = ("FacilityFileError", "UnsupportedProjectionError", "facility_from_dict",
                      "load_facility", "resolve_facility_path")


def __getattr__(name: str):
    if name in _FILE_FORMAT_NAMES:
        from cadra.io import facility_file

        return getattr(facility_file, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "AffineFit", "Facility", "ReferenceMark", "Station", "View", "Wire", "affine_inverse",
    "apply_affine", "fit_affine_to_wires", "nominal_image_to_plane", *_FILE_FORMAT_NAMES,
]
