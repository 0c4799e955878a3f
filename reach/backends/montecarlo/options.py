"""Settings of the montecarlo back-end."""

from __future__ import annotations

from dataclasses import dataclass

from reach.backends.options import parse_options, ranged

NAME = "montecarlo"


@dataclass
class Options:
    samples: int = ranged(1000, 1, 10_000_000)           # i.i.d. runs (safety) or runs (stochastic reach)
    structured: int | None = ranged(None, 0, 10_000_000)  # most structured runs (None: structured_cap)
    search_rounds: int = ranged(3, 0, 1000)        # cross-entropy generations after the i.i.d. round
    search_size: int = ranged(200, 1, 100_000)          # runs per generation (one batch: no deadline inside)
    seed: int = 0
    dt: float | None = None        # simulator grid step (model default if None)
    batch: int = ranged(20000, 1, 1_000_000)            # runs per batch (an executor unit; stochastic estimates)
    input_step: float | None = None  # piece length of sampled input signals (horizon/20 if None)
    jobs: int = ranged(1, 1, 256)  # local worker processes for the i.i.d. batches
    scheduler: object = None       # or a Dask scheduler address (or Client) to run them on
    optimise: bool = True          # falsification by optimisation after the search (reach.backends.montecarlo.falsify)
    generations: int = ranged(20, 0, 100_000)     # differential evolution generations
    population: int = ranged(40, 5, 10_000)       # runs per generation (one batch: no deadline inside)
    polish: int = ranged(1000, 0, 100_000)        # polish runs from the best point (reach.backends.montecarlo.falsify)
    keep_sets: bool = False        # safety, events: KEPT_RUNS sampled runs in Result.sets (pictures)
    max_seconds: float | None = ranged(None, 0.0, open_low=True)  # safety: no search or optimisation past it

    @classmethod
    def from_dict(cls, options: dict | None) -> "Options":
        opts = cls(**parse_options(cls, options, "montecarlo"))
        if opts.scheduler is not None and not hasattr(opts.scheduler, "submit"):   # a Client passes as it is
            from reach.executors import check_address
            check_address(opts.scheduler, "options.montecarlo.scheduler")
        return opts
