"""Facility: the range's stations, views, optics and fiducial wires (docs/facility_file.md).

The geometry and data objects are :mod:`cadra.facility.reference`; the file format
(``load_facility("hffaf")`` reads ``facilities/hffaf.toml``; ``facility_from_dict``,
``FacilityFileError``) is :mod:`cadra.io.facility_file`. This package is part of the numerical
core and imports no file format (docs/architecture.md).
"""

from cadra.facility.reference import (
    AffineFit,
    Facility,
    ReferenceMark,
    Station,
    View,
    Wire,
    fit_affine_to_wires,
    nominal_image_to_plane,
)

__all__ = [
    "AffineFit", "Facility", "ReferenceMark", "Station", "View", "Wire",
    "fit_affine_to_wires", "nominal_image_to_plane",
]
