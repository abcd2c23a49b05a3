"""Emission of allocation-free C++17 for one machine (design §6).

Deterministic: the same machine file and sympy version give byte-identical files. Each
function's expressions share one common-subexpression elimination; trigonometric and other
non-polynomial functions of parameters alone are hoisted into ``prepare`` so the hot
functions only evaluate what depends on the axes.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from fractions import Fraction

import sympy as sp
from sympy.printing.cxx import CXX17CodePrinter

from ..escape import cpp_comment, cpp_string
from ..model.expressions import sin_cos
from ..model.machine import ROT_PLANE, Machine, Rotation
from ..model.units import UNITS
from ..symbolic.derive import EXPANDED_TERMS_LIMIT, derive
from . import straightline

GENERATOR = "chaincomp generate"


def fnv1a64(data: bytes) -> int:
    h = 0xCBF29CE484222325
    for b in data:
        h ^= b
        h = (h * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


class _Printer(CXX17CodePrinter):
    """C++17 printer: small integer powers as products, doubles with full precision."""

    def _print_Pow(self, expr):
        if expr.exp.is_Integer and 2 <= int(expr.exp) <= 4:
            base = self.parenthesize(expr.base, 100)
            return "(" + "*".join([base] * int(expr.exp)) + ")"
        if expr.exp.is_Integer and -4 <= int(expr.exp) <= -1:
            return "(1.0/" + self._print(sp.Pow(expr.base, -expr.exp)) + ")"
        return super()._print_Pow(expr)

    def _print_Rational(self, expr):
        if max(abs(expr.p), expr.q) > 2 ** 1000:   # products of numeric sines (sin_cos): the quotient, rounded once
            return f"{float(Fraction(int(expr.p), int(expr.q)))!r}"
        return f"({float(expr.p)!r}/{float(expr.q)!r})"

    def _print_Integer(self, expr):
        return f"{float(expr.p)!r}"


_PRINTER = _Printer()


class _ErrorPrinter(_Printer):
    """For set_errors: sin and cos of (usually small) error angles by chaincomp::sin_small /
    cos_small (a short series below 2^-6 rad, the library above), which tables of angular
    errors evaluate on every call."""

    def _print_sin(self, expr):
        return f"chaincomp::sin_small({self._print(expr.args[0])})"

    def _print_cos(self, expr):
        return f"chaincomp::cos_small({self._print(expr.args[0])})"


_ERROR_PRINTER = _ErrorPrinter()


def ccode(expr: sp.Expr) -> str:
    return _PRINTER.doprint(expr)


def exact_pose(machine: Machine, with_errors: bool = True) -> list[sp.Expr]:
    """The tool point (and direction, and with a frame its x axis) by the chain, symbolic and
    untruncated: the Pose layout."""
    zero = {s.sym: 0 for s in machine.errors} if not with_errors else {}
    p = [v.xreplace(zero) for v in machine.tool_point]
    dirs = [list(axis) for axis in machine.tool_axes]
    for el in reversed(machine.chain):
        if isinstance(el, Rotation):
            angle = el.angle.xreplace(zero)
            s, c = sin_cos(angle)
            i, j = ROT_PLANE[el.axis]
            for v in [p] + dirs:
                v[i], v[j] = _combine(c, v[i], -s, v[j]), _combine(s, v[i], c, v[j])
        else:
            for k in range(3):
                p[k] = p[k] + el.vector[k].xreplace(zero)
    return p + [c for axis in dirs for c in axis]


def _combine(a, x, b, y):
    """a*x + b*y without multiplying by 0 or 1: a quarter turn's exact 0 times the nested pose
    makes sympy ask whether the pose is finite, through every subtree (Kinova's URDF: 120 s of
    the 122 s its generate took)."""
    terms = [t if c == 1 else -t if c == -1 else c * t for c, t in ((a, x), (b, y)) if c != 0 and t != 0]
    return sp.Add(*terms)


def corrects_direction(machine: Machine) -> bool:
    """The direction enters the solver's objective when the machine has a tool axis and a
    rotary axis: with two it is corrected, with one as far as that axis can (weighted least
    squares with the point), never left to the spare freedom of the point alone."""
    return machine.tool_direction is not None and any(a.unit.kind == "angle" for a in machine.axes)


def solver_shape(machine: Machine) -> tuple[int, int, int, int, bool]:
    """The template arguments of the compensation solver for ``machine`` (compensate.hpp's
    Core<N, A, P, R, O>, which CoreOf<Kinematics> must equal): axes, their kinds (bit i set:
    axis i is an angle), pose size, residual rows, and whether the orientation is corrected
    in full (a frame and three rotary axes)."""
    pose_size = 3 + 3 * len(machine.tool_axes)
    corr_dir = corrects_direction(machine)
    mask = sum(1 << i for i, a in enumerate(machine.axes) if a.unit.kind == "angle")
    rotary = bin(mask).count("1")
    return (len(machine.axes), mask, pose_size, 6 if corr_dir else 3,
            pose_size == 9 and corr_dir and rotary >= 3)


def _core_name(shape: tuple[int, int, int, int, bool]) -> str:
    n, a, p, r, o = shape
    return f"chaincomp::Core<{n}, {a}u, {p}, {r}, {'true' if o else 'false'}>"


def solvers(shapes) -> str:
    """solvers.cpp: the compensation solver compiled once per shape, for models built with
    CHAINCOMP_PREBUILT_CORE (each declares its shape's solver extern)."""
    L = [f"// Generated by {GENERATOR}: the compensation solver of each machine shape. Do not edit.", "",
         "#include \"chaincomp/compensate.hpp\"", ""]
    L += [f"template struct {_core_name(s)};" for s in sorted(set(shapes))]
    return "\n".join(L) + "\n"


@dataclass
class _Function:
    name: str
    signature: str
    outputs: list[tuple[str, sp.Expr]]
    comment: str
    # Takes the axes' sin and cos (a Trig after `q`) instead of computing them: compensate
    # computes them once per command. A wrapper without it is declared inline.
    trig: bool = False
    # The body written already (straight-line code of a long chain); else from ``outputs``.
    lines: list[str] | None = None

    def declaration(self) -> str:
        if not self.trig:
            return f"void {self.name}({self.signature}) noexcept"
        head, rest = self.signature.split("const Axes& q", 1)
        return f"void {self.name}({head}const Axes& q, const Trig& t{rest}) noexcept"

    def trig_wrapper(self) -> str:
        args = [a.split()[-1].lstrip("&") for a in self.signature.split(",")]
        call = ", ".join(args[: args.index("q") + 1] + ["t"] + args[args.index("q") + 1:])
        return (f"inline void {self.name}({self.signature}) noexcept {{ Trig t; axis_trig<Kinematics>(q, t); "
                f"{self.name}({call}); }}")


class _Hoister:
    """Replaces non-polynomial subexpressions of parameters alone by precomputed k[i]."""

    def __init__(self, params: set[sp.Symbol]):
        self.params = params
        self.table: dict[sp.Expr, sp.Symbol] = {}
        self._done: dict[sp.Expr, sp.Expr] = {}

    def __call__(self, e: sp.Expr) -> sp.Expr:
        if e.is_Atom:
            return e
        if e in self._done:  # the nested pose shares subtrees: each is rewritten once
            return self._done[e]
        non_poly = isinstance(e, sp.Function) or (e.is_Pow and not (e.exp.is_Integer and e.exp > 0))
        if non_poly and e.free_symbols and e.free_symbols <= self.params:
            if e not in self.table:
                self.table[e] = sp.Symbol(f"k{len(self.table)}")
            out = self.table[e]
        else:
            out = e.func(*[self(a) for a in e.args])
        self._done[e] = out
        return out


def _c_name(sym: sp.Symbol, machine: Machine) -> str:
    s = machine.symbol(sym.name)
    return ("q_" if s.role == "axis" else "p_") + s.name


def _body(machine: Machine, outputs: list[tuple[str, sp.Expr]], hoisted: bool, trig: bool = False) -> list[str]:
    """Statements computing ``outputs`` with one joint CSE; inputs bound to locals first. With
    ``trig``, sin and cos of each angular axis come from ``t`` (any other function of an axis
    is still computed from ``q``)."""
    exprs = [e for _, e in outputs]
    bound = []
    if trig:
        sub = {}
        for i, a in enumerate(machine.axes):
            if a.unit.kind == "angle":
                # sympy names no machine symbol can have (they start with a letter)
                sub[sp.sin(a.sym)] = sp.Symbol(f"_s_{a.name}")
                sub[sp.cos(a.sym)] = sp.Symbol(f"_c_{a.name}")
                bound += [(sub[sp.sin(a.sym)], f"t.s[{i}]"), (sub[sp.cos(a.sym)], f"t.c[{i}]")]
        memo: dict = {}
        exprs = [_replace(e, sub, memo) for e in exprs]
    repl, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("t"), order="canonical")
    # from the reduced forms: free_symbols of the nested pose would walk its shared subtrees
    used = set().union(*(e.free_symbols for e in [r for _, r in repl] + list(reduced))) if exprs else set()
    axes = {a.sym: i for i, a in enumerate(machine.axes)}
    params = {p.sym: p for p in machine.symbols if p.role != "axis"}
    lines = [f"// {sp.count_ops(sp.Tuple(*[r for _, r in repl], *reduced))} operations after CSE"]
    rename = {}
    for sym in sorted(used, key=lambda s: (0 if s in axes else 1 if s in params else 2, str(s))):
        if sym in axes:
            rename[sym] = sp.Symbol(_c_name(sym, machine))
            lines.append(f"const double {rename[sym]} = q[{axes[sym]}];")
        elif sym in params:
            rename[sym] = sp.Symbol(_c_name(sym, machine))
            lines.append(f"const double {rename[sym]} = m.params.{sym.name};")
        elif hoisted and str(sym).startswith("k"):
            lines.append(f"const double {sym} = m.k[{str(sym)[1:]}];")
    for sym, src in bound:
        if sym in used:
            rename[sym] = sp.Symbol(str(sym)[1:])
            lines.append(f"const double {rename[sym]} = {src};")
    if trig and not any(sym in used for sym, _ in bound):
        lines.append("static_cast<void>(t);  // no sin or cos of an axis here")
    if trig and not any(sym in used for sym in axes):
        lines.append("static_cast<void>(q);  // the axes enter through t alone")
    for lhs, rhs in repl:
        lines.append(f"const double {rename.get(lhs, lhs)} = {ccode(rhs.xreplace(rename))};")
    for (target, _), e in zip(outputs, reduced):
        lines.append(f"{target} = {ccode(e.xreplace(rename))};")
    return lines


