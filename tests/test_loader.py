"""Model and property loaders: the shipped files, and one clear line for every kind of bad input."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reach.errors import InputError
from reach.model import load_model
from reach.spec import bind, load_properties
from documents import yaml_values

MODELS = sorted(p for p in Path("models").glob("*.yaml") if not p.name.startswith("_"))
GOOD = Path("models/SRA02.yaml").read_text()


def test_every_shipped_model_loads_and_binds_every_property_file():
    prop_files = sorted(Path("properties").glob("*.yaml"))
    assert len(MODELS) >= 12
    for path in MODELS:
        model = load_model(path)
        assert model.horizon > 0
        for pf in prop_files:
            for prop in load_properties(pf):
                try:
                    bind(prop, model)
                except InputError as exc:      # a property may not fit a model (unknown name)
                    assert "unknown name" in str(exc) or "horizon" in str(exc)


def test_rendezvous_family_shares_its_template():
    sra, sru = load_model("models/SRA03.yaml"), load_model("models/SRU02.yaml")
    assert [t.window for t in sra.transitions if t.window] == [(4, 120.0, 145.0)] * 2
    assert [t.window for t in sru.transitions if t.window] == [(4, 0.0, 260.0)] * 2
    assert (sra.horizon, sru.horizon) == (240.0, 300.0)
    assert sra.is_linear and not load_model("models/SRNA01.yaml").is_linear
    assert set(load_model("models/SRNA01.yaml").modes) == {"approach", "rendezvous"}


def _write(tmp_path, text, name="m.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


# ten kinds of malformed model file, and the line each must print
MALFORMED = [
    ("flow name typo", GOOD.replace("extends: _rendezvous_abort.yaml", "extends: {base}/_rendezvous_abort.yaml")
     .replace("horizon: 240", "horizon: 240\nmodes:\n  passive:\n    flow: {vx: vyy}"),
     ":8: modes.passive.flow.vx: unknown name 'vyy'"),
    ("yaml syntax", "name: x\nstate: [x, y\n", "invalid YAML"),
    ("missing field", "name: x\nstate: [x]\nmodes: {a: {flow: {x: 1}}}\n", "missing required field 'initial'"),
    ("unknown top field", "name: x\nhorizont: 3\n", "unknown field 'horizont'"),
    ("code injection", "name: x\nstate: [x]\nmodes: {a: {flow: {x: \"__import__('os').getcwd()\"}}}\n"
     "initial: {mode: a, box: {x: 0}}\nhorizon: 1\n", "only plain function calls"),
    ("wrong unit", "name: x\nstate: [x]\nmodes: {a: {flow: {x: '1[parsec]'}}}\ninitial: {mode: a, box: {x: 0}}\n"
     "horizon: 1\n", "unknown unit 'parsec'"),
    ("unknown mode", "name: x\nstate: [x]\nmodes: {a: {flow: {x: 1}}}\ninitial: {mode: b, box: {x: 0}}\nhorizon: 1\n",
     "initial.mode: unknown mode 'b'"),
    ("empty interval", "name: x\nstate: [x]\nmodes: {a: {flow: {x: 1}}}\ninitial: {mode: a, box: {x: [2, 1]}}\n"
     "horizon: 1\n", "empty interval"),
    ("singular LQR", "name: x\nstate: [x, v]\ninputs: [u]\nmodes:\n  a:\n    flow: {x: v, v: 0}\n"
     "    control: {lqr: {Q: [1, 1], R: [1]}}\ninitial: {mode: a, box: {x: 0, v: 0}}\nhorizon: 1\n",
     "LQR design failed"),
    ("bad covariance", "name: x\nstate: [x]\nmodes: {a: {flow: {x: 0}}}\ninitial: {mode: a, box: {x: 0}}\nhorizon: 1\n"
     "disturbance: {gaussian: {cov: [[1, 2], [2, 1]]}, enters: [x], step: 1}\n", "expected a 1x1 matrix"),
    ("state entered twice", "name: x\nstate: [x, v]\nmodes: {a: {flow: {x: v, v: 0}}}\ninitial: {mode: a, box: {x: 0, v: 0}}\n"
     "horizon: 1\ndisturbance: {gaussian: {mean: [0, 0], cov: [1, 1]}, enters: [v, v], step: 1}\n",
     ":6: disturbance.enters[1]: 'v' is listed twice"),
    ("bad units base", "name: x\nunits: {time: kg}\n", "'kg' is not a unit of time"),
    ("cyclic constants", "name: x\nstate: [x]\nconstants: {a: b, b: a}\n", "cycle"),
    ("control character", "name: x\nstate: [x]\nhorizon: 1\u0086\n", ":3: invalid YAML: special characters are not "
                                                                     "allowed (U+0086)"),
]


@pytest.mark.parametrize("label, text, message", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_model_gives_one_located_line(tmp_path, label, text, message):
    path = _write(tmp_path, text.replace("{base}", str(Path("models").resolve())))
    with pytest.raises(InputError) as err:
        load_model(path)
    line = str(err.value)
    assert "\n" not in line
    assert line.startswith(str(path))
    assert message in line


def test_singular_lqr_via_python_control_matches_reason(tmp_path):
    """The double integrator without input on v is uncontrollable: python-control refuses it."""
    text = MALFORMED[8][1]
    with pytest.raises(InputError, match="modes.a.control.lqr"):
        load_model(_write(tmp_path, text))


PROPS = """properties:
  - id: p
    kind: safety
    require: ["x <= 1"]
