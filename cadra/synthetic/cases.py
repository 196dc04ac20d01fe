"""Random single-view test cases with exact truth, for stage-one tests and benchmarks.

:func:`random_view_case` renders one view of a body at a random subpixel position and a random
attitude on a small frame (the model plus margin; no wires, so the pose fit is measured alone
with the image's true affine), with the renderer's exact truth. The frame's view plane and
affine come from the default facility's scale; the film placement perturbs the affine as
:func:`cadra.synthetic.simulate.film_affine` does for whole shots. Same scene code as whole shots
(:func:`cadra.synthetic.simulate.view_scene`). Measuring a case is the harness layer's job
(:func:`cadra.validation.views.measure_case`): this module never imports stage one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cadra.body import Body
from cadra.conventions import axis_from_inclinations, body_to_facility_matrix, quat_from_axis_roll
from cadra.facility.reference import ReferenceMark, View, nominal_image_to_plane
from cadra.optics.projection import Projection
from cadra.synthetic.render import RenderConfig, render
from cadra.synthetic.simulate import FilmPlacement, film_affine, view_scene

SCALE_M_PER_PX = 1.27e-4


@dataclass(frozen=True, eq=False)
class ViewCase:
    """A rendered view with its truth: pixel reference point, image axis angle (rad), the
    view-plane pose (a, b, phi), the axis tilt out of the view plane, and the scene."""

    image: np.ndarray          # float64 in [0, 1]
    image_u8: np.ndarray       # as rendered (uint8/uint16)
    affine: np.ndarray
    view: View
    u_ref_px: float
    v_ref_px: float
    axis_angle_px_rad: float
    pose: tuple[float, float, float]
    tilt_rad: float
    scene: object
    config: RenderConfig
    R_FB: np.ndarray
    r_ref_F: np.ndarray

    @property
    def projection(self) -> Projection:
        """The view's optics with the image's true affine."""
        return self.view.optics(self.affine)


def small_view(name: str = "top", size_px: int = 512, x_m: float = 0.0) -> View:
    """A wire-less view of ``size_px`` square at the default scale, centred on (x_m, 0)."""
    axes = (0, 1) if name == "top" else (0, 2)
    M = nominal_image_to_plane(x_m, SCALE_M_PER_PX, size_px, size_px)
    return View(station=1, name=name, projection="parallel", axes=axes, width_px=size_px,
                height_px=size_px, bit_depth=8, scale_m_per_px=SCALE_M_PER_PX, image_to_plane=M,
                wires=(), reference_mark=ReferenceMark(12.0, 12.0, 8.0, 2.0))


def random_view_case(body: Body, rng: np.random.Generator, config: RenderConfig | None = None,
                     *, view_name: str = "top", size_px: int = 512, max_angle_deg: float = 25.0,
                     speed_m_s: float = 800.0, clutter: bool = True,
                     inclination_deg: float | None = None) -> ViewCase:
    """Render ``body`` at a random pose (see the module docstring).

    Position: uniform within +-10 px of the frame centre (random subpixel phase); attitude:
    inclinations uniform in +-``max_angle_deg`` (a sphere: arbitrary; ``inclination_deg``
    fixes the first, theta, the random draws staying the same), random roll; velocity
    ``speed_m_s`` along +x (motion blur over the 35 ns exposure); flow clutter drawn when
    ``clutter`` (bow shock only if ``config.bow_shock``).
    """
    config = RenderConfig() if config is None else config
    view = small_view(view_name, size_px)
    lim = math.radians(max_angle_deg)
    theta, psi = rng.uniform(-lim, lim, 2)
    if inclination_deg is not None:
        theta = math.radians(inclination_deg)
    a = axis_from_inclinations(theta, psi)
    R = body_to_facility_matrix(quat_from_axis_roll(a, rng.uniform(0.0, 2 * math.pi)))
    r = np.zeros(3)
    r[list(view.axes)] = rng.uniform(-10.0, 10.0, 2) * SCALE_M_PER_PX
    out_axis = 3 - view.axes[0] - view.axes[1]
    r[out_axis] = rng.uniform(-0.01, 0.01)
    affine = film_affine(view.image_to_plane, FilmPlacement(), rng, size_px, size_px)
    scene, truth = view_scene(body, view, affine, R, r, np.array([speed_m_s, 0.0, 0.0]))
    if not clutter:
        from dataclasses import replace

        scene = replace(scene, body_hint=None, reference_mark=None)
    cfg = config.replace(seed=int(rng.integers(1 << 30)))
    img = render(scene, cfg, rng)
    full = float((1 << cfg.bit_depth) - 1)
    pa = np.array(view.axes)
    ab = r[pa]
    ax = R[:, 0]
    phi = math.atan2(ax[pa[1]], ax[pa[0]])
    return ViewCase(image=img.astype(np.float64) / full, image_u8=img, affine=affine, view=view,
                    u_ref_px=float(truth["u_ref_px"]), v_ref_px=float(truth["v_ref_px"]),
                    axis_angle_px_rad=math.radians(truth["axis_angle_image_deg"]),
                    pose=(float(ab[0]), float(ab[1]), phi),
                    tilt_rad=float(math.asin(np.clip(ax[out_axis], -1, 1))), scene=scene,
                    config=cfg, R_FB=R, r_ref_F=r)