def _replace(e: sp.Expr, rule: dict, memo: dict) -> sp.Expr:
    """e.xreplace(rule), rewriting each shared subtree once (xreplace would walk it as often as
    it is reached)."""
    if e in rule:
        return rule[e]
    if e.is_Atom:
        return e
    if e not in memo:
        args = [_replace(a, rule, memo) for a in e.args]
        memo[e] = e.func(*args) if any(a is not b for a, b in zip(args, e.args)) else e
    return memo[e]


def generate(machine: Machine, order: int = 2) -> dict[str, str]:
    """C++ sources for ``machine``: {'NAME.hpp': text, 'NAME.cpp': text}."""
    name = machine.name
    axes = [a.sym for a in machine.axes]
    n = len(axes)
    param_syms = [s for s in machine.symbols if s.role != "axis"]
    hoist = _Hoister({s.sym for s in param_syms})
    pose_size = 3 + 3 * len(machine.tool_axes)
    corr_dir = corrects_direction(machine)

    exact = exact_pose(machine, True)
    d = None if _paths(exact) > DIFF_PATHS_LIMIT else derive(machine, order, max_terms=EXPANDED_TERMS_LIMIT)
    functions = _expanded_functions(machine, order, hoist, exact, d) if d else _straight_functions(machine, order, hoist)

    src_hash = fnv1a64(machine.source_text.encode("utf-8"))
    src_file = os.path.basename(machine.file)
    banner = (f"// Generated by {GENERATOR} from {cpp_comment(src_file)} (FNV-1a 64: {src_hash:016x}). Do not edit.\n"
              f"// sympy {sp.__version__}; internal units: mm and rad.\n")
    pre = list(hoist.table.items())
    hpp = _header(machine, banner, n, pose_size, corr_dir, order, len(pre), src_hash, src_file, functions)
    cpp = _source(machine, banner, n, pre, functions, order)
    return {f"{name}.hpp": hpp, f"{name}.cpp": cpp}


