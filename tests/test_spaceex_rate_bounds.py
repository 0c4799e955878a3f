"""SpaceEx flows that bound a derivative by numbers (rectangular dynamics, ``1 <= x' <= 2``).

Such a location lets ``x`` move at any rate in the interval, changing at any instant: the
import reads it as ``x' == u`` for a time-varying bounded input ``u`` (one per variable; a
location with other bounds maps the same input onto its own interval). References are closed
forms: in location ``up`` the rates are ``x' in [1, 2]`` and ``y' in [-1, 1]``, the invariant
``x <= 4`` holds until the jump to ``down``, so ``y(t) >= -t`` and ``x <= 4`` throughout ``up``.
"""

from __future__ import annotations

import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st

from cli_input import bad_input
from reach.cli import main
from reach.model import load_model
from reach.model.spaceex import load_spaceex, write_yaml

HEADER = '<?xml version="1.0"?>\n<sspaceex xmlns="http://www-verimag.imag.fr/xml-namespaces/sspaceex" version="0.2">\n'

RECT = '''<component id="rect">
 <param name="x" type="real" local="false" dynamics="any"/>
 <param name="y" type="real" local="false" dynamics="any"/>
 <location id="1" name="up"><invariant>x &lt;= 4</invariant><flow>1 &lt;= x' &amp; x' &lt;= 2 &amp; y' &gt;= -1 &amp; -y' &gt;= -1</flow></location>
 <location id="2" name="down"><flow>-3 &lt;= x' &lt;= -1 &amp; y' == 1</flow></location>
 <transition source="1" target="2"><guard>x &gt;= 4</guard></transition>
</component>
'''


def write(folder, body: str, forbidden: str, horizon: float, name: str = "m"):
    (folder / f"{name}.xml").write_text(HEADER + body + "</sspaceex>\n")
    (folder / f"{name}.cfg").write_text(f'system = rect\ninitially = "loc(rect) == up & x == 0 & y == 0"\n'
                                       f'forbidden = "{forbidden}"\ntime-horizon = {horizon}\n')
    return folder / f"{name}.xml", folder / f"{name}.cfg"


def rates(model, mode: str, state: str, inputs: dict) -> float:
    """The derivative of ``state`` in ``mode`` at the input values ``inputs`` (by name)."""
    m = model.modes[mode]
    i = [str(s) for s in m.symbols].index(state)
    return float(m.flow[i].subs({s: inputs.get(str(s), 0.0) for s in m.symbols}))


def test_each_bounded_derivative_becomes_a_varying_input_over_its_interval(tmp_path):
    xml, cfg = write(tmp_path, RECT, "y <= -1.9", 2)
    model, _, _ = load_spaceex(xml, cfg)
    ranges = {u.name: (u.low, u.high, u.varying) for u in model.bounded_inputs}
    # y' has one interval: its input ranges over it; x' has two: a share of each location's
    assert ranges == {"x_rate_share": (0.0, 1.0, True), "y_rate": (-1.0, 1.0, True)}
    for share, up, down in ((0.0, 1.0, -3.0), (0.5, 1.5, -2.0), (1.0, 2.0, -1.0)):
        assert rates(model, "up", "x", {"x_rate_share": share}) == up
        assert rates(model, "down", "x", {"x_rate_share": share}) == down
    for u in (-1.0, 0.25, 1.0):
        assert rates(model, "up", "y", {"y_rate": u}) == u
    assert rates(model, "down", "y", {}) == 1.0


