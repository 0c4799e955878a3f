"""SpaceEx configuration files (``.cfg``): ``key = value`` lines, ``#`` comments, quoted values.

Read: ``system`` (the component to analyse), ``initially`` and ``forbidden`` (formulas),
``time-horizon``, ``iter-max`` and ``sampling-time`` (kept in the model's notes). The other keys are options of
SpaceEx's own algorithms (scenario, directions, tolerances, output) or of other tools reading the
same files (JuliaReach's ``zono.order``) and are kept but unused.
A key that is none of SpaceEx's and is spelt like one that is read (``forbiden``) is bad input:
what it was meant to say would otherwise be dropped without a word.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field

from reach.errors import InputError
from reach.paths import read_text

MAX_BYTES = 1_000_000

#: the keys this reader uses
READ_KEYS = ("system", "initially", "forbidden", "time-horizon", "iter-max", "sampling-time")
#: SpaceEx's other options (its analysis core's command line and web interface)
OTHER_KEYS = ("scenario", "directions", "set-aggregation", "clustering", "flowpipe-tolerance",
              "flowpipe-tolerance-rel", "local-time-horizon", "rel-err", "abs-err", "output-error",
              "output-format", "output-variables", "output-file", "verbosity",
              "simu-init-sampling-points", "fixpoint-check", "time-step")


#: what a missing required key of the cfg should say (SpaceEx's own default horizon explores
#: until a fixpoint, which reach does not do)
MISSING_HINTS = {
    "time-horizon": "SpaceEx's default explores up to a fixpoint, without a bound; give a positive "
                    "time: time-horizon = 10",
    "initially": "the initial set: initially = \"x == 0 & loc(sys) == l0\"",
    "system": "the component to analyse: system = \"sys\"",
}


@dataclass
class Config:
    file: str
    values: dict = field(default_factory=dict)     # key -> (text, line)

    def text(self, key: str) -> str | None:
        return self.values[key][0] if key in self.values else None

    def line(self, key: str) -> int | None:
        return self.values[key][1] if key in self.values else None

    def missing(self, key: str) -> InputError:
        """The error for a required key the file lacks (a key spelt like it is refused on reading),
        saying what to write."""
        return InputError(f"no '{key}' ({MISSING_HINTS.get(key, 'add it')})", self.file, line=1)

    def number(self, key: str) -> float | None:
        if key not in self.values:
            return None
        text, line = self.values[key]
        try:
            value = float(text)
        except ValueError:
            raise InputError(f"{key}: expected a number, got '{text}'", self.file, line=line) from None
        if value != value or value in (float("inf"), float("-inf")):
            raise InputError(f"{key}: expected a finite number", self.file, line=line)
        return value


def parse_cfg(text: str, file: str) -> Config:
    if len(text) > MAX_BYTES:
        raise InputError(f"file larger than {MAX_BYTES} bytes", file)
    cfg = Config(file)
    i, line, n = 0, 1, len(text)
    while i < n:
        # one logical line: key = value (a quoted value may span lines)
        start_line = line
        j = text.find("\n", i)
        j = n if j < 0 else j
        raw = text[i:j]
        stripped = raw.split("#", 1)[0].strip() if '"' not in raw.split("#", 1)[0] else raw.strip()
        if not stripped or stripped.startswith("#"):
            i, line = j + 1, line + 1
            continue
        if "=" not in stripped:
            raise InputError(f"expected 'key = value', got '{stripped[:40]}'", file, line=start_line)
        eq = text.index("=", i)
        key = text[i:eq].strip()
        k = eq + 1
        while k < n and text[k] in " \t":
            k += 1
        if k < n and text[k] == '"':
            close = text.find('"', k + 1)
            if close < 0:
                raise InputError(f"{key}: unterminated quoted value", file, line=start_line)
            value = text[k + 1:close]
            line += text.count("\n", i, close)
            rest_end = text.find("\n", close)
            rest_end = n if rest_end < 0 else rest_end
            rest = text[close + 1:rest_end].split("#", 1)[0].strip()
            if rest and line > start_line:              # the closing quote of another line's value
                raise InputError(f"{key}: the quoted value opened here is closed on line {line}, followed by "
                                 f"'{rest[:30]}' (a closing quote missing on this line?)", file, line=start_line)
            if rest:
                raise InputError(f"{key}: unexpected text after the quoted value", file, line=line)
            i = rest_end + 1
        else:
            value = text[k:j].split("#", 1)[0].strip()
            i = j + 1
        line += 1
        if not key or not all(c.isalnum() or c in "-_." for c in key):      # zono.order: other tools' options
            raise InputError(f"'{key}' is not a cfg key", file, line=start_line)
        if key in cfg.values and key in READ_KEYS:
            raise InputError(f"duplicate key '{key}' (first on line {cfg.values[key][1]})", file, line=start_line)
        cfg.values[key] = (value, start_line)     # an option read by SpaceEx only: the last one stands
    _refuse_misspelt_keys(cfg)
    return cfg


def _refuse_misspelt_keys(cfg: Config) -> None:
    for key, (_, line) in cfg.values.items():
        if key in READ_KEYS or key in OTHER_KEYS:
            continue
        near = difflib.get_close_matches(key, READ_KEYS, n=1, cutoff=0.75)
        if near:
            raise InputError(f"unknown key '{key}' (a misspelling of '{near[0]}'? as written it would be "
                             "ignored)", cfg.file, line=line)


def read_cfg(path) -> Config:
    return parse_cfg(read_text(path, (".cfg",), "SpaceEx configuration", MAX_BYTES), str(path))
