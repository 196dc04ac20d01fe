"""The papers' studies on top of the fitter (their outputs: :mod:`cadra.report.studies`,
:mod:`cadra.report.roll`):

- :mod:`cadra.studies.single`: seed 004's single fits with linear forms and the quasi-linear
  trends against amplitude (steps 1 and 2);
- :mod:`cadra.studies.holdone`: seed 004's hold-one-parameter study (Fig. 15);
- :mod:`cadra.studies.segmented_roll`: seed 003's global segmented fit of pure rolling
  motion, with the paper's Tables 2 and 3 beside it.
"""
