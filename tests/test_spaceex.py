"""SpaceEx import: the published files, hand-written constructs, malformed input, round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reach.cli import main
from reach.errors import InputError
from reach.model import load_model
from reach.model.simulate import Simulator
from reach.model.spaceex import documents, load_spaceex, write_yaml
from reach.model.spaceex.cfg import parse_cfg

ROOT = Path(__file__).resolve().parents[1] / "models" / "spaceex"

# (xml, cfg, states, modes, transitions, bounded inputs, forbidden terms): counted from the files
# (Building: 48 states + t + the input u1, output y1 is an alias; Gearbox: 5 + clock, the two
# locations plus a start mode because the initial set lies in both, 2 impacts + 4 meshings + 2
# start jumps; Platoon: 9 + the input aL (+ clocks); filtered oscillator 4th order: 2 + 4 filter
# states, 4 locations in a cycle; drivetrain: 11 + t, 5 locations, 5 transitions).
PUBLISHED = [
    ("Building/BLDC01.xml", "Building/BLDC01-BDS01.cfg", 50, 1, 0, 1, 1),
    ("Building/BLDC01.xml", "Building/BLDC01-BDU02.cfg", 50, 1, 0, 1, 1),
    ("Building/BLDF01.xml", "Building/BLDF01-BDS01.cfg", 50, 1, 0, 1, 1),
    ("Building/BLDF01.xml", "Building/BLDF01-BDU01.cfg", 50, 1, 0, 1, 1),
    ("Building/BLDF01.xml", "Building/BLDF01-BDU02.cfg", 50, 1, 0, 1, 1),
    ("Gearbox/GRBX01-MES01.xml", "Gearbox/GRBX01-MES01.cfg", 6, 3, 8, 0, 2),
    ("Platoon/PLAA01-BND.xml", "Platoon/PLAA01-BND.cfg", 10, 2, 2, 1, 0),
    ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND30.cfg", 12, 2, 2, 1, 0),
    ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND42.cfg", 12, 2, 2, 1, 0),
    ("Platoon/PLAN01-UNB.xml", "Platoon/PLAN01-UNB50.cfg", 11, 2, 2, 1, 0),
    ("FilteredOscillator/filtered_oscillator.xml", "FilteredOscillator/filtered_oscillator.cfg", 6, 4, 4, 0, 0),
    ("BouncingBall/bball.xml", "BouncingBall/bball.cfg", 2, 1, 1, 0, 0),
    ("BouncingBall/bball_flattened.xml", "BouncingBall/bball_flattened.cfg", 2, 1, 1, 0, 0),
    ("Powertrain/drivetrain_2theta_30percent.xml", "Powertrain/drivetrain_2theta_30percent.cfg", 12, 5, 5, 0, 1),
    ("Rendezvous_ARCH18/SRA01-SR0_.xml", "Rendezvous_ARCH18/SRA01-SR0_-LOS.cfg", 5, 3, 3, 0, 3),
    ("Rendezvous_ARCH18/SRA01-SR0_.xml", "Rendezvous_ARCH18/SRA01-SR0_-collision.cfg", 5, 3, 3, 0, 1),
    ("Rendezvous_ARCH18/SRNA01-SR0_.xml", "Rendezvous_ARCH18/SRNA01-SR0_-LOS.cfg", 5, 2, 1, 0, 3),
]


@pytest.mark.parametrize("xml,cfg,n,modes,transitions,inputs,terms", PUBLISHED)
def test_published_files_import_with_the_expected_structure(xml, cfg, n, modes, transitions, inputs, terms):
    model, props, _ = load_spaceex(ROOT / xml, ROOT / cfg)
    assert (model.n, len(model.modes), len(model.transitions), len(model.bounded_inputs)) == \
        (n, modes, transitions, inputs)
    assert len(props) == terms


def test_building_details():
    model, props, _ = load_spaceex(ROOT / "Building/BLDF01.xml", ROOT / "Building/BLDF01-BDU02.cfg")
    (u,) = model.bounded_inputs
    assert (u.name, u.low, u.high, u.varying) == ("u1", 0.8, 1.0, True)
    assert "y1" not in model.state                       # the output is an alias of x25
    assert model.horizon == 20.1                          # time-horizon of BDU02.cfg
    assert props[0].raw["avoid"] == ["x25 < -0.00078", "t <= 20", "t >= 20"]
    constant, _, _ = load_spaceex(ROOT / "Building/BLDC01.xml", ROOT / "Building/BLDC01-BDS01.cfg")
    assert constant.bounded_inputs[0].varying is False     # u1' == 0 in BLDC01


def test_powertrain_initial_set_is_the_published_segment():
    model, props, _ = load_spaceex(ROOT / "Powertrain/drivetrain_2theta_30percent.xml",
                                   ROOT / "Powertrain/drivetrain_2theta_30percent.cfg")
    P = model.initial.polytope
    assert P is not None
    i = model.state.index
    # x4 in [27, 33]; x1 = 0.00056 x4 - 0.06; x7 = 12 x4
    assert model.initial.low[i("x4")] == pytest.approx(27) and model.initial.high[i("x4")] == pytest.approx(33)
    for x4 in (27.0, 30.0, 33.0):
        x = np.zeros(model.n)
        x[i("x4")] = x4
        x[i("x1")] = 0.00056 * x4 - 0.01512 - 0.04488
        x[i("x2")] = 0.467 * x4 - 12.609 - 12.401
        x[i("x6")] = x[i("x9")] = x[i("x11")] = x4
        x[i("x7")] = 12 * x4
        x[i("x8")] = x[i("x10")] = 0.00006 * x4 - 0.00162 - 0.0015
        assert np.all(P.A @ x <= P.b + 1e-9) and np.allclose(P.E @ x, P.f, atol=1e-9)
    assert props[0].raw["modes"] == ["error"]


@pytest.mark.parametrize("xml,cfg", [
    ("BouncingBall/bball.xml", "BouncingBall/bball.cfg"),
    ("FilteredOscillator/filtered_oscillator.xml", "FilteredOscillator/filtered_oscillator.cfg"),
    ("Building/BLDC01.xml", "Building/BLDC01-BDS01.cfg"),
    ("Building/BLDF01.xml", "Building/BLDF01-BDU01.cfg"),
    ("Gearbox/GRBX01-MES01.xml", "Gearbox/GRBX01-MES01.cfg"),
    ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND42-forbidden.cfg"),
    ("Powertrain/drivetrain_2theta_30percent.xml", "Powertrain/drivetrain_2theta_30percent.cfg"),
    ("Rendezvous_ARCH18/SRA01-SR0_.xml", "Rendezvous_ARCH18/SRA01-SR0_-LOS.cfg"),
])
def test_simulated_runs_agree_with_solve_ivp(xml, cfg):
    """The first stretch of a run in one mode (after jumps at t = 0), simulated, against scipy's
    solve_ivp of the same right-hand side; time-varying inputs held at their upper bound."""
    model, _, _ = load_spaceex(ROOT / xml, ROOT / cfg)
    model.horizon = min(model.horizon, 0.2)
    x0 = (model.initial.low + model.initial.high) / 2
    if not model.initial.is_box:
        from reach.backends.montecarlo.initial_sampling import PolytopeSampler
        x0 = PolytopeSampler(model.initial.polytope, model.initial.low, model.initial.high).structured()[-1]
    signal = None
    if model.varying_inputs:
        values = np.array([[[u.high for u in model.varying_inputs]]])
        signal = (model.horizon, values)
        for u in model.varying_inputs:
            x0[u.index] = u.high
    sim = Simulator(model, dt=model.horizon / 200)
    t, m, X = sim.run(x0[None, :], record=True, signal=signal).path[0]
    start = int(np.flatnonzero(t == 0)[-1])
    jump = (m[start + 1:] != m[start]) | (np.diff(t[start:]) <= 0)     # a mode change or a self-loop
    stop = start + 1 + (int(np.argmax(jump)) if jump.any() else len(t) - start - 1)
    assert t[stop - 1] > 0.005
    mode = model.modes[list(model.modes)[m[start]]]
    if mode.linear is not None:
        A, b = mode.linear
        f = lambda s, y: A @ y + b                  # noqa: E731
    else:
        f = lambda s, y: mode.rhs(y[None, :])[0]    # noqa: E731
    ref = solve_ivp(f, (0, t[stop - 1]), X[start], t_eval=t[start:stop], rtol=1e-10, atol=1e-12, method="LSODA")
    scale = 1 + np.abs(ref.y.T).max()
    assert np.max(np.abs(ref.y.T - X[start:stop])) < 1e-6 * scale


def test_rendezvous_file_is_the_suites_sra01():
    """The benchmark authors' SpaceEx SRA01 and the suite's own models/SRA01.yaml: same flows."""
    imported, _, _ = load_spaceex(ROOT / "Rendezvous_ARCH18/SRA01-SR0_.xml",
                                  ROOT / "Rendezvous_ARCH18/SRA01-SR0_-LOS.cfg")
    own = load_model(ROOT.parent / "SRA01.yaml")
    order = [imported.state.index(s) for s in own.state]
    for mine, theirs in (("approach", "P2"), ("rendezvous", "P3"), ("passive", "Passive")):
        A, b = imported.modes[theirs].linear
        A_own, b_own = own.modes[mine].linear
        assert np.allclose(A[np.ix_(order, order)], A_own, atol=1e-9) and np.allclose(b[order], b_own)
    assert np.array_equal(imported.initial.low[order], own.initial.low)


def test_bouncing_ball_bounces_at_the_ground():
    """The may-transition is taken where the run leaves x >= 0: v flips with factor 0.75."""
    model, _, _ = load_spaceex(ROOT / "BouncingBall/bball.xml", ROOT / "BouncingBall/bball.cfg")
    model.horizon = 6.0
    runs = Simulator(model, dt=0.01).run(np.array([[10.0, 0.0]]), record=True)
    t, m, X = runs.path[0]
    assert np.isnan(runs.blocked_at[0])
    impact = np.sqrt(20.0)                               # x = 10 - t^2/2 hits 0
    k = np.flatnonzero(np.diff(X[:, 1]) > 1.0)[0]
    assert t[k] == pytest.approx(impact, abs=1e-6)
    assert X[k + 1, 1] == pytest.approx(0.75 * impact, rel=1e-6)


def test_check_and_import_give_the_same_verdicts(tmp_path, capsys):
    xml, cfg = ROOT / "Gearbox/GRBX01-MES01.xml", ROOT / "Gearbox/GRBX01-MES01.cfg"
    assert main(["import", str(xml), str(cfg), "--out", str(tmp_path)]) == 0
    yaml_model = load_model(tmp_path / "models" / "GRBX01-MES01.yaml")
    direct, _, _ = load_spaceex(xml, cfg)
    assert yaml_model.state == direct.state and list(yaml_model.modes) == list(direct.modes)
    for name, mode in direct.modes.items():
        assert [str(f) for f in yaml_model.modes[name].flow] == [str(f) for f in mode.flow]
        assert mode.timeless == yaml_model.modes[name].timeless
    assert np.array_equal(yaml_model.initial.low, direct.initial.low)
    code = main(["check", str(xml), str(cfg), "-b", "montecarlo", "-o", "samples=40", "-o", "search_rounds=0"])
    yaml_code = main(["check", str(tmp_path / "models" / "GRBX01-MES01.yaml"),
                      str(tmp_path / "properties" / "GRBX01-MES01.yaml"), "-b", "montecarlo",
                      "-o", "samples=40", "-o", "search_rounds=0"])
    out = capsys.readouterr().out
    assert code == yaml_code == 3                       # undecided: Monte Carlo never says SAFE
    assert "GRBX01-MES01 " in out and "UNKNOWN" in out and "UNSAFE" not in out


# ---------------------------------------------------------------- hand-written cases
HEADER = '<?xml version="1.0"?>\n<sspaceex xmlns="http://www-verimag.imag.fr/xml-namespaces/sspaceex" version="0.2">\n'


def write(tmp_path, body: str, cfg: str):
    (tmp_path / "m.xml").write_text(HEADER + body + "</sspaceex>\n")
    (tmp_path / "m.cfg").write_text(cfg)
    return tmp_path / "m.xml", tmp_path / "m.cfg"


NETWORK = '''<component id="a">
 <param name="x" type="real" local="false" dynamics="any"/>
 <param name="k" type="real" local="false" dynamics="const"/>
 <param name="go" type="label" local="false"/>
 <location id="1" name="off"><invariant>x &lt;= 1</invariant><flow>x' == k</flow></location>
 <location id="2" name="on"><invariant>true</invariant><flow>x' == -k*x</flow></location>
 <transition source="1" target="2"><label>go</label><guard>x &gt;= 1</guard><assignment>x := 2*x</assignment></transition>
</component>
<component id="b">
 <param name="y" type="real" local="false" dynamics="any"/>
 <param name="go" type="label" local="false"/>
 <location id="1" name="idle"><flow>y' == 0</flow></location>
 <location id="2" name="busy"><flow>y' == 1</flow></location>
 <location id="3" name="never"><flow>y' == 2</flow></location>
 <transition source="1" target="2" asap="true"><label>go</label></transition>
</component>
<component id="sys">
 <param name="x" type="real" local="false" dynamics="any"/>
 <param name="y" type="real" local="false" dynamics="any"/>
 <param name="go" type="label" local="false"/>
 <bind component="a" as="A"><map key="x">x</map><map key="k">0.5</map><map key="go">go</map></bind>
 <bind component="b" as="B"><map key="y">y</map><map key="go">go</map></bind>
</component>
'''


def test_network_synchronises_on_labels_and_keeps_reachable_locations(tmp_path):
    xml, cfg = write(tmp_path, NETWORK, 'system = sys\ninitially = "loc(A)==off & loc(B)==idle & '
                     '0 <= x <= 0.5 & y == 0"\nforbidden = "loc(B) == busy & y >= 3"\ntime-horizon = 4\n')
    model, props, _ = load_spaceex(xml, cfg)
    assert list(model.modes) == ["off__idle", "on__busy"]           # 'never' is unreachable
    (tr,) = model.transitions
    assert (tr.source, tr.target, tr.urgent, str(tr.reset[0])) == ("off__idle", "on__busy", True, "2*x")
    assert float(model.modes["off__idle"].flow[0]) == 0.5
    assert props[0].raw == {"id": "m", "kind": "safety", "modes": ["on__busy"], "avoid": ["y >= 3"],
                            "description": "forbidden = loc(B) == busy & y >= 3"}


def test_a_label_no_transition_of_a_declaring_component_takes_blocks_and_is_reported(tmp_path, capsys):
    """Component b declares 'go' but takes it nowhere: a's 'go' transitions can never
    synchronise. The composition has none (SpaceEx semantics), and import and check say why."""
    idle_b = NETWORK.replace('<transition source="1" target="2" asap="true"><label>go</label></transition>\n', "")
    xml, cfg = write(tmp_path, idle_b, 'system = sys\ninitially = "loc(A)==off & loc(B)==idle & '
                     '0 <= x <= 0.5 & y == 0"\nforbidden = "y >= 3"\ntime-horizon = 4\n')
    model, _, _ = load_spaceex(xml, cfg)
    assert list(model.modes) == ["off__idle"] and not model.transitions
    for argv in (["import", str(xml), str(cfg), "--out", str(tmp_path / "out")],
                 ["check", str(xml), str(cfg), "-b", "montecarlo", "-o", "samples=20"]):
        main(argv)
        err = capsys.readouterr().err.splitlines()
        assert err[0] == (f"warning: {xml}: label 'go': B declares it but no transition of it takes it, so "
                          "the transitions labelled 'go' in A are never taken (synchronisation on shared labels)")
        # and so the runs reaching x = 1 in off__idle stop there
        assert err[1:] == [f"warning: {xml}: modes.off__idle.invariant: runs of mode 'off__idle' that reach the "
                           "boundary of x <= 1 stop there (no transition out of it is enabled there): nothing "
                           "after is checked"]
    xml, cfg = write(tmp_path, NETWORK, 'system = sys\ninitially = "loc(A)==off & loc(B)==idle & '
                     '0 <= x <= 0.5 & y == 0"\nforbidden = "y >= 3"\ntime-horizon = 4\n')
    main(["import", str(xml), str(cfg), "--out", str(tmp_path / "out2")])
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("extra,message", [
    ("t == 0", "unknown name 't' (the system's variables: x, y)"),
    ("loc(C) == c", "loc(C): no component instance 'C' (the system's: A, B)"),
])
def test_names_the_system_lacks_in_initially_are_bad_input(tmp_path, extra, message):
    """Not dropped: the initial set would silently differ from the one written."""
    xml, cfg = write(tmp_path, NETWORK, 'system = sys\ninitially = "loc(A)==off & loc(B)==idle & '
                     f'x == 0 & y == 0 & {extra}"\ntime-horizon = 1\n')
    with pytest.raises(InputError) as info:
        load_spaceex(xml, cfg)
    assert str(info.value) == f"{cfg}:2: initially: {message}"


@pytest.mark.parametrize("body,cfg,needle", [
    (NETWORK.replace("x' == k", "x' == k | x' == 1"), "", "disjunction"),
    (NETWORK.replace("x' == k", "x' &gt;= x"), "", "flow: construct"),
    (NETWORK.replace("x' == k", "x' &gt;= k"), "", "flow: 'x'' is bounded on one side only"),
    (NETWORK.replace("x := 2*x", "x + 1 := 2"), "", "assignment: construct"),
    (NETWORK.replace('<location id="3"', '<foo/><location id="3"'), "", "construct <foo>"),
    (NETWORK.replace('type="label" local="false"/>\n <location id="1" name="idle"',
                     'type="int" local="false"/>\n <location id="1" name="idle"'), "", 'type="int"'),
    (NETWORK.replace("x' == k", "x' == foo(k)"), "", "function 'foo'"),
    (NETWORK.replace("x' == k", "x' == k @ 2"), "", "unexpected character"),
    (NETWORK.replace('<map key="k">0.5</map>', ''), "", "constant 'A.k' has no value"),
    (NETWORK, 'initially = "x == 0 | x == 1"\n', "union of initial sets"),
    (NETWORK, 'initially = "x == 0 & y == 0"\nforbidden = "x <= "\n', "empty side"),
    (NETWORK.replace("</component>\n<component id=\"b\">", "<bogus>", 1), "", "invalid XML"),
    (NETWORK.replace("x' == k", "x' == 0 5*k"), "", "missing operator between '0' and '5'"),
    (NETWORK, 'initially = "x == 0 & y == 0"\nforbidden = "x >= 6 2"\n', "missing operator between '6' and '2'"),
    (NETWORK, 'initially = "x == 0 & y x == 0"\n', "missing operator between 'y' and 'x'"),
])
def test_constructs_outside_scope_name_the_construct_and_line(tmp_path, capsys, body, cfg, needle):
    text = 'system = sys\ntime-horizon = 1\n' + (cfg or 'initially = "loc(A)==off & loc(B)==idle & x == 0 & y == 0"\n')
    xml, cfgp = write(tmp_path, body, text)
    assert main(["check", str(xml), str(cfgp), "-b", "montecarlo"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
    assert err[0].startswith("reach: ") and (":" in err[0].split(" ", 1)[1])
    assert any(ch.isdigit() for ch in err[0].split(":")[2]) or "cfg" in err[0]


def test_entity_declarations_are_refused(tmp_path, capsys):
    (tmp_path / "m.xml").write_text('<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY a "aaaaaaaaaa">'
                                    '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">]>\n<sspaceex>&b;</sspaceex>\n')
    (tmp_path / "m.cfg").write_text("system = s\n")
    assert main(["import", str(tmp_path / "m.xml"), str(tmp_path / "m.cfg"), "--out", str(tmp_path)]) == 2
    assert "document type declarations" in capsys.readouterr().err


def test_a_misspelt_required_cfg_key_is_named_at_its_line(tmp_path, capsys):
    text = ('system = sys\n# horizon\ntime-horizn = 1\n'
            'initially = "loc(A)==off & loc(B)==idle & x == 0 & y == 0"\nforbidden = "x >= 5"\n')
    xml, cfg = write(tmp_path, NETWORK, text)
    assert main(["check", str(xml), str(cfg), "-b", "montecarlo"]) == 2
    assert capsys.readouterr().err.strip() == (f"reach: {cfg}:3: unknown key 'time-horizn' (a misspelling "
                                               "of 'time-horizon'? as written it would be ignored)")


@pytest.mark.parametrize("command", ["check", "import"])
@pytest.mark.parametrize("right_one_too", [False, True])
def test_a_misspelt_forbidden_key_is_named_at_its_line(tmp_path, capsys, command, right_one_too):
    """``forbidden`` may be absent (``reach import`` converts the model alone): a key spelt like
    it is refused where it stands, also beside a correct ``forbidden`` (its set would be lost)."""
    text = ('system = sys\ntime-horizon = 1\n'
            'initially = "loc(A)==off & loc(B)==idle & x == 0 & y == 0"\nforbiden = "x >= 5"\n'
            + ('forbidden = "y >= 5"\n' if right_one_too else ''))
    xml, cfg = write(tmp_path, NETWORK, text)
    args = ["-b", "montecarlo"] if command == "check" else ["--out", str(tmp_path / "out")]
    assert main([command, str(xml), str(cfg)] + args) == 2
    assert capsys.readouterr().err.strip() == (f"reach: {cfg}:4: unknown key 'forbiden' (a misspelling "
                                               "of 'forbidden'? as written it would be ignored)")


def test_spacex_options_spelt_like_read_keys_are_kept(tmp_path):
    """SpaceEx's own ``local-time-horizon`` is close to ``time-horizon`` but is no misspelling."""
    cfg = parse_cfg("system = s\nlocal-time-horizon = 2\ntime-horizon = 1\n", "m.cfg")
    assert cfg.number("time-horizon") == 1 and cfg.text("local-time-horizon") == "2"


