"""The input contract on random and perturbed documents: a file either loads into a consistent
model (or property list) or fails with one line ``file:line: field: message`` whose line lies in
the file; nothing else escapes.

Perturbed documents start from the shipped SRA01 model with its template merged in (so every
field is present) and replace one value, anywhere in the tree, by a random YAML value; most of
them reach the deep checks (flows, gains, guards, windows, the initial box) that random
documents never get to.
"""

import re

import numpy as np
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reach.errors import InputError
from reach.model import load_model
from reach.spec import load_properties
from documents import yaml_values

LOCATED = re.compile(r"^(?P<file>[^\n:]+):(?P<line>\d+): (?:[^\n]+: )?[^\n]+$")



def merged_sra01() -> dict:
    """SRA01 with its templates merged by hand (plain dict updates, template first)."""
    def read(name):
        return yaml.safe_load(open(f"models/{name}.yaml"))

    def merge(base, top):
        out = dict(base)
        for k, v in top.items():
            out[k] = merge(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
        return out

    doc = merge(merge(read("_rendezvous_arch"), read("_rendezvous_abort")), read("SRA01"))
    doc.pop("extends", None)
    return doc


def paths(tree, prefix=()):
    """Every path to a value in a nested dict/list document."""
    yield prefix
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from paths(v, prefix + (k,))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            yield from paths(v, prefix + (i,))


BASE = None


def base_document():
    global BASE
    if BASE is None:
        BASE = merged_sra01()
    return BASE


def replaced(tree, path, value):
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(tree, dict):
        return {k: (replaced(v, rest, value) if k == head else v) for k, v in tree.items()}
    return [replaced(v, rest, value) if i == head else v for i, v in enumerate(tree)]


def check_contract(path, loader):
    lines = path.read_text().count("\n") + 1
    try:
        result = loader(path)
    except InputError as err:
        message = str(err)
        match = LOCATED.match(message)
        assert match, message
        assert match["file"] == str(path) and 1 <= int(match["line"]) <= lines, message
        return None
    return result


def consistent(model):
    """What every loaded model guarantees to the back-ends."""
    n = model.n
    assert n == len(model.symbols) and model.horizon > 0 and np.isfinite(model.horizon)
    assert model.initial.mode in model.modes
    assert model.initial.low.shape == model.initial.high.shape == (n,)
    assert np.all(model.initial.low <= model.initial.high)
    for mode in model.modes.values():
        assert len(mode.flow) == n
    for tr in model.transitions:
        assert tr.source in model.modes and tr.target in model.modes


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(yaml_values)
def test_random_documents_load_consistently_or_fail_on_one_located_line(tmp_path, data):
    path = tmp_path / "random.yaml"
    path.write_text(yaml.safe_dump(data))
    model = check_contract(path, load_model)
    if model is not None:
        consistent(model)
    check_contract(path, load_properties)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_perturbed_arch_models_load_consistently_or_fail_on_one_located_line(tmp_path, data):
    doc = base_document()
    where = data.draw(st.sampled_from(list(paths(doc))[1:]), label="path")
    value = data.draw(yaml_values, label="value")
    path = tmp_path / "perturbed.yaml"
    path.write_text(yaml.safe_dump(replaced(doc, where, value), sort_keys=False))
    model = check_contract(path, load_model)
    if model is not None:
        consistent(model)


def test_the_unperturbed_document_is_sra01():
    """The hand-merged base loads to the same automaton as the shipped file."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "sra01.yaml"
        path.write_text(yaml.safe_dump(base_document(), sort_keys=False))
        mine, shipped = load_model(path), load_model("models/SRA01.yaml")
    assert list(mine.modes) == list(shipped.modes) and mine.horizon == shipped.horizon
    for name in mine.modes:
        A, b = mine.modes[name].linear
        A0, b0 = shipped.modes[name].linear
        np.testing.assert_array_equal(A, A0)
        np.testing.assert_array_equal(b, b0)
    np.testing.assert_array_equal(mine.initial.low, shipped.initial.low)


def test_found_by_the_fuzzing_a_mapping_where_a_mode_name_belongs(tmp_path):
    """Once a traceback with exit code 1 (a "violation"); now exit 2 with one located line."""
    import subprocess
    import sys

    for where in (("transitions", "abort", "from"), ("transitions", "dock", "to"), ("initial", "mode")):
        path = tmp_path / "bad.yaml"
        path.write_text(yaml.safe_dump(replaced(base_document(), where, {"a": []}), sort_keys=False))
        assert check_contract(path, load_model) is None
        try:
            load_model(path)
        except InputError as err:
            assert err.field == ".".join(where), err
    run = subprocess.run([sys.executable, "-m", "reach", "check", str(path), "properties/rendezvous.yaml"],
                         capture_output=True, text=True)
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and "initial.mode" in run.stderr


def test_found_by_the_fuzzing_a_missing_template_is_reported_where_it_is_named(tmp_path):
    path = tmp_path / "child.yaml"
    for parent in ("missing.yaml", "", "."):
        path.write_text(f"name: child\nextends: '{parent}'\n")
        assert check_contract(path, load_model) is None
        try:
            load_model(path)
        except InputError as err:
            assert err.line == 2 and err.field == "extends" and err.file == str(path)


def _expanding_aliases(levels: int = 9) -> str:
    """A YAML 'billion laughs': each key lists the previous one nine times."""
    text = "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
    for k in range(1, levels):
        prev, name = chr(96 + k), chr(97 + k)
        text += f"{name}: &{name} [" + ", ".join(f"*{prev}" for _ in range(9)) + "]\n"
    return text


@given(st.integers(0, 6), st.sampled_from([b"\x00", b"\xff\xfe", b"\xc3"]))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_file_that_is_not_text_is_refused_on_the_line_of_its_first_bad_byte(tmp_path, line, bad):
    lines = [f"key{k}: {k}" for k in range(7)]
    lines[line] = lines[line][:4] + bad.decode("latin-1") + lines[line][4:]
    path = tmp_path / "m.yaml"
    path.write_bytes("\n".join(lines).encode("latin-1") + b"\n")
    try:
        load_model(path)
    except InputError as exc:
        match = LOCATED.match(str(exc))
        assert match and int(match["line"]) == line + 1, str(exc)
    else:
        raise AssertionError("a file with a NUL or invalid UTF-8 byte loaded")


def test_expanding_aliases_are_refused_at_the_field_they_grow_under(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("name: bomb\n" + _expanding_aliases())
    try:
        load_model(path)
    except InputError as exc:
        match = LOCATED.match(str(exc))
        assert match, str(exc)
        expanding = path.read_text().splitlines()[int(match["line"]) - 1]
        assert "YAML nodes" in str(exc) and expanding.startswith(str(exc).split(": ")[1] + ":"), str(exc)
    else:
        raise AssertionError("an alias bomb loaded")


def test_a_file_of_too_many_nodes_is_refused_while_it_is_read(tmp_path):
    """A list of 300,000 zeros under ``notes`` (600 kB): refused at the line of the node past
    the limit while the parser composes, not after the whole tree is built (a 5 MB list took a
    minute and 1.7 GB)."""
    path = tmp_path / "m.yaml"
    path.write_text("name: big\nnotes:\n" + "".join(f"  - {k % 10}\n" for k in range(300_000)))
    try:
        load_model(path)
    except InputError as exc:
        match = LOCATED.match(str(exc))
        assert match and "more than 200000 YAML nodes" in str(exc), str(exc)
        assert 3 <= int(match["line"]) <= 200_001, str(exc)      # a line of the list, near its 200,000th item
    else:
        raise AssertionError("a file of 300,000 nodes loaded")


def test_a_state_named_like_a_python_keyword_is_refused_where_it_is_declared(tmp_path, capsys):
    """``lambda`` was accepted as a state name and every expression using it failed to parse;
    it is refused at the declaration, with the name to write instead."""
    from reach.cli import main

    (tmp_path / "kw.yaml").write_text("name: kw\nstate: [lambda]\nmodes:\n  a: {flow: {lambda: \"-lambda\"}}\n"
                                      "initial: {mode: a, box: {lambda: [0, 1]}}\nhorizon: 1\n")
    assert main(["lint", str(tmp_path / "kw.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("kw.yaml:2: state[0]: 'lambda' is a Python keyword, which expressions cannot name "
                        "(write 'lambda_')")
