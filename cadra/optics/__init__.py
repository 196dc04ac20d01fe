"""Optics: how a facility point becomes an image point (docs/conventions.md, "Projections").

:class:`~cadra.optics.projection.Projection` is the protocol every view's optics implements;
:class:`~cadra.optics.projection.ParallelProjection` (collimated shadowgraph) is the one
implementation today. Depends on :mod:`cadra.geometry` only.
"""

from cadra.optics.projection import ParallelProjection, Projection, intersect_rays

__all__ = ["ParallelProjection", "Projection", "intersect_rays"]