def test_rectangular_verdicts_meet_the_closed_form_bounds(tmp_path, capsys):
    """y >= -t in 'up' (y' >= -1), reached by y' = -1 while x stays below 4 (t <= 2 at x' >= 1);
    x <= 4 by the invariant, and x falls in 'down'."""
    cases = [("y <= -2.01", 2, {"star": 0, "montecarlo": 3}),
             ("y <= -1.9", 2, {"star": 1, "montecarlo": 1}),
             ("x >= 4.01", 4, {"star": 0, "montecarlo": 3})]
    for k, (forbidden, horizon, expected) in enumerate(cases):
        xml, cfg = write(tmp_path, RECT, forbidden, horizon, name=f"m{k}")
        for backend, code in expected.items():
            options = ["-o", "samples=200"] if backend == "montecarlo" else []
            got = main(["check", str(xml), str(cfg), "-b", backend, "--counterexamples", str(tmp_path / "cx"),
                        *options])
            out = capsys.readouterr().out
            assert got == code, (forbidden, backend, out)
            if code == 1:
                cx = next((tmp_path / "cx").glob(f"m{k}_{backend}*.json"))
                assert main(["replay", str(cx)]) == 1, capsys.readouterr().out


def test_the_imported_yaml_gives_the_same_rates_and_verdicts(tmp_path, capsys):
    xml, cfg = write(tmp_path, RECT, "y <= -1.9", 2)
    direct, _, docs = load_spaceex(xml, cfg)
    model_file, prop_file = write_yaml(docs, tmp_path / "out")
    again = load_model(model_file)
    for mode in direct.modes:
        assert [sympy.simplify(a - b) for a, b in zip(direct.modes[mode].flow, again.modes[mode].flow)] == \
            [0] * len(direct.modes[mode].flow)
    assert main(["check", str(model_file), str(prop_file), "-b", "star"]) == 1
    assert main(["check", str(xml), str(cfg), "-b", "star"]) == 1
    capsys.readouterr()


def test_equal_bounds_are_the_rate_itself(tmp_path):
    body = RECT.replace("1 &lt;= x' &amp; x' &lt;= 2", "2 &lt;= x' &amp; x' &lt;= 2")
    xml, cfg = write(tmp_path, body, "y <= -1.9", 2)
    model, _, _ = load_spaceex(xml, cfg)
    (u,) = [u for u in model.bounded_inputs if u.name == "x_rate"]      # 'down' alone ranges: [-3, -1]
    assert (u.low, u.high) == (-3.0, -1.0)
    assert rates(model, "up", "x", {"x_rate": -3.0}) == 2.0
    assert rates(model, "down", "x", {"x_rate": -2.5}) == -2.5


def test_bounds_that_cross_by_rounding_only_hold_both_readings(tmp_path):
    """``0.1*3 <= x'`` and ``x' <= 0.3`` cross by one rounding (0.30000000000000004 > 0.3): the
    rates between them; bounds that truly cross are bad input."""
    body = RECT.replace("1 &lt;= x' &amp; x' &lt;= 2", "0.1*3 &lt;= x' &amp; x' &lt;= 0.3")
    xml, cfg = write(tmp_path, body, "y <= -1.9", 2)
    model, _, _ = load_spaceex(xml, cfg)
    ends = sorted(rates(model, "up", "x", {"x_rate_share": v}) for v in (0.0, 1.0))
    assert ends == [0.3, 0.1 * 3]
    assert max(abs(rates(model, "down", "x", {"x_rate_share": v}) - e) for v, e in ((0.0, -3.0), (1.0, -1.0))) == 0


def test_a_variable_named_like_the_internal_marker_is_read_as_a_variable(tmp_path, capsys):
    """``x' + primed_rate_ <= 3`` reads a state: bad input, whatever the state's name."""
    body = RECT.replace('<param name="y"', '<param name="primed_rate_" type="real" local="false" dynamics="any"/>\n'
                                           ' <param name="y"')
    body = body.replace("1 &lt;= x' &amp; x' &lt;= 2", "x' + primed_rate_ &lt;= 3 &amp; x' &gt;= 0 &amp; "
                                                         "primed_rate_' == 0")
    xml, cfg = write(tmp_path, body, "y <= -1.9", 2)
    err = bad_input(["check", str(xml), str(cfg), "-b", "star"], capsys)
    assert "construct 'x' + primed_rate_ <= 3' is not supported" in err, err


