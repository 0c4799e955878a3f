"""Mode names YAML 1.1 reads as booleans: unquoted ``on`` and ``off`` arrive as true and false.
Wherever a mode name is expected (a property's modes, a transition's ends, the initial mode),
the error says so and how to quote it, instead of naming a mode 'True'."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_input import bad_input
from reach.cli import main


HEATER_YAML = """name: heater
state: [T]
modes:
  'on': {flow: {T: "-0.1*(T - 10) + 3"}, invariant: ["T <= 22"]}
  'off': {flow: {T: "-0.1*(T - 10)"}, invariant: ["T >= 18"]}
transitions:
  heat_off: {from: 'on', to: 'off', guard: ["T >= 21"]}
  heat_on: {from: 'off', to: 'on', guard: ["T <= 19"]}
initial: {mode: 'on', box: {T: 20}}
horizon: 30
"""
HEATER_PROPS = "properties:\n  - id: hot\n    kind: safety\n    modes: ['on', 'off']\n    require: ['T <= 23']\n"
BOOLEAN = "mode name read as a boolean by YAML; quote it: "


@pytest.mark.parametrize("edits,where", [
    ([("from: 'on'", "from: on")], f"models.yaml:7: transitions.heat_off.from: {BOOLEAN}'on'"),
    ([("from: 'on'", "from: [on]")], f"models.yaml:7: transitions.heat_off.from: {BOOLEAN}'on'"),
    ([("to: 'off'", "to: off")], f"models.yaml:7: transitions.heat_off.to: {BOOLEAN}'off'"),
    ([("mode: 'on'", "mode: on")], f"models.yaml:9: initial.mode: {BOOLEAN}'on'"),
    ([("mode: 'on'", "mode: on"), ("box: {T: 20}", "constraints: ['T == 20']")],
     f"models.yaml:9: initial.mode: {BOOLEAN}'on'"),
    ([("modes: ['on', 'off']", "modes: [on, off]")], f"props.yaml:4: properties[0].modes[0]: {BOOLEAN}'on'"),
    ([("modes: ['on', 'off']", "modes: ['on', off]")], f"props.yaml:4: properties[0].modes[1]: {BOOLEAN}'off'"),
])
def test_mode_names_yaml_reads_as_booleans_are_named_as_such(tmp_path, capsys, edits, where):
    """YAML 1.1 reads unquoted on/off as true/false: where a mode name is expected, say so."""
    model, props = HEATER_YAML, HEATER_PROPS
    assert main(["check", *map(str, _written(tmp_path, model, props)), "-b", "montecarlo", "-o", "samples=10"]) == 3
    for old, new in edits:
        assert old in model + props
        model, props = model.replace(old, new, 1), props.replace(old, new, 1)
    err = bad_input(["check", *map(str, _written(tmp_path, model, props)), "-b", "montecarlo"], capsys)
    assert err == f"reach: {tmp_path}/{where}"


def _written(folder: Path, model: str, props: str) -> tuple[Path, Path]:
    (folder / "models.yaml").write_text(model)
    (folder / "props.yaml").write_text(props)
    return folder / "models.yaml", folder / "props.yaml"