def _expanded_functions(machine: Machine, order: int, hoist: "_Hoister", exact: list[sp.Expr], d) -> list[_Function]:
    """The functions by the expanded series and sympy's cse: what short chains (every bundled
    machine) use, and compile to the fewest operations."""
    axes = [a.sym for a in machine.axes]
    n = len(axes)
    pose_size = 3 + 3 * len(machine.tool_axes)
    nominal = exact_pose(machine, False)
    jac = [[sp.diff(e, a) for a in axes] for e in exact]
    n_err = len(machine.errors)
    vecs = d.point + (d.direction or []) + (d.reference or [])
    gain = [d.gain(v) for v in vecs]
    errors = {k: [d.error(v, k) for v in vecs] for k in range(1, order + 1)}
    functions = [
        _Function("pose_exact", "const Model& m, const Axes& q, Pose& out",
                  [(f"out[{i}]", hoist(e)) for i, e in enumerate(exact)],
                  POSE_EXACT, trig=True),
        _Function("pose_nominal", "const Model& m, const Axes& q, Pose& out",
                  [(f"out[{i}]", hoist(e)) for i, e in enumerate(nominal)],
                  POSE_NOMINAL, trig=True),
        _Function("pose_jacobian", "const Model& m, const Axes& q, Pose& out, Jacobian& J",
                  [(f"out[{i}]", hoist(e)) for i, e in enumerate(exact)]
                  + [(f"J({i}, {j})", hoist(jac[i][j])) for i in range(pose_size) for j in range(n)],
                  POSE_JACOBIAN, trig=True),
        _Function("pose_jacobian_gain", "const Model& m, const Axes& q, Pose& out, Jacobian& J, Gain& G",
                  [(f"out[{i}]", hoist(e)) for i, e in enumerate(exact)]
                  + [(f"J({i}, {j})", hoist(jac[i][j])) for i in range(pose_size) for j in range(n)]
                  + [(f"G({i}, {c})", hoist(gain[i][c])) for i in range(pose_size) for c in range(n_err)],
                  POSE_JACOBIAN_GAIN, trig=True),
    ]
    for k in range(1, order + 1):
        functions.append(_Function(f"error_order{k}", "const Model& m, const Axes& q, Pose& out",
                                   [(f"out[{i}]", hoist(e)) for i, e in enumerate(errors[k])], ERROR_ORDER.format(k=k)))
    return functions