def test_missing_cfg_is_bad_input(tmp_path):
    (tmp_path / "m.xml").write_text(HEADER + NETWORK + "</sspaceex>\n")
    with pytest.raises(InputError, match="no .cfg"):
        documents(tmp_path / "m.xml")


def test_write_yaml_sanitises_the_name(tmp_path):
    xml, cfg = write(tmp_path, NETWORK, 'system = sys\ninitially = "loc(A)==off & loc(B)==idle & x == 0 & y == 0"\n'
                     'time-horizon = 1\n')
    docs = documents(xml, cfg, name="../../evil name")
    model_path, prop_path = write_yaml(docs, tmp_path / "out")
    assert model_path.parent == tmp_path / "out" / "models" and prop_path is None


THERMOSTAT = '''<component id="heater">
 <param name="T" type="real" local="false" dynamics="any"/>
 <param name="d" type="real" local="false" dynamics="any" controlled="false"/>
 <location id="1" name="on"><invariant>T &lt;= 21 &amp; -0.2 &lt;= d &lt;= 0.2</invariant>
  <flow>T' == -0.1*(T - 10) + 3 + d</flow></location>
 <location id="2" name="off"><invariant>T &gt;= 19 &amp;&amp; -0.2 &lt;= d &amp; d &lt;= 0.2</invariant>
  <flow>T' == -0.1*(T - 10) + d</flow></location>
 <transition source="1" target="2"><guard>T &gt;= 21</guard></transition>
 <transition source="2" target="1"><guard>T &lt;= 19</guard></transition>
</component>
'''


