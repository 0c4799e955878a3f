"""``reach plot MODEL PROPS --backend B [--backend B2] [--vars x,y] [--out FILE]``: check with each
back-end keeping its sets (option ``keep_sets``), then draw them (:mod:`.reach_sets`).

Options: ``-o KEY=VALUE`` goes to every back-end, ``-o B.KEY=VALUE`` to back-end ``B`` only. A
taylor check keeps sets only with ``remainder: rigorous`` (its verified step enclosures), which
the picture asks for unless the user chose a remainder. A back-end of which nothing is drawn
(fsr keeps no sets, a failed taylor sweep keeps none, ...) is named with the reason, in the
picture and on the console (:func:`reach.plotting.reach_sets.nothing_drawn`). The exit code is
the check's (:func:`reach.checking.exit_code` over every back-end's results), unless nothing at
all could be drawn: then an InputError (one line, exit 2) says why, the picture saying it too.
"""

from __future__ import annotations

import dataclasses
import importlib
import time
from pathlib import Path

from reach.backends.options import split_options
from reach.errors import InputError


def _knows(backend: str, name: str) -> bool:
    from reach.backends import BACKENDS, OPTIONS

    cls = getattr(importlib.import_module(BACKENDS[backend]), OPTIONS[backend])
    return name in {f.name for f in dataclasses.fields(cls)}


def load(model_path: str, properties_path: str | None, only: list[str] | None):
    """``(model, bound properties, spaceex)``: a YAML model and property file, or a SpaceEx
    ``.xml`` with its ``.cfg`` (its forbidden set as one property)."""
    from reach.checking import is_spaceex, load_bound
    from reach.locate import find_model

    if is_spaceex(model_path):
        return None, None, True
    model, props = load_bound(find_model(model_path), properties_path, only)
    return model, props, False


def default_file(model, backends: list[str], axes) -> Path:
    """``MODEL_BACKENDS_X_Y.png`` in the working folder: a name reach makes, so a symbolic link
    there is refused (:func:`reach.paths.writable_file`), never written through."""
    from reach.paths import safe_name

    return Path(f"{safe_name(model.name)}_{'_'.join(safe_name(b) for b in backends)}_"
                f"{safe_name(axes[0].name)}_{safe_name(axes[1].name)}.png")


def plot_files(model_path: str, properties_path: str, backends: list[str], variables: str | None,
               out: Path | None, options: dict, only: list[str] | None = None, exact: bool = True,
               stream=None):
    """Check and draw; returns ``(exit code, output path, drawing summary, seconds to draw)``.
    InputError when nothing at all could be drawn (the picture, written, says why)."""
    from reach.checking import check_model, check_spaceex, exit_code, resolve_backend
    from reach.backends import validate_options
    from reach.paths import writable_file
    from reach.plotting.axes import parse_vars
    from reach.plotting.reach_sets import missing_text, plot_reach_sets

    per_backend = split_options(options, backends)
    for b in backends:
        resolve_backend(b)
        opts = per_backend[b]
        if _knows(b, "keep_sets"):
            opts["keep_sets"] = True
        if b == "taylor":
            opts.setdefault("remainder", "rigorous")
        validate_options(b, opts)
    model, bound, spaceex = load(model_path, properties_path, only)
    axes = None if spaceex else parse_vars(model, variables, bound)      # bad --vars before any work
    if out is None and not spaceex:     # the default file, refused (a link there) before any work
        out = writable_file(default_file(model, backends, axes), "--out")
    results = {}
    for b in backends:
        if spaceex:
            res, model, _, props = check_spaceex(model_path, properties_path, b, per_backend[b])
            bound = list(props.values())
            axes = axes or parse_vars(model, variables, bound)
        else:
            res = check_model(resolve_backend(b), model, bound, per_backend[b])
        results[b] = res
        if stream is not None:
            print(f"{b}: " + ", ".join(f"{r.property} {r.status.value} ({len(r.sets)} sets)" for r in res),
                  file=stream)
    # checked again now: the default name of a SpaceEx model is known only here, and a link may
    # have appeared while the back-ends ran
    out = writable_file(default_file(model, backends, axes) if out is None else out, "--out")
    start = time.perf_counter()
    summary = plot_reach_sets(model, results, bound, axes, out, exact=exact)
    seconds = time.perf_counter() - start
    missing = summary["nothing_drawn"]
    if not any(summary["sets"].values()) and not summary["counterexamples"]:
        raise InputError(f"nothing could be drawn: {'; '.join(f'{b} {why}' for b, why in missing.items())} "
                         f"(the picture {out} says so too)", field="--backend")
    if stream is not None:
        for b, why in missing.items():
            print(missing_text(b, why), file=stream)
    return exit_code([r for rs in results.values() for r in rs]), out, summary, seconds
