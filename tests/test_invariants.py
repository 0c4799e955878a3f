"""Every invariant and guard of the shipped rendezvous models as the expected half-space.

References: the ARCH-COMP rendezvous benchmark (Chan & Mitra; SpaceEx files SRA01-SR0_.xml and
SRNA01-SR0_.xml in shared/spaceex/Rendezvous_ARCH18), whose locations are

* P2 (approach): ``x <= -100`` and ``t <= t_abort_hi`` (abort models);
* P3 (rendezvous): the octagon ``|x|, |y| <= 100``, ``|x + y|, |x - y| <= 141.1`` and
  ``t <= t_abort_hi`` (abort models);
* Passive: the abort window ``t_abort_lo <= t <= t_abort_hi`` as the guard into it,

with the abort windows of the suite's ARCH sources (SRA01 [120, 120] ... SRU02 [0, 260]).
The half-spaces are compared as sets of normalised rows ``a.x <= b`` (state ``x, y, vx, vy, t``),
so a dropped, duplicated-instead-of-kept or shifted constraint fails.
"""

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import sympy

from reach.model import load_model

WINDOWS = {"SRA01": (120, 120), "SRA02": (120, 125), "SRA03": (120, 145), "SRA04": (240, 240),
           "SRA05": (235, 240), "SRA06": (230, 240), "SRA07": (50, 150), "SRA08": (0, 240),
           "SRU01": (260, 260), "SRU02": (0, 260)}
SPACEEX = Path("/work/shared/spaceex/Rendezvous_ARCH18")


def row(x=0.0, y=0.0, t=0.0, b=0.0):
    """``x_coef x + y_coef y + t_coef t <= b`` over the state ``(x, y, vx, vy, t)``."""
    return np.array([x, y, 0.0, 0.0, t]), float(b)


APPROACH = [row(x=1, b=-100)]
OCTAGON = [row(x=1, b=100), row(x=-1, b=100), row(y=1, b=100), row(y=-1, b=100),
           row(x=1, y=1, b=141.1), row(x=-1, y=-1, b=141.1), row(x=1, y=-1, b=141.1),
           row(x=-1, y=1, b=141.1)]


def normalised(rows):
    """Rows scaled to unit max-norm, sorted: a canonical form of a set of half-spaces."""
    out = []
    for a, b in rows:
        s = np.max(np.abs(a))
        out.append(tuple(np.round(np.r_[a / s, b / s], 9)))
    return sorted(out)


def as_rows(H, g):
    return list(zip(np.asarray(H, dtype=float), np.asarray(g, dtype=float)))


def assert_same_halfspaces(actual, expected):
    assert len(actual) == len(expected)
    np.testing.assert_allclose(normalised(actual), normalised(expected), atol=1e-9)


@pytest.mark.parametrize("name", sorted(WINDOWS))
def test_abort_models_have_the_arch_invariants_and_window(name):
    lo, hi = WINDOWS[name]
    model = load_model(f"models/{name}.yaml")
    assert [str(s) for s in model.symbols] == ["x", "y", "vx", "vy", "t"]
    assert set(model.modes) == {"approach", "rendezvous", "passive"}
    deadline = row(t=1, b=hi)
    assert_same_halfspaces(as_rows(*model.modes["approach"].invariant_halfspaces), APPROACH + [deadline])
    assert_same_halfspaces(as_rows(*model.modes["rendezvous"].invariant_halfspaces), OCTAGON + [deadline])
    assert model.modes["passive"].invariant == []
    aborts = [tr for tr in model.transitions if tr.target == "passive"]
    assert sorted(tr.source for tr in aborts) == ["approach", "rendezvous"]
    for tr in aborts:
        assert not tr.urgent and tr.window == (4, lo, hi)
        assert_same_halfspaces(as_rows(*model.guard_halfspaces(tr)), [row(t=-1, b=-lo), row(t=1, b=hi)])
    dock, = [tr for tr in model.transitions if tr.target == "rendezvous"]
    assert dock.source == "approach" and dock.urgent
    assert_same_halfspaces(as_rows(*model.guard_halfspaces(dock)), OCTAGON)


def test_the_no_abort_model_has_the_arch_invariants():
    model = load_model("models/SRNA01.yaml")
    assert set(model.modes) == {"approach", "rendezvous"}
    assert_same_halfspaces(as_rows(*model.modes["approach"].invariant_halfspaces), APPROACH)
    assert_same_halfspaces(as_rows(*model.modes["rendezvous"].invariant_halfspaces), OCTAGON)


def test_si_model_has_the_same_invariants_in_seconds():
    """The SI-unit variant: metres as before, the clock in seconds (t_abort_hi = 125 min)."""
    model = load_model("models/rendezvous_si_bryson.yaml")
    deadline = row(t=1, b=125 * 60)
    assert_same_halfspaces(as_rows(*model.modes["approach"].invariant_halfspaces), APPROACH + [deadline])
    assert_same_halfspaces(as_rows(*model.modes["rendezvous"].invariant_halfspaces), OCTAGON + [deadline])


def spaceex_rows(text):
    """Half-spaces of a SpaceEx conjunction such as ``t<=120 & (x>=-100 & x+y<=141.1)``."""
    symbols = sympy.symbols("x y vx vy t")
    rows = []
    for atom in re.split(r"&", text.replace("(", "").replace(")", "")):
        lhs, op, rhs = re.match(r"\s*(.+?)\s*(<=|>=)\s*(.+?)\s*$", atom).groups()
        g = sympy.sympify(lhs) - sympy.sympify(rhs)
        g = g if op == "<=" else -g
        a = np.array([float(g.diff(s)) for s in symbols])
        rows.append((a, -float(g.subs({s: 0 for s in symbols}))))
    return rows


def spaceex_invariants(file):
    root = ET.parse(SPACEEX / file).getroot()
    return {loc.get("name"): spaceex_rows(loc.find("{*}invariant").text)
            for loc in root.iter() if loc.tag.endswith("location") and loc.find("{*}invariant") is not None}


@pytest.mark.skipif(not SPACEEX.is_dir(), reason="the ARCH SpaceEx files are not on this machine")
def test_sra01_and_srna01_match_the_arch_spaceex_locations():
    arch = spaceex_invariants("SRA01-SR0_.xml")
    model = load_model("models/SRA01.yaml")
    assert_same_halfspaces(as_rows(*model.modes["approach"].invariant_halfspaces), arch["P2"])
    assert_same_halfspaces(as_rows(*model.modes["rendezvous"].invariant_halfspaces), arch["P3"])
    # SRNA01: the same spatial constraints (its ``t <= 200`` is the ARCH horizon, here the model's)
    arch = spaceex_invariants("SRNA01-SR0_.xml")
    model = load_model("models/SRNA01.yaml")
    spatial = lambda rows: [(a, b) for a, b in rows if not (a[4] and not a[:4].any())]
    assert_same_halfspaces(as_rows(*model.modes["approach"].invariant_halfspaces), spatial(arch["P2"]))
    assert_same_halfspaces(as_rows(*model.modes["rendezvous"].invariant_halfspaces), spatial(arch["P3"]))