def test_thermostat_violation_is_found_saved_and_replayed(tmp_path, capsys):
    """Hysteresis thermostat with a disturbance input: T <= 20.5 is violated (it heats to 21)."""
    xml, cfg = write(tmp_path, THERMOSTAT, 'system = heater\ninitially = "loc(heater) == on & T == 20"\n'
                     'forbidden = "T >= 20.5"\ntime-horizon = 60\n')
    model, props, _ = load_spaceex(xml, cfg)
    assert model.varying_inputs[0].name == "d" and len(model.transitions) == 2
    out = tmp_path / "cex"
    assert main(["check", str(xml), str(cfg), "-b", "montecarlo", "--counterexamples", str(out)]) == 1
    text = capsys.readouterr().out
    assert "UNSAFE" in text
    (saved,) = out.glob("*.json")
    assert main(["replay", str(saved)]) == 1                    # it violates the property
    assert "replayed" in capsys.readouterr().out
    # independent: no run heats faster than with d = 0.2, whose T' = -0.1 (T - 10) + 3.2 reaches
    # 20.5 at t = 10 ln((42 - 20) / (42 - 20.5)) (closed form of the linear ODE)
    import json
    data = json.loads(saved.read_text())
    assert data["violation_time"] >= 10 * np.log(22 / 21.5) - 1e-9
    assert data["violation_state"][0] >= 20.5 and data["input_signal"]["inputs"] == ["d"]


