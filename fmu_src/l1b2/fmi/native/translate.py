"""Translate the plain-float physics kernels (Python source) into C: one physics for both.

The fused coupled step (:func:`l1b2.physics.coupled.motor_substeps`) and the
kernels it calls are written in a small subset of Python so that numba
compiles them; :func:`translate_kernels` turns the *same source* into C99 for
the native ``L1B2Motor`` FMU (:mod:`l1b2.fmi.native.build`). The subset, and
nothing else (anything outside it raises :class:`TranslationError` naming the
function and line):

* statements: assignment (also to tuples, subscripts and chained), augmented
  assignment, ``if``/``elif``/``else``, ``for ... in range(...)``, ``break``,
  ``continue``, ``return`` (a value or a tuple), docstrings;
* expressions: float and int constants, ``1j``-style imaginary constants,
  arithmetic ``+ - * / % **``, comparisons (also chained), ``and``/``or``/``not``,
  conditional expressions, calls of other kernels, of ``math`` functions, of
  ``abs``/``min``/``max``/``complex``, ``cmath.exp``/``cmath.phase``,
  ``.real``/``.imag``/``.conjugate()``, subscripts of the state and parameter
  vectors, of tuples, of the table cell (``cell[i, j]``, ``cell.shape[0]``);
  module-level numbers and tuples of numbers are inlined as constants.

Python's semantics are kept where C's differ: ``%`` is the floored modulo
(sign of the divisor, CPython's ``float_rem``), ``min``/``max`` keep the first
argument on ties (and NaN), ``abs`` of a complex is ``hypot``, complex
division is CPython's ``_Py_c_quot``, ``cmath.exp`` is CPython's ``cmath_exp``
for finite arguments, and a float in a complex operation is the complex
``(x, 0)`` as in CPython. With the library's ``-ffp-contract=off`` the
generated C then performs the Python function's floating-point operations one
by one (tests/test_native_motor.py compares bit for bit against the plain
Python function, and within 1e-9 against the numba-compiled one).
"""

from __future__ import annotations

import ast
import inspect
import math
import textwrap

from ...errors import L1B2Error

PREFIX = "l1b2k_"
_MATH = {"sqrt": "sqrt", "sin": "sin", "cos": "cos", "tan": "tan", "exp": "exp", "expm1": "expm1", "log": "log",
         "acos": "acos", "asin": "asin", "atan": "atan", "atan2": "atan2", "sinh": "sinh", "cosh": "cosh",
         "tanh": "tanh", "floor": "floor", "copysign": "copysign", "hypot": "hypot", "fabs": "fabs",
         "isfinite": "isfinite", "log1p": "log1p"}
_RESERVED = {"auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else", "enum",
             "extern", "float", "for", "goto", "if", "inline", "int", "long", "register", "restrict", "return",
             "short", "signed", "sizeof", "static", "struct", "switch", "typedef", "union", "unsigned", "void",
             "volatile", "while", "main", "y0", "y1", "yn", "j0", "j1", "jn", "exp", "log", "sin", "cos", "tan",
             "pow", "sqrt", "floor", "ceil", "fabs", "round", "gamma", "signgam", "time", "index", "NAN", "INFINITY"}

