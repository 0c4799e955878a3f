"""Polygons for quadratic requirements: star's unsafe pieces are polyhedra, so a quadratic
constraint is replaced by a polygon that holds its set (an over-approximation of the unsafe set:
every SAFE on the polygons is a SAFE on the exact set; a witness is replayed on the exact one).

A constraint ``g(x) <= 0`` of an unsafe piece (``< 0`` read closed) whose ``g`` is a quadratic in
two states with a definite Hessian is an ellipse condition. With ``g = (x - c)^T Q (x - c) - rho``
for ``Q`` positive definite (a sign flip makes a negative definite one so):

* inside, ``{g <= 0}`` (``x^2 + y^2 <= r^2`` as an unsafe set, a safe ring's hole): the
  circumscribed polygon of :data:`SIDES` sides, the unit circle's mapped onto the ellipse,
  ``(L u_k)^T x <= (L u_k)^T c + sqrt(rho)`` (``Q = L L^T``, ``u_k`` on the unit circle); every
  row joins the piece's conjunction;
* outside, ``{-g <= 0}`` (the unsafe set of a requirement ``x^2 + y^2 <= r^2``): the complement
  of an inscribed polygon, its vertices ``c + s sqrt(rho) L^{-T} u_k`` on the ellipse pulled in by
  ``s = 1 - 1e-9``, is the union of the half-planes
  beyond its sides, each ``n_k^T x >= n_k^T v_k``: the piece splits into one piece per side.

With :data:`SIDES` = 128 the polygons lie within ``1 / cos(pi / 128) - 1 = 3.0e-4`` of the
ellipse, relative to its ``Q``-radius ``sqrt(rho)``, however elongated it is. A piece with any other nonlinear constraint, or splitting into more
than :data:`MAX_PIECES` pieces, has no polygon (the back-end says it is unsupported). The centre
and ``rho`` are computed exactly from the constraint's coefficients (a disc of radius 1e-3 at
1e4 loses its radius to cancellation in floats), then rounded; an ellipse whose ``Q`` has a
condition number above 1e8 has none either."""

from __future__ import annotations

import numpy as np
import sympy

from reach.model.constraints import halfspaces

SIDES = 128
MAX_PIECES = 512
SHRINK = 1e-9           # the inscribed polygon's vertices, pulled in against rounding


def polygon_pieces(constraints, symbols) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """Polyhedra ``[(H, g)]`` whose union holds ``{x : every constraint}`` (module docstring),
    ``[]`` where the set is empty; None where a constraint has no polygon."""
    n = len(symbols)
    partial = [([], [])]                        # conjunctions under way: rows and bounds
    for c in constraints:
        exact = halfspaces([c], symbols)
        if exact is not None:
            H, g = (np.atleast_2d(np.asarray(exact[0], float)).reshape(-1, n),
                    np.atleast_1d(np.asarray(exact[1], float)))
            partial = [(rows + list(H), bounds + list(g)) for rows, bounds in partial]
            continue
        ellipse = _ellipse(c.g, symbols)
        if ellipse is None:
            return None
        index, centre, Q, rho, inside = ellipse
        if inside:
            if rho < 0:
                return []                       # no state meets it: the piece is empty
            rows, bounds = _outer(index, centre, Q, rho, n)
            partial = [(p + rows, b + bounds) for p, b in partial]
        else:
            if rho <= 0:
                continue                        # every state meets it
            sides = _beyond_sides(index, centre, Q, rho, n)
            partial = [(p + [row], b + [bound]) for p, b in partial for row, bound in sides]
            if len(partial) > MAX_PIECES:
                return None
    return [(np.array(rows, float).reshape(-1, n), np.array(bounds, float)) for rows, bounds in partial]


def _ellipse(g, symbols):
    """``(index, c, Q, rho, inside)`` when ``g`` is a quadratic in two states with a definite
    Hessian: ``{g <= 0}`` is ``(x - c)^T Q (x - c) <= rho`` (inside) or ``>= rho`` (not
    inside), ``Q`` positive definite, over the states ``index``; None otherwise."""
    expr = sympy.sympify(g)
    expr = sympy.expand(expr.xreplace({f: sympy.Rational(f) for f in expr.atoms(sympy.Float)}))  # exact
    free = expr.free_symbols
    names = [s for s in symbols if s in free]
    if len(names) != 2 or free - set(names):
        return None
    try:
        poly = sympy.Poly(expr, *names)
    except sympy.PolynomialError:
        return None
    if poly.total_degree() != 2:
        return None
    coeff = {m: sympy.Rational(v) for m, v in zip(poly.monoms(), poly.coeffs())}   # exact binary values
    zero = sympy.Integer(0)
    Q = sympy.Matrix([[coeff.get((2, 0), zero), coeff.get((1, 1), zero) / 2],
                      [coeff.get((1, 1), zero) / 2, coeff.get((0, 2), zero)]])
    q = sympy.Matrix([coeff.get((1, 0), zero), coeff.get((0, 1), zero)])
    c0 = coeff.get((0, 0), zero)
    det, trace = Q.det(), Q.trace()
    if det <= 0:
        return None                             # indefinite or degenerate: no ellipse
    sign = 1 if trace > 0 else -1               # negative definite: {g <= 0} is the outside
    Q, q, c0 = sign * Q, sign * q, sign * c0
    Qf = np.array(Q.tolist(), dtype=float)
    if np.linalg.cond(Qf) > 1e8:
        return None                             # too thin an ellipse for its float factor
    centre = -Q.inv() * q / 2                   # exact: a small disc far out keeps its radius
    rho = (centre.T * Q * centre)[0, 0] - c0
    centre_f, rho_f = np.array(centre.tolist(), dtype=float).reshape(2), float(rho)
    if not np.all(np.isfinite(centre_f)) or not np.isfinite(rho_f):
        return None
    return [symbols.index(s) for s in names], centre_f, Qf, rho_f, sign > 0


def _outer(index, centre, Q, rho, n):
    """Rows of the circumscribed polygon (module docstring): the unit circle's, ``u_k^T w <= 1``,
    mapped onto the ellipse ``x = c + sqrt(rho) L^{-T} w``: ``(L u_k)^T x <= (L u_k)^T c +
    sqrt(rho)``, padded outward against rounding (as close to the ellipse everywhere, however
    elongated, relative to its ``Q``-radius)."""
    theta = 2 * np.pi * np.arange(SIDES) / SIDES
    U = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    D = U @ np.linalg.cholesky(Q).T                  # rows (L u_k)^T
    h = D @ centre + np.sqrt(max(rho, 0.0))
    h = h + 1e-12 * (1.0 + np.abs(D) @ np.abs(centre) + np.abs(h))
    rows = np.zeros((SIDES, n))
    rows[:, index] = D
    return list(rows), list(h)


def _beyond_sides(index, centre, Q, rho, n):
    """``(row, bound)`` per side of the inscribed polygon: ``-n_k^T x <= -n_k^T v_k``, the
    half-plane beyond side ``k`` (module docstring)."""
    theta = 2 * np.pi * np.arange(SIDES) / SIDES
    U = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    L = np.linalg.cholesky(Q)
    V = centre + (1 - SHRINK) * np.sqrt(rho) * np.linalg.solve(L.T, U.T).T
    out = []
    for k in range(SIDES):
        a, b = V[k], V[(k + 1) % SIDES]
        normal = np.array([b[1] - a[1], a[0] - b[0]])
        if normal @ (a - centre) < 0:
            normal = -normal
        row = np.zeros(n)
        row[index] = -normal
        out.append((row, float(-normal @ a)))
    return out
