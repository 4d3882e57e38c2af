"""Forward-mode derivatives for the contact laws: a :class:`Dual` array that numpy code runs on unchanged.

A :class:`Dual` carries a value ``val`` (any shape ``S``) and its derivative ``der``
(shape ``S + (P,)``) with respect to ``P`` seed variables.  It implements numpy's
dispatch protocols (``__array_ufunc__``, ``__array_function__``) for the operations
the contact laws, the foot kinematics and :func:`pinmsk.contact.ground_reaction` use,
so the *same* functions that compute forces from floats and arrays compute exact
(to rounding) Jacobians when some inputs are Duals: one implementation of each law,
no hand-written second copy.  :class:`pinmsk.contact.ContactFit` seeds the free
parameters (``Dual.variables``) and reads the residual's Jacobian off ``der``.

Supported: ``+ - * / **``, unary ``-``, comparisons (on the value, returning bools),
indexing and item assignment, ``sum``/``mean``/``ravel``/``reshape``/``copy``; ufuncs
``add subtract multiply true_divide negative power sqrt exp log arctan tanh sin cos
absolute square maximum minimum matmul`` and the comparisons; functions ``np.where``
(plain condition), ``np.clip``, ``np.stack``, ``np.concatenate``, ``np.zeros_like``,
``np.sum``, ``np.mean``.  Anything else raises ``TypeError`` (numpy's "not supported
for Dual"), never a silently wrong derivative.  ``max``/``where``/``clip`` give the
derivative of the branch taken (one-sided at ties).
"""
from __future__ import annotations

import numpy as np

from ..backend import is_symbolic


class Dual:
    """Value ``val`` (shape ``S``) and derivative ``der`` (``S + (P,)``) w.r.t. ``P`` seed variables."""

    __slots__ = ("val", "der")
    __array_priority__ = 1000

    def __init__(self, val, der):
        self.val = np.asarray(val, dtype=float)
        self.der = np.asarray(der, dtype=float)
        if self.der.shape[:-1] != self.val.shape:
            raise ValueError(f"Dual: derivative shape {self.der.shape} does not extend value shape {self.val.shape}")

    @classmethod
    def _new(cls, val, der) -> "Dual":
        """Unchecked constructor for the operations (``val``, ``der`` already float arrays)."""
        d = object.__new__(cls)
        d.val = val
        d.der = der
        return d

    @classmethod
    def variables(cls, x, scale=None) -> "Dual":
        """``x`` (P,) as seed variables (``der`` = identity, or ``diag(scale)`` for ``x * scale``)."""
        x = np.asarray(x, dtype=float)
        if scale is None:
            return cls(x, np.eye(x.size))
        scale = np.asarray(scale, dtype=float)
        return cls(x * scale, np.diag(scale))

    # -- array-like attributes ----------------------------------------------
    @property
    def shape(self):
        return self.val.shape

    @property
    def ndim(self):
        return self.val.ndim

    @property
    def size(self):
        return self.val.size

    @property
    def n_seeds(self) -> int:
        return self.der.shape[-1]

    def __len__(self):
        return len(self.val)

    def __repr__(self):
        return f"Dual(val={self.val!r}, der shape {self.der.shape})"

    def __float__(self):
        return float(self.val)

    def copy(self) -> "Dual":
        return Dual._new(self.val.copy(), self.der.copy())

    def ravel(self) -> "Dual":
        return Dual._new(self.val.ravel(), self.der.reshape(-1, self.n_seeds))

    def reshape(self, *shape) -> "Dual":
        if len(shape) == 1 and isinstance(shape[0], tuple):
            shape = shape[0]
        val = self.val.reshape(shape)
        return Dual._new(val, self.der.reshape(val.shape + (self.n_seeds,)))

    def sum(self, axis=None) -> "Dual":
        if axis is None:
            return Dual._new(np.asarray(self.val.sum()), self.der.reshape(-1, self.n_seeds).sum(axis=0))
        ax = axis % self.ndim
        return Dual._new(np.asarray(self.val.sum(axis=ax)), self.der.sum(axis=ax))

    def mean(self, axis=None) -> "Dual":
        n = self.val.size if axis is None else self.val.shape[axis]
        return self.sum(axis) * (1.0 / n)

    # -- indexing -------------------------------------------------------------
    @staticmethod
    def _didx(idx):
        return (idx if isinstance(idx, tuple) else (idx,)) + (slice(None),)

    def __getitem__(self, idx):
        return Dual._new(np.asarray(self.val[idx]), self.der[self._didx(idx)])

    def __setitem__(self, idx, value):
        # copy on write: the operations share derivative arrays between Duals (``x + 1.0`` keeps
        # ``x.der``), so an assignment must never write through to another Dual
        self.val, self.der = np.array(self.val, dtype=float), self.der.copy()
        if isinstance(value, Dual):
            self.val[idx] = value.val
            self.der[self._didx(idx)] = value.der
        else:
            self.val[idx] = value
            self.der[self._didx(idx)] = 0.0

    # -- arithmetic -----------------------------------------------------------
    def __add__(self, o):
        return _add(self, o)

    __radd__ = __add__

    def __sub__(self, o):
        return _add(self, _neg(o))

    def __rsub__(self, o):
        return _add(_neg(self), o)

    def __mul__(self, o):
        return _mul(self, o)

    __rmul__ = __mul__

    def __truediv__(self, o):
        return _div(self, o)

    def __rtruediv__(self, o):
        return _div(o, self)

    def __pow__(self, o):
        return _pow(self, o)

    def __rpow__(self, o):
        return _pow(o, self)

    def __neg__(self):
        return _neg(self)

    def __pos__(self):
        return self

    def __matmul__(self, o):
        return _matmul(self, o)

    def __rmatmul__(self, o):
        return _matmul(o, self)

    def __lt__(self, o):
        return self.val < value(o)

    def __le__(self, o):
        return self.val <= value(o)

    def __gt__(self, o):
        return self.val > value(o)

    def __ge__(self, o):
        return self.val >= value(o)

    # -- numpy protocols --------------------------------------------------------
    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        fn = _UFUNCS.get(ufunc)
        if method != "__call__" or fn is None or kwargs:
            return NotImplemented
        return fn(*inputs)

    def __array_function__(self, func, types, args, kwargs):
        fn = _FUNCTIONS.get(func)
        if fn is None:
            return NotImplemented
        return fn(*args, **kwargs)


