"""Where reach reads and writes: capped reads of regular text files, and output names that
cannot leave their folder.

* :func:`read_text` opens only regular files (not ``/dev/zero``, a FIFO or a directory) of at
  most ``MAX_BYTES``, with an allowed suffix, and refuses text with NUL bytes. Its errors name the
  file and never quote its content.
* :func:`safe_name` turns a model or property name into one file-name component: letters and
  digits of any script, ``.``, ``-`` and ``_`` only, no leading dot, at most 80 characters (a
  longer name cut and ended by its hash), so
  ``name: "../../x"`` writes ``x`` inside the output folder, never outside it.
* :func:`printable` escapes control characters (and the Unicode line separators) of a user's name
  for terminal output and table cells.
"""

from __future__ import annotations

import hashlib
import os
import re
import stat
from pathlib import Path

from reach.errors import InputError

MAX_BYTES = 5_000_000
YAML_SUFFIXES = (".yaml", ".yml")


def read_bytes(path, suffixes: tuple[str, ...] | None = None, what: str = "file",
               max_bytes: int = MAX_BYTES) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` bytes (an InputError otherwise)."""
    path = Path(path)
    shown = printable(str(path))
    if path.is_dir():
        raise InputError(f"a folder, not a file (a {what} must be a plain file)", shown)
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise InputError(f"a {what} must be a {' or '.join(suffixes)} file", shown)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise InputError("no such file", shown) from None
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read file: {exc.__class__.__name__}", shown) from None
    if not stat.S_ISREG(info.st_mode):
        raise InputError(f"not a regular file (a {what} must be a plain file)", shown)
    if info.st_size > max_bytes:
        raise InputError(f"file larger than {max_bytes} bytes ({info.st_size})", shown)
    try:
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise InputError(f"cannot read file: {exc.__class__.__name__}", shown) from None
    if len(data) > max_bytes:
        raise InputError(f"file larger than {max_bytes} bytes", shown)
    return data


def read_text(path, suffixes: tuple[str, ...] | None = None, what: str = "file",
              max_bytes: int = MAX_BYTES) -> str:
    """The UTF-8 text of a regular file (:func:`read_bytes`), refusing NUL bytes."""
    data = read_bytes(path, suffixes, what, max_bytes)
    shown = printable(str(path))
    if b"\x00" in data:
        raise InputError(f"contains NUL bytes: not a text {what}", shown, line=_line_of(data, data.index(b"\x00")))
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", shown, line=_line_of(data, exc.start)) from None


def _line_of(data: bytes, offset: int) -> int:
    """The 1-based line holding byte ``offset`` of ``data``."""
    return data.count(b"\n", 0, offset) + 1


_UNSAFE_CHARS = re.compile(r"[^\w.-]+")


def safe_name(name, fallback: str = "unnamed") -> str:
    """One file-name component made from ``name`` (see the module docstring); a longer one is
    cut to 71 characters and ends in 8 hex digits of its hash, so two long names that share
    their first 80 characters still name two files."""
    text = _UNSAFE_CHARS.sub("_", str(name)).strip("._")
    if len(text) > 80:
        text = f"{text[:71]}_{hashlib.sha256(str(name).encode('utf-8', 'surrogatepass')).hexdigest()[:8]}"
    return text or fallback


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")       # and the line separators splitlines() splits at


def few(names, limit: int = 10, empty: str = "") -> str:
    """``a, b, c`` for messages: the first ``limit`` names, then how many in all (``empty`` for none)."""
    names = list(names)
    if not names:
        return empty
    shown = ", ".join(names[:limit])
    return shown if len(names) <= limit else f"{shown}, ... ({len(names)} in all)"


def printable(text) -> str:
    """``text`` with control characters and line separators shown as escapes (``\\x1b``,
    ``\\u2028``), for one-line messages."""
    return _CONTROL.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), str(text))


def names_folder(text) -> bool:
    """Whether the output name ``text``, as the user wrote it, names a folder: it ends in a path
    separator (``x.png/``) or in ``.`` or ``..`` (``x.png/.``). :class:`~pathlib.Path` drops a
    trailing ``/`` and a last ``.``, so this is asked of the text, before it becomes a path."""
    text = os.fspath(text)
    separators = os.sep + (os.altsep or "")
    return text.endswith(tuple(separators)) or os.path.basename(text) in (".", "..")


def folder_name_message(text) -> str:
    """``x.png/ names a folder (it ends in '/')``: why the output name ``text`` is not a file's."""
    text = os.fspath(text)
    if text.endswith(tuple(os.sep + (os.altsep or ""))):
        ending = text[-1]
    else:
        ending = os.path.basename(text) if text in (".", "..") else os.sep + os.path.basename(text)
    return f"{printable(text)} names a folder (it ends in '{printable(ending)}'), not a file"


def file_in_the_way(folder) -> Path | None:
    """The nearest existing one of ``folder`` and the folders above it, if that is not a folder
    (``out`` for ``out/plots`` where ``out`` is a file): then ``folder`` cannot be made."""
    folder = Path(folder)
    for above in (folder, *folder.parents):
        try:
            if not above.exists():
                continue
            return None if above.is_dir() else above
        except OSError:                                 # (a name too long, no permission): mkdir says
            return None
    return None


def writable_folder(folder, option: str) -> Path:
    """``folder``, created if needed; one that cannot be made or written is bad input (``option``
    names the command-line option it came from), and so is one below a file (``out/plots`` where
    ``out`` is a file), named as such. A relative folder reached through a symbolic
    link (a default ``counterexamples/`` linked elsewhere) is bad input too: what is written
    below the working folder stays there; an absolute folder is the user's to name."""
    folder = Path(folder)
    if not folder.is_absolute():
        for depth in range(1, len(folder.parts) + 1):
            prefix = Path(*folder.parts[:depth])
            if prefix.is_symlink():
                raise InputError(f"{printable(prefix)} is a symbolic link: not written through", field=option)
    blocking = file_in_the_way(folder)
    if blocking is not None:
        raise InputError(f"{printable(blocking)} is a file, not a folder", field=option)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the folder {printable(folder)} ({exc.__class__.__name__})",
                         field=option) from None
    if not os.access(folder, os.W_OK):
        raise InputError(f"cannot write in {printable(folder)}", field=option)
    return folder


def writable_file(path, option: str, probe: bool = True) -> Path:
    """``path`` can be written: its folder exists or is made (:func:`writable_folder`), and it is
    not a folder, a read-only file, a symbolic link (writing would go through it, to wherever
    it points) nor another non-regular file (a FIFO, which would block the write, or a device); a file is opened (and removed again if it was new), so that a place that takes
    no file (``/proc``) is bad input before any computation, not after it. ``probe=False`` skips
    that opening: for a file another process may be creating and locking at the same time (a
    lock file, which the probe could remove under it). A name written as a folder's
    (:func:`names_folder`: ``x.png/``) is bad input, not the file ``x.png``."""
    if names_folder(path):
        raise InputError(f"{folder_name_message(path)} (give a file name)", field=option)
    path = Path(path)
    writable_folder(path.parent, option)
    if path.is_symlink():
        raise InputError(f"{printable(path)} is a symbolic link: not written through", field=option)
    if path.is_dir():
        raise InputError(f"{printable(path)} is a folder (give a file name)", field=option)
    if path.exists() and not path.is_file():        # a FIFO would block the write, a device take it
        raise InputError(f"{printable(path)} is not a regular file: not written", field=option)
    if path.exists() and not os.access(path, os.W_OK):
        raise InputError(f"cannot write {printable(path)}", field=option)
    if not probe:
        return path
    existed = path.exists()
    try:                    # a folder the file system will not create files in (/proc), checked now
        with open(path, "ab"):
            pass
    except OSError as exc:
        raise InputError(f"cannot write {printable(path)} ({exc.__class__.__name__})", field=option) from None
    if not existed:
        path.unlink(missing_ok=True)
    return path


def within(path, roots) -> bool:
    """Whether ``path`` (its links resolved) lies in one of the folders ``roots``: files that
    another file names (a suite's instances) are read only there, so a file handed to reach
    cannot make it read, and quote, a file anywhere else."""
    try:
        real = Path(path).resolve()
        return any(real.is_relative_to(Path(root).resolve()) for root in roots)
    except (OSError, RuntimeError, ValueError):
        return False
