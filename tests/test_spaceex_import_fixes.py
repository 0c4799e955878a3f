"""SpaceEx import: the bugs a tester found (B1-B7), each with the tester's minimal model.

Every test failed on the importer before its fix: a false SAFE (B1-B3), a wrong verdict (B4,
B5), a silently ignored attribute (B6), a needless refusal (B7). Truths are worked out by hand
in each docstring; a refusal must be one line naming the file, the line and the construct.
"""

from __future__ import annotations

import numpy as np
import pytest

from reach.checking import check_spaceex
from reach.cli import main
from reach.model.spaceex import load_spaceex

HEAD = ('<?xml version="1.0" encoding="UTF-8"?>\n<sspaceex xmlns="http://www-verimag.imag.fr/xml-namespaces/'
        'sspaceex" version="0.2" math="SpaceEx">\n')
REAL = '<param name="{}" type="real" local="false" d1="1" d2="1" dynamics="any"/>'


def write(tmp_path, body: str, cfg: str, name: str = "m"):
    """``name.xml`` (line 3 is the body's first line) and ``name.cfg`` in ``tmp_path``."""
    xml, cfgp = tmp_path / f"{name}.xml", tmp_path / f"{name}.cfg"
    xml.write_text(HEAD + body + "</sspaceex>\n")
    cfgp.write_text(cfg)
    return xml, cfgp


def verdict(xml, cfg) -> str:
    return check_spaceex(xml, cfg, "star", {})[0][0].status.value