def value(x):
    """The value of ``x`` (a Dual's ``val``; anything else unchanged)."""
    return x.val if isinstance(x, Dual) else x


def asarray(x):
    """``x`` as a float array, or ``x`` itself if it is a :class:`Dual` or a CasADi value (the laws'
    ``np.asarray``)."""
    return x if isinstance(x, Dual) or is_symbolic(x) else np.asarray(x, dtype=float)


def _col(a):
    """A plain operand shaped to multiply a derivative (trailing seed axis)."""
    return a[..., None] if type(a) is np.ndarray else np.asarray(a, dtype=float)[..., None]


def _full(d: Dual, shape) -> np.ndarray:
    """``d.der`` broadcast to ``shape + (P,)`` (a copy when it has to grow)."""
    target = tuple(shape) + (d.n_seeds,)
    if d.der.shape == target:
        return d.der
    out = np.empty(target)
    out[...] = d.der
    return out


def vector(*components):
    """The components (each (...,) plain or Dual) stacked along a new last axis: ``(..., k)``.

    What the contact code uses to build 3-vectors: a plain ``np.empty`` fill for arrays
    (``np.stack`` costs ~5x more on small arrays), a Dual when any component is one, a CasADi
    row ``(1, k)`` (one frame) when any is a CasADi value.
    """
    if any(isinstance(c, Dual) for c in components):
        return stack(components, axis=-1)
    if any(is_symbolic(c) for c in components):
        # one frame under CasADi: scalars (1, 1) -> a row (1, k), as the (N, k) arrays with N = 1
        import casadi as ca
        return ca.horzcat(*(c if is_symbolic(c) else float(np.asarray(c).reshape(())) for c in components))
    shape = max((np.shape(c) for c in components), key=len)
    out = np.empty(shape + (len(components),))
    for j, c in enumerate(components):
        out[..., j] = c
    return out


def _add(a, b):
    if isinstance(a, Dual) and isinstance(b, Dual):
        return Dual._new(a.val + b.val, a.der + b.der)
    if isinstance(b, Dual):
        a, b = b, a
    val = a.val + b
    return Dual._new(val, _full(a, val.shape))


