"""Controllers turned into control laws at load time.

* ``gain``: ``u = K (s - s_ref)`` over the listed states ``feedback`` (the ARCH gains are given as
  ``u = K x``).
* ``lqr``: ``u = -K (s - s_ref)`` with ``K`` the infinite-horizon LQR gain of the mode's
  linearisation, solved with python-control's ``lqr`` (section 3.4 of the rendezvous paper).
  ``Q``/``R`` are given as diagonals or full matrices, or by Bryson's rule from the largest
  desired values: ``q_ii = 1/max(x_i)^2``, ``r_ii = 1/max(u_i)^2``.
* ``network``: a SIREN network (:mod:`reach.model.network`) read from an ``.npz`` file (path
  relative to the file that names it), ``(u_1..u_m) = net(s)`` over the ``feedback`` states, its
  outputs taken as the model's inputs in order.
"""

from __future__ import annotations

import numpy as np
import sympy

from pathlib import Path

from reach.errors import Where
from reach.model.automaton import Controller
from reach.model.network import Siren


def _matrix(value, size: int, where: Where, what: str) -> np.ndarray:
    """A weight matrix from a diagonal list or a full square list of lists."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise where.error(f"{what} must be a list of numbers or a square matrix") from None
    if arr.ndim == 1:
        arr = np.diag(arr)
    if arr.shape != (size, size):
        raise where.error(f"{what} must be {size}x{size} (or a diagonal of length {size}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise where.error(f"{what} has non-finite entries")
    return arr


def linearise(flow: list[sympy.Expr], states: list[sympy.Symbol], inputs: list[sympy.Symbol],
              point: dict, where: Where):
    """Jacobians ``A = df/ds``, ``B = df/du`` at ``point`` (rows: the states ``states``)."""
    jac_s = sympy.Matrix(flow).jacobian(states).subs(point)
    jac_u = sympy.Matrix(flow).jacobian(inputs).subs(point)
    try:
        return np.array(jac_s, dtype=float), np.array(jac_u, dtype=float)
    except (TypeError, ValueError):
        raise where.error("cannot linearise the flow at the set-point (it depends on other states)") from None


def design_lqr(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray, where: Where) -> np.ndarray:
    """LQR gain ``K`` (``u = -K x``) by python-control; a clear error if it has no solution."""
    import control

    if np.any(np.linalg.eigvalsh((Q + Q.T) / 2) < -1e-12):
        raise where.error("Q must be positive semidefinite")
    if np.any(np.linalg.eigvalsh((R + R.T) / 2) <= 0):
        raise where.error("R must be positive definite")
    try:
        K, _, _ = control.lqr(A, B, Q, R)
    except Exception as exc:  # python-control raises several types for unsolvable Riccati equations
        raise where.error(f"LQR design failed: {str(exc).splitlines()[0]}") from None
    return np.asarray(K, dtype=float)


def bryson(maxima: dict, names: list[str], where: Where, parse) -> np.ndarray:
    """Bryson's rule: diagonal ``1/max_i^2`` (a missing name gets weight 0)."""
    unknown = set(maxima) - set(names)
    if unknown:
        raise where.error(f"unknown name '{sorted(unknown)[0]}' (expected one of {', '.join(names)})")
    diag = []
    for name in names:
        if name not in maxima:
            diag.append(0.0)
            continue
        value = parse(maxima[name], where.child(name))
        if value <= 0:
            raise where.error(f"Bryson maximum for '{name}' must be positive")
        diag.append(1.0 / value ** 2)
    return np.diag(diag)


def _feedback(spec: dict, state: list[str], where: Where) -> list[str]:
    """The ``feedback`` state names (all states by default), checked."""
    on = spec.get("feedback", list(state))
    if not isinstance(on, list) or not all(isinstance(s, str) for s in on):
        raise where.child("feedback").error("expected a list of state names")
    for s in on:
        if s not in state:
            raise where.child("feedback").error(f"unknown state '{s}'")
    return on


