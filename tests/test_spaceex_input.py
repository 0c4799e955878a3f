"""SpaceEx import: names the model lacks, networks too large to compose, the wording of its
errors, and locations where no time passes.

Every bad input ends in exit code 2 with one line ``file:line: field: message``; a network
whose product of locations is too large is refused while the product is built, not after.
"""

from __future__ import annotations

import keyword
from pathlib import Path

import numpy as np
import pytest
import sympy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_input import bad_input
from reach.cli import main
from reach.errors import InputError
from reach.model import load_model
from reach.model.expr import CONSTANTS, FUNCTIONS
from reach.model.spaceex import load_spaceex, write_yaml
from reach.model.spaceex.compose import MAX_LOCATIONS

HEADER = '<?xml version="1.0"?>\n<sspaceex xmlns="http://www-verimag.imag.fr/xml-namespaces/sspaceex" version="0.2">\n'

THERMOSTAT = '''<component id="heater">
 <param name="T" type="real" local="false" dynamics="any"/>
 <param name="c" type="real" local="false" dynamics="any"/>
 <location id="1" name="on"><invariant>T &lt;= 22</invariant><flow>T' == -0.1*(T - 10) + 3 &amp; c' == 1</flow></location>
 <location id="2" name="off"><invariant>T &gt;= 18</invariant><flow>T' == -0.1*(T - 10) &amp; c' == 1</flow></location>
 <transition source="1" target="2"><guard>T &gt;= 21</guard><assignment>c := 0</assignment></transition>
 <transition source="2" target="1"><guard>T &lt;= 19</guard></transition>
</component>
'''
CFG = 'system = heater\ninitially = "loc(heater) == on & T == 20 & c == 0"\nforbidden = "T >= 22.01"\ntime-horizon = 30\n'


def write(folder: Path, body: str, cfg: str, name: str = "m") -> tuple[Path, Path]:
    (folder / f"{name}.xml").write_text(HEADER + body + "</sspaceex>\n")
    (folder / f"{name}.cfg").write_text(cfg)
    return folder / f"{name}.xml", folder / f"{name}.cfg"


def check(xml, cfg) -> list[str]:
    return ["check", str(xml), str(cfg), "-b", "montecarlo", "-o", "samples=20", "-o", "search_rounds=0"]


# ------------------------------------------------------------------ names the model lacks
@pytest.mark.parametrize("key,line,formula", [
    ("forbidden", 3, "xx >= 22.01"),
    ("forbidden", 3, "T >= 22 & xx <= 1"),
    ("forbidden", 3, "T >= 23 | xx >= 22.01"),
    ("initially", 2, "loc(heater) == on & T == 20 & c == 0 & xx == 3"),
    ("initially", 2, "loc(heater) == on & T == 20 & xx == 3 & c == 0"),
])
def test_an_unknown_name_in_the_cfg_is_bad_input_naming_it_and_the_known_ones(tmp_path, capsys, key, line,
                                                                               formula):
    cfg = CFG.replace('"loc(heater) == on & T == 20 & c == 0"' if key == "initially" else '"T >= 22.01"',
                      f'"{formula}"')
    xml, cfg_path = write(tmp_path, THERMOSTAT, cfg)
    err = bad_input(check(xml, cfg_path), capsys)
    assert err == (f"reach: {cfg_path}:{line}: {key}: unknown name 'xx' (the system's variables: T, c)")
    err = bad_input(["import", str(xml), str(cfg_path), "--out", str(tmp_path / "out")], capsys)
    assert "unknown name 'xx'" in err and not (tmp_path / "out").exists()


def test_a_forbidden_set_over_an_unknown_name_is_not_an_unsafe_verdict(tmp_path, capsys):
    """``xx >= 22.01`` with no ``xx`` once became 'everything forbidden' and UNSAFE at t = 0."""
    xml, cfg = write(tmp_path, THERMOSTAT, CFG.replace("T >= 22.01", "xx >= 22.01"))
    with pytest.raises(InputError, match="unknown name 'xx'"):
        load_spaceex(xml, cfg)
    bad_input(check(xml, cfg), capsys)


def test_an_unknown_component_in_initially_is_bad_input(tmp_path, capsys):
    xml, cfg = write(tmp_path, THERMOSTAT, CFG.replace("c == 0", "c == 0 & loc(cooler) == on"))
    err = bad_input(check(xml, cfg), capsys)
    assert err == f"reach: {cfg}:2: initially: loc(cooler): no component instance 'cooler' (the system's: heater)"


def test_a_variable_declared_but_used_nowhere_is_named_as_such(tmp_path, capsys):
    body = THERMOSTAT.replace('<param name="c"', '<param name="idle" type="real" local="false" dynamics="any"/>\n'
                              ' <param name="c"')
    xml, cfg = write(tmp_path, body, CFG.replace("T >= 22.01", "idle >= 1"))
    err = bad_input(check(xml, cfg), capsys)
    assert err == (f"reach: {cfg}:3: forbidden: 'idle' takes no part in the system (no flow, bound or "
                   "definition), so a constraint on it says nothing about the runs")


