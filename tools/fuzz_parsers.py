"""Fuzz the input parsers: every generated input must give a result or the project's own error.

Parsers: the aero expression parser (``parse_expression``), aero model files (``load_model``,
then ``compile``), trajectory files (``load_trajectory``, then ``load_shot_data`` with a valid
shot file) and shot files (``load_shot``). Inputs are valid seeds (bundled models, sample
shots, a trajectory made from a sample shot's truth) mutated at random -- lines deleted,
duplicated or swapped; a number replaced by a huge, tiny, NaN, inf, negative or wrong-typed
value; two values swapped; random text spliced in; the file cut short or binary bytes
inserted -- and random text. Anything but a result or the parser's own error class (a
``ValueError`` subclass named in :data:`ALLOWED`) counts as uncaught and is printed with its
input.

    python tools/fuzz_parsers.py [--n 10000] [--seed 0]

The last line printed is a JSON object: per parser the inputs tried, how many parsed, how many
were refused with the parser's error, and the number of uncaught exceptions.
``tests/test_fuzz_parsers.py`` drives the same mutators from hypothesis.
"""

from __future__ import annotations

import argparse
import json
import random
import re
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

SHOT = ROOT / "sample_shots" / "m2_2429" / "shot.toml"
SHOTS = [ROOT / "sample_shots" / n / "shot.toml" for n in ("m2_2429", "m1_2366", "sphere_1",
                                                              "cone_1", "m3_2397")]
NASTY = ["1e300", "-1e300", "1e-300", "nan", "inf", "-inf", "0", "-0.0", "-1", "-7.5", "1e9",
         "9" * 401, "-" + "9" * 30, '"text"', "true", "[1, 2]", "{}", "", "0x1F", "1_000",
         "'q'", "1/0", "exp(1000)", "log(-mach)", "1e308*10", "(", ")", ",", "#", "\\", "é",
         "\x00", "nan(", "--", "**", "a" * 50]
FUNCS = ["sin", "cos", "tan", "asin", "acos", "atan", "sqrt", "abs", "exp", "log"]
NAMES = ["alpha", "beta", "sigma", "mach", "reynolds", "q_hat", "pi", "a", "b", "c_1", "zz"]
NUMBER = re.compile(r"-?\d+(\.\d*)?([eE][-+]?\d+)?|nan|inf|true|false")


# --- seeds ---------------------------------------------------------------------------------


def model_seeds() -> list[str]:
    return [p.read_text(encoding="utf-8")
            for p in sorted((ROOT / "cadra" / "aero" / "models").glob("*.toml"))]


def shot_seeds() -> list[str]:
    return [p.read_text(encoding="utf-8") for p in SHOTS]


def trajectory_seed(n: int = 8) -> str:
    """A trajectory file of the first ``n`` stations of the M2-2429 sample's truth."""
    import pandas as pd

    from cadra.io.trajectory import COLUMNS, trajectory_to_csv

    t = pd.read_csv(SHOT.parent / "truth.csv").iloc[:n]
    t = t[["station", "t_s", "x_m", "y_m", "z_m", "theta_deg", "psi_deg"]].copy()
    t["status"] = ["ok", "warning", "failed", *["ok"] * (n - 3)][:n]
    for c, v in (("sigma_x_m", 1e-4), ("sigma_y_m", 1e-4), ("sigma_z_m", 1e-4),
                 ("sigma_theta_deg", 0.1), ("sigma_psi_deg", 0.1)):
        t[c] = v
    t["x_top_minus_side_m"], t["x_consistency"], t["reason"], t["warnings"] = 1e-7, 0.3, "", ""
    return trajectory_to_csv(t[list(COLUMNS)], {"shot_id": "M2-2429", "producer": "fuzz"})


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
    from cadra.fitting.data import FitDataError
    from cadra.io.shotfile import ShotFileError
    from cadra.io.trajectory import TrajectoryFileError

    return {"expression": (ExpressionError,),
            "model_file": (ModelFileError, ExpressionError),
            "trajectory_file": (TrajectoryFileError, FitDataError),
            "shot_file": (ShotFileError,)}


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
    from cadra.fitting.data import load_shot_data
    from cadra.io.trajectory import load_trajectory

    p = folder / "trajectory.csv"
    p.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    load_trajectory(p)
    return load_shot_data(SHOT, p)


def load_shot_text(text: str | bytes, folder: Path):
    from cadra.io.shotfile import load_shot

    p = folder / "shot.toml"
    p.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    return load_shot(p)


def run_one(kind: str, text, folder: Path, errors: tuple) -> str:
    """``"ok"``, ``"refused"`` (the parser's own error), or raises the uncaught exception."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning flood is a failure too
        try:
            if kind == "expression":
                parse_expression_input(text)
            elif kind == "model_file":
                load_model_text(text, folder)
            elif kind == "trajectory_file":
                load_trajectory_text(text, folder)
            else:
                load_shot_text(text, folder)
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
    return seed if u < 0.1 else mutate(r, seed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=10000, help="inputs per parser")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--parsers", default="expression,model_file,trajectory_file,shot_file")
    args = ap.parse_args(argv)
    errors = allowed()
    seeds = {"expression": [], "model_file": model_seeds(), "shot_file": shot_seeds(),
             "trajectory_file": [trajectory_seed(8), trajectory_seed(4)]}
    result = {"n_per_parser": args.n, "seed": args.seed}
    uncaught_total = 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for kind in args.parsers.split(","):
            r = random.Random(f"{args.seed}-{kind}")
            counts = {"ok": 0, "refused": 0, "uncaught": 0}
            t0 = time.perf_counter()
            for _ in range(args.n):
                text = generate(kind, r, seeds[kind])
                try:
                    counts[run_one(kind, text, folder, errors[kind])] += 1
                except Exception as exc:  # noqa: BLE001 - the point of the tool
                    counts["uncaught"] += 1
                    if counts["uncaught"] <= 5:
                        print(f"--- {kind}: uncaught {type(exc).__name__}: {exc}\n"
                              f"input: {text!r}"[:2000])
                        traceback.print_exc(limit=-3)
            counts["seconds"] = round(time.perf_counter() - t0, 1)
            print(f"{kind}: {counts}", flush=True)
            uncaught_total += counts["uncaught"]
            result[kind] = counts
    result["uncaught"] = uncaught_total
    print(json.dumps(result))
    return 1 if uncaught_total else 0


if __name__ == "__main__":
    sys.exit(main())
