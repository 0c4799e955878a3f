"""Shared test set-up: the repository root as working directory, and the hypothesis profiles.

Profiles (``HYPOTHESIS_PROFILE`` picks one; default ``ci`` when ``CI`` is set, else ``dev``):

* ``ci``: derandomised (each test's examples follow from its own source, so a CI run is
  repeatable), no example database, no deadline, failing examples printed with their blob;
* ``dev``: random exploration from one seed for the whole run (every test worker takes the
  same one), printed in the report header; ``HYPOTHESIS_SEED=N`` repeats a run.

The tests run on one worker process per core (pytest-xdist, ``-n auto`` in pyproject.toml);
``-n 0`` runs them in this process.

Every test also runs under pytest-timeout (``[tool.pytest.ini_options]`` in pyproject.toml),
so a hang fails with the stacks of all threads instead of stalling the suite.
"""

import os
import random
from pathlib import Path

import hypothesis
import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parent.parent

settings.register_profile("ci", derandomize=True, database=None, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
PROFILE = os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if os.environ.get("CI") else "dev")
settings.load_profile(PROFILE)
SEED = None if settings.default.derandomize else int(os.environ.get("HYPOTHESIS_SEED") or random.getrandbits(32))
if SEED is not None:             # the test workers (pytest-xdist) start after this and take the same seed
    os.environ["HYPOTHESIS_SEED"] = str(SEED)


def hypothesis_line() -> str:
    if SEED is None:
        return f"hypothesis: profile {PROFILE!r}, derandomized (examples fixed by each test's source)"
    return f"hypothesis: profile {PROFILE!r}, seed {SEED} (HYPOTHESIS_SEED={SEED} repeats this run)"


def pytest_report_header(config):
    return hypothesis_line()


def pytest_terminal_summary(terminalreporter):
    """The profile and seed again at the end, where ``-q`` still shows it."""
    terminalreporter.write_line(hypothesis_line())


def pytest_collection_modifyitems(config, items):
    """Seed every hypothesis test with the run's seed (an explicit --hypothesis-seed wins)."""
    if SEED is None or config.getoption("hypothesis_seed", None) is not None:
        return
    for item in items:
        function = getattr(item, "function", None)
        if function is not None and hypothesis.is_hypothesis_test(function):
            hypothesis.seed(SEED)(function)


@pytest.fixture(autouse=True)
def _in_repo_root(monkeypatch):
    """Model and property paths in the tests are relative to the repository root."""
    monkeypatch.chdir(ROOT)
    os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def draw():
    """Draw back-ends' results on a new figure's axes (the figures closed after the test):
    ``draw(model, bound, results, x, y, exact=True)`` returns ``(axes, summary)`` of
    :func:`reach.plotting.reach_sets.plot_reach_sets`, laid out and rendered."""
    from reach.plotting.axes import make_axis
    from reach.plotting.reach_sets import plot_reach_sets, pyplot

    plt = pyplot()
    figures = []

    def drawn(model, bound, results, x: str, y: str, exact: bool = True):
        fig, ax = plt.subplots(figsize=(8, 6.5), layout="constrained")
        figures.append(fig)
        summary = plot_reach_sets(model, results, bound, (make_axis(model, x), make_axis(model, y)), out=None,
                                  ax=ax, exact=exact)
        fig.canvas.draw()
        return ax, summary

    yield drawn
    for fig in figures:
        plt.close(fig)
