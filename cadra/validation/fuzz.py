"""The input parsers' fuzzer: every generated input must give a result or the parser's own error.

Parsers (:data:`PARSERS`): the aero expression parser (``parse_expression``), aero model files
(``load_model``, then ``compile``), trajectory files (``load_trajectory``, then
``load_shot_data`` with a valid shot file) and shot files (``load_shot``), the facility
reference file (``load_facility``), shot specifications (``load_shot_spec``), truth tables
(``load_truth``), bias-table CSVs (``load_bias_table``) and station histories
(``load_history``). Inputs are valid seeds (:func:`seeds_of`: bundled models, sample shots, a
trajectory made from a sample shot's truth, the facility file, the sample specs, a sample
truth table, bias tables and a history written by the calibration library's own writers)
mutated at random (:func:`mutate`, :func:`mutate_entry`) -- lines deleted, duplicated or
swapped; a number replaced by a huge, tiny, NaN, inf, negative or wrong-typed value; two
values swapped; random text spliced in; the file cut short or binary bytes inserted -- and
random text. Anything but a result or the parser's own error class (a ``ValueError``
subclass, :func:`allowed`) counts as uncaught. A history line whose mutation still parses as
a JSON object is, half the time, signed again (its ``sha256`` recomputed, :func:`resign`), so
the checks behind the hash are reached too.

The mutators take any ``random.Random``-like source: :func:`run` drives them from seeded
``random.Random`` s (``tools/fuzz_parsers.py``), ``tests/test_fuzz_parsers.py`` from
hypothesis.
"""

from __future__ import annotations

import json
import random
import re
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

from cadra.facility.reference import REPO_ROOT
from cadra.io.trajectory import trajectory_to_csv
from cadra.validation.truth_files import SAMPLE_SHOTS, trajectory_table

#: the bundled aero models (seeds of the model files)
MODELS = Path(__file__).resolve().parents[1] / "aero" / "models"
#: the sample shot whose shot file the trajectory files are loaded with
SHOT = SAMPLE_SHOTS / "m2_2429" / "shot.toml"
#: the sample shot files (seeds of the shot files)
SHOTS = [SAMPLE_SHOTS / n / "shot.toml" for n in ("m2_2429", "m1_2366", "sphere_1", "cone_1",
                                                   "m3_2397")]
NASTY = ["1e300", "-1e300", "1e-300", "nan", "inf", "-inf", "0", "-0.0", "-1", "-7.5", "1e9",
         "9" * 401, "-" + "9" * 30, '"text"', "true", "[1, 2]", "{}", "", "0x1F", "1_000",
         "'q'", "1/0", "exp(1000)", "log(-mach)", "1e308*10", "(", ")", ",", "#", "\\", "é",
         "\x00", "nan(", "--", "**", "a" * 50]
FUNCS = ["sin", "cos", "tan", "asin", "acos", "atan", "sqrt", "abs", "exp", "log"]
NAMES = ["alpha", "beta", "sigma", "mach", "reynolds", "q_hat", "pi", "a", "b", "c_1", "zz"]
NUMBER = re.compile(r"-?\d+(\.\d*)?([eE][-+]?\d+)?|nan|inf|true|false")


# --- seeds ---------------------------------------------------------------------------------


def model_seeds() -> list[str]:
    return [p.read_text(encoding="utf-8") for p in sorted(MODELS.glob("*.toml"))]


def shot_seeds() -> list[str]:
    return [p.read_text(encoding="utf-8") for p in SHOTS]


def trajectory_seed(n: int = 8) -> str:
    """A trajectory file of the first ``n`` stations of the M2-2429 sample's truth (the first
    three stations ok, warning and failed)."""
    t = trajectory_table(TRUTH, rows=slice(None, n),
                         status=["ok", "warning", "failed", *["ok"] * (n - 3)][:n],
                         x_top_minus_side_m=1e-7, x_consistency=0.3)
    return trajectory_to_csv(t, {"shot_id": "M2-2429", "producer": "fuzz"})


