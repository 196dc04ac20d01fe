"""Stage one: shadowgraphs -> positions and attitudes (docs/stage1.md).

Per image: wires and the image-to-plane map (:mod:`cadra.measure.wires`), the first guess
(:mod:`cadra.measure.locate`), the model's pose by silhouette least squares
(:mod:`cadra.measure.silhouette_lsq`: the outline template :mod:`cadra.measure.template`, the
per-segment edge offsets :mod:`cadra.measure.edge_segments`) and the centroid cross-check
(:mod:`cadra.measure.centroid`);
per station: the two views combined (:mod:`cadra.measure.station`,
:mod:`cadra.measure.combine`); per shot: :mod:`cadra.measure.shot` (process pool, progress,
atomic outputs). The Otsu baseline is :mod:`cadra.measure.baseline`. This package never
imports the synthetic side (:mod:`cadra.synthetic`); the harness that measures synthetic
cases is :mod:`cadra.validation`. View geometry goes through :mod:`cadra.optics`.
"""