def refusal(xml, cfg, capsys) -> str:
    """The one line ``reach check`` prints for bad input (exit 2), without the ``reach: ``."""
    assert main(["check", str(xml), str(cfg), "-b", "star"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("reach: "), err
    return err[0][len("reach: "):]


# ------------------------------------------------------------------ B1: alias per location
ALIAS = f'''  <component id="sys">
    {REAL.format("x")}
    {REAL.format("y")}
    <location id="1" name="A">
      <invariant>y == x</invariant>
      <flow>x' == 0</flow>
    </location>
    <location id="2" name="B">
      <invariant>y == -x</invariant>
      <flow>x' == 0</flow>
    </location>
  </component>
'''


@pytest.mark.parametrize("forbidden, truth", [
    ("loc(sys)==A & x >= 0.5", "UNSAFE"),          # the tester's posA.cfg
    ("x >= 0.5", "UNSAFE"),                        # pos.cfg
    ("loc(sys)==A & x <= -0.5 | loc(sys)==B & x >= 0.5", "SAFE"),
])
def test_an_alias_defined_per_location_is_read_with_each_initial_locations_definition(tmp_path, forbidden, truth):
    """``initially = 1 <= y <= 2`` with no loc(): both A and B are initial. In A, y == x, so
    x is in [1, 2] there; in B, y == -x, so x is in [-2, -1]; x never moves. Before the fix the
    set was read with one location's definition (B's) in both (x in [-2, -1] in A too): a
    false SAFE for x >= 0.5 in A."""
    xml, cfg = write(tmp_path, ALIAS, f'system = "sys"\ninitially = "1 <= y & y <= 2"\ntime-horizon = 1\n'
                                      f'forbidden = "{forbidden}"\n')
    assert verdict(xml, cfg) == truth


def test_the_start_jumps_carry_each_locations_own_initial_set(tmp_path):
    xml, cfg = write(tmp_path, ALIAS, 'system = "sys"\ninitially = "1 <= y & y <= 2"\ntime-horizon = 1\n'
                                      'forbidden = "x >= 0.5"\n')
    model, _, docs = load_spaceex(xml, cfg)
    jumps = docs.model["transitions"]
    assert jumps["start_to_A"]["guard"] == ["1 <= (x)", "(x) <= 2"]
    assert jumps["start_to_B"]["guard"] == ["1 <= (-x)", "(-x) <= 2"]
    assert model.initial.low[0] <= -2 and model.initial.high[0] >= 2      # a box holding both


# ------------------------------------------------------------------ B2: repeated elements
PLANT = f'''  <component id="sys">
    {REAL.format("x")}
    {REAL.format("y")}
    <location id="1" name="a">
      <invariant>x &lt;= 1</invariant>
      <flow>x' == 1 &amp; y' == 0</flow>
    </location>
    <location id="2" name="b">
      <invariant>x &lt;= 1</invariant>
      <flow>x' == 1 &amp; y' == 0</flow>
    </location>
    <transition source="1" target="2">
      <guard>x &gt;= 1</guard>
      <assignment>x := 0</assignment>
    </transition>
  </component>
'''
START = 'system = "sys"\ninitially = "x == 0 & y == 0 & loc(sys) == a"\ntime-horizon = 1.5\n'


JOIN = "SpaceEx reads one; write its conditions in one <{}>, joined with &"


@pytest.mark.parametrize("old, repeat, message", [
    ("<assignment>x := 0</assignment>", "<assignment>y := 10</assignment>",
     "17: component 'sys': transition: a second <assignment> (the first is at line 16): " + JOIN.format("assignment")),
    ("<guard>x &gt;= 1</guard>", "<guard>y &gt;= 1</guard>",
     "16: component 'sys': transition: a second <guard> (the first is at line 15): " + JOIN.format("guard")),
    ("<invariant>x &lt;= 1</invariant>", "<invariant>x &lt;= 0.5</invariant>",
     "8: component 'sys': location 'a': a second <invariant> (the first is at line 7): " + JOIN.format("invariant")),
    ("<flow>x' == 1 &amp; y' == 0</flow>", "<flow>y' == 3</flow>",
     "9: component 'sys': location 'a': a second <flow> (the first is at line 8): " + JOIN.format("flow")),
])
def test_a_repeated_element_is_refused_at_its_line_never_dropped(tmp_path, capsys, old, repeat, message):
    """Only the first of each was read: the dropped y := 10 made 'y >= 5' SAFE (the jump at
    t = 1 sets y = 10: UNSAFE), the dropped guard y >= 1 made b reachable, the dropped
    invariant x <= 0.5 let x reach 0.7 in a, the dropped flow was blamed as missing. The repeat
    goes right after the first element of its kind (in location a, or in the transition)."""
    body = PLANT.replace(old, f"{old}\n      {repeat}", 1)
    xml, cfg = write(tmp_path, body, START + 'forbidden = "y >= 5"\n')
    assert refusal(xml, cfg, capsys) == f"{xml}:{message}"


SYNC = '''  <component id="mover">
    <param name="x" type="real" local="false" d1="1" d2="1" dynamics="any"/>
    <param name="sw" type="label" local="false"/><param name="zz" type="label" local="false"/>
    <location id="1" name="up"><flow>x' == 1</flow></location>
    <location id="2" name="down"><flow>x' == -1</flow></location>
    <transition source="1" target="2" ATTRS>
      LABELS
      <guard>x &gt;= 1</guard>
    </transition>
  </component>
  <component id="watch">
    <param name="y" type="real" local="false" d1="1" d2="1" dynamics="any"/>
    <param name="sw" type="label" local="false"/><param name="zz" type="label" local="false"/>
    <location id="1" name="w0"><flow>y' == 0</flow></location>
    <location id="2" name="w1"><flow>y' == 0</flow></location>
    <transition source="1" target="2">
      <label>sw</label>
      <assignment>y := 1</assignment>
    </transition>
  </component>
  <component id="sys">
    <param name="x" type="real" local="false" d1="1" d2="1" dynamics="any"/>
    <param name="y" type="real" local="false" d1="1" d2="1" dynamics="any"/>
    <param name="sw" type="label" local="false"/><param name="zz" type="label" local="false"/>
    <bind component="mover" as="m"><map key="x">x</map><map key="sw">sw</map></bind>
    <bind component="watch" as="w"><map key="y">y</map><map key="sw">sw</map></bind>
  </component>
'''
SYNC_CFG = 'system = "sys"\ninitially = "x == 0 & y == 0 & loc(m) == up & loc(w)==w0"\ntime-horizon = 3\n' \
           'forbidden = "x >= 1.2"\n'


def test_a_second_label_is_refused_at_its_line(tmp_path, capsys):
    xml, cfg = write(tmp_path, SYNC.replace("ATTRS", "").replace("LABELS", "<label>sw</label><label>zz</label>"),
                     SYNC_CFG)
    assert refusal(xml, cfg, capsys) == (f"{xml}:9: component 'mover': transition: a second <label> (the first "
                                         "is at line 9): SpaceEx reads one; a transition takes one label")


# ------------------------------------------------------------------ B3: instance names
TIMERS = '''  <component id="timer">
    <param name="k" type="real" local="true" d1="1" d2="1" dynamics="const"/>
    <param name="out" type="real" local="false" d1="1" d2="1" dynamics="any"/>
    <location id="1" name="run">
      <flow>out' == k</flow>
    </location>
  </component>
  <component id="N">
    <param name="o" type="real" local="false" d1="1" d2="1" dynamics="any"/>
    <bind component="timer" as="T"><map key="out">o</map></bind>
  </component>
  <component id="sys">
    <param name="o1" type="real" local="false" d1="1" d2="1" dynamics="any"/>
    <param name="o2" type="real" local="false" d1="1" d2="1" dynamics="any"/>
    BINDS
  </component>
'''


@pytest.mark.parametrize("binds, k, message", [
    ('<bind component="timer" as="T"><map key="out">o1</map></bind>\n'
     '    <bind component="timer" as="T"><map key="out">o2</map></bind>', "T.k",
     "18: component 'sys': bind 'T': duplicate instance name (as=\"T\" is also bound at line 17); each bind "
     "needs its own 'as'"),
    ('<bind component="N" as="N"><map key="o">o1</map></bind>\n'
     '    <bind component="timer" as="N.T"><map key="out">o2</map></bind>', "N.T.k",
     "18: component 'sys': bind 'N.T': an instance name ('as') cannot contain a dot (a dot separates nested "
     "instances: 'N.T' is instance T inside N)"),
])
def test_two_instances_under_one_name_are_refused_at_the_binds_line(tmp_path, capsys, binds, k, message):
    """Two timers with independent constants k in [1, 2] drift apart (o1 - o2 = (k1 - k2) t
    reaches 0.5): UNSAFE. Merged into one instance they shared one k, and the check said SAFE."""
    xml, cfg = write(tmp_path, TIMERS.replace("BINDS", binds),
                     f'system = "sys"\ninitially = "o1 == 0 & o2 == 0 & 1 <= {k} & {k} <= 2"\ntime-horizon = 1\n'
                     'forbidden = "o1 - o2 >= 0.5"\n')
    assert refusal(xml, cfg, capsys) == f"{xml}:{message}"


def test_two_distinct_timers_drift_apart(tmp_path):
    """The same model with two instance names is the UNSAFE system the tester meant."""
    binds = ('<bind component="timer" as="T1"><map key="out">o1</map></bind>\n'
             '    <bind component="timer" as="T2"><map key="out">o2</map></bind>')
    xml, cfg = write(tmp_path, TIMERS.replace("BINDS", binds),
                     'system = "sys"\ninitially = "o1 == 0 & o2 == 0 & 1 <= T1.k & T1.k <= 2 & 1 <= T2.k & '
                     'T2.k <= 2"\ntime-horizon = 1\nforbidden = "o1 - o2 >= 0.5"\n')
    assert verdict(xml, cfg) == "UNSAFE"


def test_a_system_param_named_like_an_instances_local_is_refused(tmp_path, capsys):
    """A dotted param of the system (``T.k``) would be the same variable as the local k of the
    instance T."""
    binds = ('<bind component="timer" as="T"><map key="out">o1</map></bind>\n'
             '    <bind component="timer" as="U"><map key="out">o2</map></bind>')
    body = TIMERS.replace("BINDS", binds).replace(
        '<param name="o1"', '<param name="T.k" type="real" local="false" dynamics="const"/>\n    <param name="o1"')
    xml, cfg = write(tmp_path, body, 'system = "sys"\ninitially = "o1 == 0 & o2 == 0 & 1 <= T.k & T.k <= 2 & '
                                     'U.k == 1"\ntime-horizon = 1\nforbidden = "o1 - o2 >= 0.5"\n')
    assert refusal(xml, cfg, capsys) == (f"{xml}:18: bind 'T': param 'k': the local variable 'T.k' of this instance "
                                         "has the name of a "
                                         "param of the system 'sys' (two variables under one name)")


# ------------------------------------------------------------------ B4: unprimed == in a reset
JUMP = f'''  <component id="sys">
    {REAL.format("x")}
    {REAL.format("y")}
    {REAL.format("z")}
    {REAL.format("t")}
    <location id="1" name="a">
      <invariant>t &lt;= 1</invariant>
      <flow>x' == 0 &amp; y' == 0 &amp; z' == 0 &amp; t' == 1</flow>
    </location>
    <location id="2" name="b">
      <flow>x' == 0 &amp; y' == 0 &amp; z'==0 &amp; t' == 1</flow>
    </location>
    <transition source="1" target="2">
      <guard>t &gt;= 1</guard>
      <assignment>RESET &amp; y := 7</assignment>
    </transition>
  </component>
'''
JUMP_CFG = 'system = "sys"\ninitially = "loc(sys)==a & x == 1 & y == 2 & z == 3 & t == 0"\ntime-horizon = 2\n' \
           'forbidden = "FORBIDDEN"\n'


def test_an_unprimed_equality_in_an_assignment_is_refused(tmp_path, capsys):
    """``x == 5`` relates values before the jump (x is 1 then, so the jump never fires and b is
    unreachable: SAFE); it was read as the reset x := 5, and b was reached (UNSAFE)."""
    xml, cfg = write(tmp_path, JUMP.replace("RESET", "x == 5"), JUMP_CFG.replace("FORBIDDEN", "loc(sys)==b"))
    assert refusal(xml, cfg, capsys) == (
        f"{xml}:17: component 'sys': transition a -> b: assignment: 'x == 5' constrains the state before the "
        "jump (unprimed names are the values before it): put it in the guard, or write x' == ... or x := ... "
        "for a reset")


@pytest.mark.parametrize("reset", ["x := 5", "x' == 5", "x = 5", "x'=5"])
@pytest.mark.parametrize("forbidden, truth", [("loc(sys)==b & x >= 4.9", "UNSAFE"), ("x <= 0.5", "SAFE")])
def test_resets_are_primed_or_assigned(tmp_path, reset, forbidden, truth):
    """``x := 5``, ``x' == 5`` and ``x = 5`` (the published Platoon files write ``t=0``) set x
    to 5 at the jump at t = 1."""
    xml, cfg = write(tmp_path, JUMP.replace("RESET", reset), JUMP_CFG.replace("FORBIDDEN", forbidden))
    assert verdict(xml, cfg) == truth


# ------------------------------------------------------------------ B5: input out of range
RAMP = f'''  <component id="sys">
    {REAL.format("x")}
    {REAL.format("u")}
    <location id="1" name="a">
      <invariant>-1 &lt;= u &amp;&amp; u &lt;= 1 &amp; x &lt;= 5</invariant>
      <flow>x' == 1 + 0*u</flow>
    </location>
  </component>
'''


@pytest.mark.parametrize("initially", ["x == 0 & u >= 5", "x == 0 & u >= 0.5 & u <= -0.5"])
def test_an_initial_term_on_an_input_outside_its_range_empties_the_initial_set(tmp_path, capsys, initially):
    """{x = 0, u >= 5} meets the invariant -1 <= u <= 1 nowhere: no run exists. The term was
    ignored (with a warning), and x >= 1.5 reached at t = 1.5 (UNSAFE). An empty initial set is
    bad input, as ``initially = false`` is."""
    xml, cfg = write(tmp_path, RAMP, f'system = "sys"\ninitially = "{initially}"\ntime-horizon = 2\n'
                                     'forbidden = "x >= 1.5"\n')
    line = refusal(xml, cfg, capsys)
    assert line.startswith(f"{cfg}:2: initially: the initial set is empty: 'u >= ")
    assert line.endswith("holds nowhere in the time-varying inputs' ranges (u in [-1, 1])")


def test_an_initial_term_on_an_input_inside_its_range_is_still_ignored_with_a_warning(tmp_path, capsys):
    xml, cfg = write(tmp_path, RAMP, 'system = "sys"\ninitially = "x == 0 & u >= 0.5"\ntime-horizon = 2\n'
                                     'forbidden = "x >= 1.5"\n')
    assert main(["check", str(xml), str(cfg), "-b", "star", "--counterexamples", str(tmp_path)]) == 1
    assert f"{cfg}:2: initially: 'u >= 0.5' ignored: u is a time-varying input" in capsys.readouterr().err


# ------------------------------------------------------------------ B6: transition attributes
@pytest.mark.parametrize("attrs", ['urgent="true"', 'ASAP="true"', 'priority="1"'])
def test_an_unknown_transition_attribute_is_refused_at_its_line(tmp_path, capsys, attrs):
    """``urgent="true"`` was read as absent: a may-transition, and x passed 1.2 (UNSAFE), where
    the urgent jump at x = 1 turns x back (SAFE, as with asap)."""
    xml, cfg = write(tmp_path, SYNC.replace("ATTRS", attrs).replace("LABELS", "<label>sw</label>"), SYNC_CFG)
    assert refusal(xml, cfg, capsys) == (f"{xml}:8: component 'mover': transition: construct {attrs} is not "
                                         "supported (a transition may carry source, target, asap, timedriven "
                                         "and bezier)")


@pytest.mark.parametrize("attrs", ['asap="true"', 'asap="true" timedriven="false" bezier="true"'])
def test_the_model_editors_transition_attributes_are_read(tmp_path, attrs):
    xml, cfg = write(tmp_path, SYNC.replace("ATTRS", attrs).replace("LABELS", "<label>sw</label>"), SYNC_CFG)
    assert verdict(xml, cfg) == "SAFE"


# ------------------------------------------------------------------ B7: keyword names
KEYWORD = f'''  <component id="sys">
    {REAL.format("NAME")}
    {REAL.format("y")}
    <location id="1" name="a">
      <invariant>NAME &lt;= 10</invariant>
      <flow>NAME' == 1 &amp; y' == 2*NAME</flow>
    </location>
  </component>
'''


@pytest.mark.parametrize("name", ["lambda", "in", "if", "not", "None", "True"])
@pytest.mark.parametrize("forbidden, truth", [("y >= 4.1 | NAME >= 2.5", "SAFE"), ("y >= 3.9", "UNSAFE")])
def test_variables_named_like_python_keywords_import_and_check(tmp_path, name, forbidden, truth):
    """NAME' = 1 and y' = 2 NAME from 0: y = t^2 reaches 4 and NAME 2 at the horizon 2."""
    xml, cfg = write(tmp_path, KEYWORD.replace("NAME", name),
                     f'system = "sys"\ninitially = "{name} == 0 & y == 0"\ntime-horizon = 2\n'
                     f'forbidden = "{forbidden.replace("NAME", name)}"\n')
    assert verdict(xml, cfg) == truth
    model, _, _ = load_spaceex(xml, cfg)
    assert model.state == [f"{name}_", "y"]


# ====================================================================== third round (S1-S6)
# S1: a const param that a flow or an assignment changes
CONST = f'''  <component id="sys">
    {REAL.format("x")}
    <param name="k" type="real" local="false" d1="1" d2="1" dynamics="const"/>
    <location id="1" name="A">
      <flow>FLOW_A</flow>
    </location>
    <location id="2" name="B">
      <flow>FLOW_B</flow>
    </location>
    <transition source="1" target="2">
      <guard>x &gt;= 1</guard>
      ASSIGN
    </transition>
  </component>
'''
CONST_CFG = 'system = "sys"\ninitially = "x == 0 & k == 1 & loc(sys) == A"\ntime-horizon = 3\nforbidden = "k >= 1.5"\n'
DECLARED = "component 'sys': {}: 'k' is declared dynamics=\"const\" (line 5) and cannot change: {} (SpaceEx keeps " \
           "a constant through flows and jumps)"


@pytest.mark.parametrize("flow_a, flow_b, assign, message", [
    ("x' == 1 &amp; k' == 1", "x' == 1", "", "7: " + DECLARED.format(
        "location 'A': flow", "the flow k' == 1 contradicts it, only k' == 0 agrees")),
    ("x' == 1", "x' == 1 &amp; k' == -x", "", "10: " + DECLARED.format(
        "location 'B': flow", "the flow k' == - x contradicts it, only k' == 0 agrees")),
    ("x' == 1 &amp; k' == 0", "x' == 1 &amp; k' == 0", "<assignment>k := 5</assignment>", "14: " + DECLARED.format(
        "transition A -> B: assignment", "the assignment to k contradicts it")),
    ("x' == 1", "x' == 1", "<assignment>k := 5</assignment>", "14: " + DECLARED.format(
        "transition A -> B: assignment", "the assignment to k contradicts it")),
])
def test_a_flow_or_assignment_that_changes_a_const_param_is_refused(tmp_path, capsys, flow_a, flow_b, assign,
                                                                    message):
    """SpaceEx keeps a ``dynamics="const"`` param constant (k' == 0 in flows, k' == k in jumps),
    so k stays 1 and k >= 1.5 is never reached. The flow k' == 1 was read as a clock (UNSAFE at
    t = 0.5), the reset k := 5 next to k' == 0 as a reset (UNSAFE at t = 1), and the reset
    alone was refused with a message that did not mention const."""
    body = CONST.replace("FLOW_A", flow_a).replace("FLOW_B", flow_b).replace("ASSIGN", assign)
    xml, cfg = write(tmp_path, body, CONST_CFG)
    assert refusal(xml, cfg, capsys) == f"{xml}:{message}"


def test_a_const_param_whose_flow_is_zero_stays_accepted(tmp_path):
    body = CONST.replace("FLOW_A", "x' == k &amp; k' == 0").replace("FLOW_B", "x' == 1 &amp; k' == 0")
    xml, cfg = write(tmp_path, body.replace("ASSIGN", "<assignment>x := 0</assignment>"), CONST_CFG)
    assert verdict(xml, cfg) == "SAFE"


CONST_MAP = f'''  <component id="C">
    {REAL.format("x")}
    {REAL.format("v")}
    <location id="1" name="A">
      <flow>x' == v &amp; v' == 1</flow>
    </location>
  </component>
  <component id="sys">
    {REAL.format("x")}
    <param name="g" type="real" local="false" d1="1" d2="1" dynamics="const"/>
    <bind component="C" as="c">
      <map key="x">x</map>
      <map key="v">g</map>
    </bind>
  </component>
'''


def test_a_flow_on_a_variable_mapped_onto_a_const_param_is_refused_naming_the_bind(tmp_path, capsys):
    """The child's v (flow v' == 1) is the system's const g: g grew (UNSAFE at t = 0.5)."""
    xml, cfg = write(tmp_path, CONST_MAP, 'system = "sys"\ninitially = "x == 0 & g == 1"\ntime-horizon = 3\n'
                                          'forbidden = "g >= 1.5"\n')
    assert refusal(xml, cfg, capsys) == (
        f"{xml}:7: component 'C': location 'A': flow: 'v' is mapped by bind 'c' (line 13) to 'g', declared "
        "dynamics=\"const\" (line 12), and cannot change: the flow v' == 1 contradicts it, only v' == 0 agrees "
        "(SpaceEx keeps a constant through flows and jumps)")


# ------------------------------------------------------------------ S2: strict empty initial set
STILL = f'''  <component id="sys">
    {REAL.format("x")}
    <location id="1" name="A">
      INVARIANT<flow>x' == 0</flow>
    </location>
  </component>
'''


@pytest.mark.parametrize("initially", ["x > 1 & x < 1", "x > 1 & x <= 1", "x == 1 & x > 1", "1 < x & x < 1"])
def test_an_initial_set_empty_once_its_strict_bounds_are_kept_is_refused(tmp_path, capsys, initially):
    """No point has x > 1 and x < 1: no run exists. The set was closed into x = 1, and x >= 0.5
    gave a counterexample whose initial state lies outside the written set."""
    xml, cfg = write(tmp_path, STILL.replace("INVARIANT", ""),
                     f'system = "sys"\ninitially = "{initially}"\ntime-horizon = 1\nforbidden = "x >= 0.5"\n')
    assert refusal(xml, cfg, capsys) == (f"{cfg}:2: initially: the initial set is empty (its constraints exclude "
                                         "each other once its strict bounds are kept strict: x > 1 & x <= 1 "
                                         "holds nowhere)")


@pytest.mark.parametrize("invariant, initially, forbidden, truth", [
    ("", "x > 1 & x <= 2", "x >= 2.5", "SAFE"),
    ("", "x > 1 & x < 1.5", "x >= 1.2", "UNSAFE"),
    ("<invariant>x &lt; 1</invariant>", "x == 1", "x >= 0.5", "UNSAFE"),   # the invariant is read closed
])
def test_a_strict_initial_set_with_points_is_read_as_its_closure(tmp_path, invariant, initially, forbidden, truth):
    xml, cfg = write(tmp_path, STILL.replace("INVARIANT", invariant),
                     f'system = "sys"\ninitially = "{initially}"\ntime-horizon = 1\nforbidden = "{forbidden}"\n')
    assert verdict(xml, cfg) == truth


def test_a_strict_initial_term_on_an_input_outside_its_open_range_is_refused(tmp_path, capsys):
    """u > 1 holds nowhere in u's range [-1, 1]; it was ignored as if u = 1 could hold."""
    xml, cfg = write(tmp_path, RAMP, 'system = "sys"\ninitially = "x == 0 & u > 1"\ntime-horizon = 2\n'
                                     'forbidden = "x >= 1.5"\n')
    assert refusal(xml, cfg, capsys) == (f"{cfg}:2: initially: the initial set is empty: 'u > 1' holds nowhere "
                                         "in the time-varying inputs' ranges (u in [-1, 1])")


# ------------------------------------------------------------------ S3: duplicate location names
DUPNAME = f'''  <component id="sys">
    {REAL.format("x")}
    <location id="1" name="A">
      <flow>x' == 1</flow>
    </location>
    <location id="2" name="B">
      <flow>x' == 0</flow>
    </location>
    <location id="3" name="SECOND">
      <flow>x' == -1</flow>
    </location>
    <transition source="1" target="2">
      <guard>x &gt;= 1</guard>
    </transition>
    <transition source="2" target="3">
      <guard>x &gt;= 1</guard>
    </transition>
  </component>
'''
DUPNAME_CFG = 'system = "sys"\ninitially = "x == 0 & loc(sys) == A"\ntime-horizon = 2\nforbidden = "x <= -0.5"\n'


def test_a_repeated_location_name_is_refused_at_its_line(tmp_path, capsys):
    """loc(sys) == A meant both locations named A, and the run started in the second one as
    well (UNSAFE at t = 0.5); SpaceEx's editor renames a repeat, so A is the first only (SAFE)."""
    xml, cfg = write(tmp_path, DUPNAME.replace("SECOND", "A"), DUPNAME_CFG)
    assert refusal(xml, cfg, capsys) == (
        f"{xml}:11: component 'sys': duplicate location name 'A' (location id '1' at line 5 has it too); loc() in "
        "the cfg names a location by its name: give each location its own")


def test_distinct_location_names_give_the_first_locations_run(tmp_path):
    """From A at x = 0: B at t = 1 with x = 1, A2 at once, x falls back to 0 at t = 2."""
    xml, cfg = write(tmp_path, DUPNAME.replace("SECOND", "A2"), DUPNAME_CFG)
    assert verdict(xml, cfg) == "SAFE"


# ------------------------------------------------------------------ S4: where an alias is defined
DEFINED = f'''  <component id="sys">
    {REAL.format("x")}
    {REAL.format("y")}
    <location id="1" name="A">
      <invariant>DEFINITION</invariant>
      <flow>x' == 1</flow>
    </location>
    <location id="2" name="B">
      <flow>x' == 1</flow>
    </location>
    <transition source="1" target="2">
      <guard>y &gt;= 1</guard>
    </transition>
  </component>
'''


@pytest.mark.parametrize("definition, construct", [
    ("y == x'", "a derivative x' outside the left side of a flow"),
    ("y == foo(x)", "function 'foo'"),
])
@pytest.mark.parametrize("forbidden", ["y >= 5 & loc(sys) == A", "x >= 5"])
def test_an_error_in_an_aliass_definition_is_reported_at_the_definition(tmp_path, capsys, definition, construct,
                                                                        forbidden):
    """The definition is the invariant at line 7. The message named the use: the guard's line
    14, or the cfg's forbidden line 3 paired with the XML's file name."""
    xml, cfg = write(tmp_path, DEFINED.replace("DEFINITION", definition),
                     f'system = "sys"\ninitially = "x == 0 & loc(sys) == A"\nforbidden = "{forbidden}"\n'
                     'time-horizon = 1\n')
    assert refusal(xml, cfg, capsys) == (f"{xml}:7: component 'sys': location 'A': invariant: construct not "
                                         f"supported: {construct}")


def test_an_error_in_a_cfg_relation_names_the_cfg(tmp_path, capsys):
    xml, cfg = write(tmp_path, DEFINED.replace("DEFINITION", "y == 2*x"),
                     'system = "sys"\ninitially = "x == 0 & loc(sys) == A"\nforbidden = "foo(x) >= 5"\n'
                     'time-horizon = 1\n')
    assert refusal(xml, cfg, capsys) == f"{cfg}:3: forbidden: construct not supported: function 'foo'"


@pytest.mark.parametrize("key, value, line, message", [
    ("forbidden", "x >= 1e999", 3, "forbidden: number is not finite"),
    ("initially", "x == 0 & y <= 1e999 & loc(sys) == A", 2, "initially: number is not finite"),
    ("time-horizon", "1e999", 4, "time-horizon: expected a finite number"),
    ("iter-max", "-5", 5, "iter-max: expected a whole number, -1 for no bound, got '-5'"),
    ("iter-max", "2.5", 5, "iter-max: expected a whole number, -1 for no bound, got '2.5'"),
])
def test_a_bad_number_in_the_cfg_names_the_cfgs_field(tmp_path, capsys, key, value, line, message):
    """An overflowing literal or a bad iter-max in the cfg is bad input at the cfg's line and field, as its
    user wrote them (not the converted document's ``properties[0].avoid[0]``)."""
    fields = {"system": '"sys"', "initially": '"x == 0 & loc(sys) == A"', "forbidden": '"x >= 5"',
              "time-horizon": "1"}
    fields[key] = value if key in ("time-horizon", "iter-max") else f'"{value}"'
    xml, cfg = write(tmp_path, DEFINED.replace("DEFINITION", "y == 2*x"),
                     "".join(f"{k} = {v}\n" for k, v in fields.items()))
    assert refusal(xml, cfg, capsys) == f"{cfg}:{line}: {message}"


def test_a_map_to_a_number_without_a_double_is_refused_at_the_map(tmp_path, capsys):
    """``<map key="k">1e999</map>``: bad input at the map's line, not where a flow reads k."""
    body = f'''  <component id="base">
    {REAL.format("x")}
    <param name="k" type="real" local="false" d1="1" d2="1" dynamics="const"/>
    <location id="1" name="A">
      <flow>x' == k</flow>
    </location>
  </component>
  <component id="sys">
    {REAL.format("x")}
    <bind component="base" as="b">
      <map key="x">x</map>
      <map key="k">1e999</map>
    </bind>
  </component>
'''
    xml, cfg = write(tmp_path, body, 'system = "sys"\ninitially = "x == 0"\nforbidden = "x >= 5"\ntime-horizon = 1\n')
    assert refusal(xml, cfg, capsys) == f"{xml}:14: bind 'b': map 'k': the number 1e999 is not finite"


# ------------------------------------------------------------------ S5: an alias defined in some locations
PARTLY = f'''  <component id="P">
    {REAL.format("x")}
    {REAL.format("y")}
    <location id="1" name="A">
      <invariant>y == 2*x</invariant>
      <flow>x' == 1</flow>
    </location>
    <location id="2" name="C">
      <flow>x' == 1</flow>
    </location>
    <transition source="1" target="2">
      <guard>x &gt;= 1</guard>
    </transition>
  </component>
  <component id="Q">
    {REAL.format("y")}
    {REAL.format("c")}
    <location id="1" name="q0">
      <flow>c' == 0</flow>
    </location>
    <location id="2" name="bad">
      <flow>c' == 0</flow>
    </location>
    <transition source="1" target="2">
      <guard>y &gt;= 3</guard>
    </transition>
  </component>
  <component id="sys">
    {REAL.format("x")}
    {REAL.format("y")}
    {REAL.format("c")}
    <bind component="P" as="p"><map key="x">x</map><map key="y">y</map></bind>
    <bind component="Q" as="q"><map key="y">y</map><map key="c">c</map></bind>
  </component>
'''


def test_an_alias_read_where_it_is_not_defined_is_refused_at_the_reading_text(tmp_path, capsys):
    """y == 2 x in A only; Q's guard reads y in (C, q0), where nothing defines it. The message
    pointed at the definition (line 7) and said y was not defined by an equality."""
    xml, cfg = write(tmp_path, PARTLY, 'system = "sys"\ninitially = "x == 0 & c == 0 & loc(p) == A & '
                                       'loc(q) == q0"\nforbidden = "loc(q) == bad"\ntime-horizon = 1.2\n')
    assert refusal(xml, cfg, capsys) == (
        f"{xml}:27: component 'Q': transition q0 -> bad: guard: 'y' has no flow and is defined by an equality in "
        "location 'p.A, q.q0' (line 7) but not in 'p.C, q.q0', where this guard reads it (it would be free there, "
        "any value at any instant: not supported)")


# ------------------------------------------------------------------ S6: the start jump and iter-max
TWO = f'''  <component id="sys">
    {REAL.format("x")}
    {REAL.format("y")}
    <location id="1" name="A">
      <flow>x' == 1 &amp; y' == 0</flow>
    </location>
    <location id="2" name="B">
      <flow>x' == -1 &amp; y' == 0</flow>
    </location>
    <location id="3" name="C">
      <invariant>x &gt;= 0.5</invariant>
      <flow>x' == 1 &amp; y' == 1</flow>
    </location>
    TRANSITION
  </component>
'''


JUMP_AC = '<transition source="1" target="3"><guard>x &gt;= 0.5</guard></transition>'


@pytest.mark.parametrize("jump, loc, forbidden, iters, truth", [
    ("", "", "x <= -0.5", 0, "UNSAFE"),             # in B at t = 0.5, no jump in the model
    ("", "", "x <= -1.5", 0, "SAFE"),
    ("", "& loc(sys) == B", "x <= -0.5", 0, "UNSAFE"),
    (JUMP_AC, "", "y >= 0.2", 0, "UNKNOWN"),        # needs the model's jump A -> C (y >= 0.2 at t = 0.7)
    (JUMP_AC, "", "y >= 0.2", 1, "UNSAFE"),
    (JUMP_AC, "", "y >= 0.6", 1, "SAFE"),           # y is at most 0.5 at the horizon
])
def test_the_start_jump_does_not_count_against_iter_max(tmp_path, jump, loc, forbidden, iters, truth):
    """Two initial locations (no loc(); C's invariant excludes x = 0) add a start mode and its
    urgent jumps; star counted that jump against iter-max, so iter-max = 0 left a model with no
    transition at all UNKNOWN. The cfg's bound still holds for the model's own jumps (A -> C)."""
    xml, cfg = write(tmp_path, TWO.replace("TRANSITION", jump),
                     f'system = "sys"\ninitially = "x == 0 & y == 0 {loc}"\ntime-horizon = 1\n'
                     f'forbidden = "{forbidden}"\niter-max = {iters}\n')
    assert verdict(xml, cfg) == truth
    model, _, docs = load_spaceex(xml, cfg)
    assert model.hints["iter-max"] == iters + (0 if loc else 1)
    assert ("iter-max-start" in docs.model["notes"]) == (not loc)


# ------------------------------------------------------ published forms refused before (round 3)
OSCILLATOR = f'''  <component id="sys">
    {REAL.format("x")}
    {REAL.format("v")}
    {REAL.format("u")}
    <location id="1" name="run">
      <invariant>{{bound}}</invariant>
      <flow>x' == v &amp; v' == -x + u</flow>
    </location>
  </component>
'''


@pytest.mark.parametrize("bound", ["-u &lt;= 0.5 &amp; u &lt;= 0.5", "2*u &gt;= -1 &amp; u &lt;= 0.5",
                                   "-0.5 &lt;= u &lt;= 0.5", "u/2 &gt;= -0.25 &amp; -u &gt;= -0.5"])
def test_an_input_bounded_through_a_multiple_of_itself_is_an_input(tmp_path, bound):
    """``-u <= 0.5`` (JuliaReach's platoon writes ``-aL <= 9``) bounds u by a number as
    ``-0.5 <= u`` does. x'' = -x + u from rest with |u| <= 0.5: x(t) = int_0^t sin(t - s) u(s) ds
    is at most 0.5 int_0^t |sin r| dr = 0.5 (1 - cos t) for t <= pi, so over a horizon of 3 the
    largest x is 0.5 (1 - cos 3) = 0.99500 (u = 0.5 throughout): x >= 0.99 is reached, 1.01 never."""
    body = OSCILLATOR.format(bound=bound)
    model, _, _ = load_spaceex(*write(tmp_path, body, 'system = sys\ninitially = "x == 0 & v == 0"\n'
                                      'forbidden = "x >= 1.01"\ntime-horizon = 3\n'))
    (u,) = model.bounded_inputs
    assert (u.name, u.low, u.high, u.varying) == ("u", -0.5, 0.5, True)
    assert verdict(*write(tmp_path, body, 'system = sys\ninitially = "x == 0 & v == 0"\nforbidden = "x >= 1.01"\n'
                                      'time-horizon = 3\n', "safe")) == "SAFE"
    assert verdict(*write(tmp_path, body, 'system = sys\ninitially = "x == 0 & v == 0"\nforbidden = "x >= 0.99"\n'
                                      'time-horizon = 3\n', "unsafe")) == "UNSAFE"


@pytest.mark.parametrize("initially, forbidden", [
    ("((x == 0)) & v == 0", "x >= 0.99"),
    ("(((x == 0) & (v == 0)))", "((x >= 0.99))"),
    ("x == 0 & v == 0", "((x >= 1.01)) | ((v >= 5))"),
])
def test_redundant_parentheses_around_relations_are_read(tmp_path, initially, forbidden):
    """``((x == 1))`` (ARCH-COMP HPWC's Fischer cfg writes ``((loc(aut0) == k0 & true))``) is the
    relation inside; an arithmetic group ``((x + 1))*2`` stays a term."""
    body = OSCILLATOR.format(bound="-0.5 &lt;= u &lt;= 0.5")
    truth = "SAFE" if "1.01" in forbidden else "UNSAFE"
    assert verdict(*write(tmp_path, body, f'system = sys\ninitially = "{initially}"\nforbidden = "{forbidden}"\n'
                                      'time-horizon = 3\n')) == truth
    term = body.replace("v' == -x + u", "v' == -((x + 1))*2/2 + 1 + u")
    assert verdict(*write(tmp_path, term, f'system = sys\ninitially = "{initially}"\nforbidden = "{forbidden}"\n'
                                      'time-horizon = 3\n', "term")) == truth


def test_import_refuses_what_its_own_loader_would(tmp_path, capsys):
    """``reach import`` builds the automaton before writing: a nonlinear initial set is bad input
    at the cfg's line there too, and nothing is written."""
    body = OSCILLATOR.format(bound="-0.5 &lt;= u &lt;= 0.5")
    xml, cfg = write(tmp_path, body, 'system = sys\ninitially = "x*x + v*v <= 1"\nforbidden = "x >= 2"\n'
                                     'time-horizon = 3\n')
    assert main(["import", str(xml), str(cfg), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{cfg}:2:" in err[0] and "not linear" in err[0]
    assert not (tmp_path / "out").exists()


def test_a_purely_discrete_system_and_an_unbounded_horizon_are_named(tmp_path, capsys):
    """Every location ``flow false`` with an assignment (the Dutch railway network): the message
    is the purely discrete one, not the assignment's; SpaceEx's ``time-horizon = -1`` says what
    -1 means there."""
    discrete = f'''  <component id="sys">
    {REAL.format("x")}
    <location id="1" name="a"><flow>false</flow></location>
    <location id="2" name="b"><flow>false</flow></location>
    <transition source="1" target="2"><assignment>x := x + 1</assignment></transition>
  </component>
'''
    xml, cfg = write(tmp_path, discrete, 'system = sys\ninitially = "x == 0"\nforbidden = "x >= 2"\ntime-horizon = 3\n')
    assert "purely discrete automaton is not supported" in refusal(xml, cfg, capsys)
    body = OSCILLATOR.format(bound="-0.5 &lt;= u &lt;= 0.5")
    xml, cfg = write(tmp_path, body, 'system = sys\ninitially = "x == 0 & v == 0"\nforbidden = "x >= 2"\n'
                                     'time-horizon = -1\n', "unbounded")
    line = refusal(xml, cfg, capsys)
    assert line.startswith(f"{cfg}:4: time-horizon:") and "SpaceEx's -1" in line


CIRCLE = f'''  <component id="circle">
    {REAL.format("x")}
    {REAL.format("y")}
    <param name="hop" type="label" local="false"/>
    <location id="1" name="p"><invariant>y &gt;= 0</invariant><flow>x' == -y &amp; y' == x</flow></location>
    <location id="2" name="n"><invariant>y &lt;= 0</invariant><flow>x' == -y &amp; y' == x</flow></location>
    <transition source="1" target="2"><label>hop</label><guard>y &lt;= 0</guard></transition>
    <transition source="2" target="1"><label>hop</label><guard>y &gt;= 0</guard></transition>
  </component>
'''


@pytest.mark.parametrize("forbidden, truth", [("y <= -0.75", "UNSAFE"), ("y <= -0.76", "UNKNOWN")])
def test_a_path_past_iter_max_is_left_and_the_others_followed(tmp_path, forbidden, truth):
    """(x, y) = (1, 0) in p or n, rotating: y = sin t. With iter-max 1 (two jumps with the start
    jump) the path start -> p -> n (at t = pi) reaches y = sin 4 = -0.7568 by the horizon 4: a
    violation of y <= -0.75 within the bound is UNSAFE even though the path start -> n -> p ...
    goes past the bound; y <= -0.76 is met by no path within it, and the deeper ones are not
    followed: UNKNOWN, not SAFE."""
    assert -0.76 < np.sin(4.0) < -0.75
    xml, cfg = write(tmp_path, CIRCLE, f'system = circle\ninitially = "x == 1 & y == 0"\nforbidden = "{forbidden}"\n'
                                       'time-horizon = 4\niter-max = 1\n')
    assert verdict(xml, cfg) == truth


# ------------------------------------------------------------------ S13b: the tester's round 13b
TWO_MODES = f'''  <component id="sys">
    {REAL.format("x")}
    <location id="1" name="A">
      <invariant>{{inv}}</invariant>
      <flow>x' == 1</flow>
    </location>
    <location id="2" name="B">
      <flow>x' == 0</flow>
    </location>
    <transition source="1" target="2">
      <guard>{{guard}}</guard>
    </transition>
  </component>
'''
SAFE_CFG = 'system = sys\ninitially = "x == 0 & loc(sys) == A"\nforbidden = "x >= 5"\ntime-horizon = 3\n'
DEEP = "(" * 1000 + "x <= 2" + ")" * 1000
TOO_DEEP = "construct not supported or malformed: too many nested parentheses (more than 200)"


@pytest.mark.parametrize("inv, guard, initially, forbidden, at", [
    ("x &lt;= 2", "x &gt;= 2", "x == 0 & " + DEEP, "x >= 5", "cfg:2: initially"),
    ("x &lt;= 2", "x &gt;= 2", "x == 0", DEEP, "cfg:3: forbidden"),
    ("x &lt;= 2", DEEP.replace("<=", "&gt;="), "x == 0", "x >= 5", "xml:13: component 'sys': transition A -> B: guard"),
    ("x &lt;= 2", DEEP.replace("<=", "&gt;=") + " &amp; x &lt;= 3", "x == 0", "x >= 5",
     "xml:13: component 'sys': transition A -> B: guard"),
    (DEEP.replace("<=", "&lt;="), "x &gt;= 2", "x == 0", "x >= 5", "xml:6: component 'sys': location 'A': invariant"),
])
def test_parentheses_nested_1000_deep_are_refused_at_their_line(tmp_path, capsys, inv, guard, initially,
                                                                 forbidden, at):
    """Before, the formula parser recursed into Python's limit: 'input nested too deeply', with
    no file, line or field. The depth is now checked before the parser recurses."""
    body = TWO_MODES.format(inv=inv, guard=guard)
    xml, cfg = write(tmp_path, body, f'system = sys\ninitially = "{initially}"\nforbidden = "{forbidden}"\n'
                                     'time-horizon = 3\n')
    path = {"cfg": cfg, "xml": xml}[at[:3]]
    assert refusal(xml, cfg, capsys).startswith(f"{path}{at[3:]}: {TOO_DEEP} (in '")


def test_parentheses_nested_within_the_limit_are_read(tmp_path):
    """190 levels of grouped formulas (each level three frames of the recursive parser) load."""
    guard = "(" * 190 + "x &gt;= 2" + ")" * 190
    xml, cfg = write(tmp_path, TWO_MODES.format(inv="x &lt;= 2", guard=guard), SAFE_CFG)
    model, _, docs = load_spaceex(xml, cfg)
    assert docs.model["transitions"]["A_to_B"]["guard"] == ["x >= 2"]


PAIR = f'''  <component id="T">
    {REAL.format("c")}
    <param name="tick" type="label" local="false"/>
    <location id="1" name="w"><invariant>c &lt;= 1</invariant><flow>c' == 1</flow></location>
    <transition source="1" target="1"><label>tick</label><guard>c &gt;= 1</guard><assignment>c := 0</assignment></transition>
  </component>
  <component id="Cnt">
    {REAL.format("n")}
    <param name="tick" type="label" local="false"/>
    <location id="1" name="z"><flow>n' == 0</flow></location>
    <transition source="1" target="1"><label>tick</label><assignment>n := n + 1</assignment></transition>
  </component>
  <component id="sys">
    {REAL.format("n")}
    <param name="s" type="label" local="true"/>
    <bind component="T" as="tm"><map key="tick">s</map></bind>
    <bind component="Cnt" as="ct"><map key="n">{{target}}</map><map key="tick">s</map></bind>
  </component>
'''


@pytest.mark.parametrize("target, message", [
    ("zz.q", "'zz.q': 'zz' is no instance in network 'sys' (its instances: tm, ct)"),
    ("tm.q", "'tm.q': 'q' is no param of instance 'tm' (component 'T')"),
    ("tm.tick", "'tm.tick': the bind of 'tm' maps 'tick' to 's' (line 18); map to that instead"),
    ("tm.c.d", "'tm.c.d': instance 'tm' (component 'T') is a base component's, with no instance 'c'"),
])
def test_a_dotted_map_must_name_an_instances_own_param(tmp_path, capsys, target, message):
    """A dotted name was read as a fresh variable ``zz.q`` whatever it named: the counter's n
    silently lost its link. It must be a param of an instance of the network that its bind
    leaves unmapped (the instance's own variable)."""
    xml, cfg = write(tmp_path, PAIR.format(target=target), 'system = sys\ninitially = "n == 0 & tm.c == 0"\n'
                                                          'forbidden = "n >= 3"\ntime-horizon = 2\n')
    assert refusal(xml, cfg, capsys) == f"{xml}:19: bind 'ct': map 'n': {message}"


def test_contradictory_loc_terms_in_initially_are_refused_at_the_cfg(tmp_path, capsys):
    """Before, the empty set of initial locations surfaced as 'the system has no continuous
    variable' at the XML's component: the wrong file and construct."""
    xml, cfg = write(tmp_path, TWO_MODES.format(inv="x &lt;= 2", guard="x &gt;= 2"),
                     'system = sys\ninitially = "x == 0 & loc(sys) == A & loc(sys) == B"\nforbidden = "x >= 5"\n'
                     'time-horizon = 3\n')
    assert refusal(xml, cfg, capsys) == (f"{cfg}:2: initially: the initial set is empty (no location of sys "
                                         "satisfies loc(sys) == A and loc(sys) == B)")


GO = '''  <component id="A">
    {x}
    <param name="go" type="label" local="false"/>
    <location id="1" name="a1"><invariant>x &lt;= 2</invariant><flow>x' == 1</flow></location>
    <location id="2" name="a2"><flow>x' == -1</flow></location>
    <transition source="1" target="2"><label>go</label><guard>x &gt;= 1</guard></transition>
  </component>
  <component id="B">
    {y}
    <param name="go" type="label" local="false"/>
    <location id="1" name="b1"><flow>y' == 2</flow></location>
    <location id="2" name="b2"><flow>y' == 0.5</flow></location>
    <transition source="1" target="2"><label>go</label><assignment>y := 0</assignment></transition>
  </component>
  <component id="sys">
    {x}
    {y}
    <param name="go" type="label" local="false"/>
    <bind component="A" as="pa"><map key="x">x</map>{{map_go}}</bind>
    <bind component="B" as="pb"><map key="y">y</map>{{map_go}}</bind>
  </component>
'''.format(x=REAL.format("x"), y=REAL.format("y"))
GO_CFG = ('system = sys\ninitially = "x==0 & y==0 & loc(pa)==a1 & loc(pb)==b1"\n'
          'forbidden = "loc(pa)==a2 & loc(pb)==b1"\ntime-horizon = 5\n')


def test_an_unmapped_param_named_like_a_network_param_is_warned_about(tmp_path, capsys):
    """SpaceEx's tools differ on an unmapped non-local param: HyST's flattening makes it local to
    the instance (FlattenRenameUtils.getRenamings: 'local, use prefix'), CORA's converter keeps
    its name. The import keeps the local reading, so pa and pb no longer synchronise on 'go';
    the network's own 'go' is shadowed, and the import says so at each bind."""
    xml, cfg = write(tmp_path, GO.format(map_go=""), GO_CFG)
    assert main(["import", str(xml), str(cfg), "--out", str(tmp_path / "out")]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "not mapped" in line]
    assert warnings == [f"warning: {xml}:{line}: bind '{inst}': the label 'go' of component '{comp}' is not "
                        f"mapped, so it is the instance's own '{inst}.go', not the label 'go' of network 'sys' "
                        f"(line 20); map it (<map key=\"go\">go</map>) to join them"
                        for line, inst, comp in ((21, "pa", "A"), (22, "pb", "B"))]
    xml, cfg = write(tmp_path, GO.format(map_go='<map key="go">go</map>'), GO_CFG, "mapped")
    assert "ignored" not in load_spaceex(xml, cfg)[2].model["notes"]


# a component whose constant k its bind in sys maps by {map_k} (or leaves unmapped: "")
BOUND_K = f'''  <component id="base">
    {REAL.format("x")}
    <param name="k" type="real" local="false" d1="1" d2="1" dynamics="const"/>
    <location id="1" name="A"><flow>x' == k</flow></location>
  </component>
  <component id="sys">
    {REAL.format("x")}
    <bind component="base" as="b"><map key="x">x</map>{{map_k}}</bind>
  </component>
'''
X_CFG = 'system = sys\ninitially = "x == 0"\nforbidden = "x >= 5"\ntime-horizon = 1\n'


def test_a_number_of_too_many_digits_is_refused_in_the_projects_words(tmp_path, capsys):
    """Python's 'Exceeds the limit (4300 digits) for integer string conversion' was quoted."""
    big = "9" * 5000
    xml, cfg = write(tmp_path, TWO_MODES.format(inv="x &lt;= 2", guard=f"x &gt;= {big}"), SAFE_CFG)
    assert refusal(xml, cfg, capsys).startswith(
        f"{xml}:13: component 'sys': transition A -> B: guard: construct not supported or malformed: the number "
        f"'{big[:20]}...' has too many digits (5000; at most 4000) (in '")
    xml, cfg = write(tmp_path, BOUND_K.format(map_k=f'<map key="k">{big}</map>'), X_CFG, "map")
    assert refusal(xml, cfg, capsys) == (f"{xml}:10: bind 'b': map 'k': the number '{big[:20]}...' has too many "
                                         "digits (5000; at most 4000)")


def test_a_real_mapped_to_a_label_is_refused_at_the_map(tmp_path, capsys):
    """Before, the real became the label's name and the cfg's 'x' took 'no part in the system'."""
    body = f'''  <component id="h">
    {REAL.format("x")}
    <location id="1" name="A"><flow>x' == 1</flow></location>
  </component>
  <component id="sys">
    {REAL.format("x")}
    <param name="L" type="label" local="false"/>
    <bind component="h" as="h"><map key="x">L</map></bind>
  </component>
'''
    xml, cfg = write(tmp_path, body, X_CFG)
    assert refusal(xml, cfg, capsys) == (f"{xml}:10: bind 'h': map 'x': binds the real 'x' to the label 'L' of "
                                         "component 'sys' (a real maps to a real, a label to a label)")


def test_cfg_names_that_sanitise_to_nothing_import_to_distinct_files(tmp_path, capsys):
    """'..cfg' and '....cfg' both became 'model.yaml', the second import overwriting the first."""
    xml, _ = write(tmp_path, TWO_MODES.format(inv="x &lt;= 2", guard="x &gt;= 2"), SAFE_CFG)
    written = set()
    for name in ("..cfg", "....cfg"):
        (tmp_path / name).write_text(SAFE_CFG)
        assert main(["import", str(xml), str(tmp_path / name), "--out", str(tmp_path / "out")]) == 0
        written |= {p.name for p in (tmp_path / "out" / "models").iterdir()}
    assert len(written) == 2 and all(name.startswith("model_") for name in written)


def test_a_constant_without_a_value_names_its_param(tmp_path, capsys):
    xml, cfg = write(tmp_path, BOUND_K.format(map_k=""), X_CFG)
    assert refusal(xml, cfg, capsys) == (f"{xml}:5: component 'base': param 'k': the constant 'b.k' has no value "
                                         "(map it to a number in a bind, or give it one in the cfg's initially)")



def test_a_number_past_the_doubles_is_refused_at_its_spaceex_field(tmp_path, capsys):
    """A 400-digit bound in an invariant (fewer digits than the parser's cap, more than any
    double): refused at the XML line naming the location's invariant, not the imported YAML's
    ``modes.A.invariant[0]``."""
    big = "9" * 400
    xml, cfg = write(tmp_path, TWO_MODES.format(inv=f"x &lt;= {big}", guard="x &gt;= 1"), SAFE_CFG)
    message = refusal(xml, cfg, capsys)
    assert message.startswith(f"{xml}:") and ": location 'A': invariant: expression " in message
    assert "modes." not in message


def test_an_iter_max_past_a_count_is_refused_at_its_cfg_line(tmp_path, capsys):
    xml, cfg = write(tmp_path, BOUND_K.format(map_k='<map key="k">1</map>'), X_CFG + "iter-max = 1e30\n")
    assert refusal(xml, cfg, capsys) == f"{cfg}:5: iter-max: expected at most 1e+09 (-1 for no bound), got '1e30'"


def test_other_tools_dotted_cfg_options_are_kept_unused(tmp_path):
    """JuliaReach's ARCH cfgs carry ``zono.order`` and ``zono.nTaylor``: options of its own
    algorithms, as SpaceEx's ``directions`` are; they were refused as no cfg key. x' = 1 from 0
    reaches 1 at the horizon: x >= 5 is never met."""
    xml, cfg = write(tmp_path, BOUND_K.format(map_k='<map key="k">1</map>'),
                     X_CFG + "zono.order = 10\nzono.nTaylor = 5\n")
    assert verdict(xml, cfg) == "SAFE"