FACILITY = REPO_ROOT / "facilities" / "hffaf.toml"
SPECS = sorted((SAMPLE_SHOTS / "specs").glob("*.toml"))
TRUTH = SHOT.parent / "truth.csv"
PARSERS = ("expression", "model_file", "trajectory_file", "shot_file", "facility_file",
           "shot_spec", "truth_table", "bias_table", "station_history")


def facility_seeds() -> list[str]:
    """The parallel HFFAF and the point-source range (its sparks and films mutated too)."""
    return [FACILITY.read_text(encoding="utf-8"),
            (FACILITY.parent / "brl_spark.toml").read_text(encoding="utf-8")]


def spec_seeds() -> list[str]:
    return [p.read_text(encoding="utf-8") for p in SPECS]


def truth_seeds() -> list[str]:
    text = TRUTH.read_text(encoding="utf-8")
    return [text, "\n".join(text.split("\n")[:4]) + "\n"]


def bias_tables():
    """Three valid :class:`BiasTable` s of facility ``hffaf`` (16, 3 and 1 stations; some
    channels not estimated), in time order."""
    import numpy as np

    from cadra.calibration.table import BiasTable

    rng = np.random.default_rng(17)
    out = []
    for k, n in enumerate((16, 3, 1)):
        sigma = np.full((n, 4), 2e-4)
        sigma[:, 3] = 5e-7
        bias = rng.normal(0, 1, (n, 4)) * sigma
        if n > 1:
            sigma[1, 2], bias[1, 2] = np.nan, 0.0
        out.append(BiasTable(facility="hffaf", created_utc=f"2026-11-2{k}T10:00:00.000001Z",
                             stations=np.arange(1, n + 1), bias=bias, sigma=sigma,
                             shots=("SPH-B1", "SPH-B2")[:k + 1], method="fuzz seed",
                             note="note, with \"quotes\""))
    return out


def bias_table_seeds() -> list[str]:
    """Bias-table CSVs written by :func:`save_bias_table`."""
    from cadra.calibration.table import save_bias_table

    with tempfile.TemporaryDirectory() as tmp:
        return [save_bias_table(t, Path(tmp) / f"t{k}.csv").read_text(encoding="utf-8")
                for k, t in enumerate(bias_tables())]


def history_seeds() -> list[str]:
    """Station histories written by :func:`append_entry` (three entries; one entry)."""
    from cadra.calibration.history import append_entry

    out = []
    for tables in (bias_tables(), bias_tables()[1:2]):
        with tempfile.TemporaryDirectory() as tmp:
            for t in tables:
                path = append_entry(t, tmp)
            out.append(path.read_text(encoding="ascii"))
    return out


JSON_NASTY = [None, "x", "", True, -1, 0, 1e300, -1e300, 1e-320, [], {}, [None], ["x"], [1.5],
              "NaN", float("inf"), 1e30, 0.5, 2**70, "2026-13-40T99:00:00Z",
              "2026-11-22T10:00:00+05:00", "hffaf/../x"]


def mutate_entry(r, text: str) -> str:
    """A history with one entry's JSON changed: a key deleted, duplicated (``{"a":1,"a":2}``)
    or given a wrong-typed or extreme value (or one list element so changed), then signed
    again (:func:`resign`)."""
    lines = text.split("\n")
    spots = [i for i, line in enumerate(lines) if line.startswith("{")]
    if not spots:
        return text
    i = r.choice(spots)
    obj = json.loads(lines[i])
    obj.pop("sha256", None)
    key = r.choice(sorted(obj))
    k = r.randint(0, 3)
    if k == 0:
        del obj[key]
    elif k == 1 and isinstance(obj[key], list) and obj[key]:
        obj[key][r.randrange(len(obj[key]))] = r.choice(JSON_NASTY)
    else:
        obj[key] = r.choice(JSON_NASTY)
    lines[i] = json.dumps(obj, sort_keys=True, separators=(",", ":"))
    text = resign(_Always(), "\n".join(lines))
    if k == 3:  # a duplicated key, after signing (the parser must refuse it, not pick one)
        lines = text.split("\n")
        lines[i] = lines[i].replace("{", '{"facility":"hffaf",', 1)
        text = "\n".join(lines)
    return text