# ---------------------------------------------------------------- the formula parser
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import sympy  # noqa: E402

from reach.errors import Where  # noqa: E402
from reach.model.expr import parse_expr  # noqa: E402
from reach.model.spaceex.formula import Relation, parse_formula, to_python  # noqa: E402

ATOMS = st.tuples(st.sampled_from(["x", "y", "x + y", "2*x - y"]), st.sampled_from(["<=", "<", ">=", ">"]),
                  st.integers(-3, 3))


def formulas(depth=3):
    leaf = ATOMS.map(lambda a: (f"{a[0]} {a[1]} {a[2]}", lambda x, y, a=a: _cmp(eval_expr(a[0], x, y), a[1], a[2])))
    return st.recursive(leaf, lambda sub: st.tuples(sub, st.sampled_from(["&", "&&", "|"]), sub).map(_join),
                        max_leaves=8)


def eval_expr(text, x, y):
    return {"x": x, "y": y, "x + y": x + y, "2*x - y": 2 * x - y}[text]


def _cmp(a, op, b):
    return {"<=": a <= b, "<": a < b, ">=": a >= b, ">": a > b}[op]


def _join(t):
    (ta, fa), op, (tb, fb) = t
    if op == "|":
        return f"({ta}) | ({tb})", lambda x, y: fa(x, y) or fb(x, y)
    return f"({ta}) {op} ({tb})", lambda x, y: fa(x, y) and fb(x, y)


