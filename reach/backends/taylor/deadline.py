"""The time budget of one taylor check (option ``max_seconds``, 120 s by default, None for none):
a wall-clock instant, so that worker processes keep it too. No ADS level, refinement level, sweep
branch or flowpipe step starts past it; what was cut short is unbounded (UNKNOWN, its reason
naming the budget), what was finished stands."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass


@dataclass(frozen=True)
class Deadline:
    seconds: float | None           # the budget as given (None: none)
    at: float = math.inf            # the time.time() instant it ends

    @classmethod
    def start(cls, seconds: float | None) -> "Deadline":
        return cls(seconds, math.inf if seconds is None else time.time() + seconds)

    def passed(self) -> bool:
        return time.time() > self.at

    def left(self) -> float:
        return self.at - time.time()

    @property
    def text(self) -> str:
        return f"time budget of {self.seconds:g} s (option max_seconds) exhausted"

    def cut(self, why: str) -> bool:
        """Whether the reason ``why`` says that this budget cut the work short."""
        return self.seconds is not None and self.text in why


NONE = Deadline(None)


class OutOfTime(Exception):
    """Raised where a check cannot go on past its :class:`Deadline` (an ADS level)."""
