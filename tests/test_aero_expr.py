"""The coefficient-form language (cadra.aero.expr) and the compiled evaluator
(cadra.aero.program): safe parsing, clear errors, and the numba stack machine against the
independent numpy reference evaluator, for float64 and complex128 (complex step)."""

import pickle

import numpy as np
import pytest
from numba import njit

from cadra.aero import (
    COEFFICIENTS,
    VARIABLES,
    ExpressionError,
    compile_program,
    eval_coefficients,
    evaluate_tree,
    parse_expression,
    to_text,
)
from cadra.aero import program as P
from cadra.aero.expr import simplify

RNG = np.random.default_rng(20240604)
PARAMS = ("A", "B", "C", "alpha_ref", "M_ref")


def parse(text, params=PARAMS):
    return parse_expression(text, params, context="coefficients.Cm")


# --- parsing -------------------------------------------------------------------------------


def test_precedence_and_structure():
    assert parse("A + B*C") == ("add", ("par", "A"), ("mul", ("par", "B"), ("par", "C")))
    assert parse("-A**2") == ("neg", ("pow", ("par", "A"), ("num", 2.0)))
    assert parse("A**B**C") == ("pow", ("par", "A"), ("pow", ("par", "B"), ("par", "C")))
    assert parse("A - B - C") == ("sub", ("sub", ("par", "A"), ("par", "B")), ("par", "C"))
    assert parse("+alpha") == ("var", "alpha")
    assert parse("pi") == ("num", np.pi)
    assert parse("max(A, B, C)") == ("max", ("max", ("par", "A"), ("par", "B")), ("par", "C"))
    assert parse("A if alpha < alpha_ref else B") == parse("where(alpha < alpha_ref, A, B)")
    assert parse("piecewise(alpha < A, 1, alpha < B, 2, 3)") == (
        "where", ("lt", ("var", "alpha"), ("par", "A")), ("num", 1.0),
        ("where", ("lt", ("var", "alpha"), ("par", "B")), ("num", 2.0), ("num", 3.0)))


def test_multiline_and_undeclared_policy():
    t = parse("A\n  + B*sin(alpha)\n")
    assert t == ("add", ("par", "A"), ("mul", ("par", "B"), ("sin", ("var", "alpha"))))
    # parameters=None accepts any valid name as a parameter
    assert parse_expression("foo*alpha") == ("mul", ("par", "foo"), ("var", "alpha"))


@pytest.mark.parametrize("text, fragment", [
    ("__import__('os')", "unknown function '__import__'"),
    ("__builtins__", "invalid name '__builtins__'"),
    ("__import__('os').system('ls')", "attribute access"),
    ("alpha.real", "attribute access"),
    ("sin.__class__", "attribute access"),
    ("alpha[0]", "subscripts"),
    ("(lambda: 1)()", "this call not allowed"),
    ("lambda x: x", "lambda not allowed"),
    ("'abc'", "strings are not allowed"),
    ("f'{A}'", "f-strings not allowed"),
    ("A ^ 2", "use ** for powers"),
    ("A // 2", "operator '//'"),
    ("A % 2", "operator '%'"),
    ("A and B", "'and'/'or'"),
    ("not A", "'not'"),
    ("A == B", "only < > <= >="),
    ("A < B < C", "chained comparisons"),
    ("foo(alpha)", "unknown function 'foo'"),
    ("eval('1')", "unknown function 'eval'"),
    ("open", "undeclared name 'open'"),
    ("Cm_A9 * alpha", "undeclared name 'Cm_A9'"),
    ("sin(alpha, beta)", "sin() takes 1 argument(s), got 2"),
    ("max(A)", "max() takes at least 2 argument(s), got 1"),
    ("where(A, B)", "where() takes 3 argument(s), got 2"),
    ("piecewise(A, B, C, A)", "odd number"),
    ("sin(x=alpha)", "keyword arguments"),
    ("sin(*A)", "starred"),
    ("sin", "used without a call"),
    ("alpha(1)", "unknown function 'alpha'"),
    ("[A, B]", "list literals"),
    ("(A, B)", "tuples"),
    ("True", "not allowed (numbers only)"),
    ("1j * A", "complex literals"),
    ("(x := 1)", "assignment expressions"),
    ("A +", "syntax error"),
    ("", "empty expression"),
    ("A # comment", "comments"),
    ("α * A", "non-ASCII"),
    ("import os", "syntax error"),
])
def test_rejections_name_the_problem(text, fragment):
    with pytest.raises(ExpressionError) as info:
        parse(text)
    msg = str(info.value)
    assert fragment in msg
    assert msg.startswith("coefficients.Cm: ")


