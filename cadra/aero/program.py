"""Compiled aerodynamic-model programs and their numba evaluator.

An :class:`AeroModel` (``cadra.aero.model``) compiles its coefficient forms into one flat
*program* for a small stack machine (``cadra.aero.expr`` does the compiling). The evaluator
:func:`eval_coefficients` runs that program inside numba-jitted code (the 6-DOF integrator of
``cadra.dynamics``) for float64 or complex128 inputs (complex-step derivatives).

Program layout
--------------
``ops`` (int64) are opcodes, ``args`` (float64, same length) their operands: a constant value,
or an integer index stored as a float (variable, parameter, temporary slot or coefficient).

- ``ops[0]`` is ``HEADER`` with ``args[0] = PROGRAM_FORMAT``; a program without it (or of
  another format) evaluates to NaN.
- ``ops[1:starts[0]]`` is the *prelude*: common subexpressions shared by several coefficients
  (``sin(alpha)``, ``mach - M_ref``, ...), each computed once per call and stored in a
  temporary slot (``STORE_T``).
- ``ops[starts[k]:starts[k+1]]`` is the program of coefficient ``COEFFICIENTS[k]``; it ends
  with ``OUT k``. An empty program means the coefficient is 0.

Machine: an accumulator ``acc`` (the top of the stack, kept in a register) over a value stack
in ``stack[0:depth]``; temporaries live at the *end* of ``stack``: slot ``t`` is
``stack[len(stack) - 1 - t]``. A ``stack`` of length ``AeroProgram.stack_size`` (= maximum
depth + number of temporaries) is enough; longer is fine. Opcodes are dense small integers in
one ``if/elif ==`` chain (LLVM makes it a jump table): fused ops combine the accumulator with
an operand from a constant (C), variable (V), parameter (P) or temporary (T); ``PMUL``/``AMUL``
push or add a product of two V/P/T operands (the parameter-times-term pattern of Table 4).
Table of opcodes: docs/aero_models.md.

Complex-step rules (docs/aero_models.md): comparisons, ``min``/``max``, ``abs`` and ``where``
decide on real parts; everything else is the analytic complex function, so
``Im f(x + ih) / h`` is the exact derivative.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit

#: output order of :func:`eval_coefficients`
COEFFICIENTS = ("CD", "CL", "CC", "Cl", "Cm", "Cn", "Clp", "Cmq", "Cnr")
#: input order of the ``variables`` vector; angles in radians
VARIABLES = ("alpha", "beta", "sigma", "mach", "reynolds", "p_hat", "q_hat", "r_hat", "phi")
N_COEFFICIENTS = len(COEFFICIENTS)
N_VARIABLES = len(VARIABLES)

# --- opcodes -------------------------------------------------------------------------------
# Operand sources of the fused ops, in this order: C constant (args value), V variable,
# P parameter, T temporary slot. ``<OP>_<src>`` combines the accumulator with that operand.
SOURCES = ("C", "V", "P", "T")
PUSH_C, PUSH_V, PUSH_P, PUSH_T = 0, 1, 2, 3  # push acc; acc = operand
ADD_C, ADD_V, ADD_P, ADD_T = 4, 5, 6, 7  # acc = acc + x
SUB_C, SUB_V, SUB_P, SUB_T = 8, 9, 10, 11  # acc = acc - x
RSUB_C, RSUB_V, RSUB_P, RSUB_T = 12, 13, 14, 15  # acc = x - acc
MUL_C, MUL_V, MUL_P, MUL_T = 16, 17, 18, 19  # acc = acc * x
DIV_C, DIV_V, DIV_P, DIV_T = 20, 21, 22, 23  # acc = acc / x
RDIV_C, RDIV_V, RDIV_P, RDIV_T = 24, 25, 26, 27  # acc = x / acc
MAX_C, MAX_V, MAX_P, MAX_T = 28, 29, 30, 31  # acc = max(acc, x)   (on real parts)
MIN_C, MIN_V, MIN_P, MIN_T = 32, 33, 34, 35  # acc = min(acc, x)
# binary on the stack: acc = pop() <op> acc
ADD, SUB, MUL, DIV, POW, ATAN2, MAX, MIN = 36, 37, 38, 39, 40, 41, 42, 43
LT, GT, LE, GE = 44, 45, 46, 47  # 1.0 or 0.0, comparing real parts
SELECT = 48  # b = acc, a = pop(), c = pop(): acc = a if c.real != 0 else b
# unary on the accumulator
NEG, SQR, POW_C, SIN, COS, TAN, ASIN, ACOS, ATAN, SQRT, ABS, EXP, LOG = range(49, 62)
STORE_T = 62  # temporary[args] = acc; acc = pop()
OUT = 63  # out[args] = acc; acc = pop()
# two-operand products x*y, x and y from V, P or T (not C); ``args`` packs both indices:
# ``i_x + i_y * PAIR`` (exact in a float64)
PAIR_SOURCES = ("V", "P", "T")
PAIR = 1 << 20
PMUL_VV, PMUL_VP, PMUL_VT, PMUL_PV, PMUL_PP, PMUL_PT, PMUL_TV, PMUL_TP, PMUL_TT = range(64, 73)
AMUL_VV, AMUL_VP, AMUL_VT, AMUL_PV, AMUL_PP, AMUL_PT, AMUL_TV, AMUL_TP, AMUL_TT = range(73, 82)
HEADER = 82  # ops[0]: args[0] = PROGRAM_FORMAT (checked by the evaluator)
N_OPCODES = 83

#: version of the opcode set and program layout. Bump it whenever opcodes or their meaning
#: change: numba's on-disk cache of a *caller* (e.g. the integrator) embeds a copy of
#: :func:`eval_coefficients` and is not invalidated when this file changes; a stale copy then
#: sees a program of another format and returns NaNs instead of silently wrong numbers.
PROGRAM_FORMAT = 2

#: opcode -> mnemonic (for :func:`disassemble`)
OPCODE_NAMES = {}
for _base, _name in ((0, "PUSH"), (4, "ADD"), (8, "SUB"), (12, "RSUB"), (16, "MUL"), (20, "DIV"),
                     (24, "RDIV"), (28, "MAX"), (32, "MIN")):
    for _k, _s in enumerate(SOURCES):
        OPCODE_NAMES[_base + _k] = f"{_name}_{_s}"
for _code, _name in enumerate(
        ("ADD", "SUB", "MUL", "DIV", "POW", "ATAN2", "MAX", "MIN", "LT", "GT", "LE", "GE",
         "SELECT", "NEG", "SQR", "POW_C", "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "SQRT",
         "ABS", "EXP", "LOG", "STORE_T", "OUT"), start=36):
    OPCODE_NAMES[_code] = _name
for _k, (_x, _y) in enumerate((x, y) for x in PAIR_SOURCES for y in PAIR_SOURCES):
    OPCODE_NAMES[PMUL_VV + _k] = f"PMUL_{_x}{_y}"  # push acc; acc = x * y
    OPCODE_NAMES[AMUL_VV + _k] = f"AMUL_{_x}{_y}"  # acc = acc + x * y
OPCODE_NAMES[HEADER] = "HEADER"
assert len(OPCODE_NAMES) == N_OPCODES


@dataclass(frozen=True, eq=False)
class AeroProgram:
    """A compiled aerodynamic model: plain numpy arrays, picklable, ready for numba.

    Attributes
    ----------
    ops : (n,) int64 opcodes.
    args : (n,) float64 operands (constants, or indices stored as floats).
    starts : (10,) int64; coefficient ``k``'s program is ``ops[starts[k]:starts[k+1]]``;
        ``ops[0]`` is the format header, ``ops[1:starts[0]]`` the prelude of shared
        subexpressions.
    stack_size : int, the length ``stack`` must have (depth + temporaries), >= 1.
    param_names : names of the ``params`` vector, in order.
    angle_plane : ``"alpha_beta"`` or ``"sigma"`` (docs/conventions.md).
    moment_reference : ``"cg"``: moments are about the (nominal) centre of gravity.
    n_temps : number of temporary slots (at the end of ``stack``).
    """

    ops: np.ndarray
    args: np.ndarray
    starts: np.ndarray
    stack_size: int
    param_names: tuple[str, ...]
    angle_plane: str
    moment_reference: str = "cg"
    n_temps: int = 0

    def new_stack(self, dtype=np.float64) -> np.ndarray:
        """A scratch stack of the right length for :func:`eval_coefficients`."""
        return np.zeros(max(self.stack_size, 1), dtype=dtype)

    def evaluate(self, variables, params) -> np.ndarray:
        """The 9 coefficients at one point (slow path, allocates): ``variables`` in the order
        of :data:`VARIABLES`, ``params`` in the order of :attr:`param_names`."""
        variables = np.asarray(variables)
        params = np.asarray(params)
        dtype = np.result_type(variables.dtype, params.dtype, np.float64)
        out = np.empty(N_COEFFICIENTS, dtype=dtype)
        eval_coefficients(self.ops, self.args, self.starts,
                          np.ascontiguousarray(variables, dtype=dtype),
                          np.ascontiguousarray(params, dtype=dtype), out, self.new_stack(dtype))
        return out

    def disassemble(self) -> str:
        """Readable listing of the program (one op a line)."""
        return disassemble(self.ops, self.args, self.starts, self.param_names)

    @cached_property
    def variables_read(self) -> frozenset[str]:
        """Names of the :data:`VARIABLES` the program reads (the flight variables its
        coefficients depend on); read once per program (every fit problem asks)."""
        names = set()
        for op, a in zip(self.ops, self.args, strict=True):
            op = int(op)
            if op < ADD and SOURCES[op % 4] == "V":
                names.add(VARIABLES[int(a)])
            elif PMUL_VV <= op < HEADER:
                k = (op - PMUL_VV) % 9
                for src, j in ((PAIR_SOURCES[k // 3], int(a) % PAIR),
                               (PAIR_SOURCES[k % 3], int(a) // PAIR)):
                    if src == "V":
                        names.add(VARIABLES[j])
        return frozenset(names)


def disassemble(ops, args, starts, param_names=()) -> str:
    """Readable listing of a program: mnemonic and operand per line, sections labelled."""
    lines = []
    bounds = {int(starts[k]): COEFFICIENTS[k] for k in range(N_COEFFICIENTS)
              if starts[k] < starts[k + 1]}
    if starts[0] > 0:
        lines.append("prelude:")
    for i, (op, a) in enumerate(zip(ops, args, strict=True)):
        if i in bounds:
            lines.append(f"{bounds[i]}:")
        name = OPCODE_NAMES.get(int(op), f"?{int(op)}")
        if op < ADD or op == POW_C:  # fused / push / pow_c: a source operand
            src = SOURCES[int(op) % 4] if op < ADD else "C"
            if src == "C":
                operand = repr(float(a))
            elif src == "V":
                operand = VARIABLES[int(a)]
            elif src == "P":
                j = int(a)
                operand = param_names[j] if j < len(param_names) else f"p[{j}]"
            else:
                operand = f"t{int(a)}"
        elif op == HEADER:
            operand = f"format {a:g}"
        elif op >= PMUL_VV:
            k = (int(op) - PMUL_VV) % 9
            ix, iy = int(a) % PAIR, int(a) // PAIR
            names = []
            for src, j in ((PAIR_SOURCES[k // 3], ix), (PAIR_SOURCES[k % 3], iy)):
                if src == "V":
                    names.append(VARIABLES[j])
                elif src == "P":
                    names.append(param_names[j] if j < len(param_names) else f"p[{j}]")
                else:
                    names.append(f"t{j}")
            operand = " * ".join(names)
        elif op == STORE_T:
            operand = f"t{int(a)}"
        elif op == OUT:
            operand = COEFFICIENTS[int(a)]
        else:
            operand = ""
        lines.append(f"  {i:4d}  {name:8s} {operand}".rstrip())
    return "\n".join(lines)


# --- complex-step-safe helpers ---------------------------------------------------------------


@njit(cache=True, inline="always")
def _div(a, b):
    # complex division by exactly zero raises in numba; give inf/nan like float division
    if b == 0.0:
        return a * np.inf
    return a / b


@njit(cache=True, inline="always")
def _max(a, b):
    # decide on real parts; NaN propagates
    if a.real > b.real:
        return a
    if a.real <= b.real:
        return b
    return a + b


@njit(cache=True, inline="always")
def _min(a, b):
    if a.real < b.real:
        return a
    if a.real >= b.real:
        return b
    return a + b


@njit(cache=True, inline="always")
def _atan2(y, x):
    # analytic in (y, x) away from the branch cut; branches chosen on real parts
    if x.real > 0.0:
        return np.arctan(y / x)
    if x.real < 0.0:
        if y.real >= 0.0:
            return np.arctan(y / x) + np.pi
        return np.arctan(y / x) - np.pi
    if y.real > 0.0:
        return 0.5 * np.pi - np.arctan(x / y)
    if y.real < 0.0:
        return -0.5 * np.pi - np.arctan(x / y)
    return 0.0 * y


# --- the evaluator -------------------------------------------------------------------------


@njit(cache=True, error_model="numpy")
def eval_coefficients(ops, args, starts, variables, params, out, stack) -> None:
    """Evaluate the 9 aerodynamic coefficients of a compiled model.

    Parameters
    ----------
    ops : (n,) int64 opcodes of an :class:`AeroProgram`.
    args : (n,) float64 operands.
    starts : (10,) int64 section starts.
    variables : (9,) float64 or complex128, in the order of :data:`VARIABLES` (angles rad).
    params : (n_params,) parameter values (SI, radians), same dtype as ``out``.
    out : (9,) written with the coefficients in the order of :data:`COEFFICIENTS`.
    stack : scratch of ``out``'s dtype, length >= ``AeroProgram.stack_size``.
    """
    n = starts[starts.shape[0] - 1]
    if starts[0] < 1 or ops[0] != HEADER or args[0] != PROGRAM_FORMAT:
        # not a program of this format (or a stale cached copy of this evaluator): NaNs.
        # (n = 0 rather than an early return: LLVM lays the loop out better, ~30% faster)
        n = 0
    for k in range(out.shape[0]):
        out[k] = 0.0
    tb = stack.shape[0] - 1  # temporary slot t is stack[tb - t]
    acc = out[0]
    sp = -1
    for i in range(1, n):
        op = ops[i]
        if op == PUSH_C:
            sp += 1
            stack[sp] = acc
            acc = args[i]
        elif op == PUSH_V:
            sp += 1
            stack[sp] = acc
            acc = variables[int(args[i])]
        elif op == PUSH_P:
            sp += 1
            stack[sp] = acc
            acc = params[int(args[i])]
        elif op == PUSH_T:
            sp += 1
            stack[sp] = acc
            acc = stack[tb - int(args[i])]
        elif op == ADD_C:
            acc = acc + args[i]
        elif op == ADD_V:
            acc = acc + variables[int(args[i])]
        elif op == ADD_P:
            acc = acc + params[int(args[i])]
        elif op == ADD_T:
            acc = acc + stack[tb - int(args[i])]
        elif op == SUB_C:
            acc = acc - args[i]
        elif op == SUB_V:
            acc = acc - variables[int(args[i])]
        elif op == SUB_P:
            acc = acc - params[int(args[i])]
        elif op == SUB_T:
            acc = acc - stack[tb - int(args[i])]
        elif op == RSUB_C:
            acc = args[i] - acc
        elif op == RSUB_V:
            acc = variables[int(args[i])] - acc
        elif op == RSUB_P:
            acc = params[int(args[i])] - acc
        elif op == RSUB_T:
            acc = stack[tb - int(args[i])] - acc
        elif op == MUL_C:
            acc = acc * args[i]
        elif op == MUL_V:
            acc = acc * variables[int(args[i])]
        elif op == MUL_P:
            acc = acc * params[int(args[i])]
        elif op == MUL_T:
            acc = acc * stack[tb - int(args[i])]
        elif op == DIV_C:
            acc = _div(acc, args[i])
        elif op == DIV_V:
            acc = _div(acc, variables[int(args[i])])
        elif op == DIV_P:
            acc = _div(acc, params[int(args[i])])
        elif op == DIV_T:
            acc = _div(acc, stack[tb - int(args[i])])
        elif op == RDIV_C:
            acc = _div(args[i], acc)
        elif op == RDIV_V:
            acc = _div(variables[int(args[i])], acc)
        elif op == RDIV_P:
            acc = _div(params[int(args[i])], acc)
        elif op == RDIV_T:
            acc = _div(stack[tb - int(args[i])], acc)
        elif op == MAX_C:
            acc = _max(acc, args[i])
        elif op == MAX_V:
            acc = _max(acc, variables[int(args[i])])
        elif op == MAX_P:
            acc = _max(acc, params[int(args[i])])
        elif op == MAX_T:
            acc = _max(acc, stack[tb - int(args[i])])
        elif op == MIN_C:
            acc = _min(acc, args[i])
        elif op == MIN_V:
            acc = _min(acc, variables[int(args[i])])
        elif op == MIN_P:
            acc = _min(acc, params[int(args[i])])
        elif op == MIN_T:
            acc = _min(acc, stack[tb - int(args[i])])
        elif op == PMUL_VV:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = variables[(k & (PAIR - 1))] * variables[(k >> 20)]
        elif op == PMUL_VP:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = variables[(k & (PAIR - 1))] * params[(k >> 20)]
        elif op == PMUL_VT:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = variables[(k & (PAIR - 1))] * stack[tb - (k >> 20)]
        elif op == PMUL_PV:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = params[(k & (PAIR - 1))] * variables[(k >> 20)]
        elif op == PMUL_PP:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = params[(k & (PAIR - 1))] * params[(k >> 20)]
        elif op == PMUL_PT:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = params[(k & (PAIR - 1))] * stack[tb - (k >> 20)]
        elif op == PMUL_TV:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = stack[tb - (k & (PAIR - 1))] * variables[(k >> 20)]
        elif op == PMUL_TP:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = stack[tb - (k & (PAIR - 1))] * params[(k >> 20)]
        elif op == PMUL_TT:
            k = int(args[i])
            sp += 1
            stack[sp] = acc
            acc = stack[tb - (k & (PAIR - 1))] * stack[tb - (k >> 20)]
        elif op == AMUL_VV:
            k = int(args[i])
            acc = acc + variables[(k & (PAIR - 1))] * variables[(k >> 20)]
        elif op == AMUL_VP:
            k = int(args[i])
            acc = acc + variables[(k & (PAIR - 1))] * params[(k >> 20)]
        elif op == AMUL_VT:
            k = int(args[i])
            acc = acc + variables[(k & (PAIR - 1))] * stack[tb - (k >> 20)]
        elif op == AMUL_PV:
            k = int(args[i])
            acc = acc + params[(k & (PAIR - 1))] * variables[(k >> 20)]
        elif op == AMUL_PP:
            k = int(args[i])
            acc = acc + params[(k & (PAIR - 1))] * params[(k >> 20)]
        elif op == AMUL_PT:
            k = int(args[i])
            acc = acc + params[(k & (PAIR - 1))] * stack[tb - (k >> 20)]
        elif op == AMUL_TV:
            k = int(args[i])
            acc = acc + stack[tb - (k & (PAIR - 1))] * variables[(k >> 20)]
        elif op == AMUL_TP:
            k = int(args[i])
            acc = acc + stack[tb - (k & (PAIR - 1))] * params[(k >> 20)]
        elif op == AMUL_TT:
            k = int(args[i])
            acc = acc + stack[tb - (k & (PAIR - 1))] * stack[tb - (k >> 20)]
        elif op == ADD:
            acc = stack[sp] + acc
            sp -= 1
        elif op == SUB:
            acc = stack[sp] - acc
            sp -= 1
        elif op == MUL:
            acc = stack[sp] * acc
            sp -= 1
        elif op == DIV:
            acc = _div(stack[sp], acc)
            sp -= 1
        elif op == POW:
            acc = stack[sp] ** acc
            sp -= 1
        elif op == ATAN2:
            acc = _atan2(stack[sp], acc)
            sp -= 1
        elif op == MAX:
            acc = _max(stack[sp], acc)
            sp -= 1
        elif op == MIN:
            acc = _min(stack[sp], acc)
            sp -= 1
        elif op == LT:
            acc = 1.0 if stack[sp].real < acc.real else 0.0
            sp -= 1
        elif op == GT:
            acc = 1.0 if stack[sp].real > acc.real else 0.0
            sp -= 1
        elif op == LE:
            acc = 1.0 if stack[sp].real <= acc.real else 0.0
            sp -= 1
        elif op == GE:
            acc = 1.0 if stack[sp].real >= acc.real else 0.0
            sp -= 1
        elif op == SELECT:
            if stack[sp - 1].real != 0.0:
                acc = stack[sp]
            sp -= 2
        elif op == NEG:
            acc = -acc
        elif op == SQR:
            acc = acc * acc
        elif op == POW_C:
            acc = acc ** args[i]
        elif op == SIN:
            acc = np.sin(acc)
        elif op == COS:
            acc = np.cos(acc)
        elif op == TAN:
            acc = np.tan(acc)
        elif op == ASIN:
            acc = np.arcsin(acc)
        elif op == ACOS:
            acc = np.arccos(acc)
        elif op == ATAN:
            acc = np.arctan(acc)
        elif op == SQRT:
            acc = np.sqrt(acc)
        elif op == ABS:
            if acc.real < 0.0:
                acc = -acc
        elif op == EXP:
            acc = np.exp(acc)
        elif op == LOG:
            acc = np.log(acc)
        elif op == STORE_T:
            stack[tb - int(args[i])] = acc
            acc = stack[sp]
            sp -= 1
        elif op == OUT:
            out[int(args[i])] = acc
            acc = stack[sp]
            sp -= 1
    if n == 0:
        for k in range(out.shape[0]):
            out[k] = np.nan


@njit(cache=True)
def eval_coefficients_batch(ops, args, starts, variables, params, out, stack) -> None:
    """:func:`eval_coefficients` at each row of ``variables`` (m, 8), into ``out`` (m, 9)."""
    for i in range(variables.shape[0]):
        eval_coefficients(ops, args, starts, variables[i], params, out[i], stack)
