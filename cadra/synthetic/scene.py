"""What the renderer draws, in pixel coordinates: the :class:`Scene` and its polygons.

Other modules say what to draw (body silhouettes as polygons, fiducial wires, the scanner
reference mark, motion blur, a hint for flow clutter); :mod:`cadra.synthetic.render` draws it.
Pixel convention (``docs/conventions.md``): ``(u, v) = (column, row)``, origin at the centre of
the top-left pixel; pixel ``(u, v)`` covers ``[u - 1/2, u + 1/2] x [v - 1/2, v + 1/2]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cadra.geometry import as_polygon as _as_polygon

__all__ = ["Scene", "distort_scene", "dot_grid_scene", "reference_mark_polygon", "wire_polygon"]


@dataclass(frozen=True, eq=False)
class Scene:
    """What to draw, in pixel coordinates (``docs/conventions.md``).

    Attributes
    ----------
    width_px, height_px
        Image size (columns, rows).
    bodies
        Closed polygons, each ``(N, 2)`` of ``(u, v)`` px (either orientation, not
        self-intersecting): the exact outline of each dark object at mid-exposure.
    wires
        Opaque straight fiducial wires ``((u0, v0), (u1, v1), width_px)``: a rectangle of that
        width centred on the segment, square ends (put the ends outside the image for a wire
        that crosses the field).
    reference_mark
        ``(u, v, arm_px, width_px)``: an upright cross centred at ``(u, v)``; each arm reaches
        ``arm_px`` from the centre and is ``width_px`` wide. ``None``: no mark.
    motion_blur_px
        Image displacement ``(du, dv)`` of the bodies over the exposure (velocity x shutter
        time). Bodies are swept from ``-m/2`` to ``+m/2`` about the polygons, so the polygons
        are the truth at mid-exposure. Wires and mark do not move.
    body_hint
        ``(u_centre, v_centre, axis_du, axis_dv, radius_px)``: where to draw bow-shock and wake
        clutter; the axis (normalized here) points in the flight direction. ``None``: no flow
        clutter.
    wire_outlines
        Fiducial wires given as closed polygons instead (a distorted image's wires are
        curved: :func:`distort_scene`); drawn like ``wires``.
    mark_outline
        The reference mark as a closed polygon instead of ``reference_mark`` (distorted).
    """

    width_px: int
    height_px: int
    bodies: tuple[np.ndarray, ...] = ()
    wires: tuple[tuple[np.ndarray, np.ndarray, float], ...] = ()
    reference_mark: tuple[float, float, float, float] | None = None
    motion_blur_px: tuple[float, float] = (0.0, 0.0)
    body_hint: tuple[float, float, float, float, float] | None = None
    wire_outlines: tuple[np.ndarray, ...] = ()
    mark_outline: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("width_px", "height_px"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"Scene.{name} must be a positive int, got {value!r}")
            object.__setattr__(self, name, int(value))
        if isinstance(self.bodies, np.ndarray) and self.bodies.ndim == 2:
            raise ValueError("Scene.bodies is a tuple of polygons; wrap a single one: (poly,)")
        bodies = tuple(_as_polygon(b, f"Scene.bodies[{i}]") for i, b in enumerate(self.bodies))
        object.__setattr__(self, "bodies", bodies)
        wires = []
        for i, wire in enumerate(self.wires):
            try:
                p0, p1, width = wire
            except (TypeError, ValueError):
                raise ValueError(f"Scene.wires[{i}] must be ((u0, v0), (u1, v1), width)") from None
            p0 = np.array(p0, dtype=np.float64).reshape(2)
            p1 = np.array(p1, dtype=np.float64).reshape(2)
            width = float(width)
            ok = np.all(np.isfinite(p0)) and np.all(np.isfinite(p1)) and math.isfinite(width)
            if not ok or width <= 0.0 or np.hypot(*(p1 - p0)) == 0.0:
                raise ValueError(f"Scene.wires[{i}] needs distinct finite ends and width > 0")
            p0.setflags(write=False)
            p1.setflags(write=False)
            wires.append((p0, p1, width))
        object.__setattr__(self, "wires", tuple(wires))
        object.__setattr__(self, "wire_outlines", tuple(
            _as_polygon(w, f"Scene.wire_outlines[{i}]") for i, w in enumerate(self.wire_outlines)))
        if self.mark_outline is not None:
            object.__setattr__(self, "mark_outline",
                               _as_polygon(self.mark_outline, "Scene.mark_outline"))
        if self.reference_mark is not None:
            mark = tuple(float(x) for x in self.reference_mark)
            if len(mark) != 4 or not all(map(math.isfinite, mark)):
                raise ValueError("Scene.reference_mark must be (u, v, arm_px, width_px)")
            if not 0.0 < mark[3] / 2 < mark[2]:
                raise ValueError("Scene.reference_mark needs 0 < width_px / 2 < arm_px")
            object.__setattr__(self, "reference_mark", mark)
        blur = tuple(float(x) for x in self.motion_blur_px)
        if len(blur) != 2 or not all(map(math.isfinite, blur)):
            raise ValueError("Scene.motion_blur_px must be (du, dv) px")
        object.__setattr__(self, "motion_blur_px", blur)
        if self.body_hint is not None:
            hint = tuple(float(x) for x in self.body_hint)
            if len(hint) != 5 or not all(map(math.isfinite, hint)) or hint[4] <= 0.0:
                raise ValueError("Scene.body_hint must be (u, v, axis_du, axis_dv, radius_px > 0)")
            norm = math.hypot(hint[2], hint[3])
            if norm == 0.0:
                raise ValueError("Scene.body_hint axis has zero length")
            hint = (hint[0], hint[1], hint[2] / norm, hint[3] / norm, hint[4])
            object.__setattr__(self, "body_hint", hint)


def wire_polygon(p0, p1, width_px: float) -> np.ndarray:
    """Rectangle ``(4, 2)`` of a wire of ``width_px`` centred on segment ``p0 -> p1`` (u, v px)."""
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    d = (p1 - p0) / np.hypot(*(p1 - p0))
    n = np.array([-d[1], d[0]]) * (0.5 * width_px)
    return np.array([p0 + n, p1 + n, p1 - n, p0 - n])


def reference_mark_polygon(u: float, v: float, arm_px: float, width_px: float) -> np.ndarray:
    """Upright cross ("plus") ``(12, 2)`` centred at ``(u, v)``: one polygon, so it is exact."""
    a, h = arm_px, 0.5 * width_px
    off = np.array(
        [(a, -h), (a, h), (h, h), (h, a), (-h, a), (-h, h),
         (-a, h), (-a, -h), (-h, -h), (-h, -a), (h, -a), (h, -h)]
    )  # fmt: skip
    return off + np.array([u, v])


def distort_scene(scene: Scene, distortion) -> Scene:
    """``scene`` (ideal pixel coordinates) as a distorted image records it
    (:class:`cadra.optics.distortion.Distortion`): every outline's edges cut to
    :data:`~cadra.optics.distortion.DENSIFY_PX` and its vertices mapped through ``D``; the
    straight wires and the mark become polygons (``wire_outlines``, ``mark_outline``); the
    motion blur and the flow hint follow ``D``'s Jacobian at the bodies' centre. None: the
    scene itself."""
    if distortion is None:
        return scene
    from dataclasses import replace

    from cadra.geometry import densify_polygon
    from cadra.optics.distortion import DENSIFY_PX

    def d(poly):
        return distortion.distort(densify_polygon(poly, DENSIFY_PX))

    bodies = tuple(d(p) for p in scene.bodies)
    wires = tuple(d(wire_polygon(p0, p1, w)) for p0, p1, w in scene.wires)
    wires += tuple(d(p) for p in scene.wire_outlines)
    mark = scene.mark_outline
    if scene.reference_mark is not None:
        mark = reference_mark_polygon(*scene.reference_mark)
    centre = (np.mean(np.concatenate(scene.bodies), axis=0) if scene.bodies
              else np.array([scene.width_px, scene.height_px]) / 2.0)
    J = distortion.jacobian(centre)
    hint = scene.body_hint
    if hint is not None:
        c = distortion.distort(np.array(hint[:2]))
        a = J @ np.array(hint[2:4])
        hint = (float(c[0]), float(c[1]), float(a[0]), float(a[1]), hint[4])
    blur = J @ np.array(scene.motion_blur_px)
    return replace(scene, bodies=bodies, wires=(), wire_outlines=wires, reference_mark=None,
                   mark_outline=None if mark is None else d(mark),
                   motion_blur_px=(float(blur[0]), float(blur[1])), body_hint=hint)


def dot_grid_scene(width_px: int, height_px: int, points_px: np.ndarray, dot_radius_px: float,
                   distortion=None) -> Scene:
    """A calibration plate's image: dark dots of ``dot_radius_px`` (96-gons) at the ideal
    image points ``points_px`` (N, 2), recorded through ``distortion`` (None: none;
    :func:`distort_scene`). What :mod:`cadra.calibration.distortion` calibrates from."""
    a = np.linspace(0.0, 2 * math.pi, 96, endpoint=False)
    ring = dot_radius_px * np.stack([np.cos(a), np.sin(a)], axis=1)
    scene = Scene(width_px=width_px, height_px=height_px,
                  bodies=tuple(p + ring for p in np.asarray(points_px, dtype=float)))
    return distort_scene(scene, distortion)