@settings(max_examples=60, deadline=None)
@given(formulas(), st.lists(st.tuples(st.integers(-4, 4), st.integers(-4, 4)), min_size=5, max_size=10))
def test_formulas_become_an_equivalent_dnf(formula, points):
    text, truth = formula
    dnf = parse_formula(text)
    for x, y in points:
        def holds(rel: Relation):
            a = to_python(rel.parts[0], str)
            b = to_python(rel.parts[1], str)
            env = {"x": sympy.Integer(x), "y": sympy.Integer(y)}
            return _cmp(float(parse_expr(a, env, Where())), rel.ops[0], float(parse_expr(b, env, Where())))
        assert any(all(holds(r) for r in term) for term in dnf) == truth(x, y)


def test_dotted_cfg_name_gives_a_valid_property_id_and_json(tmp_path, capsys):
    xml, cfg = write(tmp_path, NETWORK, 'system = sys\ninitially = "loc(A)==off & loc(B)==idle & x == 0 & y == 0"\n'
                     'forbidden = "x >= 5"\ntime-horizon = 1\n')
    dotted = tmp_path / "m.4th_order.cfg"
    dotted.write_text(cfg.read_text())
    assert main(["check", str(xml), str(dotted), "-b", "montecarlo", "--json", "-o", "samples=20"]) == 3
    import json
    (row,) = json.loads(capsys.readouterr().out)
    assert row["property"] == "m_4th_order" and row["status"] == "unknown"


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_mangled_models_are_bad_input_or_load(tmp_path_factory, data):
    """Cut, duplicate or replace a span of a valid XML or cfg: it loads or is one InputError."""
    tmp = tmp_path_factory.mktemp("mangled")
    xml_text = HEADER + NETWORK + "</sspaceex>\n"
    cfg_text = ('system = sys\ninitially = "loc(A)==off & loc(B)==idle & 0 <= x <= 0.5 & y == 0"\n'
                'forbidden = "loc(B) == busy & y >= 3 | x >= 4"\ntime-horizon = 4\n')
    which = data.draw(st.sampled_from(["xml", "cfg"]))
    text = xml_text if which == "xml" else cfg_text
    i = data.draw(st.integers(0, len(text) - 1))
    j = data.draw(st.integers(i, min(len(text), i + 12)))
    piece = data.draw(st.sampled_from(["", text[i:j] * 2, "&", "(", ")", "'", "<", "==", "loc(", "|", "\"", "x"]))
    text = text[:i] + piece + text[j:]
    (tmp / "m.xml").write_text(xml_text if which == "cfg" else text)
    (tmp / "m.cfg").write_text(cfg_text if which == "xml" else text)
    try:
        load_spaceex(tmp / "m.xml", tmp / "m.cfg")
    except InputError as exc:
        assert str(exc).count("\n") == 0


