"""SIREN network controller: forward pass, DA evaluation, model law, shipped weights, errors."""

import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
import sympy
from hypothesis import given, settings, strategies as st

from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.flow import compile_expressions
from reach.errors import InputError, Where
from reach.model import load_model
from reach.model.network import Siren

WEIGHTS = Path("models/weights/cw_siren.npz")
TEST_SET = Path("models/weights/cw_siren_test.npz")


def random_arrays(rng, sizes=(4, 6, 5, 2), omega=3.0):
    arrays = {}
    for i, (m, n) in enumerate(zip(sizes[:-1], sizes[1:]), start=1):
        arrays[f"W{i}"] = rng.uniform(-1, 1, (n, m))
        arrays[f"b{i}"] = rng.uniform(-1, 1, n)
    arrays.update(omega=np.array(omega), input_offset=rng.uniform(-1, 1, sizes[0]),
                  input_scale=rng.uniform(0.5, 2.0, sizes[0]))
    return arrays


def reference(arrays, s):
    """Eq. 29 neuron by neuron with math.sin, then the linear output layer."""
    layers = sum(1 for k in arrays if k.startswith("W"))
    x = [(v - o) / c for v, o, c in zip(s, arrays["input_offset"], arrays["input_scale"])]
    for i in range(1, layers + 1):
        W, b = arrays[f"W{i}"], arrays[f"b{i}"]
        z = [sum(W[r][c] * x[c] for c in range(len(x))) + b[r] for r in range(len(b))]
        x = [math.sin(float(arrays["omega"]) * v) for v in z] if i < layers else z
    return x


def load(path):
    return Siren.load(path, Where(str(Path(path).parent / "test.yaml"), "control.network", 3))


@pytest.fixture
def small(tmp_path):
    arrays = random_arrays(np.random.default_rng(1))
    np.savez(tmp_path / "small.npz", **arrays)
    return arrays, load(tmp_path / "small.npz")


def test_forward_pass_matches_neuron_by_neuron_reference(small):
    arrays, net = small
    points = np.random.default_rng(2).uniform(-2, 2, (7, 4))
    expected = np.array([reference(arrays, p) for p in points])
    assert np.allclose(net.evaluate(*points[0]), expected[0], rtol=1e-12, atol=1e-12)
    batched = net.evaluate(*points.T)                  # one (N,) array per input
    assert np.allclose(np.stack(batched, axis=1), expected, rtol=1e-12, atol=1e-12)


def test_shipped_forward_pass_matches_reference():
    with np.load(WEIGHTS, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    net = load(WEIGHTS)
    s = [480.0, -560.0, 0.01, -0.02]
    assert np.allclose(net.evaluate(*s), reference(arrays, s), rtol=1e-10, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(*[st.floats(-2000.0, 2000.0)] * 2, *[st.floats(-1.0, 1.0)] * 2), min_size=1, max_size=40))
def test_a_state_in_a_batch_gets_its_outputs_alone(states):
    """The shipped network on a batch of states: every state's outputs are bit for bit those of
    the state evaluated alone (so a batched integrator's runs do not depend on their batch)."""
    net = Siren.load(WEIGHTS, Where("test"))
    S = np.array(states, dtype=float)
    batch = net.evaluate(*S.T)
    for k, s in enumerate(S):
        alone = net.evaluate(*[np.array([v]) for v in s])
        assert all(batch[j][k] == alone[j][0] for j in range(net.n_outputs))
        assert all(batch[j][k] == float(v) for j, v in enumerate(net.evaluate(*s)))


def test_da_evaluation_matches_numpy_and_finite_differences(small):
    _, net = small
    alg = algebra(3, 4)
    centre = np.array([0.3, -0.2, 0.5, 0.1])
    outputs = net.evaluate(*DA.variables(alg, centre, np.ones(4)))
    assert np.allclose([o.cons for o in outputs], net.evaluate(*centre), rtol=1e-13, atol=1e-13)
    h = 1e-5
    for j in range(4):
        step = h * np.eye(4)[j]
        fd = (np.array(net.evaluate(*(centre + step))) - np.array(net.evaluate(*(centre - step)))) / (2 * h)
        assert np.allclose([o.c[1 + j] for o in outputs], fd, rtol=1e-6, atol=1e-8)


