"""Flow expansion (section 2.1, eqs. 1-4): a mode's closed-loop vector field compiled once from
its sympy expressions into a function that runs on floats, numpy arrays and DA numbers alike,
and an 8th-order Runge-Kutta on DA states.

Integrator: explicit Runge-Kutta with the 8th-order Dormand-Prince tableau (the DOP853
coefficients, as shipped with scipy), with the step sequence chosen on the constant part: the
nominal run is integrated by an adaptive DOP853 at the requested tolerance (:mod:`.nominal`) and
the DA run steps through the same accepted nodes, each step cut in two. Every DA coefficient is
propagated by the same RK formula, so the nominal accuracy is the step-size control (as in the
paper's DA integrators).
"""

from __future__ import annotations

import numpy as np
import sympy

from reach.backends.taylor.da import DA

_UNARY = {
    sympy.sin: ("sin", np.sin), sympy.cos: ("cos", np.cos), sympy.exp: ("exp", np.exp),
    sympy.log: ("log", np.log),
}


class Unsmooth(ValueError):
    """The expression has a non-smooth or unsupported part (abs, min, piecewise...)."""


def compile_expressions(exprs: list[sympy.Expr], symbols: list[sympy.Symbol]):
    """``f(values) -> list`` evaluating ``exprs`` at ``values``: floats, arrays, DAs, Taylor models
    or interval jets (anything with the arithmetic operators, ``sin``/``cos``/``exp``/``log``/``sqrt``
    methods and ``const_like``).

    Common subexpressions are shared (``sympy.cse``); the tree is walked once here and turned
    into nested closures, so no text is evaluated.
    """
    replacements, reduced = sympy.cse([sympy.sympify(e) for e in exprs])
    index = {s: i for i, s in enumerate(symbols)}
    temps = {}
    for j, (sym, _) in enumerate(replacements):
        temps[sym] = len(symbols) + j
    steps = [_build(e, index, temps) for _, e in replacements]
    outputs = [_build(e, index, temps) for e in reduced]

    def f(values):
        env = list(values)
        for step in steps:
            env.append(step(env))
        outs = [out(env) for out in outputs]
        series = next((v for v in env if hasattr(v, "const_like")), None)
        if series is not None:      # constant rates (a clock's 1) become constant series
            outs = [o if hasattr(o, "const_like") else series.const_like(o) for o in outs]
        return outs

    return f


def compile_numeric(exprs: list[sympy.Expr], symbols: list[sympy.Symbol]):
    """The same function for floats and numpy arrays only (numpy code from ``sympy.lambdify``)."""
    fn = sympy.lambdify([symbols], [sympy.sympify(e) for e in exprs], modules="numpy", cse=True)
    return lambda values: [np.asarray(v, dtype=float) + 0.0 * values[0] for v in fn(list(values))]


def _build(e, index, temps):
    if e in temps:
        k = temps[e]
        return lambda env: env[k]
    if e in index:
        k = index[e]
        return lambda env: env[k]
    if e.is_Number or (e.is_number and not e.free_symbols):
        v = float(e)
        return lambda env: v
    if e.is_Add:
        return _build_sum(e, index, temps)
    if e.is_Mul:
        parts = [_build(a, index, temps) for a in e.args]
        return lambda env: _product(p(env) for p in parts)
    if e.is_Pow:
        base = _build(e.base, index, temps)
        if not e.exp.is_number:
            exponent = _build(e.exp, index, temps)
            return lambda env: _exp(_log(base(env)) * exponent(env))
        p = float(e.exp)
        if p.is_integer() and p >= 0:
            p = int(p)
        if p == 0.5:
            return lambda env: _sqrt(base(env))
        return lambda env: base(env) ** p
    if hasattr(e.func, "_imp_"):     # a function implemented in Python, e.g. a network output
        impl, args = e.func._imp_, [_build(a, index, temps) for a in e.args]
        return lambda env: impl(*[a(env) for a in args])
    if e.func in _UNARY:
        name, fn = _UNARY[e.func]
        arg = _build(e.args[0], index, temps)
        return lambda env: (getattr(a, name)() if hasattr(a := arg(env), name) else fn(a))
    raise Unsmooth(f"cannot expand '{e.func.__name__}' in a Taylor series ({e})")


