"""Flow expansion speed: reach's DA (reach.backends.taylor) against DACE through daceypy.

The closed-loop approach flow of SRNA01 (nonlinear orbital dynamics + LQR) is expanded to order
``n`` in the initial position deviations over the same DOP853 step nodes with both libraries; the
end maps are compared coefficient by coefficient and the wall times reported as a ratio.

daceypy is needed only here: ``pip install --target DIR daceypy`` and run with ``PYTHONPATH=DIR``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import sympy

from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.flow import (A_DOP853, B_DOP853, compile_expressions, compile_numeric,
                                        nominal, propagate)
from reach.model.loader import load_model


def plain_rk8(f, x, nodes, t_end):
    """The same DOP853 steps with per-component objects only (works for any DA type)."""
    t = nodes[0]
    for t_next in list(nodes[1:]) + [t_end]:
        t_next = min(t_next, t_end)
        h = t_next - t
        if h <= 0:
            continue
        k = []
        for i in range(len(B_DOP853)):
            xi = list(x)
            for j in range(i):
                if A_DOP853[i, j] != 0.0:
                    xi = [a + (h * A_DOP853[i, j]) * b for a, b in zip(xi, k[j])]
            k.append(f(xi))
        for j, w in enumerate(B_DOP853):
            if w != 0.0:
                x = [a + (h * w) * b for a, b in zip(x, k[j])]
        t = t_next
        if t >= t_end:
            break
    return x


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--order", type=int, default=4)
    parser.add_argument("--time", type=float, default=30.0, help="minutes of flow")
    args = parser.parse_args()
    import daceypy

    model = load_model("models/SRNA01.yaml")
    mode = model.modes["approach"]
    center = np.array([-900.0, -400.0, 0.0, 0.0, 0.0])
    half = np.array([25.0, 25.0, 0.0, 0.0, 0.0])
    run = nominal(compile_numeric(mode.flow, model.symbols), center, args.time)
    steps = len(run.nodes) - 1

    f_reach = compile_expressions(mode.flow, model.symbols)
    alg = algebra(args.order, 2)
    x0 = [DA.var(alg, 0, center[0], half[0]), DA.var(alg, 1, center[1], half[1])] + \
         [DA.const(alg, c) for c in center[2:]]
    start = time.perf_counter()
    ours = propagate(f_reach, x0, run.nodes, args.time)
    t_ours = time.perf_counter() - start
    start = time.perf_counter()
    ours_plain = plain_rk8(f_reach, x0, run.nodes, args.time)
    t_ours_plain = time.perf_counter() - start

    daceypy.DA.init(args.order, 2)
    modules = [{"sqrt": lambda a: a.sqrt() if hasattr(a, "sqrt") else np.sqrt(a)}]
    fn = sympy.lambdify([model.symbols], mode.flow, modules=modules, cse=True)

    def f_dace(x):
        return [v if isinstance(v, daceypy.DA) else daceypy.DA(float(v)) for v in fn(x)]

    y0 = [center[0] + half[0] * daceypy.DA(1), center[1] + half[1] * daceypy.DA(2)] + \
         [daceypy.DA(float(c)) for c in center[2:]]
    start = time.perf_counter()
    theirs = plain_rk8(f_dace, y0, run.nodes, args.time)
    t_dace = time.perf_counter() - start

    worst = 0.0
    for ours_i, theirs_i in zip(ours, theirs):
        for k, (a, b) in enumerate(alg.exps[:, :2]):
            c = theirs_i.getCoefficient([int(a), int(b)])
            worst = max(worst, abs(ours_i.c[k] - c) / max(1.0, abs(c)))
    print(f"SRNA01 approach flow, order {args.order}, 2 variables, {steps} DOP853 steps to t = {args.time} min")
    print(f"  reach DA, vectorised stages : {t_ours:8.3f} s")
    print(f"  reach DA, per-component RK  : {t_ours_plain:8.3f} s")
    print(f"  daceypy (DACE), same RK     : {t_dace:8.3f} s")
    print(f"  ratio daceypy / reach       : {t_dace / t_ours:8.2f}")
    print(f"  largest relative coefficient difference: {worst:.2e}")


if __name__ == "__main__":
    main()