def test_a_dotted_suffix_naming_two_variables_is_ambiguous(tmp_path, capsys):
    body = THERMOSTAT + '''<component id="sys">
 <bind component="heater" as="a"/>
 <bind component="heater" as="b"/>
</component>
'''
    cfg = ('system = sys\ninitially = "loc(a) == on & loc(b) == on & a.T == 20 & b.T == 20 & a.c == 0 & '
           'b.c == 0"\nforbidden = "T >= 22.01"\ntime-horizon = 30\n')
    xml, cfg_path = write(tmp_path, body, cfg)
    err = bad_input(check(xml, cfg_path), capsys)
    assert err == f"reach: {cfg_path}:3: forbidden: 'T' is ambiguous (a.T, b.T): write the instance's name"


RESERVED = set(FUNCTIONS) | set(CONSTANTS) | {"true", "false", "loc"}
IDENTIFIERS = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,7}(\.[A-Za-z_][A-Za-z0-9_]{0,5})?", fullmatch=True).filter(
    lambda s: s not in RESERVED and s.split(".")[-1] not in ("T", "c") and not keyword.iskeyword(s))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=IDENTIFIERS, key=st.sampled_from(["initially", "forbidden"]),
       shape=st.sampled_from(["{} >= 1", "T + 2*{} <= 3", "-1 <= {} <= 1", "{} == 0", "{}^2 >= T"]),
       where=st.integers(0, 2))
def test_any_name_the_system_lacks_is_bad_input_naming_it(tmp_path_factory, capsys, name, key, shape, where):
    """An identifier the model does not declare, anywhere in ``initially`` or ``forbidden``,
    is bad input naming the cfg's line, the field and the identifier."""
    tmp = tmp_path_factory.mktemp("names")
    atom = shape.format(name)
    base = ["loc(heater) == on", "T == 20", "c == 0"] if key == "initially" else ["T >= 22.01"]
    base.insert(min(where, len(base)), atom)
    text = " & ".join(base)
    cfg = CFG.replace('"loc(heater) == on & T == 20 & c == 0"' if key == "initially" else '"T >= 22.01"',
                      f'"{text}"')
    xml, cfg_path = write(tmp, THERMOSTAT, cfg)
    line = 2 if key == "initially" else 3
    err = bad_input(check(xml, cfg_path), capsys)
    assert err.startswith(f"reach: {cfg_path}:{line}: {key}: unknown name '{name}'"), err


@pytest.mark.parametrize("old,new,line,field", [
    ("T' == -0.1*(T - 10) + 3", "T' == -0.1*(T - 10) + 3 + q", 6, "location 'on': flow"),
    ("T &lt;= 22", "q &lt;= 22", 6, "location 'on': invariant"),
    ("T &gt;= 21", "q &gt;= 21", 8, "transition on -> off: guard"),
    ("c := 0", "q := 0", 8, "transition on -> off: assignment"),
    ("c := 0", "c := q", 8, "transition on -> off: assignment"),
    ("&amp; c' == 1</flow></location>\n <location id=\"2\"", "&amp; q' == 1</flow></location>\n <location id=\"2\"",
     6, "location 'on': flow"),
])
def test_an_unknown_name_in_the_xml_names_file_line_and_field(tmp_path, capsys, old, new, line, field):
    assert old in THERMOSTAT
    xml, cfg = write(tmp_path, THERMOSTAT.replace(old, new, 1), CFG)
    err = bad_input(check(xml, cfg), capsys)
    assert err == (f"reach: {xml}:{line}: component 'heater': {field}: unknown name 'q' "
                   "(the component's params: T, c)")


@pytest.mark.parametrize("declared", ['', '\n <param name="go" type="real" local="false" dynamics="any"/>'])
def test_a_transition_label_that_is_not_a_declared_label_is_bad_input(tmp_path, capsys, declared):
    """An undeclared label (or a real param's name) is in no component's alphabet: the
    transition would move alone, never synchronised, a slip the model's author should hear of."""
    body = THERMOSTAT.replace('<transition source="2" target="1">',
                              '<transition source="2" target="1"><label>go</label>', 1)
    body = body.replace('dynamics="any"/>\n <location', f'dynamics="any"/>{declared}\n <location', 1)
    xml, cfg = write(tmp_path, body, CFG)
    err = bad_input(check(xml, cfg), capsys)
    line = 9 + declared.count("\n")
    assert err.startswith(f"reach: {xml}:{line}: component 'heater': transition label 'go' is not declared"), err