def _build_sum(e, index, temps):
    """A sum; its terms ``number * variable`` are gathered into one weighted sum of arrays."""
    slots, weights, rest = [], [], []
    for a in e.args:
        coeff, factor = a.as_coeff_Mul()
        if coeff.is_Number and (factor in index or factor in temps):
            slots.append(index[factor] if factor in index else temps[factor])
            weights.append(float(coeff))
        else:
            rest.append(_build(a, index, temps))
    w = np.array(weights)

    def linear(env):
        items = [env[k] for k in slots]
        series = next((v for v in items if hasattr(v, "weighted_sum")), None)
        if series is not None:
            return type(series).weighted_sum(w, items)
        return _sum(float(wk) * v for wk, v in zip(w, items))

    if not slots:
        return lambda env: _sum(p(env) for p in rest)
    if not rest:
        return linear
    return lambda env: _sum([linear(env)] + [p(env) for p in rest])


def _sum(items):
    items = iter(items)
    out = next(items)
    for x in items:
        out = out + x
    return out


def _product(items):
    items = iter(items)
    out = next(items)
    for x in items:
        out = x * out if isinstance(x, DA) else out * x
    return out


def _sqrt(a):
    return a.sqrt() if hasattr(a, "sqrt") else np.sqrt(a)


def _log(a):
    return a.log() if hasattr(a, "log") else np.log(a)


def _exp(a):
    return a.exp() if hasattr(a, "exp") else np.exp(a)


def _tableau():
    """Butcher tableau of the 12-stage, 8th-order Dormand-Prince solution (DOP853)."""
    from scipy.integrate._ivp import dop853_coefficients as dop
    s = dop.N_STAGES
    return dop.A[:s, :s], dop.B


A_DOP853, B_DOP853 = _tableau()


def rk8(f, x: list, h, steps: int) -> list:
    """``steps`` explicit DOP853 steps (8th order) of size ``h`` of the autonomous ``x' = f(x)``.

    The state is held as one array (``(n, M)`` coefficients for DA states), so each stage is
    one weighted sum of the previous stages' rates. DA states of shape ``(B,)`` are ``B``
    independent runs (``(n, B, M)`` coefficients) and ``h`` may then be an array of ``B`` step
    sizes, one per run; a zero step leaves its run exactly as it is.
    """
    alg = next((v.alg for v in x if isinstance(v, DA)), None)
    h = np.asarray(h, dtype=float)
    if alg is not None and h.ndim == 1:
        h = h[:, None]

    def pack(values):
        if alg is None:
            return np.stack(np.broadcast_arrays(*[np.asarray(v, dtype=float) for v in values]))
        return np.stack(np.broadcast_arrays(*[v.c if isinstance(v, DA) else DA.const(alg, v).c for v in values]))

    def store(out, values):
        """``out[j] = values[j]`` (a constant rate broadcast over the runs, or its DA)."""
        for row, v in zip(out, values):
            if isinstance(v, DA) or alg is None:
                row[...] = v.c if isinstance(v, DA) else v
            else:
                row[...] = 0.0
                row[..., 0] = v

    def unpack(X):
        return list(X) if alg is None else [DA(alg, row) for row in X]

    X = pack(x)
    K = np.empty((len(B_DOP853),) + X.shape)
    for _ in range(steps):
        for i in range(len(B_DOP853)):
            Xi = X if i == 0 else X + h * _combine(A_DOP853[i, :i], K[:i])
            store(K[i], f(unpack(Xi)))
        X = X + h * _combine(B_DOP853, K)
    return unpack(X)


def _combine(weights: np.ndarray, K: np.ndarray) -> np.ndarray:
    """``sum_i w_i K[i]`` (one matrix-vector product)."""
    return (weights @ K.reshape(len(K), -1)).reshape(K.shape[1:])


def step_sizes(nodes: np.ndarray, t_end: float) -> list[float]:
    """The RK8 steps from ``nodes[0]`` to ``t_end``: along the nodes, then a last partial step."""
    t, out = nodes[0], []
    for t_next in nodes[1:]:
        if t_next > t_end:
            break
        out.append(t_next - t)
        t = t_next
    if t_end > t:
        out.append(t_end - t)
    return out


def propagate(f, x: list, nodes: np.ndarray, t_end: float) -> list:
    """DA (or float) state from ``nodes[0]`` to ``t_end`` (:func:`step_sizes`)."""
    for h in step_sizes(nodes, t_end):
        x = rk8(f, x, h, 1)
    return x


def flow_map(f, alg, center: np.ndarray, half_width: np.ndarray, uncertain: list[int],
             nodes: np.ndarray, T: float) -> list[DA]:
    """Taylor expansion of the flow ``x(T)`` in the scaled deviations (eqs. 3-4).

    ``x0_i = center_i + half_width_i xi_j`` for the ``j``-th uncertain state ``i``, so each
    ``xi_j`` ranges over ``[-1, 1]`` on the box.
    """
    x = [DA.var(alg, uncertain.index(i), c, half_width[i]) if i in uncertain else DA.const(alg, c)
         for i, c in enumerate(center)]
    return propagate(f, x, nodes, T)