RUNTIME = r"""
/* Python's semantics for the operations where C differs (see l1b2.fmi.native.translate) */
typedef struct { double re, im; } l1b2_cplx;
static inline l1b2_cplx l1b2_c(double re, double im) { l1b2_cplx z; z.re = re; z.im = im; return z; }
static inline l1b2_cplx l1b2_cadd(l1b2_cplx a, l1b2_cplx b) { return l1b2_c(a.re + b.re, a.im + b.im); }
static inline l1b2_cplx l1b2_csub(l1b2_cplx a, l1b2_cplx b) { return l1b2_c(a.re - b.re, a.im - b.im); }
static inline l1b2_cplx l1b2_cmul(l1b2_cplx a, l1b2_cplx b)
{
    return l1b2_c(a.re * b.re - a.im * b.im, a.re * b.im + a.im * b.re);
}
static inline l1b2_cplx l1b2_cdiv(l1b2_cplx a, l1b2_cplx b) /* CPython's _Py_c_quot */
{
    const double abs_br = b.re < 0 ? -b.re : b.re;
    const double abs_bi = b.im < 0 ? -b.im : b.im;
    if (abs_br >= abs_bi) {
        if (abs_br == 0.0) return l1b2_c(0.0, 0.0); /* CPython raises ZeroDivisionError */
        const double ratio = b.im / b.re;
        const double denom = b.re + b.im * ratio;
        return l1b2_c((a.re + a.im * ratio) / denom, (a.im - a.re * ratio) / denom);
    }
    if (abs_bi >= abs_br) {
        const double ratio = b.re / b.im;
        const double denom = b.re * ratio + b.im;
        return l1b2_c((a.re * ratio + a.im) / denom, (a.im * ratio - a.re) / denom);
    }
    return l1b2_c(NAN, NAN);
}
static inline l1b2_cplx l1b2_cneg(l1b2_cplx a) { return l1b2_c(-a.re, -a.im); }
static inline l1b2_cplx l1b2_cconj(l1b2_cplx a) { return l1b2_c(a.re, -a.im); }
static inline double l1b2_cabs(l1b2_cplx a) { return hypot(a.re, a.im); }
static inline double l1b2_cphase(l1b2_cplx a) { return atan2(a.im, a.re); }
static inline l1b2_cplx l1b2_cexp(l1b2_cplx z) /* CPython's cmath.exp, finite arguments */
{
    double l;
    if (z.re > 708.3964185322641) { /* CM_LOG_LARGE_DOUBLE */
        l = exp(z.re - 1.0);
        return l1b2_c(l * cos(z.im) * 2.718281828459045, l * sin(z.im) * 2.718281828459045);
    }
    l = exp(z.re);
    return l1b2_c(l * cos(z.im), l * sin(z.im));
}
static inline double l1b2_fmod(double vx, double wx) /* CPython's float_rem */
{
    double mod = fmod(vx, wx);
    if (mod) {
        if ((wx < 0) != (mod < 0)) mod += wx;
    } else {
        mod = copysign(0.0, wx);
    }
    return mod;
}
static inline double l1b2_min(double a, double b) { return b < a ? b : a; }
static inline double l1b2_max(double a, double b) { return b > a ? b : a; }
"""


class TranslationError(L1B2Error):
    """A kernel uses Python outside the subset :mod:`l1b2.fmi.native.translate` translates."""


D, CPX, LONG, BOOL = "double", "l1b2_cplx", "long", "int"


def _tuple_type(n: int) -> str:
    return f"l1b2_tup{n}"


def _is_tuple(t: str) -> bool:
    return t.startswith("l1b2_tup")


def _tuple_len(t: str) -> int:
    return int(t[len("l1b2_tup"):])


def _const(x) -> str:
    if isinstance(x, bool):
        return "1" if x else "0"
    if isinstance(x, int):
        return f"{x}.0"
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "INFINITY" if x > 0 else "(-INFINITY)"
    r = repr(float(x))
    return r if ("." in r or "e" in r) else r + ".0"


class _Function:
    """One kernel: its AST, globals and the C types of its parameters."""

    def __init__(self, f, param_types: dict[str, str]):
        self.f = f
        self.name = f.__name__
        src = textwrap.dedent(inspect.getsource(f))
        self.tree = ast.parse(src).body[0]
        self.line0 = f.__code__.co_firstlineno - 1
        self.globals = f.__globals__
        self.params = [a.arg for a in self.tree.args.args]
        self.ptypes = {p: param_types.get(p, D) for p in self.params}
        self.ret: str | None = None
        self.locals: dict[str, str] = {}