def _straight_functions(machine: Machine, order: int, hoist: "_Hoister") -> list[_Function]:
    """The functions of a long chain as straight-line code propagated through the chain
    (chaincomp.straightline): their size grows linearly with the chain."""
    out = []
    for name, trig, builder, targets in straightline.functions(machine, order, hoist):
        ops, inputs, statements = builder.g.emit(targets)
        out.append(_Function(name, SIGNATURES[name] if name in SIGNATURES else SIGNATURES["error_order"], [],
                             ERROR_ORDER.format(k=name[len("error_order"):]) if name.startswith("error_order")
                             else COMMENTS[name], trig=trig, lines=_declare(machine, ops, inputs, trig) + statements))
    return out


def _declare(machine: Machine, ops: int, inputs: list[str], trig: bool) -> list[str]:
    """The first lines of a straight-line body: its operation count and the inputs it reads."""
    used = set(inputs)
    lines = [f"// {ops} operations after CSE"]
    axes = machine.axes
    lines += [f"const double q_{a.name} = q[{i}];" for i, a in enumerate(axes) if f"q_{a.name}" in used]
    lines += [f"const double p_{s.name} = m.params.{s.name};" for s in machine.symbols
              if s.role != "axis" and f"p_{s.name}" in used]
    ks = sorted((int(n[1:]) for n in used if n.startswith("k")))
    lines += [f"const double k{i} = m.k[{i}];" for i in ks]
    sines = [(n, f"t.{n[0]}[{i}]") for i, a in enumerate(axes) for n in (f"s_{a.name}", f"c_{a.name}") if n in used]
    lines += [f"const double {n} = {src};" for n, src in sines]
    if trig and not sines:
        lines.append("static_cast<void>(t);  // no sin or cos of an axis here")
    if not any(f"q_{a.name}" in used for a in axes):
        lines.append("static_cast<void>(q);  // the axes enter through t alone" if trig and sines
                     else "static_cast<void>(q);  // no axis moves these outputs")
    if not any(n.startswith(("p_", "k")) for n in used):
        lines.append("static_cast<void>(m);  // every parameter here folded into constants")
    return lines


POSE_EXACT = "Actual tool point (and direction) with every error: the exact chain."
POSE_NOMINAL = "Nominal tool point (and direction): every error at zero."
POSE_JACOBIAN = "Actual pose and its exact Jacobian with respect to the axes (one shared CSE)."
POSE_JACOBIAN_GAIN = ("pose_jacobian, and the error gain matrix G = d pose / d error at zero errors (columns: "
                      "the errors in kParams order).")
ERROR_ORDER = "Tool error (actual - nominal) of the order-{k} truncated series in the errors."
COMMENTS = {"pose_exact": POSE_EXACT, "pose_nominal": POSE_NOMINAL, "pose_jacobian": POSE_JACOBIAN,
            "pose_jacobian_gain": POSE_JACOBIAN_GAIN}
SIGNATURES = {"pose_exact": "const Model& m, const Axes& q, Pose& out",
              "pose_nominal": "const Model& m, const Axes& q, Pose& out",
              "pose_jacobian": "const Model& m, const Axes& q, Pose& out, Jacobian& J",
              "pose_jacobian_gain": "const Model& m, const Axes& q, Pose& out, Jacobian& J, Gain& G",
              "error_order": "const Model& m, const Axes& q, Pose& out"}


# Up to this many root-to-leaf paths in the nested exact pose (and expanded terms below), a
# machine is a short chain: sympy's diff and cse over the expressions; beyond, the straight-line
# code (sympy's diff walks every path: 65 s for one component of a 41-error five-axis machine
# with 4.3 M paths).
DIFF_PATHS_LIMIT = 200_000


def _paths(exact: list[sp.Expr]) -> int:
    memo: dict = {}

    def paths(e):
        if e.is_Atom:
            return 1
        if e not in memo:
            memo[e] = 1 + sum(paths(a) for a in e.args)
        return memo[e]

    return sum(paths(e) for e in exact)




_POSE_LAYOUT = {3: "", 6: ", tool direction",
                9: ", tool direction (the frame's z axis), the frame's x axis: compensation corrects the "
                   "point and the rotation vector from them"}


def _kind(unit) -> str:
    return {"length": "kLength", "angle": "kAngle", "ratio": "kRatio"}[unit.kind]