def _neg(a):
    return Dual._new(-a.val, -a.der) if isinstance(a, Dual) else -np.asarray(a, dtype=float)


def _mul(a, b):
    if isinstance(a, Dual) and isinstance(b, Dual):
        return Dual._new(a.val * b.val, a.der * _col(b.val) + _col(a.val) * b.der)
    if isinstance(b, Dual):
        a, b = b, a
    b = np.asarray(b, dtype=float)
    return Dual._new(a.val * b, a.der * b[..., None])


def _div(a, b):
    if isinstance(b, Dual):
        inv = 1.0 / b.val
        q = value(a) * inv
        der = -_col(q * inv) * b.der
        if isinstance(a, Dual):
            der = der + a.der * _col(inv)
        return Dual._new(q, der)
    b = np.asarray(b, dtype=float)
    return Dual._new(a.val / b, a.der / b[..., None])


def _pow(a, b):
    if not isinstance(b, Dual):
        b = np.asarray(b, dtype=float)
        val = a.val ** b
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.where(b == 0, 0.0, b * a.val ** (b - 1.0))
        return Dual._new(val, a.der * _col(slope))
    av = value(a)
    val = np.power(av, b.val)
    with np.errstate(divide="ignore", invalid="ignore"):
        dlog = np.where(av > 0, val * np.log(np.where(av > 0, av, 1.0)), 0.0)
    der = b.der * _col(dlog)
    if isinstance(a, Dual):
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.where(b.val == 0, 0.0, b.val * np.power(a.val, b.val - 1.0))
        der = der + a.der * _col(slope)
    return Dual._new(val, der)


def _unary(f, df):
    def fn(a):
        if not isinstance(a, Dual):
            return f(a)
        return Dual._new(f(a.val), a.der * _col(df(a.val)))
    return fn


def _dsqrt(x):
    with np.errstate(divide="ignore"):   # infinite slope at 0: the caller's where() must not select it
        return 0.5 / np.sqrt(x)


def _dlog(x):
    with np.errstate(divide="ignore"):
        return 1.0 / x


def _lift(x, shape, n):
    """``x`` as a Dual of ``shape`` with ``n`` seeds (zero derivative if plain)."""
    if isinstance(x, Dual):
        return Dual._new(np.broadcast_to(x.val, shape), _full(x, shape))
    return Dual._new(np.broadcast_to(np.asarray(x, dtype=float), shape), np.zeros(tuple(shape) + (n,)))


def _seeds(*xs) -> int:
    return next(x.n_seeds for x in xs if isinstance(x, Dual))


def where(cond, a, b):
    """``np.where`` for a plain condition and Dual/plain branches."""
    cond = np.asarray(value(cond), dtype=bool)
    val = np.where(cond, value(a), value(b))
    if not _any_dual(a, b):
        return val
    da = a.der if isinstance(a, Dual) else 0.0
    db = b.der if isinstance(b, Dual) else 0.0
    der = np.where(cond[..., None], da, db)
    if der.shape[:-1] != val.shape:   # the condition or a plain branch is larger than the Dual ones
        der = np.broadcast_to(der, val.shape + der.shape[-1:]).copy()
    return Dual._new(val, der)


def _maximum(a, b):
    return where(value(a) >= value(b), a, b)


def _minimum(a, b):
    return where(value(a) <= value(b), a, b)


def clip(a, a_min, a_max, out=None, **kwargs):
    if out is not None or kwargs:
        return NotImplemented
    x = a
    if a_min is not None:
        x = where(value(x) < value(a_min), a_min, x) if _any_dual(x, a_min) else np.maximum(x, a_min)
    if a_max is not None:
        x = where(value(x) > value(a_max), a_max, x) if _any_dual(x, a_max) else np.minimum(x, a_max)
    return x


def _any_dual(*xs) -> bool:
    return any(isinstance(x, Dual) for x in xs)


def stack(arrays, axis=0, out=None, **kwargs):
    arrays = list(arrays)
    n = _seeds(*arrays)
    shape = np.broadcast_shapes(*(np.shape(value(a)) for a in arrays))
    ds = [_lift(a, shape, n) for a in arrays]
    ax = axis % (len(shape) + 1)
    return Dual._new(np.stack([d.val for d in ds], axis=ax), np.stack([d.der for d in ds], axis=ax))


