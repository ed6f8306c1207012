"""A grey-box model's acceleration as a flat list of operations (a *tape*), for a compiled rollout.

The equations of a declared model and its effects are written once, in numpy
(:mod:`.declared`, :mod:`.effects`, :mod:`.flight`). To integrate them without a Python call per
sample, :func:`trace` runs that same code once on symbolic values (:class:`Sym`): every numpy
operation it performs is recorded as a node. The tape is then evaluated by the C++ core
(``_core.greybox_rollout``) for every window, sample, substep and Runge-Kutta stage. Nothing is
re-implemented: an operation the tracer does not know, or Python control flow on a simulated
value (``if v > 0``), ends the trace with :class:`TraceError` and the caller keeps the numpy
path. The caller also checks the tape against the numpy path on real states before using it.

Leaves: the positions ``X j`` and velocities ``V j`` of the state, a column ``S c`` of the
per-sample series (the model's inputs after their transforms, the external columns, the
whole-record effect columns), the sample time ``T``, a parameter ``P i`` (one value per lane:
batched parameter perturbations), a constant ``C``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["Sym", "TraceError", "Tape", "floats", "OPS", "SWITCHING", "Switches", "held"]

# operation codes shared with cpp/bindings/greybox.cpp (keep the order)
OPS = ("C", "X", "V", "S", "T", "P", "add", "sub", "mul", "div", "neg", "sign", "tanh", "sin",
       "cos", "abs", "max", "min", "gt", "lt", "ge", "le", "pow", "exp", "sqrt")
CODE = {name: i for i, name in enumerate(OPS)}

_UNARY = {np.negative: "neg", np.sign: "sign", np.tanh: "tanh", np.sin: "sin", np.cos: "cos",
          np.absolute: "abs", np.exp: "exp", np.sqrt: "sqrt"}
_BINARY = {np.add: "add", np.subtract: "sub", np.multiply: "mul", np.true_divide: "div",
           np.maximum: "max", np.minimum: "min", np.greater: "gt", np.less: "lt",
           np.greater_equal: "ge", np.less_equal: "le", np.power: "pow"}
_FOLD = {"add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.true_divide,
         "max": np.maximum, "min": np.minimum, "gt": np.greater, "lt": np.less,
         "ge": np.greater_equal, "le": np.less_equal, "pow": np.power, "neg": np.negative,
         "sign": np.sign, "tanh": np.tanh, "sin": np.sin, "cos": np.cos, "abs": np.absolute,
         "exp": np.exp, "sqrt": np.sqrt}


class TraceError(ValueError):
    """The model's code did something the tracer cannot record (the numpy path is used)."""


class Tape:
    """The recorded nodes: ``ops`` (codes), ``a``, ``b`` (operand node indices), ``c``
    (constants / leaf indices)."""

    def __init__(self):
        self.ops, self.a, self.b, self.c = [], [], [], []
        self._leaves: dict = {}
        self._const: dict = {}

    def node(self, op: str, a: int = -1, b: int = -1, c: float = 0.0) -> "Sym":
        self.ops.append(CODE[op])
        self.a.append(int(a))
        self.b.append(int(b))
        self.c.append(float(c))
        return Sym(self, len(self.ops) - 1)

    def leaf(self, op: str, index: int) -> "Sym":
        key = (op, int(index))
        if key not in self._leaves:
            self._leaves[key] = self.node(op, c=index)
        return self._leaves[key]

    def const(self, value) -> "Sym":
        v = np.asarray(value, dtype=float)
        if v.ndim and not np.all(v == v.flat[0]):
            raise TraceError("a constant that differs between lanes")
        x = float(v.flat[0]) if v.size else 0.0
        key = x if x == x else "nan"
        if key not in self._const:
            self._const[key] = self.node("C", c=x)
        return self._const[key]

    def value_of(self, s: "Sym"):
        """The constant a node holds, or None."""
        return self.c[s.i] if self.ops[s.i] == CODE["C"] else None

    def arrays(self) -> tuple:
        return (np.array(self.ops, dtype=np.int32), np.array(self.a, dtype=np.int32),
                np.array(self.b, dtype=np.int32), np.array(self.c, dtype=np.float64))


def _as_sym(tape: Tape, x) -> "Sym":
    if isinstance(x, Sym):
        if x.tape is not tape:
            raise TraceError("values of two traces mixed")
        return x
    if isinstance(x, (bool, int, float, np.number, np.bool_, np.ndarray, list, tuple)):
        return tape.const(x)
    raise TraceError(f"an operand of type {type(x).__name__}")


def _apply(tape: Tape, op: str, *args) -> "Sym":
    syms = [_as_sym(tape, x) for x in args]
    vals = [tape.value_of(s) for s in syms]
    if all(v is not None for v in vals):          # constant folding, with numpy's rules
        with np.errstate(all="ignore"):
            return tape.const(_FOLD[op](*vals))
    if op in ("add", "sub") and vals[1] == 0.0:   # x + 0, x - 0
        return syms[0]
    if op == "add" and vals[0] == 0.0:
        return syms[1]
    if op == "mul" and 0.0 in vals and CODE["P"] in (tape.ops[syms[0].i], tape.ops[syms[1].i]):
        return tape.const(0.0)                    # a (finite) parameter times 0
    if op == "mul" and (vals[0] == 1.0 or vals[1] == 1.0):
        return syms[1] if vals[0] == 1.0 else syms[0]
    return tape.node(op, syms[0].i, syms[1].i if len(syms) > 1 else -1)