def _same_automaton(a, b):
    assert a.state == b.state and list(a.modes) == list(b.modes) and a.horizon == b.horizon
    for name, mode in a.modes.items():
        other = b.modes[name]
        assert [sympy.srepr(f) for f in mode.flow] == [sympy.srepr(f) for f in other.flow]
        assert [(sympy.srepr(c.g), c.strict) for c in mode.invariant] == \
            [(sympy.srepr(c.g), c.strict) for c in other.invariant]
        assert mode.timeless == other.timeless
    assert [(t.name, t.source, t.target, t.urgent, [sympy.srepr(c.g) for c in t.guard],
             {k: sympy.srepr(v) for k, v in t.reset.items()}) for t in a.transitions] == \
        [(t.name, t.source, t.target, t.urgent, [sympy.srepr(c.g) for c in t.guard],
          {k: sympy.srepr(v) for k, v in t.reset.items()}) for t in b.transitions]
    assert a.initial.mode == b.initial.mode
    assert np.array_equal(a.initial.low, b.initial.low) and np.array_equal(a.initial.high, b.initial.high)
    assert (a.initial.polytope is None) == (b.initial.polytope is None)
    assert a.bounded_inputs == b.bounded_inputs


@pytest.mark.parametrize("xml,cfg", [
    ("Gearbox/GRBX01-MES01.xml", "Gearbox/GRBX01-MES01.cfg"),
    ("Powertrain/drivetrain_2theta_30percent.xml", "Powertrain/drivetrain_2theta_30percent.cfg"),
    ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND42-forbidden.cfg"),
    ("FilteredOscillator/filtered_oscillator.xml", "FilteredOscillator/filtered_oscillator.4th_order.cfg"),
    ("Rendezvous_ARCH18/SRA01-SR0_.xml", "Rendezvous_ARCH18/SRA01-SR0_-LOS.cfg"),
    ("Building/BLDF01.xml", "Building/BLDF01-BDU02.cfg"),
])
def test_import_round_trip_is_the_same_automaton_and_property(tmp_path, xml, cfg):
    from reach.spec import bind, load_properties
    direct, props, docs = load_spaceex(ROOT / xml, ROOT / cfg)
    model_file, prop_file = write_yaml(docs, tmp_path)
    again = load_model(model_file)
    _same_automaton(direct, again)
    if prop_file is not None:
        reread = load_properties(prop_file)
        assert [p.id for p in reread] == [p.id for p in props]
        for p, q in zip(props, reread):
            bp, bq = bind(p, direct), bind(q, again)
            assert bp.modes == bq.modes
            assert {m: [[sympy.srepr(c.g) for c in piece] for piece in bp.pieces[m]] for m in bp.modes} == \
                {m: [[sympy.srepr(c.g) for c in piece] for piece in bq.pieces[m]] for m in bq.modes}


def test_folders_and_wrong_suffixes_are_bad_input(tmp_path, capsys):
    (tmp_path / "m.xml").mkdir()
    (tmp_path / "m.txt").write_text("system = s\n")
    assert main(["import", str(tmp_path / "m.xml"), str(tmp_path / "m.txt"), "--out", str(tmp_path)]) == 2
    assert ".cfg" in capsys.readouterr().err
    (tmp_path / "m.cfg").write_text("system = s\n")
    assert main(["import", str(tmp_path / "m.xml"), str(tmp_path / "m.cfg"), "--out", str(tmp_path)]) == 2
    assert "a folder, not a file" in capsys.readouterr().err


NESTED = '''<component id="lag">
 <param name="u" type="real" local="false" dynamics="any"/>
 <param name="z" type="real" local="true" dynamics="any"/>
 <param name="y" type="real" local="false" dynamics="any"/>
 <param name="c" type="real" local="false" dynamics="const"/>
 <location id="1" name="run"><flow>z' == c*(u - z) &amp; y' == z - y</flow></location>
</component>
<component id="pair">
 <param name="u" type="real" local="false" dynamics="any"/>
 <param name="y" type="real" local="false" dynamics="any"/>
 <param name="mid" type="real" local="true" dynamics="any"/>
 <bind component="lag" as="first"><map key="u">u</map><map key="y">mid</map><map key="c">2</map></bind>
 <bind component="lag" as="second"><map key="u">first.z</map><map key="y">y</map><map key="c">3</map></bind>
</component>
<component id="top">
 <param name="y" type="real" local="false" dynamics="any"/>
 <param name="s" type="real" local="false" dynamics="any"/>
 <location id="1" name="idle"><flow>s' == 1</flow></location>
</component>
<component id="sys">
 <param name="y" type="real" local="false" dynamics="any"/>
 <param name="s" type="real" local="false" dynamics="any"/>
 <bind component="pair" as="p"><map key="u">s</map><map key="y">y</map></bind>
 <bind component="top" as="clock"><map key="s">s</map><map key="y">y</map></bind>
</component>
'''


def test_nested_binds_rename_locals_per_instance_and_map_dotted_names(tmp_path):
    xml, cfg = write(tmp_path, NESTED, 'system = sys\ninitially = "y == 0 & s == 0 & p.mid == 0 & '
                     'first.z == 0 & p.second.z == 1"\nforbidden = "second.z >= 2"\ntime-horizon = 1\n')
    model, props, _ = load_spaceex(xml, cfg)
    # y, s (the system's), then the instance locals: p.mid, p.first.z, p.second.z
    assert sorted(model.state) == ["mid", "p_first_z", "p_second_z", "s", "y"]   # z: unique by path
    flows = {name: str(f) for name, f in zip(model.state, model.modes["run__run__idle"].flow)}
    assert flows["p_first_z"] == "-2*p_first_z + 2*s"            # u of 'first' is the system's s
    assert flows["p_second_z"] == "3*p_first_z - 3*p_second_z"   # u of 'second' is first.z (dotted map)
    assert flows["mid"] == "-mid + p_first_z" and flows["y"] == "p_second_z - y"
    i = model.state.index("p_second_z")
    assert model.initial.low[i] == model.initial.high[i] == 1
    assert props[0].raw["avoid"] == ["p_second_z >= 2"]


