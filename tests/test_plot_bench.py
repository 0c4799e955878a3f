"""Run plots and the abort map: files produced, clocks left out, margins consistent with star."""

from __future__ import annotations

import numpy as np

from reach.backends.star import arc_cells
from reach.backends.montecarlo import replay
from reach.bench.plots import _clocks, passive_margins, plot_abort_map, plot_model_runs
from reach.model import load_model
from reach.model.simulate import Simulator
from reach.spec import bind, load_properties


def test_run_plot_with_requirements_and_no_clock_panel(tmp_path):
    model = load_model("models/SRA02.yaml")
    traj = Simulator(model).run(model.initial.low[None], np.array([122.0]), record=True)
    assert _clocks(model, traj) == {model.state.index("t")}
    bound = [bind(p, model) for p in load_properties("properties/rendezvous.yaml")]
    out = tmp_path / "runs.png"
    plot_model_runs(model, out, runs=3, bound_props=bound)
    assert out.stat().st_size > 20_000


def test_passive_margins_positive_where_star_proves_the_collision_property(tmp_path):
    """SRA02's collision property is SAFE by star for the initial box, so no sampled run from
    inside it comes within the collision box after the abort (margins are sampled, not proved)."""
    model = load_model("models/SRA02.yaml")
    bound = [bind(p, model) for p in load_properties("properties/rendezvous.yaml")]
    centre = (model.initial.low + model.initial.high) / 2
    cells = [(centre - 1e-6, centre + 1e-6, 0.0)] + arc_cells(model, 1000.0, 1)
    times = np.array([120.0, 122.5, 125.0])
    margins, unit = passive_margins(model, bound, cells, times)
    assert margins.shape == (2, 3) and unit == "m"
    assert np.all(np.isfinite(margins[0])) and np.all(margins[0] > 0)
    collision = next(p for p in bound if p.id == "collision")
    for k, tau in enumerate(times):            # the same runs through the replay monitor
        assert not replay(model, collision, centre, float(tau)).violated
    out = tmp_path / "map.png"
    plot_abort_map(cells, [125.0, 121.0], (120.0, 125.0), out, "map", "min", margins, times, unit)
    assert out.stat().st_size > 20_000