class _Always:
    """A random source whose ``random()`` is always 0.99 (:func:`resign` signs every line)."""

    def random(self):
        return 0.99


def resign(r, text: str) -> str:
    """``text`` (a history) with, for each line that parses as a JSON object, its ``sha256``
    recomputed half the time: a mutation that kept the line JSON reaches the checks behind the
    hash."""
    from cadra.calibration.table import _sha256, canonical_json

    lines = text.split("\n")
    for i, line in enumerate(lines):
        if r.random() < 0.5:
            continue
        try:
            obj = json.loads(line)
        except ValueError:
            continue
        if not isinstance(obj, dict):
            continue
        obj.pop("sha256", None)
        try:
            lines[i] = canonical_json({**obj, "sha256": _sha256(canonical_json(obj))})
        except (ValueError, TypeError):  # NaN or inf: not canonical, leave the line unsigned
            continue
    return "\n".join(lines)


# --- mutators (any random.Random-like source: hypothesis' st.randoms() or random.Random) ------


def random_expression(r, depth: int = 0) -> str:
    """A grammatical form (mostly valid) over the language of docs/aero_models.md."""
    k = r.randint(0, 9) if depth < 6 else r.randint(0, 2)
    if k == 0:
        return r.choice(["0", "1", "2.5", "1e-3", "1e300", "0.0"] + NASTY[:4])
    if k in (1, 2):
        return r.choice(NAMES)
    if k == 3:
        return f"-{random_expression(r, depth + 1)}"
    if k in (4, 5):
        op = r.choice(["+", "-", "*", "/", "**", "<", ">=", "^", "//", "and", "=="])
        return f"({random_expression(r, depth + 1)} {op} {random_expression(r, depth + 1)})"
    if k == 6:
        return f"{r.choice(FUNCS)}({random_expression(r, depth + 1)})"
    if k == 7:
        f = r.choice(["atan2", "min", "max", "where", "piecewise", "open", "x.real"])
        n = r.randint(0, 5)
        return f"{f}({', '.join(random_expression(r, depth + 1) for _ in range(n))})"
    if k == 8:
        return f"{random_expression(r, depth + 1)} if {random_expression(r, depth + 1)} " \
               f"else {random_expression(r, depth + 1)}"
    return " + ".join(random_expression(r, depth + 1) for _ in range(r.randint(2, 40)))


def random_text(r, n: int = 60) -> str:
    alphabet = "abcxyz019.-+*/()[]{}=\"',:#\n\t _eE" + "\x00\x7fé∞"
    return "".join(r.choice(alphabet) for _ in range(r.randint(0, n)))


def mutate(r, text: str, rounds: int | None = None) -> str:
    """``text`` with 1-3 random mutations (lines, values, spliced text, truncation)."""
    for _ in range(rounds if rounds is not None else r.randint(1, 3)):
        lines = text.split("\n")
        k = r.randint(0, 9)
        i = r.randrange(len(lines))
        if k == 0 and len(lines) > 1:                      # delete a line
            del lines[i]
        elif k == 1:                                       # duplicate a line
            lines.insert(i, lines[i])
        elif k == 2:                                       # swap two lines
            j = r.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
        elif k in (3, 4, 5):                               # a value -> a nasty one
            spots = [(n, m) for n, line in enumerate(lines) for m in NUMBER.finditer(line)]
            if spots:
                n, m = r.choice(spots)
                new = r.choice(NASTY) if k != 5 else (f"{r.choice(['', '-'])}"
                                                      f"{r.random():.3f}e{r.randint(-320, 320)}")
                lines[n] = lines[n][:m.start()] + new + lines[n][m.end():]
        elif k == 6:                                       # swap two values
            spots = [(n, m) for n, line in enumerate(lines) for m in NUMBER.finditer(line)]
            if len(spots) > 1:
                (a, ma), (b, mb) = r.choice(spots), r.choice(spots)
                if a != b:
                    va, vb = ma.group(), mb.group()
                    lines[a] = lines[a][:ma.start()] + vb + lines[a][ma.end():]
                    lines[b] = lines[b][:mb.start()] + va + lines[b][mb.end():]
        elif k == 7:                                       # splice random text
            line = lines[i]
            p = r.randint(0, len(line))
            lines[i] = line[:p] + random_text(r, 12) + line[p + r.randint(0, 5):]
        elif k == 8:                                       # cut short
            text = text[:r.randint(0, len(text))]
            continue
        else:                                              # a cell / key -> empty or doubled
            line = lines[i]
            if "," in line:
                cells = line.split(",")
                c = r.randrange(len(cells))
                cells[c] = r.choice(["", cells[c] * 2, " ", "NaN", "x"])
                lines[i] = ",".join(cells)
            elif "=" in line:
                lines[i] = line.replace("=", r.choice(["==", "", "= =", "=\n="]), 1)
        text = "\n".join(lines)
    return text


