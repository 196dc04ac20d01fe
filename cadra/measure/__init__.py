"""Stage one: shadowgraphs -> positions and attitudes (docs/stage1.md).

Per image: wires and the image-to-plane map (:mod:`cadra.measure.wires`), the model's pose by
silhouette least squares and the centroid cross-check (:mod:`cadra.measure.silhouette_fit`);
per station: the two views combined (:mod:`cadra.measure.station`,
:mod:`cadra.measure.combine`); per shot: :mod:`cadra.measure.shot` (process pool, progress,
atomic outputs). The Otsu baseline is :mod:`cadra.measure.baseline`. This package never
imports the synthetic side (:mod:`cadra.synthetic`).
"""