def test_cfg_values_comments_quotes_and_lines():
    cfg = parse_cfg('# analysis\nsystem = "sys"\ninitially = "x >= 1 &\n  y == 2"  # two lines\n'
                    '\nforbidden = x >= 3 # a comment\ntime-horizon = 2.5\n', "a.cfg")
    assert cfg.text("system") == "sys" and cfg.text("initially") == "x >= 1 &\n  y == 2"
    assert (cfg.line("forbidden"), cfg.text("forbidden"), cfg.number("time-horizon")) == (6, "x >= 3", 2.5)
    assert cfg.line("time-horizon") == 7
    with pytest.raises(InputError, match=r"duplicate key 'time-horizon' \(first on line 1\)") as info:
        parse_cfg("time-horizon = 1\ntime-horizon = 2\n", "b.cfg")
    assert info.value.line == 2
    # an option only SpaceEx reads may be given twice (the published drivetrain cfg's 'directions')
    assert parse_cfg("directions = oct\ndirections = box\n", "b.cfg").text("directions") == "box"
    with pytest.raises(InputError, match="unterminated"):
        parse_cfg('a = "1\n', "c.cfg")
    with pytest.raises(InputError, match="closing quote missing on this line") as info:
        parse_cfg('system = "s"\nforbidden = "x >= 2\nscenario = "supp"\n', "e.cfg")
    assert info.value.line == 2
    with pytest.raises(InputError, match="expected a number") as info:
        parse_cfg("time-horizon = soon\n", "d.cfg").number("time-horizon")
    assert info.value.line == 1


@settings(max_examples=60, deadline=None)
@given(st.dictionaries(st.from_regex(r"[a-z][a-z0-9-]{0,8}", fullmatch=True),
                       st.from_regex(r"[A-Za-z0-9 <>=&|.()+*-]{0,30}", fullmatch=True), max_size=6),
       st.booleans())
def test_cfg_reads_back_what_was_written(values, quoted):
    from reach.model.spaceex.cfg import parse_cfg
    text = "".join(f'{k} = "{v}"\n' if quoted else f"{k} = {v}\n" for k, v in values.items())
    cfg = parse_cfg(text, "e.cfg")
    assert {k: cfg.text(k) for k in values} == {k: (v if quoted else v.strip()) for k, v in values.items()}


BALL = '''<component id="ball">
  <param name="x" type="real" local="false" d1="1" d2="1" dynamics="any"/>
  <param name="v" type="real" local="false" d1="1" d2="1" dynamics="any"/>
  <location id="1" name="air"><invariant>x &gt;= 0</invariant><flow>x' == v &amp; v' == -9.81</flow></location>
  <location id="2" name="hit"><flow>x' == 0 &amp; v' == 0</flow></location>
  <transition source="1" target="2"><guard>x &lt;= 0</guard></transition>
</component>
'''


@pytest.mark.parametrize("horizon, code", [(0.44, 0), (0.46, 1)])
def test_a_forbidden_location_reads_as_never_in_it(tmp_path, capsys, horizon, code):
    """``forbidden = "loc(ball) == hit"`` forbids the mode itself; the ball reaches it at
    sqrt(2 / 9.81) = 0.4515. The report says so, without the stored ``0 <= -1`` or a margin."""
    xml, cfg = write(tmp_path, BALL, f'system = ball\ninitially = "loc(ball)==air & x == 1 & v == 0"\n'
                                     f'forbidden = "loc(ball)==hit"\ntime-horizon = {horizon}\n')
    assert main(["check", str(xml), str(cfg), "-b", "star", "--counterexamples", str(tmp_path)]) == code
    out = capsys.readouterr().out
    assert "never in hit" in out and "0 <= -1" not in out and "margin" not in out
    if code:
        assert "violated at t=0.4515 in hit" in out


def test_imported_model_keeps_the_cfg_hints_for_star(tmp_path):
    """The cfg's ``iter-max`` bounds star's jumps on the SpaceEx files and on their import alike
    (the notes carry it), so both give the same verdicts: the ball lands in 'hit' at
    sqrt(2 / 9.81) = 0.4515, past the horizon 0.44 but not past 0.5, where iter-max 0 leaves it
    UNKNOWN (one jump allowed: UNSAFE). The sampling time sets no step: star keeps its own
    (horizon / 60)."""
    from reach.checking import check_files, check_spaceex
    for horizon, status in [(0.44, "SAFE"), (0.5, "UNKNOWN")]:
        xml, cfg = write(tmp_path, BALL, 'system = ball\ninitially = "loc(ball)==air & x == 1 & v == 0"\n'
                                         f'forbidden = "loc(ball)==hit"\ntime-horizon = {horizon}\n'
                                         'sampling-time = 0.001\niter-max = 0\n')
        direct = check_spaceex(xml, cfg, "star")[0][0]
        assert main(["import", str(xml), str(cfg), "--out", str(tmp_path / "out")]) == 0
        imported = check_files(tmp_path / "out/models/m.yaml", tmp_path / "out/properties/m.yaml", "star")[0]
        for result in (direct, imported):
            assert result.status.value == status and result.details["step"] == pytest.approx(horizon / 60)
    assert check_files(tmp_path / "out/models/m.yaml", tmp_path / "out/properties/m.yaml", "star",
                       {"max_jumps": 1})[0].status.value == "UNSAFE"        # an explicit option wins


@pytest.mark.parametrize("notes, message", [("{sampling-time: -1}", "expected a positive time"),
                                            ("{iter-max: 2.5}", "expected a whole number"),
                                            ("{sampling-time: fast}", "expected a number")])
def test_bad_hints_in_notes_are_bad_input(tmp_path, notes, message):
    (tmp_path / "m.yaml").write_text("name: m\nstate: [x]\nmodes: {a: {flow: {x: -x}}}\ninitial: {mode: a, box: {x: 1}}\n"
                                     f"horizon: 1\nnotes: {notes}\n")
    with pytest.raises(InputError, match=f"notes.*{message}"):
        load_model(tmp_path / "m.yaml")