def test_an_input_bounded_differently_per_location_takes_each_location_s_interval(tmp_path, capsys):
    """``w`` in [0, 1] in 'on' and in [-1, 0] in 'off' (HyST's hybridisation writes such
    intervals): one input ``w_share`` in [0, 1], and ``w`` in each location its own interval;
    the imported YAML is the same automaton."""
    body = THERMOSTAT.replace('<param name="c" type="real" local="false" dynamics="any"/>',
                              '<param name="c" type="real" local="false" dynamics="any"/>\n'
                              ' <param name="w" type="real" local="false" dynamics="any"/>', 1)
    body = body.replace("<invariant>T &lt;= 22</invariant>", "<invariant>T &lt;= 22 &amp; 0 &lt;= w &lt;= 1</invariant>")
    body = body.replace("<invariant>T &gt;= 18</invariant>", "<invariant>T &gt;= 18 &amp; -1 &lt;= w &lt;= 0</invariant>")
    body = body.replace("T' == -0.1*(T - 10) + 3", "T' == -0.1*(T - 10) + 3 + w")
    body = body.replace("T' == -0.1*(T - 10) &amp;", "T' == -0.1*(T - 10) + 2*w &amp;")
    xml, cfg = write(tmp_path, body, CFG)
    model, _, docs = load_spaceex(xml, cfg)
    (u,) = model.bounded_inputs
    assert (u.name, u.low, u.high, u.varying) == ("w_share", 0.0, 1.0, True)

    def rate(mode, share):
        m = model.modes[mode]
        values = {str(s): 0.0 for s in m.symbols}
        values.update(T=10.0, w_share=share)
        return float(m.flow[[str(s) for s in m.symbols].index("T")].subs({s: values[str(s)] for s in m.symbols}))

    assert [rate("on", v) for v in (0.0, 0.5, 1.0)] == [3.0, 3.5, 4.0]        # w in [0, 1]
    assert [rate("off", v) for v in (0.0, 0.5, 1.0)] == [-2.0, -1.0, 0.0]     # 2 w, w in [-1, 0]
    model_file, prop_file = write_yaml(docs, tmp_path / "out")
    again = load_model(model_file)
    assert [sympy.simplify(a - b) for m in model.modes for a, b in zip(model.modes[m].flow, again.modes[m].flow)] == \
        [0] * sum(len(model.modes[m].flow) for m in model.modes)


def test_an_input_also_read_by_another_invariant_names_that_invariant(tmp_path, capsys):
    """``0 <= w <= 1 & w <= T - 18``: ``w`` is bounded by numbers, but also read by a row that
    mixes in a state, which an input may not be: the message names that row, not "neither
    bounded by numbers"."""
    body = THERMOSTAT.replace('<param name="c" type="real" local="false" dynamics="any"/>',
                              '<param name="c" type="real" local="false" dynamics="any"/>\n'
                              ' <param name="w" type="real" local="false" dynamics="any"/>', 1)
    body = body.replace("<invariant>T &lt;= 22</invariant>",
                        "<invariant>T &lt;= 22 &amp; 0 &lt;= w &lt;= 1 &amp; w &lt;= T - 18</invariant>")
    body = body.replace("<invariant>T &gt;= 18</invariant>", "<invariant>T &gt;= 18 &amp; 0 &lt;= w &lt;= 1</invariant>")
    body = body.replace("T' == -0.1*(T - 10) + 3", "T' == -0.1*(T - 10) + 3 + w")
    xml, cfg = write(tmp_path, body, CFG)
    err = bad_input(check(xml, cfg), capsys)
    assert err == (f"reach: {xml}:7: the input 'w' (no flow, bounded by numbers) also appears in the invariant "
                   "'w <= T-18' of location 'on' (an input may only be bounded by numbers: not supported)"), err


@pytest.mark.parametrize("flag,value,line", [
    ("asap", "maybe", 8), ("asap", "1", 8), ("timedriven", "yes", 8), ("local", "ja", 5),
])
def test_a_flag_that_is_neither_true_nor_false_is_bad_input(tmp_path, capsys, flag, value, line):
    """``asap="maybe"`` read as false would drop the urgency and change the verdict: refused at
    the element's line (``TRUE`` is true, as any case of true)."""
    where = ('<transition source="1" target="2">' if flag != "local" else
             '<param name="c" type="real" local="false"')
    new = where.replace('local="false"', f'local="{value}"') if flag == "local" else \
        where.replace(">", f' {flag}="{value}">')
    assert where in THERMOSTAT
    xml, cfg = write(tmp_path, THERMOSTAT.replace(where, new, 1), CFG)
    err = bad_input(check(xml, cfg), capsys)
    assert err.startswith(f"reach: {xml}:{line}: component 'heater': ") and \
        f'{flag}="{value}": expected true or false' in err, err


# ------------------------------------------------------------------ networks too large
SWITCH = '''<component id="sw">
 <param name="x" type="real" local="false" dynamics="any"/>
 <location id="1" name="on"><flow>x' == 1</flow></location>
 <location id="2" name="off"><flow>x' == -1</flow></location>
 <transition source="1" target="2"><guard>x &gt;= 1</guard></transition>
 <transition source="2" target="1"><guard>x &lt;= 0</guard></transition>
</component>
'''


