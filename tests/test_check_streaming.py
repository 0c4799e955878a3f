"""``reach check`` prints each property's answer as soon as it is final, in the file's order: a
file of twenty properties at up to 120 s each printed nothing for 40 minutes."""

from __future__ import annotations

import yaml

import reach.checking
from reach.cli import main
from reach.result import Status


def _files(tmp_path):
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "name": "m", "state": ["x"], "horizon": 1, "modes": {"a": {"flow": {"x": -1}}},
        "initial": {"mode": "a", "box": {"x": [0.5, 1]}}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump({"properties": [
        {"id": f"p{k}", "kind": "safety", "modes": ["a"], "require": [f"x <= {k + 1}"]} for k in range(3)]}))
    return str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml")


def test_each_answer_is_printed_before_the_next_property_is_checked(tmp_path, monkeypatch, capsys):
    real = reach.checking.resolve_backend("star")
    seen_before: dict[str, str] = {}

    class Recording:
        """star, noting what had been printed when each check started."""
        name = real.name

        def supports(self, model, prop):
            return real.supports(model, prop)

        def check(self, model, prop, options):
            seen_before[prop.id] = capsys.readouterr().out
            return real.check(model, prop, options)

    monkeypatch.setattr(reach.checking, "resolve_backend", lambda name: Recording())
    assert main(["check", *_files(tmp_path), "-b", "star"]) == 0
    assert "p0 " not in seen_before["p0"]
    assert "p0 " in seen_before["p1"] and "SAFE" in seen_before["p1"]
    assert "p1 " in seen_before["p2"] and "p2 " not in seen_before["p2"]


def test_the_answers_keep_the_files_order_and_json_is_printed_once(tmp_path, capsys):
    model, props = _files(tmp_path)
    assert main(["check", model, props, "-b", "star"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "m with star:" and [line.split()[0] for line in out[1:]] == ["p0", "p1", "p2"]
    assert main(["check", model, props, "-b", "star", "--json"]) == 0
    import json
    assert [row["property"] for row in json.loads(capsys.readouterr().out)] == ["p0", "p1", "p2"]


def test_done_sees_every_result_once_in_the_files_order(tmp_path):
    from reach.checking import check_model, load_bound

    model_path, props_path = _files(tmp_path)
    model, props = load_bound(model_path, props_path, None)
    order = []
    results = check_model(reach.checking.resolve_backend("star"), model, props, {},
                          lambda prop, r: order.append((prop.id, r.status)))
    assert order == [(r.property, r.status) for r in results] == [(f"p{k}", Status.SAFE) for k in range(3)]