def test_error_positions():
    with pytest.raises(ExpressionError) as info:
        parse("A + B*foo")
    e = info.value
    assert (e.line, e.column) == (1, 7)
    assert "undeclared name 'foo'" in str(e) and "column 7" in str(e)
    with pytest.raises(ExpressionError) as info:
        parse("A\n  + B.real")
    assert (info.value.line, info.value.column) == (2, 5)
    with pytest.raises(ExpressionError) as info:
        parse("  A + + * B")
    assert info.value.line == 1 and info.value.column >= 3
    # a file prefix keeps the position
    p = info.value.prefixed("model.toml")
    assert str(p).startswith("model.toml: coefficients.Cm: ") and p.column == info.value.column


def test_to_text_round_trip():
    texts = ["A + B*C", "-(A - B)**2", "A - (B - C)", "A/(B*C)", "(A + B)*C", "A**-B",
             "-A**2", "(-A)**2", "where(alpha < alpha_ref, A, B + C)", "max(A, B, C)",
             "atan2(A, -B) + 2.5e-3", "A - -B", "2**-1", "(A < B) * C"]
    for t in texts:
        tree = parse(t)
        assert parse(to_text(tree)) == tree, t


def test_simplify_powers_and_constants():
    a = ("par", "A")
    assert simplify(parse("A**2")) == ("sqr", a)
    assert simplify(parse("A**4")) == ("sqr", ("sqr", a))
    assert simplify(parse("A**3")) == ("mul", ("sqr", a), a)
    assert simplify(parse("A**-2")) == ("div", ("num", 1.0), ("sqr", a))
    assert simplify(parse("A**0.5")) == ("sqrt", a)
    assert simplify(parse("A**1.5")) == ("powc", a, 1.5)
    assert simplify(parse("2*3 + A")) == ("add", ("num", 6.0), a)
    assert simplify(parse("sin(pi/2)*A")) == ("mul", ("num", 1.0), a)
    assert simplify(parse("-(-A)")) == a
    # impossible constants are left for run time (inf / nan), not raised at compile time
    assert simplify(parse("1/0")) == ("div", ("num", 1.0), ("num", 0.0))


# --- compiled program vs the numpy reference ------------------------------------------------

EXPRESSIONS = [
    "A + B*sin(alpha) - C*cos(beta)**2",
    "A*(sin(alpha) - sin(alpha_ref))**2 + B*(mach - M_ref)**3 / (1 + C*sigma)",
    "where(alpha < alpha_ref, A*alpha, B*alpha**2) + (mach >= M_ref)*C",
    "max(A, B + C*sin(sigma)**2) - min(A, B, C*alpha)",
    "abs(alpha - alpha_ref) + sqrt(mach) + exp(-beta**2) + log(mach + 2)",
    "tan(alpha) + asin(beta) + acos(beta) + atan(alpha)",
    "atan2(beta, alpha) + atan2(-beta, -alpha) + atan2(alpha, 0*alpha) + atan2(beta, -1)",
    "mach**B + (mach + 1)**1.5 + 2**alpha",
    "(alpha <= alpha_ref) - (alpha > A) + (beta < 0)*p_hat + q_hat*r_hat*reynolds",
    "piecewise(sigma < 0.1, A, sigma < 0.3, B*sigma, C*sigma**2)",
    "A*sin(4*phi) + B*cos(2*phi)*sin(sigma) + C*(phi - pi/4)**2*p_hat",
    "-(A - (B - (C - (alpha - (beta - (sigma - (mach - M_ref)))))))",
    "A/alpha + B/sin(alpha) + alpha/B + 3/alpha + alpha/3",
]


def random_points(n, dtype=np.float64):
    V = np.zeros((n, len(VARIABLES)), dtype=dtype)
    V[:, 0] = RNG.uniform(-0.9, 0.9, n)
    V[:, 1] = RNG.uniform(-0.5, 0.5, n)
    V[:, 2] = RNG.uniform(0.0, 0.9, n)
    V[:, 3] = RNG.uniform(0.5, 1.5, n)
    V[:, 4] = RNG.uniform(1e5, 1e6, n)
    V[:, 5:8] = RNG.normal(0, 0.01, (n, 3))
    V[:, 8] = RNG.uniform(-np.pi, np.pi, n)        # phi, the aerodynamic roll angle
    return V


