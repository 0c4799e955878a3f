"""Many subdomains' expansions in lockstep: their nominal runs, DA propagations, Picard
expansions and event maps batched.

The candidate maps of a subdomain (:meth:`.problem.EventProblem.candidate_steps`) are written as a
generator that yields a request each time it needs a run: a :class:`Propagation` (a mode's flow,
a DA state, the RK8 step sizes: the state carried along its nominal run), a
:class:`.nominal.NominalRun` (the nominal run itself), a :class:`.event.Picard` (the expansion
in time about an event and the event function on it: each pass of the time refinement) or a
:class:`.event.EventSolve` (that expansion and the event map solved from it), and receives the
answer back. A request has a ``key`` (requests with the same key can be answered together),
``batch`` (the most answered at once, None for no limit), a ``length`` (the work it asks for:
batches are formed of requests of similar lengths) and ``answer(requests) -> answers``. :func:`run_one` answers one
generator's requests one at a time; :func:`run_batch` advances a whole ADS level's generators
together, answering their pending requests group by group.

A batch of propagations stacks the states along a leading axis (state ``i`` of run ``b`` is row
``b`` of one DA of shape ``(B,)``) and steps them together, each run with its own step sizes; a
run leaves the batch after its last step. The flow sees a batch of ``B`` states, so a network
layer (coefficient-major, :class:`.da.Layer`) is one stacked ``(k, m) x (M, m, B)`` product and
one series evaluation for all ``B`` subdomains: the per-operation overhead is paid once per
batch. Nominal runs are batched the same way (:mod:`.nominal`: rows of one array, each with its
own step control).

Each run's arithmetic is the same as on its own up to the order in which BLAS sums a matrix
product's terms, which can depend on the batch's size: the maps agree with the one-at-a-time path
to rounding (the nominal runs, whose step control would amplify it, are bit for bit).
"""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np

from reach.backends.taylor.da import DA
from reach.backends.taylor.deadline import NONE, Deadline, OutOfTime
from reach.backends.taylor.flow import rk8

#: the budget of the check this context works for (:func:`within`); the DA propagations look at
#: it every :data:`CHECK_EVERY` steps, so a stiff flow's thousands of steps stop at the budget
_DEADLINE: ContextVar[Deadline] = ContextVar("taylor_deadline", default=NONE)
CHECK_EVERY = 16


@contextmanager
def within(deadline: Deadline):
    """Run the propagations of this context under ``deadline`` (OutOfTime past it)."""
    token = _DEADLINE.set(deadline)
    try:
        yield
    finally:
        _DEADLINE.reset(token)

# runs stepped together: a SIREN network (5 sine layers of 32 neurons, order 4 in 2 variables)
# costs 22-26 us per run in batches of 16 to 96 once the allocator keeps freed blocks
# (:func:`.units.keep_freed_memory`; 56 us per run at 96 without). Each batch also pays the
# Python overhead of its sequence of array operations (about 0.7 CPU s for a CW SIREN
# propagation), so a worker's share of an ADS level is best stepped in few batches
BATCH = 96

@dataclass
class Propagation:
    """A request: carry the DA state ``x`` by RK8 steps ``steps`` of the flow ``f``."""

    f: object
    x: list
    steps: list

    batch = BATCH

    @property
    def length(self) -> int:
        return len(self.steps)

    def key(self):
        alg = next(v.alg for v in self.x if isinstance(v, DA))
        return ("propagation", id(self.f), alg.order, alg.nvars, len(self.x))

    @staticmethod
    def answer(requests: list["Propagation"]) -> list[list]:
        return propagate_batch(requests)


def propagate_batch(requests: list[Propagation]) -> list[list]:
    """The requests (same flow, same algebra, same state size) stepped as one batch; a run leaves
    the batch after its last step (the runs are taken longest first, so the batch is a prefix).
    OutOfTime past the budget of the context (:func:`within`)."""
    alg = next(v.alg for v in requests[0].x if isinstance(v, DA))
    n = len(requests[0].x)
    order = sorted(range(len(requests)), key=lambda b: -len(requests[b].steps))
    runs = [requests[b] for b in order]
    x = [DA(alg, np.stack([np.broadcast_to(r.x[i].c if isinstance(r.x[i], DA) else DA.const(alg, r.x[i]).c,
                                           (alg.size,)) for r in runs])) for i in range(n)]
    lengths = np.array([len(r.steps) for r in runs])
    H = np.zeros((len(runs), lengths[0]))
    for b, r in enumerate(runs):
        H[b, :len(r.steps)] = r.steps
    out = [None] * len(runs)
    deadline = _DEADLINE.get()
    for k in range(lengths[0] + 1):
        if k % CHECK_EVERY == 0 and deadline.passed():
            raise OutOfTime(deadline.text)
        active = int(np.sum(lengths > k))
        for b in range(active, len(x[0].c)):       # runs whose steps are done
            out[order[b]] = [DA(alg, xi.c[b]) for xi in x]
        x = [DA(alg, xi.c[:active]) for xi in x]
        if active:
            x = rk8(requests[0].f, x, H[:active, k], 1)
    return out


def run_one(gen):
    """The value of a candidate generator, its propagations done one by one."""
    try:
        req = next(gen)
        while True:
            req = gen.send(req.answer([req])[0])
    except StopIteration as stop:
        return stop.value


def run_batch(gens: list) -> list:
    """The values of many candidate generators, advanced together (see the module docstring)."""
    out, pending = [None] * len(gens), {}

    def advance(i, value):
        try:
            pending[i] = gens[i].send(value)
        except StopIteration as stop:
            out[i] = stop.value
            pending.pop(i, None)

    for i in range(len(gens)):
        advance(i, None)
    while pending:
        groups: dict = {}
        for i, req in pending.items():
            groups.setdefault(req.key(), []).append(i)
        for members in groups.values():
            members.sort(key=lambda i: -pending[i].length)     # runs of similar lengths together
            size = pending[members[0]].batch or len(members)
            for start in range(0, len(members), size):
                part = members[start:start + size]
                answers = pending[part[0]].answer([pending[i] for i in part])
                for i, answer in zip(part, answers):
                    advance(i, answer)
    return out
