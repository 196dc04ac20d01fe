"""Stage one: shadowgraphs -> positions and attitudes (docs/stage1.md).

Per image: the wires and the image-to-plane map (:mod:`cadra.imaging.wires`), and the model's
pose from its silhouette (:mod:`cadra.imaging.silhouette`: first guess, outline template,
per-segment edge offsets, least squares, centroid cross-check); a finned body's roll
(:mod:`cadra.imaging.roll`); per station: the two views combined (:mod:`cadra.imaging.station`,
:mod:`cadra.imaging.combine`), the overlays (:mod:`cadra.imaging.overlay`); per shot:
:mod:`cadra.imaging.shot` (process pool, progress; images from memory or files). Its outputs
are written by :mod:`cadra.report.stage1`. This package never imports the synthetic side
(:mod:`cadra.synthetic`); the harness that measures synthetic cases is
:mod:`cadra.validation`. View geometry goes through :mod:`cadra.optics`.
"""
