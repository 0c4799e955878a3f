"""Random YAML-like documents (hypothesis) for the loader and input-contract fuzz tests: scalars of
every kind and nested lists and mappings keyed by the model and property formats' own field names."""

from hypothesis import strategies as st

scalars = (st.none() | st.booleans() | st.integers(-5, 5) | st.floats(allow_nan=True) |
           st.text(alphabet="xytv0123456789+-*/()[]<=>_ abcdmnops", max_size=12))
yaml_values = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=3) | st.dictionaries(
        st.sampled_from(["name", "state", "modes", "flow", "initial", "box", "mode", "horizon", "x", "a",
                         "transitions", "guard", "from", "to", "control", "gain", "lqr", "invariant",
                         "disturbance", "properties", "id", "kind", "require", "avoid", "extends"]),
        children, max_size=5),
    max_leaves=25)