def _header(machine, banner, n, pose_size, corr_dir, order, n_pre, src_hash, src_file, functions) -> str:
    name = machine.name
    shape = solver_shape(machine)
    params = [s for s in machine.symbols if s.role != "axis"]
    L = [banner, "#pragma once", "", "#include <Eigen/Core>", "", "#include \"chaincomp/compensate.hpp\"",
         "#include \"chaincomp/model_info.hpp\"", "",
         "// Built by chaincomp (CHAINCOMP_PREBUILT_CORE), the compensation solver of this machine's",
         "// shape is compiled once, apart (solvers.cpp, or chaincomp build's cached object); without",
         "// the macro this model compiles it in.",
         "#ifdef CHAINCOMP_PREBUILT_CORE", f"extern template struct {_core_name(shape)};", "#endif", "",
         f"namespace chaincomp::models::{name} {{", "",
         f"constexpr const char* kName = \"{name}\";",
         f"constexpr std::uint64_t kSourceHash = 0x{src_hash:016x}ull;",
         f"constexpr int kNumAxes = {n};",
         f"constexpr int kNumParams = {len(params)};",
         f"constexpr int kNumErrors = {len(machine.errors)};  // the error parameters, in kParams order",
         f"constexpr int kPoseSize = {pose_size};  // tool point{_POSE_LAYOUT[pose_size]}",
         f"constexpr bool kCorrectsDirection = {'true' if corr_dir else 'false'};",
         f"constexpr int kOrder = {order};",
         f"constexpr int kNumPrecomputed = {n_pre};", "",
         "using Axes = Eigen::Matrix<double, kNumAxes, 1>;      // "
         + ", ".join(f"{a.name} [{'mm' if a.unit.kind == 'length' else 'rad'}]" for a in machine.axes),
         "using Pose = Eigen::Matrix<double, kPoseSize, 1>;",
         "using Jacobian = Eigen::Matrix<double, kPoseSize, kNumAxes>;",
         f"using Gain = Eigen::Matrix<double, kPoseSize, {max(len(machine.errors), 1)}>;"
         "  // d pose / d error, one column per error",
         "using Trig = chaincomp::AxisTrig<kNumAxes>;  // sin and cos of the angular axes", "",
         "// Every constant and error by name, in internal units (mm, rad); defaults: nominal, errors 0.",
         "struct Params {"]
    for s in params:
        default = s.to_internal(s.nominal) if s.nominal is not None else 0.0
        L.append(f"  double {s.name} = {default!r};  // {s.role}, declared in {s.unit.name}: {cpp_comment(s.meaning)}")
    L += ["};", "", "// Immutable after prepare(): the parameters and what depends on them alone.",
          "struct Model {", "  Params params;", f"  double k[{max(n_pre, 1)}] = {{}};",
          "  // Errors that vary along an axis (tables, polynomials), evaluated at the axes of each",
          "  // call; nullptr: every error is the constant in params. prepare() sets nullptr.",
          "  const VaryingErrors* varying = nullptr;", "};", "",
          "inline constexpr AxisInfo kAxes[kNumAxes] = {"]
    for a in machine.axes:
        L.append(f"    {{\"{a.name}\", \"{a.unit.name}\", UnitKind::{_kind(a.unit)}, {a.unit.to_internal!r}, "
                 f"{a.limits[0]!r}, {a.limits[1]!r}}},")
    L += ["};", "inline constexpr ParamInfo kParams[kNumParams] = {"]
    for s in params:
        role = "kConstant" if s.role == "constant" else "kError"
        nominal = s.to_internal(s.nominal) if s.nominal is not None else 0.0
        L.append(f"    {{\"{s.name}\", ParamRole::{role}, \"{s.unit.name}\", UnitKind::{_kind(s.unit)}, "
                 f"{s.unit.to_internal!r}, {nominal!r}}},")
    src_literal = cpp_string(src_file.encode("utf-8", "surrogateescape"))   # the name's bytes, as the OS has them
    L += ["};",
          f"inline constexpr MachineInfo kInfo = {{kName, kSourceHash, {src_literal}, kNumAxes, kAxes, "
          f"kNumParams, kParams, kPoseSize, kCorrectsDirection, {'true' if shape[4] else 'false'}}};", "",
          "// Parameters from / to an array in kParams order.",
          "Params params_from_array(const double* v) noexcept;",
          "void params_to_array(const Params& p, double* v) noexcept;",
          "// Fills m from p (computes the parameter-only subexpressions once).",
          "void prepare(const Params& p, Model& m) noexcept;",
          "// Sets each error parameter whose values[i] (kParams order) is not NaN and recomputes what",
          "// depends on it: the errors that vary along an axis, at each evaluation.",
          "void set_errors(Model& m, const double* values) noexcept;", ""]
    for f in functions:
        L += [f"// {f.comment}", f"{f.declaration()};"]
    L += ["", "// The sizes and functions the generic compensation needs.", "struct Kinematics {",
          "  static constexpr int kNumAxes = models::" + name + "::kNumAxes;",
          "  static constexpr int kNumParams = models::" + name + "::kNumParams;",
          "  static constexpr bool kCorrectsDirection = models::" + name + "::kCorrectsDirection;",
          "  static constexpr bool kAxisIsAngle[kNumAxes] = {"
          + ", ".join("true" if a.unit.kind == "angle" else "false" for a in machine.axes) + "};",
          "  using Model = models::" + name + "::Model;", "  using Axes = models::" + name + "::Axes;",
          "  using Pose = models::" + name + "::Pose;", "  using Jacobian = models::" + name + "::Jacobian;",
          "  using Gain = models::" + name + "::Gain;",
          "  using Trig = models::" + name + "::Trig;",
          "  static void pose_nominal(const Model& m, const Axes& q, const Trig& t, Pose& out) noexcept { "
          "models::" + name + "::pose_nominal(m, q, t, out); }",
          "  static void pose_exact(const Model& m, const Axes& q, const Trig& t, Pose& out) noexcept { "
          "models::" + name + "::pose_exact(m, q, t, out); }",
          "  static void pose_jacobian(const Model& m, const Axes& q, const Trig& t, Pose& out, Jacobian& J) noexcept { "
          "models::" + name + "::pose_jacobian(m, q, t, out, J); }",
          "  static void pose_jacobian_gain(const Model& m, const Axes& q, const Trig& t, Pose& out, Jacobian& J, "
          "Gain& G) noexcept { models::" + name + "::pose_jacobian_gain(m, q, t, out, J, G); }",
          "  static void set_errors(Model& m, const double* values) noexcept { "
          "models::" + name + "::set_errors(m, values); }",
          "};", "", "// The functions above with the axes' sin and cos computed here."]
    L += [f.trig_wrapper() for f in functions if f.trig]
    L += ["", "using Workspace = chaincomp::Workspace<Kinematics>;",
          "static_assert(std::is_trivially_destructible_v<Workspace>, \"init_workspace never destroys one\");",
          f"static_assert(std::is_same_v<chaincomp::CoreOf<Kinematics>, {_core_name(shape)}>, "
          "\"the solver declared extern above\");",
          "using Result = chaincomp::Result<Kinematics>;", "",
          "// Corrected axes such that the actual tool pose equals the nominal one at `command`; where the",
          "// axes cannot hold the whole pose, the least |point|^2 + (direction_weight * direction)^2 (mm).",
          "inline Status compensate(const Model& m, Workspace& ws, const Axes& command, Result& out,",
          "                         double direction_weight = chaincomp::kDefaultDirectionWeight) noexcept {",
          "  return chaincomp::compensate<Kinematics>(m, ws, command, out, direction_weight);", "}", "",
          "extern const ModelEntry kEntry;", "", f"}}  // namespace chaincomp::models::{name}", ""]
    return "\n".join(L)


