"""SymForce side of tools/bench_chains: runs in .venv-bench (symforce 0.12.0), never in the
product's virtual environment, and imports nothing of chaincomp.

Reads a chain exported by tools/bench_chains (JSON: the names of the axes, constants and
errors; the elementary transforms, leftmost first, each a rotation about x, y or z by an
expression or a translation by three; the tool point and direction), models it with
SymForce's geometry and generates one C++ function with symforce.codegen:

    void NAME(q, c, e, pose*, J*, G*)   pose = [tool point; tool direction] at (q, c, e),
                                        J = d pose / d q at (q, c, e),
                                        G = d pose / d e at (q, c, e = 0)

the outputs of chaincomp's pose_jacobian_gain. Two models of the chain (--model):
  pose3   each transform an sf.Pose3 (rotations sf.Rot3.from_angle_axis: unit quaternions,
          SymForce's own representation), composed with Pose3 products;
  matrix  each transform a 4x4 sf.Matrix (rotation matrices of cos and sin), multiplied.
Prints one JSON line: seconds (model, Jacobians and codegen), SymForce's own "Total ops"
figure, the header's path and size.

Usage: python gen_symforce.py CHAIN.json OUT_DIR FUNCTION_NAME {pose3,matrix}
"""

import json
import os
import re
import sys
import time

import symforce

symforce.set_symbolic_api("symengine")  # SymForce's default and fastest back end
symforce.set_epsilon_to_number()  # no epsilon enters these functions; this silences the warning
import symforce.symbolic as sf  # noqa: E402
from symforce import codegen  # noqa: E402
from symforce.values import Values  # noqa: E402

AXIS = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}


def parse(text: str, names: dict):
    """An expression from the export (sympy's str(): names, numbers, + - * / **, the
    functions machine files allow); evaluated with SymForce's symbols and functions."""
    env = {"__builtins__": {}, "sin": sf.sin, "cos": sf.cos, "tan": sf.tan, "asin": sf.asin,
           "acos": sf.acos, "atan": sf.atan, "atan2": sf.atan2, "sqrt": sf.sqrt, "pi": sf.pi,
           "Rational": sf.Rational, "Integer": sf.Integer, "Float": sf.S}
    # integers and ratios stay exact: 1/2 -> Rational(1, 2), not 0.5
    text = re.sub(r"(?<![\w.])(\d+)/(\d+)(?![\w.])", r"Rational(\1, \2)", text)
    return eval(text, env | names)  # noqa: S307  (the export of our own machine files)


def number(text: str):
    v = float(text)
    return int(v) if v in (0.0, 1.0, -1.0) else v


def elementary(el, names, model):
    if el[0] == "R":
        angle = parse(el[2], names)
        if model == "pose3":
            return sf.Pose3(R=sf.Rot3.from_angle_axis(angle, sf.V3(*AXIS[el[1]])), t=sf.V3())
        # a constant angle comes with the sine and cosine chaincomp's derivation takes (0, 1 exact)
        s, c = (number(el[3]), number(el[4])) if len(el) > 3 else (sf.sin(angle), sf.cos(angle))
        i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[el[1]]
        m = sf.Matrix44.eye()
        m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
        return m
    t = sf.V3(*[parse(v, names) for v in el[1]])
    if model == "pose3":
        return sf.Pose3(R=sf.Rot3.identity(), t=t)
    m = sf.Matrix44.eye()
    m[0, 3], m[1, 3], m[2, 3] = t
    return m


def main() -> int:
    chain_path, out_dir, fname, model = sys.argv[1:5]
    with open(chain_path) as f:
        spec = json.load(f)
    t0 = time.perf_counter()
    nq, nc, ne = len(spec["axes"]), len(spec["constants"]), len(spec["errors"])

    def pose_jacobian_gain(q, c, e):
        names = {n: q[i] for i, n in enumerate(spec["axes"])}
        names |= {n: c[i] for i, n in enumerate(spec["constants"])}
        names |= {n: e[i] for i, n in enumerate(spec["errors"])}
        point = sf.V3(*[parse(v, names) for v in spec["tool_point"]])
        direction = sf.V3(*[parse(v, names) for v in spec["tool_direction"]])
        if model == "pose3":
            T = sf.Pose3.identity()
            for el in spec["chain"]:
                T = T * elementary(el, names, model)
            p, d = T * point, T.R * direction
        else:
            T = sf.Matrix44.eye()
            for el in spec["chain"]:
                T = T * elementary(el, names, model)
            p = (T * sf.V4(*point, 1))[:3, 0]
            d = T[:3, :3] * direction
        pose = sf.V6(*p, *d)
        J = pose.jacobian(q)
        G = pose.jacobian(e).subs({e[i]: 0 for i in range(ne)})
        return pose, J, G

    inputs = Values(q=sf.Matrix(nq, 1).symbolic("q"), c=sf.Matrix(nc, 1).symbolic("c"),
                            e=sf.Matrix(ne, 1).symbolic("e"))
    outputs = Values()
    outputs["pose"], outputs["J"], outputs["G"] = pose_jacobian_gain(inputs["q"], inputs["c"], inputs["e"])
    cg = codegen.Codegen(inputs=inputs, outputs=outputs, config=codegen.CppConfig(), name=fname,
                         return_key=None)
    result = cg.generate_function(output_dir=out_dir, skip_directory_nesting=True)
    seconds = time.perf_counter() - t0
    header = [str(p) for p in result.generated_files if str(p).endswith(".h")][0]
    with open(header) as f:
        text = f.read()
    m = re.search(r"// Total ops: (\d+)", text)
    print(json.dumps({"seconds": seconds, "symforce_ops": int(m.group(1)) if m else None,
                      "header": header, "bytes": os.path.getsize(header),
                      "symforce": symforce.__version__, "model": model}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
