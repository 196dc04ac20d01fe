"""The reporting layer: every table, page and figure CADRA writes or prints.

- :mod:`cadra.report.markdown`: the one Markdown table builder;
- :mod:`cadra.report.figures`: one figure style through matplotlib's object API (no backend
  switching, no pyplot state);
- a module per result: the fit (:mod:`~cadra.report.fit`, plots in
  :mod:`~cadra.report.fit_plots`), the gap diagnosis (:mod:`~cadra.report.gap`), the sphere
  calibration (:mod:`~cadra.report.calibration`), stage one (:mod:`~cadra.report.stage1`),
  the classic motion reduction (:mod:`~cadra.report.motion`), the segmented roll fit
  (:mod:`~cadra.report.roll`) and seed 004's studies (:mod:`~cadra.report.studies`).

Display units come from the channel registry (:mod:`cadra.channels`); every writer builds
its folder through the atomic output guard (:func:`cadra.atomic.atomic_output_dir`), so
an output appears whole or not at all and never replaces an input. Reports only read what
the results stored: nothing here integrates the physics again.
"""