class Sym:
    """A symbolic array (any number of lanes) whose operations are recorded on a tape."""

    __cdam_trace__ = True
    __array_priority__ = 1000
    ndim = 1

    def __init__(self, tape: Tape, i: int):
        self.tape, self.i = tape, i

    # numpy protocols
    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        if method != "__call__" or kwargs.get("out") is not None:
            raise TraceError(f"numpy {ufunc.__name__}.{method}")
        if ufunc in _UNARY and len(inputs) == 1:
            return _apply(self.tape, _UNARY[ufunc], inputs[0])
        if ufunc in _BINARY and len(inputs) == 2:
            return _apply(self.tape, _BINARY[ufunc], *inputs)
        if ufunc is np.square:
            return _apply(self.tape, "mul", inputs[0], inputs[0])
        raise TraceError(f"numpy {ufunc.__name__}")

    def __array_function__(self, func, types, args, kwargs):
        if func in (np.ones_like, np.zeros_like):
            return self.tape.const(1.0 if func is np.ones_like else 0.0)
        if func is np.broadcast_to:
            return args[0]
        if func in (np.asanyarray, np.ndim):
            return args[0] if func is np.asanyarray else 1
        raise TraceError(f"numpy {func.__name__}")

    def __array__(self, *args, **kwargs):
        raise TraceError("a simulated value converted to an array (np.asarray)")

    def __bool__(self):
        raise TraceError("Python control flow on a simulated value")

    def __float__(self):
        raise TraceError("a simulated value converted to float")

    def __len__(self):
        raise TraceError("the length of a simulated value")

    def astype(self, dtype, *args, **kwargs):
        if np.dtype(dtype).kind != "f":
            raise TraceError(f"astype({dtype})")
        return self      # comparisons already hold 0.0 / 1.0

    def copy(self):
        return self

    # arithmetic
    def __add__(self, o): return _apply(self.tape, "add", self, o)
    def __radd__(self, o): return _apply(self.tape, "add", o, self)
    def __sub__(self, o): return _apply(self.tape, "sub", self, o)
    def __rsub__(self, o): return _apply(self.tape, "sub", o, self)
    def __mul__(self, o): return _apply(self.tape, "mul", self, o)
    def __rmul__(self, o): return _apply(self.tape, "mul", o, self)
    def __truediv__(self, o): return _apply(self.tape, "div", self, o)
    def __rtruediv__(self, o): return _apply(self.tape, "div", o, self)
    def __pow__(self, o): return _apply(self.tape, "pow", self, o)
    def __rpow__(self, o): return _apply(self.tape, "pow", o, self)
    def __neg__(self): return _apply(self.tape, "neg", self)
    def __pos__(self): return self
    def __abs__(self): return _apply(self.tape, "abs", self)
    def __gt__(self, o): return _apply(self.tape, "gt", self, o)
    def __lt__(self, o): return _apply(self.tape, "lt", self, o)
    def __ge__(self, o): return _apply(self.tape, "ge", self, o)
    def __le__(self, o): return _apply(self.tape, "le", self, o)

    def __getitem__(self, key):
        raise TraceError("indexing a simulated value")


def floats(x):
    """``np.asarray(x, dtype=float)``, leaving a traced value or a :class:`Held` state as it
    is (the model code calls this where it converts a signal or state entry)."""
    if getattr(x, "__cdam_trace__", False) or (isinstance(x, Held) and x.dtype.kind == "f"):
        return x
    return np.asarray(x, dtype=float)


# -- switching terms held over a Runge-Kutta step (the numpy twin of the compiled rollout) -----
# The operations whose value jumps with the state (a dry friction's sign, a direction test):
# evaluated once per step at its start state and held over the step's four RK4 stages (the
# zero-order hold of a switching term; ``_core.greybox_rollout`` holds the same tape nodes).
SWITCHING = (np.sign, np.greater, np.less, np.greater_equal, np.less_equal)


class Switches:
    """The switching operations' results of one step: recorded at its first stage (in call
    order), replayed at the others."""

    def __init__(self):
        self.values, self.at = [], None

    def record(self):
        self.values, self.at = [], None

    def replay(self):
        self.at = 0

    def take(self, value):
        if self.at is None:
            self.values.append(value)
            return value
        if self.at >= len(self.values):
            raise RuntimeError("held switches: a stage made more switching operations than "
                               "the step's first")
        value, self.at = self.values[self.at], self.at + 1
        return value


class Held(np.ndarray):
    """A state array whose switching operations (:data:`SWITCHING`), and those of every array
    computed from it, go through ``switches`` (a :class:`Switches`)."""

    switches = None

    def __array_finalize__(self, obj):
        self.switches = getattr(obj, "switches", None)

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        sw = next(x.switches for x in inputs if isinstance(x, Held))
        args = [x.view(np.ndarray) if isinstance(x, Held) else x for x in inputs]
        if kwargs.get("out") is not None:
            kwargs["out"] = tuple(o.view(np.ndarray) if isinstance(o, Held) else o
                                  for o in kwargs["out"])
        res = getattr(ufunc, method)(*args, **kwargs)
        if method == "__call__" and ufunc in SWITCHING and sw is not None:
            res = sw.take(np.asarray(res))
        return _held(res, sw)


def _held(res, sw):
    if isinstance(res, tuple):
        return tuple(_held(r, sw) for r in res)
    if isinstance(res, np.ndarray) and res.ndim:
        out = res.view(Held)
        out.switches = sw
        return out
    return res


def held(x, switches: Switches) -> "Held":
    """``x`` (an array) whose switching operations go through ``switches``."""
    return _held(np.asarray(x, dtype=float), switches)
