"""Property-based tests of the input parsers: for the aero expression parser, aero model files,
trajectory files, shot files, the facility reference file, shot specifications, truth tables,
bias-table CSVs and station histories, generated inputs -- valid and broken (random text;
valid files mutated: lines deleted, duplicated or swapped, values swapped or replaced by huge,
tiny, NaN, inf, negative or wrong-typed ones, text spliced in, cut short; history entries with
keys deleted, duplicated or mistyped) -- give a result or the parser's own error class, never
another exception (nor a warning: warnings are errors).

The seeds, mutators and parsers are :mod:`cadra.validation.fuzz`'s. CI runs 100 examples per
test (hypothesis' default: each run draws new ones); ``tools/fuzz_parsers.py`` (the same
mutators) runs 10,000 per parser, and the slow-marked test below runs the fuzzer at 2,000.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cadra.validation import fuzz

ERRORS = fuzz.allowed()
MODELS = fuzz.model_seeds()
SHOTS = fuzz.shot_seeds()
TRAJECTORIES = [fuzz.trajectory_seed(8), fuzz.trajectory_seed(4)]
FACILITIES = fuzz.facility_seeds()
SPECS = fuzz.spec_seeds()
TRUTHS = fuzz.truth_seeds()
BIAS_TABLES = fuzz.bias_table_seeds()
HISTORIES = fuzz.history_seeds()
CI = settings(max_examples=100, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _run(kind, text):
    with tempfile.TemporaryDirectory() as tmp:
        return fuzz.run_one(kind, text, Path(tmp), ERRORS[kind])


# --- the aero expression parser --------------------------------------------------------------


@CI
@given(st.text(max_size=200))
def test_expression_random_text(text):
    assert _run("expression", text) in ("ok", "refused")


@CI
@given(st.randoms(use_true_random=False), st.booleans())
def test_expression_generated_forms(r, mutated):
    text = fuzz.random_expression(r)
    assert _run("expression", fuzz.mutate(r, text) if mutated else text) in ("ok", "refused")


@CI
@given(st.lists(st.sampled_from(["a", "b", "mach", "1", "2.5", "sin(alpha)", "-a", "(a)"]),
                min_size=1, max_size=1200),
       st.sampled_from([" + ", " - ", "*", " / "]))
def test_expression_long_chains(terms, op):
    """Sums up to 1200 terms: up to MAX_DEPTH they parse, beyond it a clear error."""
    assert _run("expression", op.join(terms)) in ("ok", "refused")


@CI
@given(st.one_of(st.integers(), st.floats(allow_nan=True, allow_infinity=True)))
def test_expression_numbers(x):
    assert _run("expression", f"a*{x!r}") in ("ok", "refused")


# --- files ---------------------------------------------------------------------------------

#: each file kind's valid seeds (the mutations start from them)
SEEDS = {"model_file": MODELS, "trajectory_file": TRAJECTORIES, "shot_file": SHOTS,
         "facility_file": FACILITIES, "shot_spec": SPECS, "truth_table": TRUTHS,
         "bias_table": BIAS_TABLES, "station_history": HISTORIES}
RANDOM_CONTENT = st.one_of(st.binary(max_size=300), st.text(max_size=300))
#: random content for each kind (a trajectory file's behind its format line, to reach
#: further than the format check)
CONTENT = {kind: RANDOM_CONTENT for kind in SEEDS} | {
    "trajectory_file": st.one_of(
        st.binary(max_size=300),
        st.text(max_size=300).map(lambda t: "# format: cadra-trajectory-1\n" + t))}
BAD_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(),
                       st.sampled_from(['"x"', "true", "[1, 2]", "{}", "-1", "9" * 400,
                                        "[[1, 2, 3], [4, 5]]", "[1e308, 1e308, 1e308]"]))
#: the TOML keys of each kind given one bad value
KEYS = {"shot_file": ["mass_g", "d_cm", "h_cm", "pressure_torr", "temperature_k", "time_s",
                      "station", "schema_version"],
        "facility_file": ["x_m", "width_px", "height_px", "bit_depth", "scale_m_per_px",
                          "u_px", "arm_px", "diameter_m", "id", "schema_version"],
        "shot_spec": ["mass_g", "pressure_torr", "temperature_k", "speed_m_s", "seed", "x_m",
                      "q_deg_s", "inertia_g_cm2", "model", "aim"]}
#: the CSV columns (and rows) of each kind given one bad cell, and the bad cells
CELLS = {"trajectory_file": (7, ["t_s", "x_m", "z_m", "theta_deg", "sigma_y_m",
                                 "sigma_psi_deg", "station", "x_consistency"],
                             fuzz.NASTY + ["1e300", "-1e-9", "nan", "inf"]),
         "bias_table": (15, ["station", "bias_x_m", "bias_time_s", "sigma_y_m", "sigma_time_s"],
                        fuzz.NASTY + ["1e400", "-1e-9", "NaN", "inf", "9" * 30])}


def test_new_seeds_parse():
    """The unmutated seeds are valid: the mutations start from files the parsers accept."""
    for kind, seeds in SEEDS.items():
        for seed in seeds:
            assert _run(kind, seed) == "ok", kind


@pytest.mark.parametrize("kind", [k for k in SEEDS if k != "station_history"])
@CI
@given(r=st.randoms(use_true_random=False), data=st.data())
def test_mutations(kind, r, data):
    seed = data.draw(st.sampled_from(SEEDS[kind]), label="seed")
    assert _run(kind, fuzz.mutate(r, seed)) in ("ok", "refused")


@pytest.mark.parametrize("kind", list(SEEDS))
@CI
@given(data=st.data())
def test_random_content(kind, data):
    assert _run(kind, data.draw(CONTENT[kind], label="content")) in ("ok", "refused")


@pytest.mark.parametrize("kind", list(KEYS))
@CI
@given(data=st.data(), value=BAD_VALUES)
def test_one_bad_value(kind, data, value):
    """One TOML value of a valid file replaced: a result or a refusal."""
    import re

    key = data.draw(st.sampled_from(KEYS[kind]), label="key")
    seed = data.draw(st.sampled_from(SEEDS[kind]), label="seed")
    text = re.sub(rf"^{key} = .*$", f"{key} = {value}", seed, count=1, flags=re.M)
    assert _run(kind, text) in ("ok", "refused")


@pytest.mark.parametrize("kind", list(CELLS))
@CI
@given(data=st.data())
def test_one_bad_cell(kind, data):
    """One cell of a valid table replaced: a result (NaN = not measured) or a refusal naming
    the column."""
    import io

    import pandas as pd

    last_row, columns, values = CELLS[kind]
    value = data.draw(st.sampled_from(values), label="value")
    row = data.draw(st.integers(0, last_row), label="row")
    column = data.draw(st.sampled_from(columns), label="column")
    text = SEEDS[kind][0]
    head = "".join(line + "\n" for line in text.splitlines() if line.startswith("#"))
    t = pd.read_csv(io.StringIO(text), comment="#", dtype=str, keep_default_na=False)
    t.loc[row, column] = value
    assert _run(kind, head + t.to_csv(index=False)) in ("ok", "refused")


@CI
@given(st.randoms(use_true_random=False), st.sampled_from(HISTORIES))
def test_station_history_mutations(r, seed):
    """Text mutations, each JSON line then signed again half the time (reaching the checks
    behind the SHA-256)."""
    assert _run("station_history", fuzz.resign(r, fuzz.mutate(r, seed))) in ("ok", "refused")


@CI
@given(st.randoms(use_true_random=False), st.sampled_from(HISTORIES))
def test_station_history_entry_mutations(r, seed):
    """One entry's key deleted, duplicated or given a wrong-typed or extreme value, signed."""
    assert _run("station_history", fuzz.mutate_entry(r, seed)) in ("ok", "refused")


@pytest.mark.slow
def test_fuzzer_many_inputs():
    """The tool's run (2,000 inputs per parser here; 10,000 from the command line)."""
    result = fuzz.run(fuzz.PARSERS, n=2000, seed=1, log=lambda line: None)
    assert result["uncaught"] == 0