def test_one_evaluation_serves_both_outputs(small, monkeypatch):
    _, net = small
    calls = []
    evaluate = net.evaluate
    monkeypatch.setattr(net, "evaluate", lambda *a: calls.append(1) or evaluate(*a))
    x = [np.array([0.1, 0.2]), np.array([0.0, 0.3]), np.array([1.0, 0.5]), np.array([-0.2, 0.4])]
    first, second = [f._imp_(*x) for f in net.functions()]
    assert len(calls) == 1 and np.allclose(second, evaluate(*x)[1])
    x[0][0] = 0.7                                      # the same array, changed: evaluated again
    assert np.allclose(net.functions()[0]._imp_(*x), evaluate(*x)[0]) and len(calls) == 2


def test_model_control_law_through_lambdify_is_the_network():
    model = load_model("models/cw_siren.yaml")
    mode = model.modes["transfer"]
    net = load(WEIGHTS)
    X = np.random.default_rng(3).uniform([445, -650, -0.02, -0.02], [555, -350, 0.02, 0.02], (50, 4))
    S = np.c_[X, np.zeros(len(X))]                     # the model's state [x, y, vx, vy, t]
    law = sympy.lambdify([model.symbols], [mode.control["ux"], mode.control["uy"]], modules="numpy")
    assert np.allclose(np.stack(law(S.T), axis=1), np.stack(net.evaluate(*X.T), axis=1), rtol=1e-12)
    assert np.allclose(mode.inputs(S), np.stack(net.evaluate(*X.T), axis=1), rtol=1e-12)
    # the closed-loop flow on DA numbers (the taylor back-end's compiler) has the numpy value
    f = compile_expressions(mode.flow, mode.symbols)
    alg = algebra(2, 2)
    x0 = [DA.var(alg, 0, 500.0, 55.0), DA.var(alg, 1, -500.0, 150.0), DA.const(alg, 0.0), DA.const(alg, 0.0),
          DA.const(alg, 0.0)]
    assert np.allclose([v.cons for v in f(x0)], mode.rhs(np.array([[500.0, -500.0, 0.0, 0.0, 0.0]]))[0],
                       rtol=1e-12, atol=1e-15)


def test_two_networks_get_distinct_function_names(small):
    _, net = small
    shipped = load(WEIGHTS)
    names = {f.__name__ for f in net.functions()} | {f.__name__ for f in shipped.functions()}
    assert len(names) == 4


def test_shipped_weights_reach_their_recorded_test_error():
    net = load(WEIGHTS)
    with np.load(TEST_SET, allow_pickle=False) as data:
        states, directions = data["states"], data["directions"]
        recorded = float(data["mean_angular_error"])
    assert states.shape == (1000, 4) and directions.shape == (1000, 2)
    out = np.stack(net.evaluate(*states.T), axis=1)
    cos = np.sum(out * directions, axis=1) / np.linalg.norm(out, axis=1)
    error = np.mean(np.arccos(np.clip(cos, -1, 1)))
    assert error == pytest.approx(recorded, rel=1e-6)
    assert error < np.radians(5.0)


MODEL = """name: net
state: [x, y, vx, vy]
inputs: [ux, uy]
modes:
  m:
    flow: {x: vx, y: vy, vx: ux, vy: uy}
    control: {network: NET, feedback: FEEDBACK}
initial: {mode: m, box: {x: 0, y: 0, vx: 0, vy: 0}}
horizon: 10
"""


def write_model(tmp_path, arrays=None, net="net.npz", feedback="[x, y, vx, vy]"):
    if arrays is not None:
        np.savez(tmp_path / "net.npz", **arrays)
    path = tmp_path / "m.yaml"
    path.write_text(MODEL.replace("NET", net).replace("FEEDBACK", feedback))
    return path


def bad_arrays(change):
    arrays = random_arrays(np.random.default_rng(4))
    change(arrays)
    return arrays


@pytest.mark.parametrize("arrays, net, feedback, words", [
    (None, "missing.npz", "[x, y, vx, vy]", ["missing.npz", "not found"]),
    (bad_arrays(lambda a: a.update(W2=np.ones((5, 7)))), "net.npz", "[x, y, vx, vy]", ["net.npz", "'W2'", "(5, 7)"]),
    (bad_arrays(lambda a: a["b1"].__setitem__(0, np.nan)), "net.npz", "[x, y, vx, vy]", ["net.npz", "'b1'", "non-finite"]),
    (bad_arrays(lambda a: a.pop("omega")), "net.npz", "[x, y, vx, vy]", ["net.npz", "'omega'", "missing"]),
    (bad_arrays(lambda a: a.update(input_scale=np.zeros(4))), "net.npz", "[x, y, vx, vy]", ["'input_scale'"]),
    (random_arrays(np.random.default_rng(5)), "net.npz", "[x, y, vx]", ["4 inputs", "3 states"]),
    (random_arrays(np.random.default_rng(6), sizes=(4, 6, 3)), "net.npz", "[x, y, vx, vy]", ["3 outputs", "2 inputs"]),
])
def test_network_errors_are_one_located_line(tmp_path, arrays, net, feedback, words):
    path = write_model(tmp_path, arrays, net, feedback)
    with pytest.raises(InputError) as info:
        load_model(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}:7: modes.m.control.network: ")
    for word in words:
        assert word in message


