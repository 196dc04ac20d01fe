"""The fiducial wires of one shadowgraph: find them, fit their lines and solve the view's
image -> plane affine (docs/stage1.md, "Wires").

- :mod:`~cadra.imaging.wires.fit`: :func:`measure_wires`, the steps from finding the wires to
  the affine and its covariance (:class:`WireMeasurement`);
- :mod:`~cadra.imaging.wires.profile`: each wire's cross-section modelled as the image forms
  it (blur before and after the pixel, fringe): centres without a phase bias;
- :mod:`~cadra.imaging.wires.formation`: how the images formed their wires, fitted once per
  view of a shot (or per image);
- :mod:`~cadra.imaging.wires.mask`: the pixels near the wires, which the silhouette leaves out;
- :mod:`~cadra.imaging.wires.phase`: the centroid's sub-pixel phase bias, where the profile
  model is not used;
- :mod:`~cadra.imaging.wires.straightness`: the test that leaves out a stretch a shock or flow
  line runs along;
- :mod:`~cadra.imaging.wires.affine`: the affine's generalized least squares and covariance.
"""

from cadra.imaging.wires.fit import WireMeasurement, measure_wires, wire_profiles
from cadra.imaging.wires.formation import fit_formation, fit_widths
from cadra.imaging.wires.mask import wire_mask

__all__ = ["WireMeasurement", "fit_formation", "fit_widths", "measure_wires", "wire_mask",
           "wire_profiles"]
