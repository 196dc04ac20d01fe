"""Model geometry: bodies of revolution with exact silhouettes (docs/bodies.md).

Bodies: :func:`sphere`, :func:`capsule` (seed 004 Fig. 6 / Table 1, presets M1, M2, M3),
:func:`cone` and :func:`bullet` (ogive, cylinder, boattail; preset M80, BRL MR 1833's 7.62 mm
M-80 ball); and one body that is not of revolution, :func:`finner` (a cone-cylinder with four
thin rectangular fins, a :class:`FinnedBody`; preset ``basic_finner``, seed 001's Basic Finner).
Each body of revolution is a :class:`Body` whose meridian ``s_m, r_m`` is measured from a
documented **reference point** on the axis (the point stage one measures; the cg is offset from
it and comes from the shot file): sphere = centre, capsule = centre of the maximum-diameter
circle, cone, bullet and finner = centre of the base plane. Body axes: x nose, y starboard, z down
(docs/conventions.md).

:func:`silhouette` gives the exact outline under parallel projection as a polygon whose
vertices lie on the outline; :func:`silhouette_area_m2` its area in closed form. A finned body's
outline depends on its roll: :func:`finner_silhouette` (:func:`outline_polygon` for any body).
Under a point source (a direct shadowgraph) the shadow's outline is the film's cut through the
cone of rays tangent to the body: :func:`conical_silhouette` (its contour generator
:func:`contour_generator`), :func:`conical_outline_polygon` for any body.
"""

from cadra.body.bullet import M80_IN, M80_MASS_G, bullet, bullet_preset, tangent_ogive_radius_m
from cadra.body.capsule import (
    PRESETS,
    TABLE1_CM,
    CapsuleOML,
    axial_offset_from_virtual_apex,
    capsule,
    preset_dimensions_m,
    solve_capsule_oml,
)
from cadra.body.conical import conical_silhouette, contour_generator
from cadra.body.finner import (
    BASIC_FINNER_CAL,
    FinnedBody,
    FinnedMassProperties,
    conical_outline_polygon,
    fin_polygons,
    finner,
    finner_mass_properties,
    finner_preset,
    finner_silhouette,
    finner_silhouette_area_m2,
    outline_polygon,
)
from cadra.body.mass import SolidProperties, solid_properties
from cadra.body.model import (
    Body,
    axial_offset_from_base,
    cg_offset_from_table2,
    meridian,
)
from cadra.body.outline import silhouette, silhouette_area_m2, surface_points
from cadra.body.shapes import cone, sphere
from cadra.body.spec import KINDS, body_from_spec

__all__ = [
    "BASIC_FINNER_CAL",
    "KINDS",
    "M80_IN",
    "M80_MASS_G",
    "PRESETS",
    "TABLE1_CM",
    "Body",
    "CapsuleOML",
    "FinnedBody",
    "FinnedMassProperties",
    "SolidProperties",
    "axial_offset_from_base",
    "axial_offset_from_virtual_apex",
    "body_from_spec",
    "bullet",
    "bullet_preset",
    "capsule",
    "cg_offset_from_table2",
    "cone",
    "fin_polygons",
    "finner",
    "finner_mass_properties",
    "finner_preset",
    "finner_silhouette",
    "finner_silhouette_area_m2",
    "meridian",
    "outline_polygon",
    "conical_outline_polygon",
    "conical_silhouette",
    "contour_generator",
    "preset_dimensions_m",
    "silhouette",
    "silhouette_area_m2",
    "solid_properties",
    "solve_capsule_oml",
    "sphere",
    "surface_points",
    "tangent_ogive_radius_m",
]
