"""The model's pose in one shadowgraph from its silhouette (docs/stage1.md):

- :mod:`~cadra.imaging.silhouette.template`: the body's outline template in a view, and its
  pixel outline at a pose;
- :mod:`~cadra.imaging.silhouette.locate`: the coarse location, the fit's first guess;
- :mod:`~cadra.imaging.silhouette.edges`: stage A, per-segment edge offsets about a trial
  outline;
- :mod:`~cadra.imaging.silhouette.polygon`: the blurred-edge model of a whole polygon,
  corners included (a finned body's roll);
- :mod:`~cadra.imaging.silhouette.noise`: the image noise's correlation and the offsets'
  covariance it makes;
- :mod:`~cadra.imaging.silhouette.fit`: the silhouette least squares (method a),
  :func:`fit_silhouette`;
- :mod:`~cadra.imaging.silhouette.centroid`: the pose from the shadow's area moments
  (method b).
"""

from cadra.imaging.silhouette.fit import FitSettings, ViewFit, fit_silhouette

__all__ = ["FitSettings", "ViewFit", "fit_silhouette"]
