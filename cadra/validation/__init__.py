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
- :mod:`~cadra.validation.gap_cases`: the gap validation's cases (shots, effect, sizes);
- :mod:`~cadra.validation.gap_measure`: stage-one-like measurements of a simulated shot;
- :mod:`~cadra.validation.gap_trials`: a blind gap-diagnosis trial, a case's trials;
- :mod:`~cadra.validation.gap_scoring`: a gap diagnosis scored against the injected truth;
- :mod:`~cadra.validation.gap_summary`: the gap validation's lines per case and figures;
- :mod:`~cadra.validation.gap_detection`: the gap diagnosis's detection-efficiency scan;
- :mod:`~cadra.validation.gap_power`: a score test's power and the detection curve's fit.
- :mod:`~cadra.validation.roll_bearing`: simulated roll-bearing records of the roll lock-in
  (two finners, Eq. 27 as forms); :mod:`~cadra.validation.lockin`: seed 001 Table IV re-run;
  :mod:`~cadra.validation.seed003_runs`: seed 003's runs and segmented-fit draws;
  :mod:`~cadra.validation.roll_images`, :mod:`~cadra.validation.finner_range`: the finner's
  roll from renders and its range shot end to end (``tools/validate_roll*.py``);
- :mod:`~cadra.validation.motion_cases`, :mod:`~cadra.validation.motion_validation`: the
  seeds' classic-motion cases on a gimbal and a pitch pivot and their tables;
  :mod:`~cadra.validation.motion_records`: solve_ivp records and the motion benchmark;
  :mod:`~cadra.validation.arms`: a yaw history's two arms by Prony's method;
- :mod:`~cadra.validation.tricyclic`, :mod:`~cadra.validation.tricyclic_table`,
  :mod:`~cadra.validation.tricyclic_gap`: seed 002's Run 21 in a wind tunnel, its tricyclic
  table and its gap diagnosis; :mod:`~cadra.validation.m80`: the M-80 end to end;
  :mod:`~cadra.validation.starts_bench`: linear-theory against epicyclic starting values.
"""
