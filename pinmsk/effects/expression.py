"""A generalized force given as an expression of the coordinate and its speed: OpenSim's
``ExpressionBasedCoordinateForce``.

OpenSim (``ExpressionBasedCoordinateForce.cpp``) parses ``expression`` with Lepton, the variables
``q`` (rad or m) and ``qdot`` (rad/s or m/s), and applies its value as the coordinate's generalized
force (N m or N).  :class:`CoordinateExpressionForce` (``coordinate_expression``) reads the same
expression (``^`` is a power) into a small tree of ``+ - * / ^``, numbers, ``q``, ``qdot`` and the
functions ``sqrt exp log sin cos tan tanh atan abs square cube recip min max step``, evaluated on any
backend (numpy over frames, CasADi at one state) and on forward-mode
:class:`~pinmsk.contact.dual.Dual` numbers for its exact state derivatives.  Its one parameter
``scale`` multiplies the expression (1: OpenSim's force).  Anything else in an expression (an unknown
function or variable) is refused by name.
"""
from __future__ import annotations

import ast

import numpy as np

from ..backend import backend_of
from ..components import Parameter
from ..errors import ModelError
from ._base import JointEffect
from .registry import register

__all__ = ["CoordinateExpressionForce", "parse_expression"]

_BINARY = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
           ast.Div: lambda a, b: a / b, ast.Pow: lambda a, b: a ** b}


def _step(xp, x):
    return xp.where(x >= 0.0, 1.0 + 0.0 * x, 0.0 * x)


#: Lepton's functions that the expression may use: name -> (number of arguments, f(xp, *args))
FUNCTIONS = {
    "sqrt": (1, lambda xp, x: xp.sqrt(x)), "exp": (1, lambda xp, x: xp.exp(x)), "log": (1, lambda xp, x: xp.log(x)),
    "sin": (1, lambda xp, x: xp.sin(x)), "cos": (1, lambda xp, x: xp.cos(x)),
    "tan": (1, lambda xp, x: xp.sin(x) / xp.cos(x)), "tanh": (1, lambda xp, x: xp.tanh(x)),
    "atan": (1, lambda xp, x: xp.arctan(x)), "abs": (1, lambda xp, x: xp.abs(x)),
    "square": (1, lambda xp, x: x * x), "cube": (1, lambda xp, x: x * x * x), "recip": (1, lambda xp, x: 1.0 / x),
    "min": (2, lambda xp, a, b: xp.minimum(a, b)), "max": (2, lambda xp, a, b: xp.maximum(a, b)),
    "step": (1, _step),
}
VARIABLES = ("q", "qdot")


def parse_expression(text: str, *, where: str = "expression"):
    """The syntax tree of a Lepton expression in ``q`` and ``qdot`` (ModelError naming what is refused)."""
    if not isinstance(text, str) or not text.strip():
        raise ModelError(f"{where}: the expression is empty")
    try:
        tree = ast.parse(text.strip().replace("^", "**"), mode="eval").body
    except SyntaxError as exc:
        raise ModelError(f"{where}: cannot read expression {text!r} ({exc.msg})") from None

    def check(node):
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            check(node.left), check(node.right)
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            check(node.operand)
        elif isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool):
            pass
        elif isinstance(node, ast.Name):
            if node.id not in VARIABLES:
                raise ModelError(f"{where}: expression {text!r} uses '{node.id}'; its variables are q and qdot")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
            name = node.func.id
            if name not in FUNCTIONS:
                raise ModelError(f"{where}: expression {text!r} calls '{name}', which pinmsk does not evaluate "
                                 f"(it evaluates {', '.join(sorted(FUNCTIONS))})")
            if len(node.args) != FUNCTIONS[name][0]:
                raise ModelError(f"{where}: {name}() takes {FUNCTIONS[name][0]} argument(s) in {text!r}")
            for a in node.args:
                check(a)
        else:
            raise ModelError(f"{where}: expression {text!r} holds {ast.unparse(node)!r}, which is not an "
                             "arithmetic expression of q and qdot")
    check(tree)
    return tree


def evaluate(tree, q, qdot):
    """The expression's value at ``q, qdot`` (numpy arrays, CasADi values or Duals)."""
    xp = backend_of(q, qdot)

    def ev(node):
        if isinstance(node, ast.BinOp):
            return _BINARY[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp):
            x = ev(node.operand)
            return -x if isinstance(node.op, ast.USub) else x
        if isinstance(node, ast.Constant):
            return float(node.value)
        if isinstance(node, ast.Name):
            return q if node.id == "q" else qdot
        return FUNCTIONS[node.func.id][1](xp, *(ev(a) for a in node.args))
    return ev(tree)


@register
class CoordinateExpressionForce(JointEffect):
    """``Q = scale * expression(q, qdot)`` on coordinate ``target`` (OpenSim's
    ExpressionBasedCoordinateForce; module docstring)."""

    family = "coordinate_expression"
    linear = True
    parameters = (Parameter("scale", 1.0, -1e6, 1e6, "", "factor on the expression (1: as written)"),)
    zero_params = {"scale": 0.0}

    def __init__(self, target: str | None = None, *, expression: str = "-q - 0.1*qdot", **values: float):
        self.expression = str(expression)
        self._tree = parse_expression(self.expression, where=f"{self.family}:{target}")
        super().__init__(target, **values)

    @classmethod
    def candidates(cls, model, context) -> list:
        """None: the diagnosis has no expression to guess."""
        return []

    def _expr(self, q, v):
        out = evaluate(self._tree, q, v)
        if backend_of(q, v).symbolic or backend_of(out).symbolic:
            return out + 0.0 * q
        return out + 0.0 * q if np.ndim(out) == 0 else out

    def _force(self, q, v, p):
        return p["scale"] * self._expr(q, v)

    def _dforce_dparams(self, q, v, p):
        return np.asarray(self._expr(q, v), dtype=float)[:, None]

    def _dforce_dstate(self, q, v, p):
        from ..contact.dual import Dual
        n = np.size(q)
        qd = Dual(np.asarray(q, dtype=float), np.stack([np.ones(n), np.zeros(n)], axis=-1))
        vd = Dual(np.asarray(v, dtype=float), np.stack([np.zeros(n), np.ones(n)], axis=-1))
        out = evaluate(self._tree, qd, vd)
        if not isinstance(out, Dual):
            return np.zeros(n), np.zeros(n)
        d = np.broadcast_to(out.der, (n, 2))
        return p["scale"] * d[:, 0], p["scale"] * d[:, 1]

    def __eq__(self, other) -> bool:
        return super().__eq__(other) and self.expression == other.expression

    def __hash__(self) -> int:
        return hash((super().__hash__(), self.expression))