def _source(machine, banner, n, pre, functions, order) -> str:
    name = machine.name
    params = [s for s in machine.symbols if s.role != "axis"]
    L = [banner, f"#include \"{name}.hpp\"", "", "#include <algorithm>", "#include <cmath>", "#include <limits>", "#include <new>", "",
         f"namespace chaincomp::models::{name} {{", "",
         "Params params_from_array(const double* v) noexcept {", "  Params p;"]
    L += [f"  p.{s.name} = v[{i}];" for i, s in enumerate(params)]
    L += ["  return p;", "}", "", "void params_to_array(const Params& p, double* v) noexcept {"]
    L += [f"  v[{i}] = p.{s.name};" for i, s in enumerate(params)]
    L += ["}", "", "void prepare(const Params& p, Model& m) noexcept {", "  m.params = p;", "  m.varying = nullptr;"]
    if pre:
        outputs = [(f"m.k[{i}]", e) for i, (e, _) in enumerate(pre)]
        body = _body(machine, outputs, hoisted=False)
        L += ["  " + line.replace("m.params.", "p.") for line in body]
    L += ["}", ""]
    L += _set_errors(machine, params, pre)
    for f in functions:
        L += [f"{f.declaration()} {{"]
        body = f.lines if f.lines is not None else _body(machine, f.outputs, hoisted=True, trig=f.trig)
        L += ["  " + line for line in body]
        L += ["}", ""]
    # Type-erased entry points: with varying errors attached, each evaluates them at `axes`
    # first (a model outside a rejecting range gives NaN).
    nan = "std::numeric_limits<double>::quiet_NaN()"
    L += ["namespace {", "",
          "void erased_prepare(const double* params, void* model) noexcept {",
          "  prepare(params_from_array(params), *static_cast<Model*>(model));", "}",
          "void erased_attach_varying(void* model, const VaryingErrors* varying) noexcept {",
          "  static_cast<Model*>(model)->varying = varying;", "}",
          "void erased_pose_exact(const void* model, const double* axes, double* pose) noexcept {",
          "  const Model& m = *static_cast<const Model*>(model);", "  const Eigen::Map<const Axes> q(axes);",
          "  Eigen::Map<Pose> pose_out(pose);", "  Pose out;",
          "  if (m.varying == nullptr) {", "    pose_exact(m, q, out);", "  } else {",
          "    Model scratch;", "    double slope[kMaxVaryingErrors];",
          "    const Model* at = model_at<Kinematics>(m, q, scratch, slope);",
          f"    if (at == nullptr) {{ pose_out.setConstant({nan}); return; }}",
          "    pose_exact(*at, q, out);", "  }", "  pose_out = out;", "}",
          "void erased_pose_exact_held(const void* model, const double* axes, double* pose) noexcept {",
          "  const Eigen::Map<const Axes> q(axes);", "  Model scratch;", "  double slope[kMaxVaryingErrors];",
          "  Pose out;",
          "  pose_exact(*model_at<Kinematics>(*static_cast<const Model*>(model), q, scratch, slope, true), q, out);",
          "  Eigen::Map<Pose> pose_out(pose);", "  pose_out = out;", "}",
          "void erased_pose_nominal(const void* model, const double* axes, double* pose) noexcept {",
          "  Pose out;", "  pose_nominal(*static_cast<const Model*>(model), Eigen::Map<const Axes>(axes), out);",
          "  Eigen::Map<Pose> pose_out(pose);", "  pose_out = out;", "}",
          "void erased_pose_jacobian_gain(const void* model, const double* axes, double* pose, double* jac,",
          "                               double* gain) noexcept {",
          "  const Model& m = *static_cast<const Model*>(model);", "  const Eigen::Map<const Axes> q(axes);",
          "  Pose out;", "  Jacobian J;", "  Gain G;", "  Model scratch;", "  double slope[kMaxVaryingErrors];",
          "  const Model* at = model_at<Kinematics>(m, q, scratch, slope);",
          "  if (at == nullptr) {", f"    out.setConstant({nan});", f"    J.setConstant({nan});",
          f"    G.setConstant({nan});", "  } else {", "    pose_jacobian_gain(*at, q, out, J, G);",
          "    if (m.varying != nullptr) add_slopes<Kinematics>(*m.varying, G, slope, J);", "  }",
          "  Eigen::Map<Pose> pose_out(pose);", "  pose_out = out;", "  Eigen::Map<Jacobian> jac_out(jac);",
          "  jac_out = J;",
          "  if (gain != nullptr) std::copy(G.data(), G.data() + kPoseSize * kNumErrors, gain);", "}",
          "void erased_pose_jacobian(const void* model, const double* axes, double* pose, double* jac) noexcept {",
          "  const Model& m = *static_cast<const Model*>(model);",
          "  if (m.varying != nullptr) {", "    erased_pose_jacobian_gain(model, axes, pose, jac, nullptr);",
          "    return;", "  }",
          "  Pose out;", "  Jacobian J;",
          "  pose_jacobian(m, Eigen::Map<const Axes>(axes), out, J);",
          "  Eigen::Map<Pose> pose_out(pose);", "  pose_out = out;", "  Eigen::Map<Jacobian> jac_out(jac);", "  jac_out = J;", "}",
          "void error_at(const Model& m, const Axes& q, int order, double* pose) noexcept {",
          "  Pose out;", "  switch (order) {"]
    L += [f"    case {k}: error_order{k}(m, q, out); break;" for k in range(1, order + 1)]
    L += ["    default: return;", "  }", "  Eigen::Map<Pose> pose_out(pose);", "  pose_out = out;", "}",
          "bool erased_error(const void* model, const double* axes, int order, double* pose) noexcept {",
          "  if (order < 1 || order > kOrder) return false;",
          "  const Model& m = *static_cast<const Model*>(model);", "  const Eigen::Map<const Axes> q(axes);",
          "  if (m.varying == nullptr) {", "    error_at(m, q, order, pose);", "    return true;", "  }",
          "  Model scratch;", "  double slope[kMaxVaryingErrors];",
          "  const Model* at = model_at<Kinematics>(m, q, scratch, slope);",
          "  if (at == nullptr) {", f"    Eigen::Map<Pose>(pose).setConstant({nan});", "  } else {",
          "    error_at(*at, q, order, pose);", "  }", "  return true;", "}",
          "int compensate_into(const void* model, Workspace& ws, const double* command, double weight,",
          "                    double* corrected, double* residual, double* before) noexcept {",
          "  Result r;",
          "  const Status s = compensate(*static_cast<const Model*>(model), ws, Eigen::Map<const Axes>(command), r, weight);",
          "  Eigen::Map<Axes> corrected_out(corrected);", "  corrected_out = r.corrected;",
          "  residual[0] = r.residual_point;", "  residual[1] = r.residual_direction;",
          "  if (before != nullptr) {", "    before[0] = r.before_point;", "    before[1] = r.before_direction;", "  }",
          "  return static_cast<int>(s);", "}",
          "int erased_compensate(const void* model, void* workspace, const double* command, double weight,",
          "                      double* corrected, double* residual, double* before) noexcept {",
          "  if (workspace != nullptr) {",
          "    return compensate_into(model, *static_cast<Workspace*>(workspace), command, weight, corrected, residual,",
          "                           before);",
          "  }",
          "  Workspace fresh;  // a cold start",
          "  return compensate_into(model, fresh, command, weight, corrected, residual, before);", "}",
          "void erased_init_workspace(void* workspace) noexcept { new (workspace) Workspace(); }", "",
          "}  // namespace", "",
          "const ModelEntry kEntry = {&kInfo, sizeof(Model), alignof(Model), erased_prepare, erased_pose_exact,",
          "                           erased_pose_nominal, erased_pose_jacobian, erased_error, kOrder,",
          "                           erased_compensate, sizeof(Workspace), alignof(Workspace),",
          "                           erased_init_workspace, kNumErrors, erased_attach_varying,",
          "                           erased_pose_jacobian_gain, erased_pose_exact_held};", "",
          f"}}  // namespace chaincomp::models::{name}", ""]
    return "\n".join(L)


