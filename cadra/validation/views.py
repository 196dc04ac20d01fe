"""The harness layer: synthetic cases with exact truth measured by stage one.

The one place that may import both sides: the synthetic data (:mod:`cadra.synthetic`) and
the measurement it tests (:mod:`cadra.imaging`), which never import each other. Tests and
benchmarks (``tools/bench_cadra1.py``) put a case and a measurement together through here.

:func:`measure_case` runs stage one's per-view measurement on a
:class:`~cadra.synthetic.cases.ViewCase`; :func:`case_errors` scores it against the case's
truth; :data:`NO_INVERSE_CRIME` are the renders the measurement does not model, which the
tests and the benchmark both use.
"""

from __future__ import annotations

import math

from cadra.body import Body
from cadra.imaging.silhouette.fit import FitSettings, ViewFit, fit_silhouette
from cadra.imaging.silhouette.locate import locate_model, pose_from_coarse
from cadra.imaging.silhouette.template import make_template
from cadra.synthetic.cases import ViewCase
from cadra.synthetic.render_config import RenderConfig

__all__ = ["IMAGE_FORMATION", "NO_INVERSE_CRIME", "case_errors", "measure_case"]

#: Render settings the measurement does not model (no "inverse crime"): Airy-like and disk
#: PSFs, twice the diffraction fringe, coarser film grain, heavy clutter (docs/stage1.md).
NO_INVERSE_CRIME: dict[str, RenderConfig] = {
    "airy_psf": RenderConfig(psf_shape="airy_like"),
    "disk_psf": RenderConfig(psf_shape="disk"),
    "fringe_x2": RenderConfig(diffraction_fringe=0.2),
    "coarse_grain": RenderConfig(film_grain_sigma=0.02, film_grain_length_px=2.0),
    "heavy_clutter": RenderConfig(scratches=20, dust=300, bow_shock_contrast=0.2,
                                  wake_contrast=0.1),
}


#: Image formations away from the default that stage one does model (it fits the edge width
#: and the fringe), each of which once broke it (docs/stage1.md, "Sharp optics", "Wide
#: edges", "A strong fringe"): 0.4 px and 2 px optics blur, 2.5x the diffraction fringe.
IMAGE_FORMATION: dict[str, RenderConfig] = {
    "sharp_optics": RenderConfig(optics_blur_sigma_px=0.4),
    "wide_blur": RenderConfig(optics_blur_sigma_px=2.0),
    "strong_fringe": RenderConfig(diffraction_fringe=0.25),
}


def measure_case(case: ViewCase, body: Body, settings: FitSettings | None = None,
                 tilt_rad: float | None = None) -> ViewFit:
    """Stage one's per-view measurement of a case with its true affine (no wires):
    locate -> silhouette fit (method a) and centroid (method b). RuntimeError if the model
    is not found. ``tilt_rad`` overrides the case's true out-of-plane tilt."""
    tpl = make_template(body, case.view.name, case.tilt_rad if tilt_rad is None else tilt_rad)
    projection = case.projection
    coarse = locate_model(case.image, tpl, projection)
    if not coarse.ok:
        raise RuntimeError(coarse.reason)
    pose0 = pose_from_coarse(coarse, tpl, projection)
    return fit_silhouette(case.image, tpl, projection, pose0, settings=settings)


def case_errors(case: ViewCase, fit: ViewFit, body: Body) -> tuple[list[float], list[float]]:
    """A fit's errors against the case's truth and its reported sigmas, per channel:
    reference point u, v (px) and, for a non-sphere, the image axis angle (deg)."""
    e = [fit.ref_px[0] - case.u_ref_px, fit.ref_px[1] - case.v_ref_px]
    s = list(fit.sigma_ref_px)
    if body.kind != "sphere":
        e.append(math.degrees(math.remainder(fit.axis_angle_px_rad - case.axis_angle_px_rad,
                                             2 * math.pi)))
        s.append(math.degrees(fit.sigma_axis_px_rad))
    return e, s