"""


@pytest.mark.parametrize("text, message", [
    ("properties: []\n", "non-empty list"),
    ("properties:\n  - id: p\n    kind: liveness\n", "unknown kind 'liveness'"),
    ("properties:\n  - id: p\n    kind: safety\n", "exactly one of 'require' or 'avoid'"),
    ("properties:\n  - id: p\n    kind: reach\n    at: 1\n    target: {box: {x: [0]}}\n", "expected [low, high]"),
    ("properties:\n  - id: p\n    kind: safety\n    require: ['x <= 1']\n  - id: p\n    kind: safety\n"
     "    require: ['x <= 1']\n", "duplicate property id 'p'"),
])
def test_malformed_property_files(tmp_path, text, message):
    with pytest.raises(InputError) as err:
        load_properties(_write(tmp_path, text, "p.yaml"))
    assert message in str(err.value) and str(err.value).startswith(str(tmp_path / "p.yaml"))


def test_property_with_unknown_name_fails_at_binding(tmp_path):
    prop = load_properties(_write(tmp_path, PROPS.replace("x <= 1", "z <= 1"), "p.yaml"))[0]
    with pytest.raises(InputError, match=r"p.yaml:4: properties\[0\].require\[0\]: unknown name 'z'"):
        bind(prop, load_model("models/SRA01.yaml"))


def test_thrust_property_binds_through_the_control_law():
    model = load_model("models/SRA01.yaml")
    thrust = bind(load_properties("properties/rendezvous.yaml")[0], model)
    K1 = np.array([[-28.8287, 0.1005, -1449.9754, 0.0046], [-0.087, -33.2562, 0.00462, -1451.5013]])
    x = np.array([[-925.0, -425.0, 0.0, 0.0, 0.0]])
    violated, depth = thrust.violation("approach")(x)
    u = K1 @ x[0, :4]                                  # the published (rounded) gains
    assert not violated[0]
    assert np.abs(u).max() / 3600 == pytest.approx(7.40, abs=0.01)     # ANCHORS: 7.40 N at t = 0
    assert depth[0] == pytest.approx(36000 - np.abs(u).max(), rel=1e-3)




@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(yaml_values)
def test_random_documents_never_crash_the_loaders(tmp_path, data):
    path = tmp_path / "random.yaml"
    path.write_text(yaml.safe_dump(data))
    for loader in (load_model, load_properties):
        try:
            loader(path)
        except InputError:
            pass


def test_models_are_found_by_path_file_name_or_name(tmp_path):
    from reach.locate import find_model

    (tmp_path / "orbit_a.yaml").write_text("name: Orbit-A\n")
    (tmp_path / "_private.yaml").write_text("name: Hidden\n")
    dirs = (str(tmp_path),)
    assert find_model(str(tmp_path / "orbit_a.yaml"), dirs) == tmp_path / "orbit_a.yaml"
    assert find_model("orbit_a", dirs) == tmp_path / "orbit_a.yaml"
    assert find_model("Orbit-A", dirs) == tmp_path / "orbit_a.yaml"
    for hidden in ("_private", "Hidden"):
        with pytest.raises(InputError, match="no model named"):
            find_model(hidden, dirs)


def test_a_model_looked_up_by_name_skips_what_is_no_regular_file(tmp_path, monkeypatch):
    """``reach check NAME`` reads the ``models/*.yaml`` of the working folder for a ``name:``;
    a FIFO there (which would block the read for ever) and a link to /dev/zero (which would
    fill the memory) are passed over, and the model that has the name is found."""
    import os

    from reach.locate import find_model

    models = tmp_path / "models"
    models.mkdir()
    os.mkfifo(models / "a_pipe.yaml")
    (models / "b_zero.yaml").symlink_to("/dev/zero")
    (models / "c_tank.yaml").write_text("name: wanted\n")
    monkeypatch.chdir(tmp_path)
    assert find_model("wanted") == Path("models") / "c_tank.yaml"


@pytest.mark.parametrize("section, other", [("state: [x, ｘ]", "x"), ("state: [x, ﬁ]", "fi"),
                                            ("state: [x]\nconstants: {ｋ: 2}", "k"),
                                            ("state: [x]\nbounded_inputs: {ｕ: {range: [0, 1]}}", "u")])
def test_a_name_expressions_would_read_as_another_is_refused(tmp_path, section, other):
    """Python's parser reads identifiers in NFKC form: ``x' = ｘ`` would be ``x' = x`` (a SAFE
    of the wrong model), so a declared name not in that form is bad input, naming the form."""
    (tmp_path / "m.yaml").write_text(f"name: m\n{section}\nmodes: {{a: {{flow: {{x: '1'}}}}}}\n"
                                     "initial: {mode: a, box: {x: 0}}\nhorizon: 1\n")
    with pytest.raises(InputError, match=f"expressions read it as '{other}'"):
        load_model(tmp_path / "m.yaml")
