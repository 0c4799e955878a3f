"""Quadratic requirements on star (reach.backends.star.polygons): the polygons hold the exact
unsafe set (hypothesis, on random ellipses) within 3e-4 of its radius, and on a slowly growing
rotation, whose radius is r0 e^{0.001 t} in closed form, star decides requirements on x^2 + y^2
both ways, its UNSAFE replayed on the exact requirement."""

from __future__ import annotations

import json

import numpy as np
import sympy
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.star.polygons import SIDES, polygon_pieces
from reach.cli import main as cli
from reach.model.constraints import Constraint

X, Y, Z = sympy.symbols("x y z")


def inside_union(pieces, P):
    return np.any([np.all(P @ H.T <= g + 1e-9, axis=1) for H, g in pieces], axis=0)


@settings(max_examples=60, deadline=None)
@given(a=st.floats(0.2, 5), b=st.floats(0.2, 5), skew=st.floats(-0.9, 0.9), cx=st.floats(-3, 3),
       cy=st.floats(-3, 3), r=st.floats(0.1, 4), outside=st.booleans())
def test_the_polygons_hold_the_exact_set_and_little_more(a, b, skew, cx, cy, r, outside):
    """g = (p - c)^T Q (p - c) - r^2 with Q = [[a, s], [s, b]] positive definite: the pieces of
    {g <= 0} (or of {-g <= 0}) hold every sampled point of the set, and no point farther than
    1e-3 of the radius from it (scaled by the ellipse's axes)."""
    s = skew * np.sqrt(a * b)
    Q = np.array([[a, s], [s, b]])
    dx, dy = X - cx, Y - cy
    g = a * dx ** 2 + 2 * s * dx * dy + b * dy ** 2 - r * r
    c = Constraint(-g if outside else g, False, "g", None)
    pieces = polygon_pieces([c], [X, Y, Z])
    assert pieces is not None and len(pieces) == (SIDES if outside else 1)
    pieces = [(H[:, :2], h) for H, h in pieces]
    rng = np.random.default_rng(0)
    L = np.linalg.cholesky(Q)
    U = rng.normal(size=(4000, 2))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    W = np.linalg.solve(L.T, U.T).T                 # (c + t W_k - c)^T Q (...) = t^2
    scale = np.linspace(1, 3, 4000) if outside else np.linspace(0, 1, 4000)
    members = np.array([cx, cy]) + (r * scale)[:, None] * W        # points of the exact unsafe set
    assert np.all(inside_union(pieces, members))
    far_in = np.array([cx, cy]) + r * 0.999 * W
    far_out = np.array([cx, cy]) + r * 1.001 * W
    if outside:        # the unsafe set is beyond the ellipse: a point well inside it is no part of it
        assert not np.any(inside_union(pieces, far_in))
    else:              # the unsafe set is the ellipse: a point well beyond it is no part of it
        assert not np.any(inside_union(pieces, far_out))


def test_a_ring_is_decided_both_ways_on_its_radius(tmp_path, capsys):
    """x' = y + 0.001 x, y' = -x + 0.001 y from x in [0.999, 1], y = 0, over 6: x^2 + y^2 =
    x0^2 e^{0.002 t}, in [0.998001, 1.012072]. star proves <= 1.013 and >= 0.997 and refutes
    <= 1.011 and >= 0.999, each counterexample replayed by reach replay."""
    model = {"name": "ring", "state": ["x", "y", "t"], "horizon": 6,
             "modes": {"go": {"flow": {"x": "y + 0.001*x", "y": "-x + 0.001*y", "t": 1}}},
             "initial": {"mode": "go", "box": {"x": [0.999, 1.0], "y": 0, "t": 0}}}
    props = {"properties": [
        {"id": "out_safe", "kind": "safety", "modes": ["go"], "require": ["x**2 + y**2 <= 1.013"]},
        {"id": "out_unsafe", "kind": "safety", "modes": ["go"], "require": ["x**2 + y**2 <= 1.011"]},
        {"id": "in_safe", "kind": "safety", "modes": ["go"], "require": ["x**2 + y**2 >= 0.997"]},
        {"id": "in_unsafe", "kind": "safety", "modes": ["go"], "require": ["x**2 + y**2 >= 0.999"]}]}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(model))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(props))
    assert cli(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "star", "--json",
                "--counterexamples", str(tmp_path / "cx")]) == 1
    rows = {r["property"]: r for r in json.loads(capsys.readouterr().out)}
    assert {k: r["status"] for k, r in rows.items()} == {"out_safe": "safe", "out_unsafe": "unsafe",
                                                         "in_safe": "safe", "in_unsafe": "unsafe"}
    assert f"polygons of {SIDES} sides" in rows["out_safe"]["details"]["semantics"]
    for name in ("out_unsafe", "in_unsafe"):
        assert cli(["replay", rows[name]["counterexample_file"]]) == 1


def test_a_small_disc_far_out_keeps_its_radius():
    """(x - 1e4)^2 + y^2 <= 1e-9: expanded in floats the constant 1e8 - 1e-9 rounds to 1e8 and
    the disc to a point. The centre and radius are computed exactly, so the polygon holds every
    point of the disc, and the pieces of its outside hold every point just beyond it."""
    r2 = sympy.Float(1e-9)
    disc = Constraint((X - 10 ** 4) ** 2 + Y ** 2 - r2, False, "disc", None)
    (H, h), = polygon_pieces([disc], [X, Y])
    theta = np.linspace(0, 2 * np.pi, 2001)
    rim = np.stack([1e4 + np.sqrt(1e-9) * np.cos(theta), np.sqrt(1e-9) * np.sin(theta)], axis=1)
    assert np.all(rim @ H.T <= h)
    beyond = polygon_pieces([Constraint(-((X - 10 ** 4) ** 2 + Y ** 2 - r2), False, "out", None)], [X, Y])
    assert np.all(inside_union(beyond, 1e4 + (rim - 1e4) * (1 + 1e-7)))


def test_a_quadratic_in_three_states_is_unsupported_and_says_where_to_go(tmp_path, capsys):
    """x^2 + y^2 + z^2 <= 1.01 has no polygon here: star says UNSUPPORTED and which
    requirements it takes."""
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(
        {"name": "still", "state": ["x", "y", "z"], "horizon": 1,
         "modes": {"go": {"flow": {"x": 0, "y": 0, "z": 0}}},
         "initial": {"mode": "go", "box": {"x": 0, "y": 0, "z": 0}}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "ball", "kind": "safety", "modes": ["go"], "require": ["x**2 + y**2 + z**2 <= 1.01"]}]}))
    assert cli(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "star"]) == 3
    assert "quadratics in two states (as polygons); this one is for taylor and montecarlo" in capsys.readouterr().out