# --- the parsers under test ----------------------------------------------------------------


def allowed():
    """Parser name -> the exception classes that count as a clear refusal."""
    from cadra.aero.expr import ExpressionError
    from cadra.aero.model import ModelFileError
    from cadra.calibration.table import StationHistoryError
    from cadra.flight.data import FitDataError
    from cadra.io.facility_file import FacilityFileError
    from cadra.io.shotfile import ShotFileError
    from cadra.io.spec_file import SpecError
    from cadra.io.trajectory import TrajectoryFileError

    return {"expression": (ExpressionError,),
            "model_file": (ModelFileError, ExpressionError),
            "trajectory_file": (TrajectoryFileError, FitDataError),
            "shot_file": (ShotFileError,),
            "facility_file": (FacilityFileError,),
            "shot_spec": (SpecError,),
            "truth_table": (TrajectoryFileError,),
            "bias_table": (StationHistoryError,),
            "station_history": (StationHistoryError,)}


def parse_expression_input(text: str):
    from cadra.aero.expr import parse_expression

    return parse_expression(text, {"a", "b", "c_1", "zz"}, context="coefficients.CD")


def load_model_text(text: str | bytes, folder: Path, evaluate: bool = False):
    from cadra.aero import load_model

    p = folder / "model.toml"
    p.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    model = load_model(p)
    model.compile()
    if evaluate:
        model.evaluate(0.3, 0.01, None, 0.9)
    return model


def load_trajectory_text(text: str | bytes, folder: Path):
    from cadra.flight.data import load_shot_data
    from cadra.io.trajectory import load_trajectory

    p = folder / "trajectory.csv"
    p.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    load_trajectory(p)
    return load_shot_data(SHOT, p)


def load_shot_text(text: str | bytes, folder: Path):
    """Load a shot file, then check its model's size against its facility as cadra1 and
    cadra2 do at load time (a facility that does not load is another parser's concern)."""
    from cadra.io.facility_file import FacilityFileError, load_facility
    from cadra.io.shot_check import check_model_size
    from cadra.io.shotfile import load_shot

    p = folder / "shot.toml"
    p.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    shot = load_shot(p)
    try:
        facility = load_facility(shot.facility)
    except (FacilityFileError, OSError):
        return shot
    check_model_size(shot, facility)
    return shot


def _write(folder: Path, name: str, text: str | bytes) -> Path:
    p = folder / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    return p


def load_facility_text(text: str | bytes, folder: Path):
    from cadra.io import facility_file

    facility_file._CACHE.clear()  # each input is a new file, never a cached earlier one
    return facility_file.load_facility(_write(folder, "facility.toml", text))


def load_spec_text(text: str | bytes, folder: Path):
    from cadra.io.spec_file import load_shot_spec

    return load_shot_spec(_write(folder, "spec.toml", text))


def load_truth_text(text: str | bytes, folder: Path):
    from cadra.io.trajectory import load_truth

    return load_truth(_write(folder, "truth.csv", text))


def load_bias_table_text(text: str | bytes, folder: Path):
    from cadra.calibration.table import load_bias_table

    return load_bias_table(_write(folder, "bias_table.csv", text))


