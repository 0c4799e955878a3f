"""The one exception type for bad user input.

Every problem with a model or property file is reported as a single line
``file:line: field.path: message`` and a non-zero exit code by the CLI; no traceback.
"""

from __future__ import annotations


class InputError(Exception):
    """A malformed model, property or suite file, or a bad command-line argument."""

    def __init__(self, message: str, file: str | None = None, field: str | None = None,
                 line: int | None = None):
        super().__init__(message)
        self.message = message
        self.file = file
        self.field = field
        self.line = line

    def __str__(self) -> str:
        location = ""
        if self.file:
            location = str(self.file) + (f":{self.line}" if self.line else "") + ": "
        field = f"{self.field}: " if self.field else ""
        return f"{location}{field}{self.message}"


class Where:
    """Where a value came from in a user file: file, dotted field path and line."""

    __slots__ = ("file", "field", "line")

    def __init__(self, file: str | None = None, field: str = "", line: int | None = None):
        self.file = file
        self.field = field
        self.line = line

    def child(self, key, line: int | None = None) -> "Where":
        field = f"{self.field}.{key}" if self.field else str(key)
        if isinstance(key, int):
            field = f"{self.field}[{key}]"
        return Where(self.file, field, line if line is not None else self.line)

    def error(self, message: str) -> InputError:
        return InputError(message, self.file, self.field or None, self.line)

    def __repr__(self) -> str:
        return f"Where({self.file!r}, {self.field!r}, {self.line!r})"


def not_a_mode(value, where: Where) -> InputError:
    """The error for ``value`` where the name of one of a model's modes is expected. YAML 1.1
    reads unquoted ``on``/``off`` (and ``yes``/``no``, ``true``/``false``) as booleans, so a mode
    named ``on`` arrives as ``True``: say so rather than name a mode 'True'."""
    if isinstance(value, bool):
        return where.error(f"mode name read as a boolean by YAML; quote it: '{'on' if value else 'off'}'")
    return where.error(f"unknown mode '{value}'")