class Translator:
    """Translates a family of kernels (name -> function) into one C file."""

    def __init__(self, functions: dict, param_types: dict[str, dict[str, str]], cell_rows: int):
        self.fns = {name: _Function(f, param_types.get(name, {})) for name, f in functions.items()}
        self.cell_rows = cell_rows
        self.tuples: set[int] = set()

    # -- errors ----------------------------------------------------------------------
    def _err(self, fn: _Function, node, what: str):
        line = getattr(node, "lineno", 1) + fn.line0
        raise TranslationError(f"{fn.name} (line {line} of {fn.f.__code__.co_filename}): {what} is not in the "
                               "translatable subset (l1b2.fmi.native.translate)")

    # -- types -----------------------------------------------------------------------
    def _global(self, fn: _Function, name: str):
        if name in fn.globals:
            return fn.globals[name]
        raise KeyError(name)

    def type_of(self, fn: _Function, node) -> str:
        if isinstance(node, ast.Constant):
            if isinstance(node.value, complex):
                return CPX
            return BOOL if isinstance(node.value, bool) else D
        if isinstance(node, ast.Name):
            if node.id in fn.locals:
                return fn.locals[node.id]
            if node.id in fn.ptypes:
                return fn.ptypes[node.id]
            return D
        if isinstance(node, ast.BinOp):
            lt, rt = self.type_of(fn, node.left), self.type_of(fn, node.right)
            return CPX if CPX in (lt, rt) else D
        if isinstance(node, ast.UnaryOp):
            if isinstance(node.op, ast.Not):
                return BOOL
            return self.type_of(fn, node.operand)
        if isinstance(node, (ast.Compare, ast.BoolOp)):
            return BOOL
        if isinstance(node, ast.IfExp):
            a, b = self.type_of(fn, node.body), self.type_of(fn, node.orelse)
            return CPX if CPX in (a, b) else (a if a == b else D)
        if isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Name):
                if f.id == "complex":
                    return CPX
                if f.id in ("abs", "min", "max", "float"):
                    return D
                if f.id == "int":
                    return LONG
                if f.id in self.fns:
                    return self.fns[f.id].ret or D
            if isinstance(f, ast.Attribute):
                if isinstance(f.value, ast.Name) and f.value.id == "cmath":
                    return CPX if f.attr == "exp" else D
                if f.attr == "conjugate":
                    return CPX
            return D
        if isinstance(node, ast.Attribute):
            return D
        if isinstance(node, ast.Subscript):
            return D
        if isinstance(node, ast.Tuple):
            return _tuple_type(len(node.elts))
        return D

    def infer(self, fn: _Function):
        """Types of the locals (first assignment; complex wins) and of the return value."""
        loc: dict[str, str] = {}
        fn.locals = loc

        def assign(target, t):
            if isinstance(target, ast.Name) and target.id not in fn.ptypes and target.id != "_":
                old = loc.get(target.id)
                if old is None or (t == CPX) or (old == BOOL and t == D):
                    loc[target.id] = t

        for node in ast.walk(fn.tree):
            if isinstance(node, ast.Assign):
                vt = self.type_of(fn, node.value)
                for tgt in node.targets:
                    if isinstance(tgt, ast.Tuple):
                        if isinstance(node.value, ast.Tuple):
                            for e, v in zip(tgt.elts, node.value.elts):
                                assign(e, self.type_of(fn, v))
                        else:
                            for e in tgt.elts:
                                assign(e, D)
                    else:
                        assign(tgt, vt)
            elif isinstance(node, ast.AugAssign):
                assign(node.target, self.type_of(fn, node.value))
            elif isinstance(node, ast.For):
                if isinstance(node.target, ast.Name) and node.target.id != "_":
                    loc[node.target.id] = LONG
            elif isinstance(node, ast.Return) and node.value is not None:
                t = self.type_of(fn, node.value)
                if _is_tuple(t):
                    self.tuples.add(_tuple_len(t))
                if isinstance(node.value, ast.Name) and loc.get(node.value.id) == LONG or (
                        isinstance(node.value, ast.Name) and fn.ptypes.get(node.value.id) == LONG):
                    t = LONG
                if fn.ret is None or fn.ret == D and t == LONG:
                    fn.ret = t

    # -- expressions -----------------------------------------------------------------
    def _as_cplx(self, fn, node) -> str:
        code = self.expr(fn, node)
        return code if self.type_of(fn, node) == CPX else f"l1b2_c({code}, 0.0)"

    def _index(self, fn, node) -> str:
        """An index: a constant (module-level int inlined), a loop variable or an int expression."""
        try:
            value = self.const_value(fn, node)
        except KeyError:
            value = None
        if isinstance(value, int) and not isinstance(value, bool):
            return str(value)
        if isinstance(node, ast.Name) and self.type_of(fn, node) == LONG:
            return node.id
        if isinstance(node, ast.BinOp) and type(node.op) in (ast.Add, ast.Sub, ast.Mult):
            op = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*"}[type(node.op)]
            return f"({self._index(fn, node.left)} {op} {self._index(fn, node.right)})"
        self._err(fn, node, "this index")

    def const_value(self, fn, node):
        """Value of a constant expression (literal, module-level name, constant subscript), else KeyError."""
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, ast.Name) and node.id not in fn.locals and node.id not in fn.ptypes:
            value = self._global(fn, node.id)
            if isinstance(value, (int, float, tuple)):
                return value
            raise KeyError(node.id)
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "math":
            if node.attr in ("pi", "inf", "e", "tau", "nan"):
                return getattr(math, node.attr)
        if isinstance(node, ast.Subscript):
            base = self.const_value(fn, node.value)
            if isinstance(base, tuple):
                return base[self.const_value(fn, node.slice)]
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return -self.const_value(fn, node.operand)
        raise KeyError(ast.dump(node))

    def expr(self, fn: _Function, node) -> str:
        try:
            value = self.const_value(fn, node)
            if isinstance(value, (int, float)):
                return _const(value)
        except KeyError:
            pass
        if isinstance(node, ast.Constant):
            if isinstance(node.value, complex):
                return f"l1b2_c({_const(node.value.real)}, {_const(node.value.imag)})"
            self._err(fn, node, f"the constant {node.value!r}")
        if isinstance(node, ast.Name):
            if node.id in fn.locals or node.id in fn.ptypes:
                return self.cname(node.id)
            self._err(fn, node, f"the name {node.id}")
        if isinstance(node, ast.BinOp):
            lt, rt = self.type_of(fn, node.left), self.type_of(fn, node.right)
            if CPX in (lt, rt):
                op = {ast.Add: "l1b2_cadd", ast.Sub: "l1b2_csub", ast.Mult: "l1b2_cmul", ast.Div: "l1b2_cdiv"}.get(
                    type(node.op))
                if op is None:
                    self._err(fn, node, "this complex operator")
                return f"{op}({self._as_cplx(fn, node.left)}, {self._as_cplx(fn, node.right)})"
            a, b = self.expr(fn, node.left), self.expr(fn, node.right)
            if isinstance(node.op, ast.Mod):
                return f"l1b2_fmod({a}, {b})"
            if isinstance(node.op, ast.Pow):
                return f"pow({a}, {b})"
            op = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}.get(type(node.op))
            if op is None:
                self._err(fn, node, "this operator")
            if LONG in (lt, rt):
                a, b = (f"(double){a}" if lt == LONG else a), (f"(double){b}" if rt == LONG else b)
            return f"({a} {op} {b})"
        if isinstance(node, ast.UnaryOp):
            if isinstance(node.op, ast.Not):
                return f"(!{self.expr(fn, node.operand)})"
            if isinstance(node.op, ast.USub):
                if self.type_of(fn, node.operand) == CPX:
                    return f"l1b2_cneg({self.expr(fn, node.operand)})"
                return f"(-{self.expr(fn, node.operand)})"
            if isinstance(node.op, ast.UAdd):
                return self.expr(fn, node.operand)
            self._err(fn, node, "this unary operator")
        if isinstance(node, ast.BoolOp):
            op = " && " if isinstance(node.op, ast.And) else " || "
            return "(" + op.join(self.expr(fn, v) for v in node.values) + ")"
        if isinstance(node, ast.Compare):
            parts, left = [], node.left
            for op, right in zip(node.ops, node.comparators):
                sym = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!="}.get(
                    type(op))
                if sym is None or CPX in (self.type_of(fn, left), self.type_of(fn, right)):
                    self._err(fn, node, "this comparison")
                parts.append(f"({self.expr(fn, left)} {sym} {self.expr(fn, right)})")
                left = right
            return parts[0] if len(parts) == 1 else "(" + " && ".join(parts) + ")"
        if isinstance(node, ast.IfExp):
            t = self.type_of(fn, node)
            a = self._as_cplx(fn, node.body) if t == CPX else self.expr(fn, node.body)
            b = self._as_cplx(fn, node.orelse) if t == CPX else self.expr(fn, node.orelse)
            return f"({self.expr(fn, node.test)} ? {a} : {b})"
        if isinstance(node, ast.Call):
            return self.call(fn, node)
        if isinstance(node, ast.Attribute):
            if node.attr in ("real", "imag") and self.type_of(fn, node.value) == CPX:
                return f"{self.expr(fn, node.value)}.{'re' if node.attr == 'real' else 'im'}"
            self._err(fn, node, f"the attribute .{node.attr}")
        if isinstance(node, ast.Subscript):
            base = node.value
            if isinstance(base, ast.Name):
                bt = self.type_of(fn, base)
                if _is_tuple(bt):
                    return f"{self.cname(base.id)}.v[{self._index(fn, node.slice)}]"
                if bt == "cell":
                    if not (isinstance(node.slice, ast.Tuple) and len(node.slice.elts) == 2):
                        self._err(fn, node, "this cell subscript")
                    i, j = (self._index(fn, e) for e in node.slice.elts)
                    return f"{self.cname(base.id)}[2 * {i} + {j}]"
                if bt in ("double*", "const double*"):
                    return f"{self.cname(base.id)}[{self._index(fn, node.slice)}]"
            if (isinstance(base, ast.Attribute) and base.attr == "shape" and isinstance(base.value, ast.Name)
                    and self.type_of(fn, base.value) == "cell"):
                return str(self.cell_rows)
            self._err(fn, node, "this subscript")
        self._err(fn, node, type(node).__name__)

    def call(self, fn, node) -> str:
        f = node.func
        args = node.args
        if node.keywords:
            self._err(fn, node, "keyword arguments")
        if isinstance(f, ast.Name):
            if f.id == "abs":
                return (f"l1b2_cabs({self.expr(fn, args[0])})" if self.type_of(fn, args[0]) == CPX
                        else f"fabs({self.expr(fn, args[0])})")
            if f.id in ("min", "max") and len(args) == 2:
                return f"l1b2_{f.id}({self.expr(fn, args[0])}, {self.expr(fn, args[1])})"
            if f.id == "complex" and len(args) == 2:
                return f"l1b2_c({self.expr(fn, args[0])}, {self.expr(fn, args[1])})"
            if f.id == "float" and len(args) == 1 and self.type_of(fn, args[0]) != CPX:
                return f"((double){self.expr(fn, args[0])})"
            if f.id == "int" and len(args) == 1 and self.type_of(fn, args[0]) != CPX:
                return f"((long)({self.expr(fn, args[0])}))"  # truncation toward zero, as Python's int()
            if f.id in self.fns:
                callee = self.fns[f.id]
                out = []
                for p, a in zip(callee.params, args):
                    pt = callee.ptypes[p]
                    out.append(self._as_cplx(fn, a) if pt == CPX else self.expr(fn, a))
                return f"{PREFIX}{f.id}({', '.join(out)})"
        if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
            if f.value.id == "math" and f.attr in _MATH:
                return f"{_MATH[f.attr]}({', '.join(self.expr(fn, a) for a in args)})"
            if f.value.id == "cmath" and f.attr in ("exp", "phase"):
                return f"l1b2_c{f.attr}({self._as_cplx(fn, args[0])})"
        if isinstance(f, ast.Attribute) and f.attr == "conjugate" and not args:
            return f"l1b2_cconj({self.expr(fn, f.value)})"
        self._err(fn, node, f"the call {ast.unparse(f)}(...)")

    # -- statements ------------------------------------------------------------------
    def cname(self, name: str) -> str:
        return name + "_" if name in _RESERVED else ("_ix" if name == "_" else name)

    def _store(self, fn, target, value: str, ind: str) -> list[str]:
        if isinstance(target, ast.Name):
            if target.id == "_":
                return []
            return [f"{ind}{self.cname(target.id)} = {value};"]
        if isinstance(target, ast.Subscript):
            return [f"{ind}{self.expr(fn, target)} = {value};"]
        self._err(fn, target, "this assignment target")

    def _value_for(self, fn, target, node) -> str:
        tt = fn.locals.get(target.id) if isinstance(target, ast.Name) else D
        return self._as_cplx(fn, node) if tt == CPX else self.expr(fn, node)

    def stmt(self, fn: _Function, node, ind: str) -> list[str]:
        out: list[str] = []
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            return []  # docstring
        if isinstance(node, ast.Assign):
            targets = node.targets
            if len(targets) == 1 and isinstance(targets[0], ast.Tuple):
                tgt = targets[0].elts
                if isinstance(node.value, ast.Tuple):  # all values first, then the targets (Python's order)
                    self.tmp += 1
                    names = [f"t{self.tmp}_{i}" for i in range(len(tgt))]
                    for n, t, v in zip(names, tgt, node.value.elts):
                        tt = fn.locals.get(t.id, D) if isinstance(t, ast.Name) else D
                        code = self._as_cplx(fn, v) if tt == CPX else self.expr(fn, v)
                        out.append(f"{ind}const {tt} {n} = {code};")
                    for n, t in zip(names, tgt):
                        out += self._store(fn, t, n, ind)
                    return out
                vt = self.type_of(fn, node.value)
                if not _is_tuple(vt) or _tuple_len(vt) != len(tgt):
                    self._err(fn, node, "this tuple assignment")
                self.tmp += 1
                tmp = f"r{self.tmp}"
                out.append(f"{ind}const {vt} {tmp} = {self.expr(fn, node.value)};")
                for i, t in enumerate(tgt):
                    out += self._store(fn, t, f"{tmp}.v[{i}]", ind)
                return out
            if len(targets) == 1:
                return self._store(fn, targets[0], self._value_for(fn, targets[0], node.value), ind)
            # chained: the value once, then every target left to right
            self.tmp += 1
            vt = self.type_of(fn, node.value)
            tmp = f"c{self.tmp}"
            out.append(f"{ind}const {vt} {tmp} = {self.expr(fn, node.value)};")
            for t in targets:
                out += self._store(fn, t, tmp, ind)
            return out
        if isinstance(node, ast.AugAssign):
            op = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}.get(type(node.op))
            if op is None or self.type_of(fn, node.target) == CPX:
                self._err(fn, node, "this augmented assignment")
            tgt = self.expr(fn, node.target)
            return [f"{ind}{tgt} = ({tgt} {op} {self.expr(fn, node.value)});"]
        if isinstance(node, ast.If):
            out.append(f"{ind}if ({self.expr(fn, node.test)}) {{")
            for s in node.body:
                out += self.stmt(fn, s, ind + "    ")
            if node.orelse:
                out.append(f"{ind}}} else {{")
                for s in node.orelse:
                    out += self.stmt(fn, s, ind + "    ")
            out.append(f"{ind}}}")
            return out
        if isinstance(node, ast.For):
            it = node.iter
            if not (isinstance(it, ast.Call) and isinstance(it.func, ast.Name) and it.func.id == "range"
                    and 1 <= len(it.args) <= 2 and not node.orelse):
                self._err(fn, node, "this for loop")
            lo, hi = ("0", it.args[0]) if len(it.args) == 1 else (self._int(fn, it.args[0]), it.args[1])
            var = self.cname(node.target.id) if isinstance(node.target, ast.Name) else "_ix"
            if var == "_ix":
                self.tmp += 1
                var = f"i{self.tmp}"
                out.append(f"{ind}for (long {var} = {lo}; {var} < {self._int(fn, hi)}; {var}++) {{")
            else:
                out.append(f"{ind}for ({var} = {lo}; {var} < {self._int(fn, hi)}; {var}++) {{")
            for s in node.body:
                out += self.stmt(fn, s, ind + "    ")
            out.append(f"{ind}}}")
            return out
        if isinstance(node, ast.Return):
            if node.value is None:
                self._err(fn, node, "a bare return")
            if isinstance(node.value, ast.Tuple):
                n = len(node.value.elts)
                self.tmp += 1
                tmp = f"ret{self.tmp}"
                out.append(f"{ind}{{")
                out.append(f"{ind}    {_tuple_type(n)} {tmp};")
                for i, e in enumerate(node.value.elts):
                    out.append(f"{ind}    {tmp}.v[{i}] = {self.expr(fn, e)};")
                out.append(f"{ind}    return {tmp};")
                out.append(f"{ind}}}")
                return out
            if fn.ret == CPX:
                return [f"{ind}return {self._as_cplx(fn, node.value)};"]
            return [f"{ind}return {self.expr(fn, node.value)};"]
        if isinstance(node, ast.Break):
            return [f"{ind}break;"]
        if isinstance(node, ast.Continue):
            return [f"{ind}continue;"]
        if isinstance(node, ast.Pass):
            return []
        self._err(fn, node, type(node).__name__)

    def _int(self, fn, node) -> str:
        try:
            value = self.const_value(fn, node)
            if isinstance(value, int):
                return str(value)
        except KeyError:
            pass
        if isinstance(node, ast.Subscript):  # cell.shape[0]
            return self.expr(fn, node)
        if isinstance(node, ast.Name) and self.type_of(fn, node) == LONG:
            return self.cname(node.id)
        self._err(fn, node, "this loop bound")

    # -- functions -------------------------------------------------------------------
    def _ctype(self, t: str) -> str:
        return "const double*" if t == "cell" else t

    def signature(self, fn: _Function) -> str:
        params = ", ".join(f"{self._ctype(fn.ptypes[p])} {self.cname(p)}" for p in fn.params)
        return f"{fn.ret or D} {PREFIX}{fn.name}({params})"

    def function(self, fn: _Function) -> str:
        self.tmp = 0
        body: list[str] = []
        for s in fn.tree.body:
            body += self.stmt(fn, s, "    ")
        decls = [f"    {t} {self.cname(n)};" for n, t in fn.locals.items()]
        return "\n".join([self.signature(fn), "{", *decls, *body, "}"])

    def translate(self, source_note: str) -> str:
        for _ in range(3):  # return types of callees, then the callers' locals
            for fn in self.fns.values():
                self.infer(fn)
        for fn in self.fns.values():
            for t in fn.ptypes.values():
                if _is_tuple(t):
                    self.tuples.add(_tuple_len(t))
        parts = [f"/* {source_note} */", "#include <math.h>", RUNTIME]
        for n in sorted(self.tuples | {_tuple_len(fn.ret) for fn in self.fns.values() if fn.ret and
                                       _is_tuple(fn.ret)}):
            parts.append(f"typedef struct {{ double v[{n}]; }} {_tuple_type(n)};")
        parts.append("")
        for fn in self.fns.values():
            parts.append(self.signature(fn) + ";")
        parts.append("")
        for fn in self.fns.values():
            parts.append(self.function(fn))
            parts.append("")
        return "\n".join(parts)


