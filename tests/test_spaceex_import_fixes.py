"""SpaceEx import: the bugs a tester found (B1-B7), each with the tester's minimal model.

Every test failed on the importer before its fix: a false SAFE (B1-B3), a wrong verdict (B4,
B5), a silently ignored attribute (B6), a needless refusal (B7). Truths are worked out by hand
in each docstring; a refusal must be one line naming the file, the line and the construct.
"""

from __future__ import annotations

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
    assert refusal(xml, cfg, capsys) == (f"{xml}:18: the local variable 'T.k' of this instance has the name of a "
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