def load_history_text(text: str | bytes, folder: Path):
    from cadra.calibration.history import HISTORY_FILENAME, load_history

    _write(folder, f"stations/hffaf/{HISTORY_FILENAME}", text)
    return load_history(folder, "hffaf")


LOADERS = {"model_file": load_model_text, "trajectory_file": load_trajectory_text,
           "shot_file": load_shot_text, "facility_file": load_facility_text,
           "shot_spec": load_spec_text, "truth_table": load_truth_text,
           "bias_table": load_bias_table_text, "station_history": load_history_text}


def seeds_of(kind: str) -> list[str]:
    """The valid inputs that ``kind``'s mutations start from."""
    return {"expression": list, "model_file": model_seeds, "shot_file": shot_seeds,
            "trajectory_file": lambda: [trajectory_seed(8), trajectory_seed(4)],
            "facility_file": facility_seeds, "shot_spec": spec_seeds,
            "truth_table": truth_seeds, "bias_table": bias_table_seeds,
            "station_history": history_seeds}[kind]()


def run_one(kind: str, text, folder: Path, errors: tuple) -> str:
    """``"ok"``, ``"refused"`` (the parser's own error), or raises the uncaught exception."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning flood is a failure too
        try:
            if kind == "expression":
                parse_expression_input(text)
            else:
                LOADERS[kind](text, folder)
        except errors:
            return "refused"
    return "ok"


def generate(kind: str, r: random.Random, seeds: list[str]) -> str | bytes:
    u = r.random()
    if kind == "expression":
        if u < 0.15:
            return random_text(r, 80)
        e = random_expression(r)
        return mutate(r, e) if u < 0.4 else e
    if u < 0.03:
        return bytes(r.randrange(256) for _ in range(r.randint(0, 300)))
    if u < 0.08:
        return random_text(r, 300)
    seed = r.choice(seeds)
    if u < 0.1:
        return seed
    if kind == "station_history":
        return mutate_entry(r, seed) if u < 0.5 else resign(r, mutate(r, seed))
    return mutate(r, seed)


def run(kinds: Sequence[str] = PARSERS, n: int = 10000, seed: int = 0,
        log: Callable[[str], None] = print) -> dict:
    """Fuzz each parser of ``kinds`` with ``n`` generated inputs (a ``random.Random`` seeded
    by ``seed`` and the parser's name). ``log`` gets one line per parser (its counts) and, for
    the first 5 uncaught exceptions of each, the exception, its input and its traceback.

    Returns the figures: ``n_per_parser``, ``seed``, per parser the inputs that parsed
    (``ok``), were refused with the parser's error (``refused``) or raised another exception
    (``uncaught``) and its ``seconds``; the total ``uncaught``."""
    unknown = sorted(set(kinds) - set(PARSERS))
    if unknown:
        raise ValueError(f"unknown parser(s) {unknown}; known: {', '.join(PARSERS)}")
    errors = allowed()
    seeds = {kind: seeds_of(kind) for kind in kinds}
    result = {"n_per_parser": n, "seed": seed}
    uncaught_total = 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for kind in kinds:
            r = random.Random(f"{seed}-{kind}")
            counts = {"ok": 0, "refused": 0, "uncaught": 0}
            t0 = time.perf_counter()
            for _ in range(n):
                text = generate(kind, r, seeds[kind])
                try:
                    counts[run_one(kind, text, folder, errors[kind])] += 1
                except Exception as exc:  # noqa: BLE001 - the point of the fuzzer
                    counts["uncaught"] += 1
                    if counts["uncaught"] <= 5:
                        log(f"--- {kind}: uncaught {type(exc).__name__}: {exc}\n"
                            f"input: {text!r}"[:2000])
                        log(traceback.format_exc(limit=-3))
            counts["seconds"] = round(time.perf_counter() - t0, 1)
            log(f"{kind}: {counts}")
            uncaught_total += counts["uncaught"]
            result[kind] = counts
    result["uncaught"] = uncaught_total
    return result


__all__ = ["NASTY", "PARSERS", "allowed", "bias_tables", "generate", "mutate", "mutate_entry",
           "random_expression", "random_text", "resign", "run", "run_one", "seeds_of"]