def test_a_compressed_bomb_is_refused_before_it_is_unpacked(tmp_path):
    """60 MB of zeros pack into 60 kB: refused by the unpacked sizes the archive states, before
    any array is read (300 million zeros in 2.3 MB took more than 3 GB)."""
    arrays = random_arrays(np.random.default_rng(8))
    (tmp_path / "inner").mkdir()
    np.save(tmp_path / "inner" / "W1.npy", np.zeros((3000, 2500)))
    with zipfile.ZipFile(tmp_path / "net.npz", "w", zipfile.ZIP_DEFLATED) as archive:
        archive.write(tmp_path / "inner" / "W1.npy", "W1.npy")
        for name, value in arrays.items():
            if name != "W1":
                np.save(tmp_path / "inner" / f"{name}.npy", value)
                archive.write(tmp_path / "inner" / f"{name}.npy", f"{name}.npy")
    assert (tmp_path / "net.npz").stat().st_size < 1_000_000
    with pytest.raises(InputError, match=r"net\.npz: its arrays take \d+ bytes unpacked, more than 50000000"):
        load_model(write_model(tmp_path))


def test_weights_outside_the_model_folder_and_the_working_folder_are_not_read(tmp_path, monkeypatch):
    (tmp_path / "model").mkdir()
    (tmp_path / "elsewhere").mkdir()
    np.savez(tmp_path / "elsewhere" / "net.npz", **random_arrays(np.random.default_rng(9)))
    monkeypatch.chdir(tmp_path / "model")
    with pytest.raises(InputError, match="lies outside the folder of the model file and the working folder"):
        load_model(write_model(tmp_path / "model", net="../elsewhere/net.npz"))


def test_pickled_arrays_are_refused(tmp_path):
    arrays = random_arrays(np.random.default_rng(7))
    arrays["W1"] = np.array([None] * 24, dtype=object).reshape(6, 4)
    with pytest.raises(InputError, match=r"net\.npz: not a readable \.npz of plain arrays"):
        load_model(write_model(tmp_path, arrays))


def test_network_models_pickle_and_run_on_worker_processes(tmp_path, monkeypatch):
    """A network model is sent to workers whole (arrays, not the evaluation cache): the copy has
    the same law, and taylor ADS levels on 2 processes give the subdomains of 1 and their bounds
    to rounding (the batches differ in size, and BLAS may sum a batch's columns in another
    order). Levels of 2 and 4 boxes are shared by the workers here (``MIN_SHARE``: 1 box)."""
    import pickle

    import reach.backends.taylor
    from reach.backends.taylor import BACKEND
    from reach.backends.taylor.keys import picklable
    from reach.spec.properties import bind, load_properties

    arrays = random_arrays(np.random.default_rng(8))
    path = write_model(tmp_path, arrays)
    path.write_text(path.read_text().replace("box: {x: 0,", "box: {x: [-0.2, 0.2],"))
    model = load_model(path)
    copy = pickle.loads(pickle.dumps(model))
    S = np.random.default_rng(9).uniform(-1, 1, (20, 4))
    assert np.array_equal(copy.modes["m"].inputs(S), model.modes["m"].inputs(S))
    assert np.allclose(copy.modes["m"].inputs(S), np.stack(load(tmp_path / "net.npz").evaluate(*S.T), axis=1),
                       rtol=1e-12)
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: reach_x, kind: event, modes: [m], maximize: 'x', require: '<= 100'}\n")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    assert picklable(model, prop)
    options = {"e_tol": 1e-12, "max_splits": 2}

    def essence(result):
        rows = result.details["subdomains"]
        return [(tuple(r["low"]), tuple(r["high"])) for r in rows], np.array([r["bound"] for r in rows])

    boxes, bounds = essence(BACKEND.check(model, prop, options))
    monkeypatch.setattr(reach.backends.taylor, "MIN_SHARE", 1)
    boxes_2, bounds_2 = essence(BACKEND.check(model, prop, {**options, "jobs": 2}))
    assert len(boxes) == 4 and boxes == boxes_2
    np.testing.assert_allclose(bounds_2, bounds, rtol=1e-10)      # a random network: bounds up to 1e9