def test_a_rate_input_name_never_shadows_a_variable(tmp_path):
    body = RECT.replace('<param name="y" type="real" local="false" dynamics="any"/>',
                        '<param name="y" type="real" local="false" dynamics="any"/>\n'
                        ' <param name="y_rate" type="real" local="false" dynamics="any"/>')
    body = body.replace("y' == 1</flow>", "y' == 1 &amp; y_rate' == 0</flow>")
    body = body.replace("-y' &gt;= -1</flow>", "-y' &gt;= -1 &amp; y_rate' == 0</flow>")
    xml, cfg = write(tmp_path, body, "y <= -1.9", 2)
    (tmp_path / "m.cfg").write_text((tmp_path / "m.cfg").read_text().replace("y == 0", "y == 0 & y_rate == 5"))
    model, _, _ = load_spaceex(xml, cfg)
    assert {u.name for u in model.bounded_inputs} == {"x_rate_share", "y_rate2"}
    assert rates(model, "up", "y", {"y_rate2": 0.5, "y_rate": 5.0}) == 0.5


@pytest.mark.parametrize("flow,line,message", [
    ("x' &gt;= 1", 6, "'x'' is bounded on one side only"),
    ("x' + y' &lt;= 1", 6, "construct 'x' + y' <= 1' is not supported"),
    ("x' &lt;= x", 6, "construct 'x' <= x' is not supported"),
    ("x' == 1 &amp; x' &lt;= 2", 6, "'x'' is given by an equality and bounded too"),
    ("x' &gt;= 2 &amp; x' &lt;= 1", 6, "the bounds of 'x'' admit no rate (2 > 1)"),
])
def test_a_flow_relation_outside_the_rectangular_form_is_bad_input_at_its_line(tmp_path, capsys, flow, line,
                                                                               message):
    body = RECT.replace("1 &lt;= x' &amp; x' &lt;= 2", flow)
    xml, cfg = write(tmp_path, body, "y <= -1.9", 2)
    err = bad_input(["check", str(xml), str(cfg), "-b", "star"], capsys)
    assert err.startswith(f"reach: {xml}:{line}: component 'rect': location 'up': flow: "), err
    assert message in err, err


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(-50, 50), st.integers(1, 40)), min_size=1, max_size=4))
def test_every_location_keeps_its_own_interval_of_rates(tmp_path_factory, intervals):
    """Locations ``l0, l1, ...`` in a cycle, each bounding ``x'`` by its own ``[lo, lo + w]``:
    at the input's two ends each location's rate is exactly its two bounds."""
    folder = tmp_path_factory.mktemp("rates")
    locations = "".join(
        f' <location id="{k}" name="l{k}"><flow>{lo / 4} &lt;= x\' &amp; x\' &lt;= {(lo + w) / 4}</flow></location>\n'
        for k, (lo, w) in enumerate(intervals))
    jumps = "".join(f' <transition source="{k}" target="{(k + 1) % len(intervals)}"><guard>x &gt;= 100</guard>'
                    '</transition>\n' for k in range(len(intervals)))
    body = f'<component id="rect">\n <param name="x" type="real" local="false" dynamics="any"/>\n{locations}{jumps}</component>\n'
    (folder / "m.xml").write_text(HEADER + body + "</sspaceex>\n")
    (folder / "m.cfg").write_text('system = rect\ninitially = "loc(rect) == l0 & x == 0"\nforbidden = "x >= 1000"\n'
                                  'time-horizon = 1\n')
    model, _, _ = load_spaceex(folder / "m.xml", folder / "m.cfg")
    (u,) = model.bounded_inputs
    one = len({(lo, w) for lo, w in intervals}) == 1
    assert u.varying and (u.low, u.high) == ((intervals[0][0] / 4, (intervals[0][0] + intervals[0][1]) / 4)
                                             if one else (0.0, 1.0))
    for k, (lo, w) in enumerate(intervals):
        ends = sorted(rates(model, f"l{k}", "x", {u.name: v}) for v in (u.low, u.high))
        assert abs(ends[0] - lo / 4) <= 1e-12 * (1 + abs(lo)) and abs(ends[1] - (lo + w) / 4) <= 1e-12 * (1 + abs(lo + w))
