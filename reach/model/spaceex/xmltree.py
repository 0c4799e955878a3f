"""A small, safe XML reader that keeps the line of every element.

Built on the standard library's expat parser. A model from a stranger must not blow up memory
or reach outside its file, so any document type declaration (where entities, internal or
external, would be declared) is refused, as are files above a size cap; expat itself never
fetches external resources.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.parsers import expat

from reach.errors import InputError
from reach.paths import printable, read_bytes

MAX_BYTES = 5_000_000
MAX_ELEMENTS = 200_000


@dataclass
class Node:
    """An element: tag, attributes, text (all character data inside, children excluded), children."""

    tag: str
    attrs: dict
    line: int
    text: str = ""
    children: list["Node"] = field(default_factory=list)

    def all(self, tag: str) -> list["Node"]:
        return [c for c in self.children if c.tag == tag]

    def first(self, tag: str) -> "Node | None":
        return next((c for c in self.children if c.tag == tag), None)


class _Refused(Exception):
    pass


def parse_xml(data: bytes, file: str) -> Node:
    """The root element of ``data``; malformed XML or a DTD is an :class:`InputError`."""
    if len(data) > MAX_BYTES:
        raise InputError(f"file larger than {MAX_BYTES} bytes", file)
    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: list[Node] = []
    root: list[Node] = []
    count = [0]

    def refuse(*_args):
        raise _Refused("document type declarations and entities are not accepted")

    def start(tag, attrs):
        count[0] += 1
        if count[0] > MAX_ELEMENTS:
            raise _Refused(f"more than {MAX_ELEMENTS} XML elements")
        node = Node(tag, dict(attrs), parser.CurrentLineNumber)
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def end(_tag):
        stack.pop()

    def chars(text):
        if stack:
            stack[-1].text += text

    parser.StartDoctypeDeclHandler = refuse
    parser.EntityDeclHandler = refuse
    parser.ExternalEntityRefHandler = refuse
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    try:
        parser.Parse(data, True)
    except _Refused as exc:
        raise InputError(str(exc), file, line=parser.CurrentLineNumber) from None
    except expat.ExpatError as exc:
        raise InputError(f"invalid XML: {expat.errors.messages[exc.code]}", file, line=exc.lineno) from None
    except (RecursionError, MemoryError, ValueError):
        raise InputError("invalid XML", file) from None
    if not root:
        raise InputError("no XML element", file)
    return root[0]


def read_xml(path) -> Node:
    """The root element of a regular file of at most ``MAX_BYTES`` (not a FIFO, device or folder)."""
    data = read_bytes(path, None, "SpaceEx model", MAX_BYTES)
    return parse_xml(data, printable(str(path)))