def motor_kernel_family() -> dict:
    """The fused coupled step and every kernel it calls (the family numba compiles), by name."""
    from ...physics import coupled, interface, slider, stator
    return {**stator.kernel_family(), **interface.kernel_family(), **slider.kernel_family(),
            "motor_substeps": coupled.motor_substeps}


#: parameter types that are not double: complex phasors, the vectors and the table cell, counts
PARAM_TYPES = {
    "envelope_step_scalar": {"Q": CPX, "F": CPX, "Y": CPX},
    "envelope_growth_rate_scalar": {"Y": CPX},
    "tip_motion_scalar": {"Q_l": CPX, "Q_b": CPX},
    "table_lookup": {"cell": "cell"},
    "motor_substeps": {"x": "double*", "p": "const double*", "cell": "cell", "cell_k": LONG, "n": LONG},
}


#: parameter types of the effect kernels (l1b2.predictor.effects.kernels): the signal, scalar and parameter
#: vectors, and the integer codes
_VEC = "const double*"
EFFECT_PARAM_TYPES = {
    **{name: {"x": _VEC, "q": _VEC, "phi": _VEC} for name in (
        "thermal_drift_force", "thermal_drift_t_force", "direction_asymmetry_force", "bar_waviness_force",
        "local_defect_force", "load_path_friction_force", "drive_saturation_force", "speed_dependent_friction_force",
        "inertia_mismatch_force", "position_load_force", "smooth_force", "smooth_pair_force", "channel_force",
        "run_level_force")},
    "input_signal": {"x": _VEC, "sig": LONG},
    "voltage_slope_force": {"x": _VEC, "q": _VEC, "phi": _VEC, "regressor": LONG},
    "knot": {"i": LONG},
    "bspline1": {"j": LONG, "k": LONG},
    "bspline_force": {"phi": _VEC},
    "pair_width": {"reg": LONG},
    "pair_factor": {"reg": LONG, "j": LONG, "x": _VEC, "q": _VEC, "o": LONG},
    "effect_force": {"kind": LONG, "x": _VEC, "q": _VEC, "phi": _VEC},
}


def translate_effect_kernels() -> str:
    """C source of the effect families' per-sample forces (``l1b2k_effect_force``), for the native Predictor FMU.

    Generated from :mod:`l1b2.predictor.effects.kernels`, the plain-float forms of the families' features.
    """
    from ...predictor.effects import kernels
    t = Translator(kernels.kernel_family(), EFFECT_PARAM_TYPES, 0)
    return t.translate("effect_kernels.c - generated by l1b2.fmi.native.translate from "
                       "l1b2.predictor.effects.kernels; do not edit")


def translate_kernels() -> str:
    """C source of :func:`l1b2.physics.coupled.motor_substeps` and its kernels (``l1b2k_motor_substeps``)."""
    from ...physics.stator import TABLE_DEGREE
    t = Translator(motor_kernel_family(), PARAM_TYPES, TABLE_DEGREE + 1)
    return t.translate("motor_kernels.c - generated by l1b2.fmi.native.translate from l1b2.physics (coupled.py, "
                       "stator.py, interface.py, slider.py); do not edit")