def network(n: int, fixed: bool) -> tuple[str, str]:
    """``n`` bound copies of a two-location switch, and a cfg that fixes each copy's initial
    location (``fixed``) or leaves the product of all of them."""
    params = "".join(f' <param name="x{i}" type="real" local="false" dynamics="any"/>\n' for i in range(n))
    binds = "".join(f' <bind component="sw" as="s{i}"><map key="x">x{i}</map></bind>\n' for i in range(n))
    body = SWITCH + '<component id="sys">\n' + params + binds + "</component>\n"
    init = " & ".join(f"x{i} == 0" + (f" & loc(s{i}) == on" if fixed else "") for i in range(n))
    return body, f'system = sys\ninitially = "{init}"\nforbidden = "x0 >= 2"\ntime-horizon = 1\n'


NETWORK_LINE = SWITCH.count("\n") + 3          # the line of <component id="sys">


@pytest.mark.parametrize("fixed", [False, True])
def test_forty_bound_components_are_refused_while_the_product_is_built(tmp_path, capsys, fixed):
    """2^40 location combinations: refused at the limit (no memory blow-up), naming the
    network component's line and what to do."""
    xml, cfg = write(tmp_path, *network(40, fixed))
    for argv in (check(xml, cfg), ["import", str(xml), str(cfg), "--out", str(tmp_path / "out")]):
        err = bad_input(argv, capsys)
        assert err.startswith(f"reach: {xml}:{NETWORK_LINE}: component 'sys': ")
        if fixed:
            assert "reaches more than" in err and "smaller network" in err
        else:
            assert f"more than {MAX_LOCATIONS} initial location combinations" in err
            assert "loc(INSTANCE) == LOCATION" in err


def test_a_synchronised_label_shared_by_many_components_is_refused_before_its_product(tmp_path, capsys):
    """Forty components that each take label 'go' in two ways: one product step would have
    2^40 transitions."""
    comp = '''<component id="sw">
 <param name="x" type="real" local="false" dynamics="any"/>
 <param name="go" type="label" local="false"/>
 <location id="1" name="on"><flow>x' == 1</flow></location>
 <transition source="1" target="1"><label>go</label><assignment>x := 0</assignment></transition>
 <transition source="1" target="1"><label>go</label><assignment>x := 1</assignment></transition>
</component>
'''
    params = "".join(f' <param name="x{i}" type="real" local="false" dynamics="any"/>\n' for i in range(40))
    binds = "".join(f' <bind component="sw" as="s{i}"><map key="x">x{i}</map><map key="go">go</map></bind>\n'
                    for i in range(40))
    body = comp + '<component id="sys">\n <param name="go" type="label" local="false"/>\n' + params + binds + \
        "</component>\n"
    init = " & ".join(f"x{i} == 0" for i in range(40))
    xml, cfg = write(tmp_path, body, f'system = sys\ninitially = "{init}"\ntime-horizon = 1\n')
    err = bad_input(check(xml, cfg), capsys)
    assert err.startswith(f"reach: {xml}:{comp.count(chr(10)) + 3}: component 'sys': ") and "label 'go'" in err


def test_many_variables_are_refused_before_the_matrices_are_built(tmp_path, capsys):
    n = 3000
    params = "".join(f' <param name="x{i}" type="real" local="false" dynamics="any"/>\n' for i in range(n))
    flow = " &amp; ".join(f"x{i}' == -x{i}" for i in range(n))
    body = f'<component id="sys">\n{params} <location id="1" name="run"><flow>{flow}</flow></location>\n</component>\n'
    init = " & ".join(f"x{i} == 0" for i in range(n))
    xml, cfg = write(tmp_path, body, f'system = sys\ninitially = "{init}"\ntime-horizon = 1\n')
    err = bad_input(check(xml, cfg), capsys)
    assert err.startswith(f"reach: {xml}:3: component 'sys': ") and "3000 variables" in err


def test_many_transitions_are_refused_before_they_are_converted(tmp_path, capsys):
    loops = "".join(f' <transition source="1" target="1"><guard>x &gt;= {i}</guard></transition>\n'
                    for i in range(60_000))
    body = ('<component id="sys">\n <param name="x" type="real" local="false" dynamics="any"/>\n'
            f' <location id="1" name="run"><flow>x\' == 1</flow></location>\n{loops}</component>\n')
    xml, cfg = write(tmp_path, body, 'system = sys\ninitially = "x == 0"\ntime-horizon = 1\n')
    err = bad_input(check(xml, cfg), capsys)
    assert err.startswith(f"reach: {xml}:3: component 'sys': ") and "too large" in err


