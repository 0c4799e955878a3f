"""Finding model files by path or by their ``name:``."""

from __future__ import annotations

from pathlib import Path

import yaml

from reach.errors import InputError

#: files searched for a model's ``name:`` are read only up to this size (a model is far smaller)
NAME_SEARCH_BYTES = 5 * 2 ** 20


def find_model(spec: str, search_dirs=("models",)) -> Path:
    """``spec`` as a path if it exists, else the model file in ``search_dirs`` whose file name
    (without ``.yaml``) or whose ``name:`` is ``spec``."""
    path = Path(spec)
    if path.exists():
        return path
    for directory in search_dirs:
        if (Path(directory) / f"{spec}.yaml").is_file() and not spec.startswith("_"):
            return Path(directory) / f"{spec}.yaml"
    for directory in search_dirs:
        for candidate in sorted(Path(directory).glob("*.yaml")):
            if candidate.name.startswith("_"):
                continue
            if not candidate.is_file() or candidate.stat().st_size > NAME_SEARCH_BYTES:
                continue                # a FIFO, a device, a link to one, or far too large to be a model
            try:
                data = yaml.safe_load(candidate.read_text(encoding="utf-8"))
            except (OSError, yaml.YAMLError, UnicodeDecodeError, RecursionError):
                continue
            if isinstance(data, dict) and data.get("name") == spec:
                return candidate
    raise InputError(f"no model file '{spec}', and no model named '{spec}' in {', '.join(search_dirs)}/")
