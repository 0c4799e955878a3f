"""YAML reading with line numbers, for error messages that point into the user's file.

``load(path)`` returns a :class:`Doc`: the plain data (dicts, lists, scalars, via the safe
loader only) and a map from field path to line, so a loader can say
``models/x.yaml:14: modes.approach.flow.vx: unknown name 'vyy'``.
"""

from __future__ import annotations

import yaml

from reach.errors import InputError, Where
from reach.paths import MAX_BYTES, YAML_SUFFIXES, printable, read_text

MAX_NODES = 200_000


class Doc:
    """Parsed YAML plus the line of every field; ``where(path)`` builds error locations."""

    def __init__(self, data, lines: dict[tuple, tuple[str, int]], file: str):
        self.data = data
        self.lines = lines
        self.file = file

    def where(self, *path) -> Where:
        """The file, field and line of ``path`` (or of its nearest ancestor with a known line).
        An entry of ``lines`` may name the field itself as a third item: a document converted
        from another format (a SpaceEx cfg's ``forbidden``) names the field its user wrote."""
        entry = self.lines.get(tuple(path), (self.file, None))
        if entry[1] is None:  # nearest ancestor with a known line
            for k in range(len(path) - 1, -1, -1):
                if tuple(path[:k]) in self.lines:
                    entry = self.lines[tuple(path[:k])]
                    break
        file, line = entry[:2]
        return Where(file, entry[2] if len(entry) > 2 else _field(path) or "", line)


#: a YAML integer beyond this (a 401-digit literal) has no double value: bad input at its line
MAX_INTEGER = 10 ** 308


def _convert(node, loader, path, lines, file, budget):
    budget[0] += 1
    if not node.tag.startswith("tag:yaml.org,2002:") or "python" in node.tag:
        raise InputError(f"YAML tag '{printable(node.tag)}' is not allowed (plain data only)", file,
                         _field(path), node.start_mark.line + 1)
    if budget[0] > MAX_NODES:
        top = path[:1]                          # the field the expansion sits under
        raise InputError(f"more than {MAX_NODES} YAML nodes (aliases expanding?)", file, _field(top),
                         lines.get(top, (file, node.start_mark.line + 1))[1])
    lines.setdefault(path, (file, node.start_mark.line + 1))
    if isinstance(node, yaml.MappingNode):
        out = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise InputError("mapping keys must be plain names", file, line=key_node.start_mark.line + 1)
            key = loader.construct_object(key_node)
            if isinstance(key, bool) or key is None:
                raise InputError(f"YAML reads the name '{printable(key_node.value)}' as {str(key).lower()}: quote it "
                                 f"(\"{printable(key_node.value)}\")", file, _field(path), key_node.start_mark.line + 1)
            if not isinstance(key, (str, int, float)):
                key = str(key)
            if key in out:
                raise InputError(f"duplicate key '{key}'", file, line=key_node.start_mark.line + 1)
            lines[path + (key,)] = (file, key_node.start_mark.line + 1)
            out[key] = _convert(value_node, loader, path + (key,), lines, file, budget)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_convert(v, loader, path + (i,), lines, file, budget) for i, v in enumerate(node.value)]
    try:
        value = loader.construct_object(node)
    except (ValueError, TypeError, OverflowError) as exc:    # an int of more than 4300 digits
        reason = "a number too long to read" if node.tag.endswith(":int") else type(exc).__name__
        raise InputError(f"invalid YAML: {reason} ({printable(node.value)[:40]}...)", file, _field(path),
                         node.start_mark.line + 1) from None
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INTEGER:
        raise InputError(f"the number {printable(node.value)[:40]}... is beyond double precision", file,
                         _field(path), node.start_mark.line + 1)
    return value


class _CountingLoader(yaml.SafeLoader):
    """The safe loader, stopping once it has composed :data:`MAX_NODES` nodes: a file of five
    million ``0,`` is refused at its 200,000th, not after a minute and 1.7 GB of nodes
    (:func:`_convert` counts again with the aliases expanded)."""

    def __init__(self, stream, file: str):
        super().__init__(stream)
        self.composed, self.file = 0, file

    def compose_node(self, parent, index):
        self.composed += 1
        if self.composed > MAX_NODES:
            raise InputError(f"more than {MAX_NODES} YAML nodes", self.file,
                             line=self.peek_event().start_mark.line + 1)
        return super().compose_node(parent, index)


def parse_text(text: str, file: str) -> Doc:
    """Parse YAML text (safe loader only) into a :class:`Doc`."""
    if len(text) > MAX_BYTES:
        raise InputError(f"file larger than {MAX_BYTES} bytes", file)
    try:
        loader = _CountingLoader(text, file)
    except yaml.reader.ReaderError as exc:      # a control character YAML does not allow
        line = text[:exc.position].count("\n") + 1 if isinstance(exc.position, int) else None
        code = exc.character if isinstance(exc.character, int) else None
        raise InputError(f"invalid YAML: {exc.reason}" + (f" (U+{code:04X})" if code is not None else ""),
                         file, line=line) from None
    try:
        node = loader.get_single_node()
        lines: dict[tuple, tuple[str, int]] = {}
        data = None if node is None else _convert(node, loader, (), lines, file, [0])
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else None
        hint = ""
        if "got '['" in str(exc.problem):
            hint = " (inside { } or [ ], quote values that contain brackets: \"10[N]\")"
        raise InputError(f"invalid YAML: {exc.problem or exc.context}{hint}", file, line=line) from None
    except yaml.YAMLError as exc:
        raise InputError(f"invalid YAML: {exc}", file) from None
    except RecursionError:
        line = getattr(loader, "line", None)
        raise InputError("invalid YAML: nested too deeply", file,
                         line=line + 1 if isinstance(line, int) else None) from None
    except (ValueError, TypeError, OverflowError) as exc:
        raise InputError(f"invalid YAML: {type(exc).__name__}", file) from None
    finally:
        loader.dispose()
    return Doc(data, lines, file)


def load(path) -> Doc:
    """Read and parse a YAML file: a regular ``.yaml``/``.yml`` file under the size cap
    (:func:`reach.paths.read_text`); anything else is an InputError."""
    text = read_text(path, YAML_SUFFIXES, "YAML file", MAX_BYTES)
    return parse_text(text, str(path))


def _field(path: tuple) -> str | None:
    field = ""
    for key in path:
        field = f"{field}[{key}]" if isinstance(key, int) else (f"{field}.{key}" if field else str(key))
    return field or None


def merge(base: Doc, child: Doc) -> Doc:
    """Child over base: mappings merge key by key, everything else is replaced."""
    lines = dict(base.lines)

    def rec(b, c, path):
        if isinstance(b, dict) and isinstance(c, dict):
            out = dict(b)
            for key, value in c.items():
                out[key] = rec(b.get(key), value, path + (key,)) if key in b else value
                if key not in b or not (isinstance(b.get(key), dict) and isinstance(value, dict)):
                    for p in [p for p in lines if p[:len(path) + 1] == path + (key,)]:
                        del lines[p]
            return out
        return c

    data = rec(base.data, child.data, ())
    for path, loc in child.lines.items():
        lines[path] = loc
    return Doc(data, lines, child.file)
