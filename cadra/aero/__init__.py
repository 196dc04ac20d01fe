"""Aerodynamic models as data: the coefficient-form language, parameters, model files, and
the compiled evaluator the 6-DOF integrator calls.

Public API (docs/aero_models.md; frames and signs: docs/conventions.md):

- :class:`Parameter`, :class:`AeroModel`, :func:`load_model`, :func:`save_model`,
  :func:`model_from_dict`, :func:`load_bundled_model`, :func:`bundled_model_names`,
  :func:`bundled_model_table`;
- :func:`resolve_model` (a bundled name or a model file path: the one resolver of model names
  used by the simulator and the CLIs), :func:`resolve_model_path`, :func:`is_model_path`,
  :class:`ModelNotFoundError`;
- :class:`AeroProgram`, :func:`eval_coefficients` (numba), :data:`COEFFICIENTS`,
  :data:`VARIABLES`;
- :func:`parse_expression`, :func:`evaluate_tree`, :class:`ExpressionError`.
"""

from cadra.aero.expr import (
    CONSTANTS,
    FUNCTIONS,
    ExpressionError,
    compile_program,
    evaluate_tree,
    parse_expression,
    to_text,
)
from cadra.aero.model import (
    ANGLE_PLANES,
    MODELS_DIR,
    AeroModel,
    ModelNotFoundError,
    Parameter,
    bundled_model_names,
    bundled_model_table,
    is_model_path,
    load_bundled_model,
    load_model,
    model_from_dict,
    resolve_model,
    resolve_model_path,
    save_model,
)
from cadra.aero.program import (
    COEFFICIENTS,
    VARIABLES,
    AeroProgram,
    eval_coefficients,
    eval_coefficients_batch,
)

__all__ = [
    "ANGLE_PLANES",
    "COEFFICIENTS",
    "CONSTANTS",
    "FUNCTIONS",
    "MODELS_DIR",
    "VARIABLES",
    "AeroModel",
    "AeroProgram",
    "ExpressionError",
    "ModelNotFoundError",
    "Parameter",
    "bundled_model_names",
    "bundled_model_table",
    "compile_program",
    "eval_coefficients",
    "eval_coefficients_batch",
    "evaluate_tree",
    "is_model_path",
    "load_bundled_model",
    "load_model",
    "model_from_dict",
    "parse_expression",
    "resolve_model",
    "resolve_model_path",
    "save_model",
    "to_text",
]
