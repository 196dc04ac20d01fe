"""The validation harness: what the benchmarks and validations in ``tools/`` and the tests
share, importable as a package (never by the stages themselves).

It may import every stage, the synthetic side and the stage it tests alike (the stages never
import each other's counterpart: the code that makes test data never imports the code it
tests). Modules:

- :mod:`~cadra.validation.views`: a synthetic single-view case measured by stage one, and
  its errors against the renderer's exact truth;
- :mod:`~cadra.validation.results`: each tool's figures as a JSON file in ``results/``, from
  which ``docs/validation.md`` and the README's figures are generated
  (:mod:`~cadra.validation.figures`);
- the cases, fixtures and scoring the tools and tests share (simulated tunnel records, gap
  cases and scoring, trajectory files made from a truth, image fixtures, the baselines a
  benchmark compares with).
- :mod:`~cadra.validation.truth_files`: stage one's trajectory file made from a truth;
- :mod:`~cadra.validation.wire_images`: wire-only images with an exact truth, their scoring;
- :mod:`~cadra.validation.fuzz`: the input parsers' fuzzer (seeds, mutators, runner);
- :mod:`~cadra.validation.otsu`, :mod:`~cadra.validation.fit_baseline`: the baselines the
  benchmarks compare with (Otsu + moments pixels; the SciPy reference fitter);
- :mod:`~cadra.validation.stage1_bench`, :mod:`~cadra.validation.stage2_bench`: the stage-one
  and stage-two benchmarks' sections (``tools/bench_cadra1.py``, ``tools/bench_cadra2.py``).
"""