def build_network_law(spec: dict, state_symbols: list[sympy.Symbol], state: list[str],
                      inputs: list[str], where: Where):
    """Control law ``{input: siren_k(feedback states)}`` from ``{network: file.npz, feedback: [...]}``."""
    extra = set(spec) - {"network", "feedback"}
    if extra:
        raise where.error(f"unknown field '{sorted(extra)[0]}' in a network control (network, feedback)")
    on = _feedback(spec, state, where)
    file = spec["network"]
    w = where.child("network")
    if not isinstance(file, str) or not file.strip():
        raise w.error("expected the path of an .npz weights file")
    base = Path(where.file).parent if where.file else Path(".")
    net = Siren.load(base / file.strip(), w)
    if net.n_inputs != len(on):
        raise w.error(f"{Path(file).name}: the network takes {net.n_inputs} inputs but 'feedback' lists {len(on)} states")
    if net.n_outputs != len(inputs):
        raise w.error(f"{Path(file).name}: the network has {net.n_outputs} outputs but the model has "
                      f"{len(inputs)} inputs")
    outputs = net.law([state_symbols[state.index(s)] for s in on])
    return dict(zip(inputs, outputs)), Controller("network", None, list(on))


def build_law(spec: dict, flow: list[sympy.Expr], state_symbols: list[sympy.Symbol], state: list[str],
              input_symbols: list[sympy.Symbol], inputs: list[str], where: Where, parse_number):
    """Control law ``{input: expr}`` from a ``gain``/``lqr`` spec, and its :class:`Controller`."""
    on = _feedback(spec, state, where)
    s_syms = [state_symbols[state.index(s)] for s in on]
    ref = spec.get("setpoint", {})
    if not isinstance(ref, dict):
        raise where.child("setpoint").error("expected {state: value}")
    for name in ref:
        if name not in on:
            raise where.child("setpoint").error(f"'{name}' is not in 'feedback'")
    ref_vec = np.array([parse_number(ref.get(s, 0), where.child("setpoint").child(s)) for s in on])
    extra = set(spec) - {"feedback", "setpoint", "gain", "lqr"}
    if extra:
        raise where.error(f"unknown field '{sorted(extra)[0]}' in control")
    if "gain" in spec:
        K = _matrix_rect(spec["gain"], (len(inputs), len(on)), where.child("gain"))
        controller = Controller("gain", K, list(on))
    else:
        lqr = spec["lqr"]
        if not isinstance(lqr, dict):
            raise where.child("lqr").error("expected {Q: ..., R: ...} or {bryson: {state: ..., input: ...}}")
        point = {sym: 0 for sym in state_symbols}
        point.update({sym: float(v) for sym, v in zip(s_syms, ref_vec)})
        point.update({u: 0 for u in input_symbols})
        rows = [flow[state.index(s)] for s in on]
        A, B = linearise(rows, s_syms, input_symbols, point, where)
        if "bryson" in lqr:
            b = lqr["bryson"]
            if not isinstance(b, dict) or set(b) - {"state", "input"}:
                raise where.child("lqr").child("bryson").error("expected {state: {name: max}, input: {name: max}}")
            Q = bryson(b.get("state", {}), on, where.child("lqr").child("bryson").child("state"), parse_number)
            R = bryson(b.get("input", {}), inputs, where.child("lqr").child("bryson").child("input"), parse_number)
        else:
            if "Q" not in lqr or "R" not in lqr:
                raise where.child("lqr").error("needs Q and R, or bryson")
            Q = _matrix(lqr["Q"], len(on), where.child("lqr").child("Q"), "Q")
            R = _matrix(lqr["R"], len(inputs), where.child("lqr").child("R"), "R")
        K = -design_lqr(A, B, Q, R, where.child("lqr"))
        controller = Controller("lqr", K, list(on), Q, R)
    law = {}
    for i, name in enumerate(inputs):
        law[name] = sum((sympy.Float(K[i, j]) * (s_syms[j] - sympy.Float(ref_vec[j]))
                         for j in range(len(on))), sympy.Integer(0))
    return law, controller


def _matrix_rect(value, shape, where: Where) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise where.error("expected a matrix of numbers") from None
    if arr.shape != shape:
        raise where.error(f"expected a {shape[0]}x{shape[1]} matrix (inputs x 'feedback' states), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise where.error("matrix has non-finite entries")
    return arr