def run_program(prog, V, params):
    dtype = np.result_type(V.dtype, params.dtype)
    out = np.empty((V.shape[0], 9), dtype=dtype)
    stack = prog.new_stack(dtype)
    for i in range(V.shape[0]):
        eval_coefficients(prog.ops, prog.args, prog.starts, V[i].astype(dtype),
                          params.astype(dtype), out[i], stack)
    return out


def reference(trees, V, params):
    env = {name: V[:, j] for j, name in enumerate(VARIABLES)}
    pm = dict(zip(PARAMS, params, strict=True))
    out = np.zeros((V.shape[0], 9), dtype=np.result_type(V.dtype, params.dtype))
    for k, name in enumerate(COEFFICIENTS):
        if name in trees:
            out[:, k] = evaluate_tree(trees[name], env, pm)
    return out


def test_program_matches_reference_float_and_complex():
    # all forms in one model (shared subexpressions across coefficients get temporaries)
    for i0 in range(0, len(EXPRESSIONS), 9):
        chunk = EXPRESSIONS[i0:i0 + 9]
        trees = {COEFFICIENTS[k]: parse(t) for k, t in enumerate(chunk)}
        prog = compile_program(trees, PARAMS, "alpha_beta")
        params = np.array([0.7, -1.3, 2.1, np.radians(21.0), 0.8])
        V = random_points(64)
        got, want = run_program(prog, V, params), reference(trees, V, params)
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)
        Vc = V.astype(complex) + 1e-3j * RNG.normal(size=V.shape)
        pc = params + 1e-3j * RNG.normal(size=params.shape)
        got, want = run_program(prog, Vc, pc), reference(trees, Vc, pc)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_python_mode_evaluator_agrees_and_stack_size_suffices():
    # the evaluator's pure-Python function with a stack of exactly stack_size: any overflow
    # would raise IndexError (two implementations of the same machine)
    trees = {COEFFICIENTS[k]: parse(t) for k, t in enumerate(EXPRESSIONS[:9])}
    prog = compile_program(trees, PARAMS, "alpha_beta")
    params = np.array([0.7, -1.3, 2.1, np.radians(21.0), 0.8])
    for v in random_points(5):
        out_py = np.empty(9)
        stack = np.zeros(prog.stack_size)
        with np.errstate(all="ignore"):
            eval_coefficients.py_func(prog.ops, prog.args, prog.starts, v, params, out_py,
                                      stack)
        np.testing.assert_allclose(out_py, run_program(prog, v[None], params)[0], rtol=1e-14)


def test_complex_step_rules():
    h = 1e-30
    params = np.array([0.5, 2.0, -1.0, 0.3, 0.0])
    forms = {
        "CD": "abs(alpha - alpha_ref)",
        "CL": "max(A*alpha, B*alpha)",
        "CC": "min(A*alpha, B*alpha)",
        "Cl": "where(alpha < alpha_ref, A*alpha**2, B*alpha**3)",
        "Cm": "(alpha > alpha_ref)*alpha",
        "Cn": "atan2(sin(alpha), C + cos(alpha))",
        "Clp": "sqrt(mach)*exp(alpha)*log(mach)",
        "Cmq": "mach**alpha",
        "Cnr": "asin(alpha/2) + acos(alpha/3) + atan(alpha) + tan(alpha)",
    }
    trees = {k: parse(v) for k, v in forms.items()}
    prog = compile_program(trees, PARAMS, "alpha_beta")

    def d_dalpha(a):
        v = np.zeros(8, dtype=complex)
        v[0], v[3] = a + 1j * h, 1.3
        return prog.evaluate(v, params.astype(complex)).imag / h

    for a in (0.1, 0.5, -0.4, 0.9):
        g = d_dalpha(a)
        m = 1.3
        assert g[0] == pytest.approx(np.sign(a - 0.3), rel=1e-15)
        assert g[1] == pytest.approx(2.0 if a > 0 else 0.5, rel=1e-15)
        assert g[2] == pytest.approx(0.5 if a > 0 else 2.0, rel=1e-15)
        assert g[3] == pytest.approx(1.0 * a if a < 0.3 else 6.0 * a**2, rel=1e-14)
        assert g[4] == pytest.approx(1.0 if a > 0.3 else 0.0, abs=0)
        # atan2(sin a, cos a - 1) has derivative d/da = (1 - cos a) / (2 - 2 cos a) = 1/2
        assert g[5] == pytest.approx(0.5, rel=1e-12)
        assert g[6] == pytest.approx(np.sqrt(m) * np.exp(a) * np.log(m), rel=1e-14)
        assert g[7] == pytest.approx(np.log(m) * m**a, rel=1e-14)
        want = (0.5 / np.sqrt(1 - (a / 2) ** 2) - (1 / 3) / np.sqrt(1 - (a / 3) ** 2)
                + 1 / (1 + a * a) + 1 / np.cos(a) ** 2)
        assert g[8] == pytest.approx(want, rel=1e-13)


