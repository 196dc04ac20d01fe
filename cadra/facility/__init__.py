"""Facility: the range's stations, views, optics and fiducial wires (docs/facility_file.md).

``load_facility("hffaf")`` reads ``facilities/hffaf.toml``; see :mod:`cadra.facility.reference`.
"""

from cadra.facility.reference import (
    AffineFit,
    Facility,
    FacilityFileError,
    ReferenceMark,
    Station,
    UnsupportedProjectionError,
    View,
    Wire,
    affine_inverse,
    apply_affine,
    facility_from_dict,
    fit_affine_to_wires,
    load_facility,
    nominal_image_to_plane,
)

__all__ = [
    "AffineFit", "Facility", "FacilityFileError", "ReferenceMark", "Station",
    "UnsupportedProjectionError", "View", "Wire", "affine_inverse", "apply_affine",
    "facility_from_dict", "fit_affine_to_wires", "load_facility", "nominal_image_to_plane",
]