DRIVEN = '''<component id="plant">
  <param name="x" type="real" local="false" d1="1" d2="1" dynamics="any"/>
  <param name="u" type="real" local="false" d1="1" d2="1" dynamics="any" controlled="false"/>
  <location id="1" name="run"><flow>x' == -x + u</flow></location>
</component>
<component id="sys">
  <param name="x" type="real" local="false" d1="1" d2="1" dynamics="any"/>
  <bind component="plant" as="p"><map key="x">x</map><map key="u">U</map></bind>
</component>
'''


@pytest.mark.parametrize("u, code", [("2", 1), ("0.5", 0)])
def test_an_input_mapped_to_a_number_is_that_number(tmp_path, u, code):
    """``<map key="u">2</map>`` fixes the input u (no flow sets it) in the instance: x' = -x + u
    from x = 0 reaches u (1 - e^-3) at t = 3, 1.90 for u = 2 and 0.475 for u = 0.5."""
    xml, cfg = write(tmp_path, DRIVEN.replace("U", u), 'system = sys\ninitially = "x == 0"\n'
                     'forbidden = "x >= 1"\ntime-horizon = 3\n')
    assert main(["check", str(xml), str(cfg), "-b", "star", "--counterexamples", str(tmp_path)]) == code


def test_a_variable_a_flow_sets_cannot_be_mapped_to_a_number(tmp_path, capsys):
    xml, cfg = write(tmp_path, DRIVEN.replace("<map key=\"x\">x</map>", "<map key=\"x\">1</map>")
                     .replace("U", "0"), 'system = sys\ninitially = "x == 0"\nforbidden = "x >= 1"\n'
                     'time-horizon = 3\n')
    assert main(["check", str(xml), str(cfg), "-b", "star"]) == 2
    assert capsys.readouterr().err.strip() == (
        f"reach: {xml}:6: component 'plant': location 'run': flow: the variable 'x' is mapped to the number 1 "
        "(at instance 'p'), but this flow sets it (only a variable that no flow or assignment sets, an input, "
        "may be fixed to a number)")


def test_a_variable_an_assignment_sets_cannot_be_mapped_to_a_number(tmp_path, capsys):
    """The same refusal names the transition whose assignment sets the variable."""
    jumping = DRIVEN.replace("<flow>x' == -x + u</flow></location>",
                             "<flow>x' == -x</flow></location>\n  <param name=\"k\" type=\"real\" local=\"false\" "
                             "d1=\"1\" d2=\"1\" dynamics=\"any\"/>\n  <location id=\"2\" name=\"rest\">"
                             "<flow>x' == 0</flow></location>\n  <transition source=\"1\" target=\"2\">"
                             "<guard>x &lt;= 0.5</guard><assignment>k := 2</assignment></transition>")
    xml, cfg = write(tmp_path, jumping.replace("<map key=\"u\">U</map>", "<map key=\"u\">0</map><map key=\"k\">1</map>"),
                     'system = sys\ninitially = "x == 1"\nforbidden = "x >= 2"\ntime-horizon = 3\n')
    assert main(["check", str(xml), str(cfg), "-b", "star"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"reach: {xml}:")
    assert ": component 'plant': transition run -> rest: assignment: the variable 'k' is mapped to the number 1" in err


def test_an_alias_longer_than_a_page_imports_and_checks(tmp_path):
    """An output defined in the invariant over 100 states with 40-digit coefficients (as the
    ISS's y1..y3 over 270), 4900 characters: the imported model and its YAML check alike.
    Closed form: x_k' = -x_k from [0.9, 1], so y = sum c_k x_k peaks at sum c_k at t = 0."""
    n = 100
    coef = [f"{0.5 + k / (3 * n):.40f}" for k in range(n)]
    params = "".join(f'<param name="x{k}" type="real" local="false" dynamics="any"/>\n' for k in range(n))
    y = " + ".join(f"{c}*x{k}" for k, c in enumerate(coef))
    assert len(y) > 4500
    flow = " &amp; ".join(f"x{k}' == -x{k}" for k in range(n))
    body = (f'<component id="sys">{params}<param name="y" type="real" local="false" dynamics="any"/>\n'
            f'<location id="1" name="run"><invariant>y == {y}</invariant>'
            f'<flow>{flow}</flow></location></component>\n')
    total = sum(float(c) for c in coef)
    initially = " & ".join(f"0.9 <= x{k} & x{k} <= 1" for k in range(n))
    for bound, code in [(1.01 * total, 0), (0.99 * total, 1)]:
        xml, cfg = write(tmp_path, body, f'system = sys\ninitially = "{initially}"\n'
                                         f'forbidden = "y >= {bound!r}"\ntime-horizon = 1\n')
        assert main(["check", str(xml), str(cfg), "-b", "star"]) == code
    out = tmp_path / "out"
    assert main(["import", str(xml), str(cfg), "--out", str(out)]) == 0
    assert main(["check", str(out / "models/m.yaml"), str(out / "properties/m.yaml"), "-b", "star"]) == 1


@pytest.mark.parametrize("line, message", [("sampling-time = -1", "sampling-time: expected a positive time, got '-1'"),
                                           ("iter-max = 2.5", "iter-max: expected a whole number, -1 for no bound, got '2.5'")])
@pytest.mark.parametrize("command", ["check", "import"])
def test_bad_cfg_hints_are_bad_input_at_their_cfg_line(tmp_path, capsys, line, message, command):
    xml, cfg = write(tmp_path, BALL, 'system = ball\ninitially = "loc(ball)==air & x == 1 & v == 0"\n'
                                     f'forbidden = "loc(ball)==hit"\ntime-horizon = 1\n{line}\n')
    args = ["-b", "star"] if command == "check" else ["--out", str(tmp_path / "out")]
    assert main([command, str(xml), str(cfg)] + args) == 2
    assert capsys.readouterr().err.strip() == f"reach: {cfg}:5: {message}"
