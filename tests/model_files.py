"""A model and its properties written from text in the tests, loaded and bound."""

import textwrap

from reach.model import load_model
from reach.spec import bind, load_properties


def load_files(folder, model_text: str, props_text: str):
    """Write ``model.yaml`` and ``props.yaml`` (dedented) into ``folder``; ``(model, {id: bound
    property})``."""
    (folder / "model.yaml").write_text(textwrap.dedent(model_text))
    (folder / "props.yaml").write_text(textwrap.dedent(props_text))
    model = load_model(folder / "model.yaml")
    return model, {p.id: bind(p, model) for p in load_properties(folder / "props.yaml")}