def test_many_locations_of_many_variables_are_refused_before_the_flow_matrices(tmp_path, capsys):
    """26 locations of 1000 states: 26 flow matrices of 1001^2 entries. With one state that
    flows, the same locations and declarations import."""
    n, m = 1000, 26
    params = "".join(f' <param name="x{i}" type="real" local="false" dynamics="any"/>\n' for i in range(n))
    flow = " &amp; ".join(f"x{i}' == {{k}}" for i in range(n))
    locations = "".join(f' <location id="{k}" name="l{k}"><flow>{flow.format(k=k)}</flow></location>\n'
                        for k in range(m))
    chain = "".join(f' <transition source="{k}" target="{k + 1}"/>\n' for k in range(m - 1))
    body = f'<component id="sys">\n{params}{locations}{chain}</component>\n'
    init = " & ".join(f"x{i} == 0" for i in range(n))
    xml, cfg = write(tmp_path, body, f'system = sys\ninitially = "loc(sys) == l0 & {init}"\ntime-horizon = 1\n')
    err = bad_input(check(xml, cfg), capsys)
    assert err.startswith(f"reach: {xml}:3: component 'sys': too large to import: 26 location combinations "
                          "of 1000 variables")
    one = f'<component id="sys">\n{params}' + "".join(
        f' <location id="{k}" name="l{k}"><flow>x0\' == {k}</flow></location>\n' for k in range(m)) + chain + \
        "</component>\n"
    xml, cfg = write(tmp_path, one, 'system = sys\ninitially = "loc(sys) == l0 & x0 == 0"\ntime-horizon = 1\n')
    model, _, _ = load_spaceex(xml, cfg)
    assert model.state == ["x0"] and len(model.modes) == m


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n=st.integers(1, 60), fixed=st.booleans())
def test_networks_of_any_size_import_or_are_refused(tmp_path_factory, capsys, n, fixed):
    tmp = tmp_path_factory.mktemp("network")
    xml, cfg = write(tmp, *network(n, fixed))
    code = main(["import", str(xml), str(cfg), "--out", str(tmp / "out")])
    err = capsys.readouterr().err
    assert code in (0, 2) and "Traceback" not in err
    if code == 2:
        assert err.count("\n") == 1 and err.startswith(f"reach: {xml}:{NETWORK_LINE}: component 'sys': ")
    if n <= 6:
        assert code == 0


# ------------------------------------------------------------------ the wording of errors
def test_an_initial_location_that_does_not_exist_names_the_cfg_line(tmp_path, capsys):
    xml, cfg = write(tmp_path, THERMOSTAT, "# heater\n" + CFG.replace("== on", "== nowhere"))
    err = bad_input(check(xml, cfg), capsys)
    assert err == f"reach: {cfg}:3: initially: component 'heater' has no location 'nowhere' (its locations: on, off)"


PAIR = '<component id="sys">\n <bind component="heater" as="h"/>\n <bind component="heater" as="g"/>\n</component>\n'
PAIR_CFG = ('system = sys\ninitially = "loc(h) == on & loc(g) == off & h.T == 20 & g.T == 20 & h.c == 0 & '
            'g.c == 0"\ntime-horizon = 1\n')


@pytest.mark.parametrize("network_of_two", [False, True])
def test_locations_are_named_as_written_not_as_python_tuples(tmp_path, capsys, network_of_two):
    body = THERMOSTAT.replace("T' == -0.1*(T - 10) + 3", "T' == 1 | T' == 2")
    cfg = CFG
    if network_of_two:
        body += PAIR
        cfg = PAIR_CFG
    xml, cfg_path = write(tmp_path, body, cfg)
    err = bad_input(check(xml, cfg_path), capsys)
    assert "('" not in err and "location 'on': flow" in err


def test_product_locations_are_shown_with_their_instances(tmp_path, capsys):
    """A message about a product location names each instance's location (``h.on, g.off``)."""
    body = THERMOSTAT.replace("<flow>T' == -0.1*(T - 10) &amp; c' == 1</flow>", "<flow>c' == 1</flow>")
    xml, cfg_path = write(tmp_path, body + PAIR, PAIR_CFG)
    err = bad_input(check(xml, cfg_path), capsys)
    assert "location 'h.on, g.off': no flow for 'g.T'" in err and "('" not in err


@pytest.mark.parametrize("stem,pid", [("..", "forbidden"), ("ü", "forbidden"), ("my model (v2)", "my_model_v2"),
                                      ("-x", "x"), ("a.4th_order", "a_4th_order")])