def test_division_by_zero_gives_inf_not_an_exception():
    trees = {"CD": parse("1/(alpha - alpha) + A"), "CL": parse("A/(alpha - alpha)")}
    prog = compile_program(trees, PARAMS, "alpha_beta")
    v = np.full(8, 0.3)
    p = np.array([2.0, 0, 0, 0, 0])
    assert np.isinf(prog.evaluate(v, p)[:2]).all()
    out = prog.evaluate(v.astype(complex), p.astype(complex))
    assert np.isinf(out[:2].real).all()


def test_program_of_another_format_evaluates_to_nan():
    prog = compile_program({"CD": parse("A + 1")}, PARAMS, "alpha_beta")
    v, p = np.zeros(8), np.ones(5)
    assert prog.ops[0] == P.HEADER and prog.args[0] == P.PROGRAM_FORMAT
    assert prog.evaluate(v, p)[0] == 2.0
    args = prog.args.copy()
    args[0] = P.PROGRAM_FORMAT - 1  # e.g. a stale cached evaluator meeting a new program
    out = np.empty(9)
    eval_coefficients(prog.ops, args, prog.starts, v, p, out, prog.new_stack())
    assert np.isnan(out).all()


def test_empty_and_zero_programs_and_cse():
    trees = {"CD": parse("0"), "Cm": parse("A*(sin(alpha) - sin(alpha_ref))"),
             "Cmq": parse("B*(sin(alpha) - sin(alpha_ref))**2")}
    prog = compile_program(trees, PARAMS, "alpha_beta")
    s = prog.starts
    assert s.shape == (10,)
    for k, name in enumerate(COEFFICIENTS):
        if name not in ("Cm", "Cmq"):
            assert s[k] == s[k + 1], name  # empty program
    # sin(alpha) - sin(alpha_ref) is computed once, in the prelude
    assert s[0] > 0 and np.count_nonzero(prog.ops == P.SIN) == 2
    assert np.count_nonzero(prog.ops[s[0]:] == P.SIN) == 0
    out = prog.evaluate([0.4, 0, 0, 1, 0, 0, 0, 0], [2.0, 3.0, 0, 0.1, 0])
    ds = np.sin(0.4) - np.sin(0.1)
    np.testing.assert_allclose(out, [0, 0, 0, 0, 2 * ds, 0, 0, 3 * ds**2, 0], rtol=1e-15)
    listing = prog.disassemble()
    assert "HEADER   format" in listing and "SIN" in listing and "Cmq:" in listing
    # a program is plain arrays: picklable
    again = pickle.loads(pickle.dumps(prog))
    np.testing.assert_array_equal(again.ops, prog.ops)


def test_callable_from_user_njit_code_both_dtypes():
    @njit
    def integrate_like(ops, args, starts, variables, params, n):
        out = np.zeros(9, dtype=variables.dtype)   # (np.empty: out[0] * 0.0 may be nan)
        stack = np.empty(16, dtype=variables.dtype)
        total = out[0] * 0.0
        for _ in range(n):
            variables[0] += 0.001
            eval_coefficients(ops, args, starts, variables, params, out, stack)
            total += out[4]
        return total

    trees = {"Cm": parse("A*sin(alpha) + B*alpha**2")}
    prog = compile_program(trees, PARAMS, "alpha_beta")
    params = np.array([-0.1, 0.2, 0, 0, 0])
    a = 0.001 * np.arange(1, 11)
    want = np.sum(-0.1 * np.sin(a) + 0.2 * a**2)
    got = integrate_like(prog.ops, prog.args, prog.starts, np.zeros(8), params, 10)
    assert got == pytest.approx(want, rel=1e-14)
    gotc = integrate_like(prog.ops, prog.args, prog.starts, np.zeros(8, complex),
                          params.astype(complex), 10)
    assert gotc.real == pytest.approx(want, rel=1e-14)