def _set_errors(machine, params, pre) -> list[str]:
    """set_errors: per error parameter, a branch that sets it and recomputes the precomputed
    k[i] depending on it (one call per evaluation, branches that always go the same way)."""
    L = ["void set_errors(Model& m, const double* values) noexcept {"]
    rename = {s.sym: sp.Symbol(f"m.params.{s.name}") for s in params}
    for i, s in enumerate(params):
        if s.role != "error":
            continue
        L.append(f"  if (!std::isnan(values[{i}])) {{")
        L.append(f"    m.params.{s.name} = values[{i}];")
        for j, (e, _) in enumerate(pre):
            if s.sym in e.free_symbols:
                L.append(f"    m.k[{j}] = {_ERROR_PRINTER.doprint(e.xreplace(rename))};")
        L.append("  }")
    L += ["}", ""]
    return L


def registry(names: list[str]) -> str:
    """registry.cpp: every compiled model by name."""
    names = sorted(names)
    L = [f"// Generated by {GENERATOR}: the models compiled into chaincomp_models. Do not edit.", "",
         "#include <cstring>", "", "#include \"chaincomp/model_info.hpp\"", ""]
    L += [f"#include \"{n}.hpp\"" for n in names]
    L += ["", "namespace chaincomp {", "", "namespace {", "const ModelEntry* const kModels[] = {"]
    L += [f"    &models::{n}::kEntry," for n in names]
    L += ["};", "}  // namespace", "",
          "namespace {", "const UnitInfo kUnits[] = {"]
    L += [f"    {{\"{u.name}\", UnitKind::{_kind(u)}, {u.to_internal!r}}}," for u in UNITS.values()]
    L += ["};", "}  // namespace", "",
          "const UnitInfo* find_unit(const char* name) noexcept {",
          "  for (const UnitInfo& u : kUnits) {", "    if (std::strcmp(u.name, name) == 0) return &u;", "  }",
          "  return nullptr;", "}", "",
          "std::size_t model_count() noexcept { return sizeof(kModels) / sizeof(kModels[0]); }", "",
          "const ModelEntry* model_at(std::size_t i) noexcept { return i < model_count() ? kModels[i] : nullptr; }",
          "", "const ModelEntry* find_model(const char* name) noexcept {",
          "  for (const ModelEntry* e : kModels) {",
          "    if (std::strcmp(e->info->name, name) == 0) return e;", "  }", "  return nullptr;", "}", "",
          "}  // namespace chaincomp", ""]
    return "\n".join(L)


