"""Optics: how a facility point becomes an image point (docs/conventions.md, "Projections").

:class:`~cadra.optics.projection.Projection` is the protocol every view's optics implements;
:class:`~cadra.optics.projection.ParallelProjection` (collimated shadowgraph) is the one
stage one and the renderer use today; :class:`~cadra.optics.projection.PointSourceProjection`
(a direct shadowgraph's conical projection) implements the protocol too. Depends on
:mod:`cadra.geometry` only.
"""

from cadra.optics.projection import (
    ParallelProjection,
    PointSourceProjection,
    Projection,
    intersect_rays,
)

__all__ = ["ParallelProjection", "PointSourceProjection", "Projection", "intersect_rays"]