def test_a_cfg_file_name_that_is_no_identifier_gives_a_valid_property_id(tmp_path, capsys, stem, pid):
    xml, _ = write(tmp_path, THERMOSTAT, CFG)
    cfg = tmp_path / f"{stem}.cfg"
    cfg.write_text(CFG)
    _, props, _ = load_spaceex(xml, cfg)
    assert [p.id for p in props] == [pid]
    assert main(check(xml, cfg)) == 3
    assert main(["import", str(xml), str(cfg), "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()


# ------------------------------------------------------------------ locations where no time passes
TIMELESS = '''<component id="tank">
 <param name="h" type="real" local="false" dynamics="any"/>
 <param name="n" type="real" local="false" dynamics="any"/>
 <location id="1" name="fill"><invariant>h &lt;= 10</invariant><flow>h' == 2 &amp; n' == 0</flow></location>
 <location id="2" name="count"><flow>false</flow></location>
 <location id="3" name="drain"><invariant>h &gt;= 1</invariant><flow>h' == -1 &amp; n' == 0</flow></location>
 <transition source="1" target="2" asap="true"><guard>h &gt;= 10</guard><assignment>n := n + 1</assignment></transition>
 <transition source="2" target="3" asap="true"></transition>
 <transition source="3" target="1"><guard>h &lt;= 1</guard></transition>
</component>
'''


@pytest.mark.parametrize("forbidden,verdicts", [("h >= 10.5", {"star": 0, "montecarlo": 3}),
                                               ("n >= 1.5", {"star": None, "montecarlo": 1})])
def test_a_timeless_location_is_marked_and_round_trips_with_the_same_verdicts(tmp_path, capsys, forbidden,
                                                                             verdicts):
    """``flow false``: no time passes in 'count'; the imported YAML is the same automaton and
    gives the same verdicts as the XML (the tank fills to 10 by t = 5, counts, drains to 1 by
    t = 14 and fills again: the second count is at t = 18.5, the level never passes 10). Star
    leaves the second count undecided (None: the same verdict from both files is all that is
    asserted)."""
    cfg = (f'system = tank\ninitially = "loc(tank) == fill & h == 0 & n == 0"\nforbidden = "{forbidden}"\n'
           'time-horizon = 30\n')
    xml, cfg_path = write(tmp_path, TIMELESS, cfg)
    direct, _, docs = load_spaceex(xml, cfg_path)
    assert [name for name, mode in direct.modes.items() if mode.timeless] == ["count"]
    assert docs.model["modes"]["count"]["flow"] is False
    model_file, prop_file = write_yaml(docs, tmp_path / "out")
    again = load_model(model_file)
    assert [(name, m.timeless) for name, m in again.modes.items()] == \
        [(name, m.timeless) for name, m in direct.modes.items()]
    assert [(t.source, t.target, t.urgent, {k: sympy.srepr(v) for k, v in t.reset.items()})
            for t in again.transitions] == \
        [(t.source, t.target, t.urgent, {k: sympy.srepr(v) for k, v in t.reset.items()}) for t in direct.transitions]
    assert np.array_equal(again.initial.low, direct.initial.low)
    for backend, expected in verdicts.items():
        options = ["-o", "samples=50"] if backend == "montecarlo" else []
        from_xml = main(["check", str(xml), str(cfg_path), "-b", backend, *options])
        from_yaml = main(["check", str(model_file), str(prop_file), "-b", backend, *options])
        out = capsys.readouterr().out
        assert from_xml == from_yaml, out
        assert expected is None or from_xml == expected, out


def test_the_constant_pi_is_a_number_in_the_xml_and_the_cfg(tmp_path):
    """``pi`` is no variable to declare: in a flow, and in the cfg's sets."""
    body = THERMOSTAT.replace("T' == -0.1*(T - 10) + 3", "T' == -0.1*(T - 10) + pi")
    xml, cfg = write(tmp_path, body, CFG.replace("T >= 22.01", "T >= 7*pi"))
    model, props, docs = load_spaceex(xml, cfg)
    assert docs.model["modes"]["on"]["flow"]["T"] == "-0.1*(T - 10) + pi"
    assert props[0].raw["avoid"] == ["T >= 7*pi"]


# ------------------------------------------------------------------ initial sets the cfg cannot give
DRIVEN = '''<component id="osc">
 <param name="x" type="real" local="false" dynamics="any"/>
 <param name="u" type="real" local="false" dynamics="any"/>
 <location id="1" name="run"><invariant>0.8 &lt;= u &lt;= 1 &amp; x &lt;= 5</invariant><flow>x' == -x + u</flow></location>
</component>
'''


@pytest.mark.parametrize("initially,message", [
    ("x == 0 & x + u <= 1.5", "initially: 'u' is a time-varying input"),
    ("x == 0 & x >= 1", "initially: the initial set is empty (its constraints exclude each other)"),
    ("x == 6", "initially: the initial set meets no location's invariant"),
])
def test_an_initial_set_the_automaton_cannot_start_in_is_named_at_the_cfg_line(tmp_path, capsys, initially,
                                                                               message):
    """A time-varying input takes any value at every instant (no initial value); an empty set
    is told apart from one that misses every invariant."""
    xml, cfg = write(tmp_path, DRIVEN, f'system = osc\ninitially = "{initially}"\nforbidden = "x >= 2"\n'
                                      f'time-horizon = 5\n')
    line = bad_input(check(xml, cfg), capsys)
    assert line.startswith(f"reach: {cfg}:2: {message}"), line


@pytest.mark.parametrize("forbidden, code", [("x >= 0.995", 0), ("x >= 0.9", 1)])
def test_an_initial_value_of_a_time_varying_input_alone_is_ignored_with_a_warning(tmp_path, capsys, forbidden,
                                                                                  code):
    """An initial value of an input (``u == 0.9``, as JuliaReach's two_tanks writes ``u == 0``
    for its input in [-0.1, 0.1]) constrains no run: the input is any signal in [0.8, 1], so a
    value at t = 0 changes nothing. The import warns and checks the same system as without it:
    x' = -x + u from 0 stays below 1 - e^{-5} = 0.9933 and reaches 0.9 (0.995 is never
    reached). (A value outside the range empties the initial set: bad input, as ``false``.)"""
    xml, cfg = write(tmp_path, DRIVEN, f'system = osc\ninitially = "x == 0 & u == 0.9"\nforbidden = "{forbidden}"\n'
                                      f'time-horizon = 5\n')
    assert main(["check", str(xml), str(cfg), "-b", "star"]) == code
    err = capsys.readouterr().err
    assert f"{cfg}:2: initially: 'u == 0.9' ignored: u is a time-varying input" in err


# ------------------------------------------------------------------ constants the cfg gives
CLOCKED = '''<component id="ramp">
 <param name="x" type="real" local="false" dynamics="any"/>
 <param name="t" type="real" local="false" dynamics="any"/>
 <param name="tmax" type="real" local="false" dynamics="const"/>
 <location id="1" name="go"><invariant>t &lt;= tmax</invariant><flow>x' == 1 &amp; t' == 1</flow></location>
</component>
'''


@pytest.mark.parametrize("tmax,code", [("tmax == 5", 0), ("tmax == 7", 1), ("tmax >= 4 & tmax <= 7", 1),
                                       ("tmax >= 4 & tmax <= 5.9", 0)])
def test_a_constant_valued_in_initially_bounds_the_runs(tmp_path, capsys, tmax, code):
    """The SpaceEx idiom of a ``const`` param bound to no number and given its value (or range)
    in the cfg: ``x = t <= tmax``, so ``x >= 6`` is reached exactly when some ``tmax`` exceeds 6."""
    xml, cfg = write(tmp_path, CLOCKED, f'system = ramp\ninitially = "x == 0 & t == 0 & {tmax}"\n'
                                        'forbidden = "x >= 6"\ntime-horizon = 10\n')
    assert main(["check", str(xml), str(cfg), "-b", "star"]) == code
    model, _, _ = load_spaceex(xml, cfg)
    assert "tmax" in model.state and model.is_linear


def test_a_constant_without_a_value_anywhere_is_bad_input_saying_where_to_give_one(tmp_path, capsys):
    xml, cfg = write(tmp_path, CLOCKED, 'system = ramp\ninitially = "x == 0 & t == 0"\n'
                                        'forbidden = "x >= 6"\ntime-horizon = 10\n')
    assert main(["check", str(xml), str(cfg), "-b", "star"]) == 2
    assert "constant 'tmax' has no value" in capsys.readouterr().err


def test_a_system_without_continuous_variables_is_bad_input(tmp_path, capsys):
    body = '''<component id="sw">
 <location id="1" name="a"/><location id="2" name="b"/>
 <transition source="1" target="2"/>
</component>
'''
    xml, cfg = write(tmp_path, body, 'system = sw\ninitially = "loc(sw) == a"\nforbidden = "loc(sw) == b"\n'
                                     'time-horizon = 1\n')
    assert main(["check", str(xml), str(cfg), "-b", "star"]) == 2
    assert "no continuous variable" in capsys.readouterr().err


@pytest.mark.parametrize("forbidden, code", [("k >= 7.01", 0), ("k <= 5.01", 1)])
def test_a_constant_only_the_cfg_reads_takes_its_range_from_initially(tmp_path, capsys, forbidden, code):
    """A ``const`` param the system never reads, given a range by ``initially`` and named by the
    forbidden set (hyst's const_range): a constant state in [5, 7], not an unknown name."""
    body = '''<component id="toy">
 <param name="k" type="real" local="false" dynamics="const"/>
 <param name="t" type="real" local="false" dynamics="any"/>
 <location id="1" name="go"><invariant>t &lt;= 20</invariant><flow>t' == 1</flow></location>
</component>
'''
    xml, cfg = write(tmp_path, body, f'system = toy\ninitially = "k >= 5 & k <= 7 & t == 0"\n'
                                     f'forbidden = "{forbidden}"\ntime-horizon = 20\n')
    assert main(["check", str(xml), str(cfg), "-b", "star", "--counterexamples", str(tmp_path / "out")]) == code


@pytest.mark.parametrize("drop,hint", [("time-horizon", "give a positive time: time-horizon = 10"),
                                       ("initially", 'initially = "x == 0 & loc(sys) == l0"')])
def test_a_missing_required_cfg_key_says_what_to_write(tmp_path, capsys, drop, hint):
    """SpaceEx reads a cfg without time-horizon as "up to a fixpoint"; the message says what
    to add instead of only naming the key."""
    cfg = "".join(line + "\n" for line in CFG.splitlines() if not line.startswith(drop))
    xml, cfg_path = write(tmp_path, THERMOSTAT, cfg)
    err = bad_input(check(xml, cfg_path), capsys)
    assert err.startswith(f"reach: {cfg_path}:1: no '{drop}' (") and hint in err, err


@pytest.mark.parametrize("read,code", [("", 0), (" &amp; w &lt;= 1", 2)])
def test_a_variable_only_jumps_write_is_kept_frozen_or_refused_where_read(tmp_path, capsys, read, code):
    """``w`` has no flow and is set on a jump. Read nowhere, it changes no run: kept as a state
    with flow 0, with a warning, and the thermostat's bound holds (T <= 22 by its invariant).
    Read by a guard, its value would matter (SpaceEx lets it move freely): bad input."""
    body = (THERMOSTAT.replace('<param name="c"', '<param name="w" type="real" local="false" dynamics="any"/>\n'
                                                 ' <param name="c"')
            .replace("<assignment>c := 0</assignment>", "<assignment>c := 0 &amp; w := 3</assignment>")
            .replace("<guard>T &lt;= 19</guard>", f"<guard>T &lt;= 19{read}</guard>"))
    xml, cfg = write(tmp_path, body, CFG)
    got = main(["check", str(xml), str(cfg), "-b", "star"])
    out, err = capsys.readouterr()
    assert got == code, out + err
    if code == 0:
        assert "'w' has no flow and nothing reads it: kept as a state with flow 0" in err + out
    else:
        assert "assignment: 'w' has no flow anywhere" in err


def test_a_forbidden_set_of_too_many_disjuncts_says_the_limit(tmp_path, capsys):
    """Each forbidden term is a property of its own: more than 256 are refused, saying so."""
    terms = " | ".join(f"T >= {30 + k}" for k in range(300))
    xml, cfg = write(tmp_path, THERMOSTAT, CFG.replace('forbidden = "T >= 22.01"', f'forbidden = "{terms}"'))
    err = bad_input(check(xml, cfg), capsys)
    assert err.startswith(f"reach: {cfg}:3: forbidden: ") and "more than 256 disjuncts (the import reads at most 256" in err, err


JUMPING_INPUT = '''<component id="c">
 <param name="x" type="real" local="false" dynamics="any"/>
 <param name="y" type="real" local="false" dynamics="any"/>
 <param name="w" type="real" local="false" dynamics="any"/>
 <location id="1" name="a"><invariant>0 &lt;= w &lt;= 1 &amp; x &lt;= 1</invariant><flow>x' == w &amp; y' == 0</flow></location>
 <location id="2" name="b"><invariant>LOW &lt;= w &lt;= HIGH</invariant><flow>x' == w &amp; y' == 0</flow></location>
 <transition source="1" target="2"><guard>x &gt;= 1</guard>RESET</transition>
</component>
'''


@pytest.mark.parametrize("low,high,reset,outcome", [
    (2, 3, "", 0),                  # the intervals do not meet: the jump never fires, x stays <= 1
    (0.5, 3, "", 1),                # they meet: the jump fires (with w in [0.5, 1]), then x grows past 1.5
    (-1, 0, "<assignment>y := w</assignment>", 2),     # the reset would read w in {0} only
    (0, 1, "<assignment>y := w</assignment>", 1),      # the same interval: a plain input, read as it is
])
def test_a_jump_keeps_an_input_bounded_per_location(tmp_path, capsys, low, high, reset, outcome):
    """SpaceEx keeps a variable no assignment sets through a jump: ``w`` must lie in both
    locations' intervals as the run jumps. x grows at rate w in [0, 1] to the guard x >= 1;
    in 'b', at rate w in [LOW, HIGH]; the horizon 3 lets it pass 1.5 only in 'b'."""
    body = JUMPING_INPUT.replace("LOW", str(low)).replace("HIGH", str(high)).replace("RESET", reset)
    forbidden = "y >= 0.5" if reset and high == 1 else "x >= 1.5"
    xml, cfg = write(tmp_path, body, f'system = c\ninitially = "loc(c) == a & x == 0 & y == 0"\n'
                                     f'forbidden = "{forbidden}"\ntime-horizon = 3\n')
    if outcome == 2:
        err = bad_input(["check", str(xml), str(cfg), "-b", "star"], capsys)
        assert "an assignment reads the input 'w', which keeps its value through the jump" in err, err
        return
    got = main(["check", str(xml), str(cfg), "-b", "star", "--counterexamples", str(tmp_path / "cx")])
    out, err = capsys.readouterr()
    assert got == outcome, out + err
    assert ("transition a -> b never fires" in err) == (low == 2), err