def library(machine: Machine, source: bytes, toolchain: str) -> str:
    """library.cpp of a model built at run time (chaincomp build): the one C entry point of
    the shared library, returning the model's identity and its function table (design §10).
    ``source`` is the machine file byte for byte (the loader compares it whole). It declares the
    model's entry instead of including the model's header: that header brings Eigen and the
    solver's templates, a second parse of which cost each build about a second."""
    name = machine.name
    src_hash = fnv1a64(source)   # the header's kSourceHash: build() checked source is the text generated from
    return "\n".join([
        f"// Generated by chaincomp build from {cpp_comment(os.path.basename(machine.file))} "
        f"(FNV-1a 64: {src_hash:016x}). Do not edit.",
        "#include \"chaincomp/model_library.hpp\"", "",
        f"namespace chaincomp::models::{name} {{",
        "extern const ModelEntry kEntry;  // the model's function table (NAME.cpp)",
        f"}}  // namespace chaincomp::models::{name}", "",
        "namespace {", "",
        "// The machine file this model was generated from.",
        f"const char kSourceText[] =\n    {cpp_string(source)};", "",
        "// ABI, compiler (first line of --version) and flags of this build.",
        f"const char kToolchain[] =\n    {cpp_string(toolchain.encode('utf-8'))};", "",
        f"const chaincomp::ModelLibrary kLibrary = {{chaincomp::kModelAbi, chaincomp::kModelLayout,",
        f"    {cpp_string(name.encode('utf-8'))}, 0x{src_hash:016x}ull, kSourceText,",
        f"    sizeof(kSourceText) - 1, kToolchain, &chaincomp::models::{name}::kEntry}};", "",
        "}  // namespace", "",
        "// The library's only exported symbol (it is built with -fvisibility=hidden).",
        "extern \"C\" __attribute__((visibility(\"default\"))) const chaincomp::ModelLibrary* "
        "chaincomp_model_library() noexcept {",
        "  return &kLibrary;", "}", ""])