def concatenate(arrays, axis=0, out=None, **kwargs):
    arrays = list(arrays)
    n = _seeds(*arrays)
    ds = [a if isinstance(a, Dual) else Dual._new(np.asarray(a, dtype=float), np.zeros(np.shape(a) + (n,)))
          for a in arrays]
    ax = axis % ds[0].ndim
    return Dual._new(np.concatenate([d.val for d in ds], axis=ax), np.concatenate([d.der for d in ds], axis=ax))


def _zeros_like(a, *args, **kwargs):
    return Dual._new(np.zeros(a.shape), np.zeros(a.der.shape))


def _matmul(a, b):
    """``a @ b`` for a plain/Dual stack of matrices ``a`` (..., M, K) and a vector (K,) or matrix (..., K, L) ``b``."""
    av, bv = value(a), value(b)
    val = av @ bv
    der = 0.0
    if isinstance(b, Dual):
        der = der + (av @ b.der if b.ndim == 1 else np.einsum("...mk,...klp->...mlp", av, b.der))
    if isinstance(a, Dual):
        der = der + (np.einsum("...mkp,k->...mp", a.der, bv) if np.ndim(bv) == 1
                     else np.einsum("...mkp,...kl->...mlp", a.der, bv))
    return Dual._new(val, der)


def einsum(subscripts, *operands, **kwargs):
    """``np.einsum`` with explicit subscripts (``"ab,b->a"``, no ellipsis) and plain/Dual operands:
    the product rule, one einsum per Dual operand with the seed axis appended."""
    if kwargs or "..." in subscripts or "->" not in subscripts:
        return NotImplemented
    ins, out = subscripts.replace(" ", "").split("->")
    ins = ins.split(",")
    seed = next(c for c in "zyxwvutsrqponmlkjihgfedcba" if c not in subscripts)
    vals = [value(o) for o in operands]
    val = np.einsum(subscripts, *vals)
    der = 0.0
    for k, o in enumerate(operands):
        if isinstance(o, Dual):
            spec = ",".join(sub + seed if j == k else sub for j, sub in enumerate(ins)) + "->" + out + seed
            der = der + np.einsum(spec, *[o.der if j == k else v for j, v in enumerate(vals)])
    return Dual._new(np.asarray(val), der)


def _compare(op):
    def fn(a, b):
        return op(value(a), value(b))
    return fn


def _np_sum(a, axis=None, **kwargs):
    return a.sum(axis) if isinstance(a, Dual) else np.sum(a, axis=axis, **kwargs)


def _np_mean(a, axis=None, **kwargs):
    return a.mean(axis) if isinstance(a, Dual) else np.mean(a, axis=axis, **kwargs)


_UFUNCS = {
    np.add: _add,
    np.subtract: lambda a, b: _add(a, _neg(b)),
    np.multiply: _mul,
    np.true_divide: _div,
    np.negative: _neg,
    np.power: _pow,
    np.sqrt: _unary(np.sqrt, _dsqrt),
    np.exp: _unary(np.exp, np.exp),
    np.log: _unary(np.log, _dlog),
    np.arctan: _unary(np.arctan, lambda x: 1.0 / (1.0 + x * x)),
    np.tanh: _unary(np.tanh, lambda x: 1.0 - np.tanh(x) ** 2),
    np.sin: _unary(np.sin, np.cos),
    np.cos: _unary(np.cos, lambda x: -np.sin(x)),
    np.absolute: _unary(np.absolute, np.sign),
    np.square: _unary(np.square, lambda x: 2.0 * x),
    np.maximum: _maximum,
    np.minimum: _minimum,
    np.matmul: _matmul,
    np.less: _compare(np.less),
    np.less_equal: _compare(np.less_equal),
    np.greater: _compare(np.greater),
    np.greater_equal: _compare(np.greater_equal),
    np.equal: _compare(np.equal),
    np.not_equal: _compare(np.not_equal),
}

_FUNCTIONS = {
    np.where: where,
    np.clip: clip,
    np.stack: stack,
    np.concatenate: concatenate,
    np.zeros_like: _zeros_like,
    np.sum: _np_sum,
    np.mean: _np_mean,
    np.einsum: einsum,
    np.shape: lambda a: a.shape,
    np.ndim: lambda a: a.ndim,
}
