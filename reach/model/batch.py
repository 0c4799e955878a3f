"""Segments in blocks of grid steps: states, guard, invariant and monitor margins in one product.

In a linear mode every quantity the simulator tests on the grid is affine in the state, and
the state ``j`` grid steps after ``z = [x; 1]`` is ``P^j z``, ``P`` the exact one-step matrix
(``expm`` of the augmented generator). Stacking the rows

    ``L = [[I_n, 0], [H_guard, -g_guard] (each urgent transition), [H_inv, -g_inv],
           [H_obs, -g_obs] (each observer's margin rows)]``

gives ``W_j = L P^j`` for ``j <= J`` once per mode and set of observers; then a block of ``B``
grid steps for ``R`` runs is one matrix product ``(B K, n+1) @ (n+1, R)``, written into one
buffer reused block after block: the states and every margin at every grid point, runs along
the last axis (so the reductions over rows and steps are contiguous). ``z`` is the state at
the last multiple of ``J`` steps into the segment (the next one ``P^J z``, the state rows of
``W_J z``), so a run's states do not depend on which runs share its chunk. Blocks hold about
:data:`BLOCK_VALUES` numbers (memory bounded, cache-sized); the block loop stops as soon as
every run of the chunk has met its event, its blocking point or the end of its segment (the
first block is short and each next one twice as long, up to that size). The rows' magnitudes,
which scale the invariant and violation tolerances, are computed only for the runs whose margin
already exceeds the unscaled tolerance.

The semantics are the general path's (:meth:`reach.model.simulate.Simulator._segment_chunk`)
step for step: the same grid points are visited, an urgent guard that holds at a grid point
is located inside the grid interval before it to the resolution of the general path's
bisection (``Simulator._first_entry``; here :func:`first_entry`, sub-grids of that interval),
the window switch is taken at ``tau``, the first grid point outside the invariant (beyond
``INVARIANT_TOLERANCE (1 + m)`` in a row, ``m`` the magnitude it combines) is not visited and
the run stops at the last instant inside (the segment's end is the general path's, ``Simulator._finish``). Only rounding differs
(``(L P^j) z`` against ``L (P^j z)``; the states at segment starts and events by
:func:`taylor_flow`). In a
mode with a scalar state (``x' = a x + b``) the guard entry and the propagation to events are
in closed form instead (:func:`scalar_entry`, ``h 2^-40`` late as the bisection's right end).
A nonlinear mode with linear guards and invariant takes the same block loop with the states
of a block from the batched RK4 of :mod:`reach.model.batch_nonlinear` and the margins from
``L [x; 1]``; its guard entries are the general path's bisection.

Observers with a ``block`` method receive the visited grid states a block at a time,
``block(t (B, R), X (B, n, R), seen (B, R), mode, rows, margins)``; one that also has
``margin_rows(mode) -> (H, g) or None`` gets ``margins`` (B, k, R), the values of ``H x - g``
at those states, from the block product (else None). The event instants go through the
ordinary call.
"""

from __future__ import annotations

import numpy as np

BLOCK_VALUES = 1 << 19           # numbers in one block product (4 MiB)
MAX_BLOCK_STEPS = 512            # grid steps of one block at most (the size of a mode's table)
FIRST_BLOCK = 16                 # grid steps of a segment's first block
SUB_BITS = 4                     # a guard entry is searched on sub-grids of 2^4 pieces per round
TAYLOR_TOLERANCE = 1e-17        # the terms taylor_flow leaves out weigh at most this (relative)
TAYLOR_PIECES = 16               # pieces taylor_flow cuts a duration into at most


class LinearTable:
    """What :func:`segment_chunk` needs of one linear mode: the rows ``L`` (guards and
    invariant located in them), the block matrices ``W_j = [L; observers' rows] P^j``, guard
    entries and propagation to off-grid instants."""

    nonlinear = False

    def __init__(self, sim, name: str):
        self.L, self.guards, self.invariant = stacked_rows(sim, name)
        self.rows = ExtendedRows(self.L)
        self.powers = sim.powers[name]
        from reach.model.simulate import BISECTION_STEPS
        self.sub = SubSteps(sim.generators[name], SUB_BITS, BISECTION_STEPS // SUB_BITS)
        self.sim, self.name = sim, name
        M = sim.generators[name]
        self.scalar = (float(M[0, 0]), float(M[0, 1])) if sim.n == 1 else None    # x' = a x + b

    def entry(self, X: np.ndarray, h: np.ndarray, guard) -> np.ndarray:
        """Earliest time in ``(0, h]`` at which ``guard`` holds (it holds at ``h``):
        :func:`first_entry`, or in closed form for a scalar flow (:func:`scalar_entry`)."""
        if self.scalar is not None:
            return scalar_entry(self.scalar, guard.rows, X[:, 0], h)
        return first_entry(self.sim, self.name, X, h, guard, self.sub)

    def propagate(self, X: np.ndarray, h) -> np.ndarray:
        """The states after time ``h`` (one per run) with no event: :func:`taylor_flow` (or,
        beyond its reach, ``Simulator.propagate``); a scalar flow in closed form, ``x(h) = x
        e^(a h) + b expm1(a h) / a`` (``x + b h`` for ``a = 0``)."""
        if self.scalar is None:
            Y = taylor_flow(self.sim.generators[self.name], X, h)
            return self.sim.propagate(self.name, X, h) if Y is None else Y
        a, b = self.scalar
        h = np.broadcast_to(np.asarray(h, dtype=float), X.shape[:1])[:, None]
        return X * np.exp(a * h) + (b * np.expm1(a * h) / a if a != 0 else b * h)

    def weights(self, extra: list) -> tuple:
        """``(W, offsets)``: ``W_j = [L; E] P^j`` for ``j = 0..J`` (the block product's
        matrices, (J + 1, K, n+1)), ``E`` the observers' rows ``extra`` stacked after ``L``
        (:class:`ExtendedRows`), ``offsets`` where each starts. ``J``, the longest block, is
        :data:`MAX_BLOCK_STEPS`, fewer where ``W`` would hold more than :data:`BLOCK_VALUES`
        numbers."""
        from reach.model.simulate import _powers

        def build(L):
            K, m = L.shape
            powers = _powers(self.powers.step, 1 + min(MAX_BLOCK_STEPS, max(1, BLOCK_VALUES // (K * m))))
            return np.einsum("kl,jlm->jkm", L, powers)

        return self.rows.get(extra, build)


class ExtendedRows:
    """``L`` with observers' margin rows appended, and what is built from it, cached per list
    of row arrays (observers compile their rows once per model and property, so the same
    arrays come back run after run)."""

    def __init__(self, L: np.ndarray):
        self.L, self.cache = L, {}

    def get(self, extra: list, build) -> tuple:
        """``(build(L_ext), offsets)`` for ``L_ext = [L; H_1, -g_1; ...]`` (``extra = [(H_i,
        g_i)]``), ``offsets[i]`` the row of ``L_ext`` where ``H_i`` starts."""
        key = tuple((id(H), id(g)) for H, g in extra)
        hit = self.cache.get(key)
        if hit is None or any(a is not b for pair, kept in zip(extra, hit[0]) for a, b in zip(pair, kept)):
            if len(self.cache) > 16:
                self.cache.clear()
            L = np.vstack([self.L] + [np.hstack([H, -g[:, None]]) for H, g in extra])
            offsets = np.cumsum([self.L.shape[0]] + [H.shape[0] for H, _ in extra])[:-1]
            hit = self.cache[key] = (list(extra), build(L), list(offsets))
        return hit[1], hit[2]


def taylor_flow(M: np.ndarray, X: np.ndarray, h) -> np.ndarray | None:
    """``[x_r; 1] <- expm(M h_r) [x_r; 1]`` for every run ``r`` (``X`` (R, n), ``h`` one
    duration per run or one for all), the Taylor series summed on the vectors: no exponential
    per distinct duration. Each ``h_r`` is cut into ``p = ceil(theta / 3)`` equal pieces, ``theta
    = ||M||_1 max_r |h_r|``, so ``||M h_r / p||_1 <= u = theta / p <= 3``; a piece is the series
    to the least degree ``d`` whose left-out terms weigh at most ``u^(d+1)/(d+1)! / (1 - u/(d+2))
    <=`` :data:`TAYLOR_TOLERANCE` of ``||z||_1`` (``d <= 28``), summed by Horner, ``y <- z + (h/(p
    k)) M y`` for ``k = d..1`` (its terms stay below ``e^u <= 20`` times ``||z||_1``, so rounding
    stays near the unit roundoff). None when ``p`` would exceed :data:`TAYLOR_PIECES`."""
    h = np.broadcast_to(np.asarray(h, dtype=float), X.shape[:1])
    theta = np.linalg.norm(M, 1) * float(np.max(np.abs(h), initial=0.0))
    pieces = max(1, int(np.ceil(theta / 3.0)))
    if pieces > TAYLOR_PIECES:
        return None
    u, degree, term = theta / pieces, 0, 1.0
    while u >= degree + 2 or term * u / (degree + 1) / (1.0 - u / (degree + 2)) > TAYLOR_TOLERANCE:
        degree += 1
        term *= u / degree                                # u^d / d!
    Mt = np.ascontiguousarray(M.T)
    steps = [(h / (pieces * k))[:, None] for k in range(1, degree + 1)]
    Z = np.hstack([X, np.ones((X.shape[0], 1))])
    for _ in range(pieces):
        Y = Z
        for k in range(degree, 0, -1):
            Y = Y @ Mt
            Y *= steps[k - 1]
            Y += Z
        Z = Y
    return Z[:, :-1]


def stacked_rows(sim, name: str):
    """``(L, guards, invariant)`` of mode ``name``: ``L`` the rows ``[I_n, 0]``, ``[H, -g]`` of
    each urgent guard and of the invariant; ``guards`` each guard's ``(offset, rows, margins)``
    in ``L``, ``invariant`` its ``(offset, rows)``."""
    model, n = sim.model, sim.n
    parts = [np.hstack([np.eye(n), np.zeros((n, 1))])]
    guards = []
    offset = n
    for tr, _ in sim.urgent[name]:
        H, g = model.guard_halfspaces(tr)
        parts.append(np.hstack([H, -g[:, None]]))
        guards.append((offset, H.shape[0], _Affine(H, g)))
        offset += H.shape[0]
    H, g = model.modes[name].invariant_halfspaces
    parts.append(np.hstack([H, -g[:, None]]))
    return np.vstack(parts), guards, (offset, H.shape[0])


def table_for(sim, name: str):
    """The block table of mode ``name`` (:class:`LinearTable`, or
    :class:`reach.model.batch_nonlinear.NonlinearTable` for a nonlinear mode), or None where
    the general path applies (:func:`eligible`)."""
    if not eligible(sim, name):
        return None
    if name in sim.powers:
        return LinearTable(sim, name)
    from reach.model.batch_nonlinear import NonlinearTable
    return NonlinearTable(sim, name)


class SubSteps:
    """``expm(M h k 2^-(b r))`` for ``k = 1..2^b`` at each level ``r = 1..rounds``: the
    sub-grids a search for a guard entry in ``(0, h]`` walks down, cached for the few durations
    ``h`` the searches start from (mostly one grid step), and a guard's margins at their ends as
    rows acting on ``[x; 1]``."""

    def __init__(self, generator: np.ndarray, bits: int, rounds: int):
        self.generator, self.bits, self.rounds, self.cache = generator, bits, rounds, {}

    def __call__(self, h: float) -> np.ndarray:
        if h not in self.cache:
            if len(self.cache) > 64:
                self.cache.clear()
            from reach.model.simulate import batched_expm
            k = np.arange(1, 2 ** self.bits + 1)
            levels = [batched_expm(self.generator, h * k * 2.0 ** (-self.bits * r)) for r in range(1, self.rounds + 1)]
            self.cache[h] = np.stack(levels)            # (rounds, 2^bits, n+1, n+1)
        return self.cache[h]

    def margins(self, h: float, guard) -> np.ndarray:
        """``(rounds, m 2^b, n+1)``: row ``i 2^b + k`` of level ``r`` is ``[H_i, -g_i] E_rk``, the
        margin of guard row ``i`` (``rows = (H, g)``) at the end ``k`` of that sub-grid as a row
        acting on ``[x; 1]``."""
        key = (h, id(guard))
        if key not in self.cache:
            H, g = guard.rows
            G = np.einsum("in,rknm->rikm", H, self(h)[:, :, :-1, :])     # (rounds, m, 2^b, n+1)
            G[..., -1] -= g[:, None]
            self.cache[key] = (guard, G.reshape(G.shape[0], -1, G.shape[-1]))
        return self.cache[key][1]


def first_entry(sim, name: str, X: np.ndarray, h: np.ndarray, guard, sub: SubSteps) -> np.ndarray:
    """Earliest time in ``(0, h]`` at which ``guard`` holds (it holds at ``h``), to ``h 2^-(b
    rounds)`` (the resolution of ``Simulator._first_entry``'s bisection): in each round the
    interval ``(lo, lo + w]`` known to hold the entry is cut into ``2^b`` pieces, the guard's
    margins at their ends are ``[H, -g] expm(M w k 2^-b) [x(lo); 1]`` (one product for all the
    ends, :meth:`SubSteps.margins`), and the first end where the guard holds becomes the new
    right end. The first end, not any sign change: an entry is never skipped between two ends
    that both hold. Runs sharing a duration share the exponentials; with many distinct
    durations, ``Simulator._first_entry``."""
    durations, which = np.unique(h, return_inverse=True)
    if durations.size > 4:
        return sim._first_entry(name, X, h, guard)
    K = 2 ** sub.bits
    out = np.empty_like(h)
    for d_index, d in enumerate(durations):
        sel = np.flatnonzero(which.reshape(-1) == d_index)
        E, G = sub(float(d)), sub.margins(float(d), guard)
        z = np.vstack([X[sel].T, np.ones((1, sel.size))])               # [x(lo); 1], (n+1, R)
        lo = np.zeros(sel.size)
        for r in range(sub.rounds):
            inside = (G[r] @ z).reshape(-1, K, sel.size).max(axis=0, initial=-np.inf) <= 0  # (2^b, R)
            inside[-1] = True                                         # the right end holds
            k = inside.argmax(axis=0)                                 # first end that holds
            moved = np.flatnonzero(k > 0)
            z[:, moved] = np.einsum("aij,ja->ia", E[r, k[moved] - 1], z[:, moved])
            lo = lo + k * d * 2.0 ** (-sub.bits * (r + 1))
        out[sel] = lo + d * 2.0 ** (-sub.bits * sub.rounds)
    return out


def scalar_entry(flow, rows, x0: np.ndarray, h: np.ndarray) -> np.ndarray:
    """First entry into ``{x : H x <= g}`` (``rows = (H, g)``) of ``x' = a x + b`` from ``x0``,
    in ``(0, h]`` where it holds at ``h``. The solution ``x(s)`` is monotone, so each row holds
    on a half-line of ``s`` and the entry is the largest of the rows' crossing instants (0 for a
    row that already holds), ``s = ln((c + b/a) / (x0 + b/a)) / a`` for the crossing of ``x = c``
    (``(c - x0) / b`` when ``a = 0``). Returned ``h 2^-40`` late, as the bisection's right end
    (where the guard holds), and at most ``h``."""
    from reach.model.simulate import BISECTION_STEPS

    a, b = flow
    H, g = rows
    H = H[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = g / np.where(H != 0, H, np.nan)                            # (m,) crossing levels
        holds = H[None, :] * x0[:, None] <= g[None, :]                 # (R, m) at s = 0
        if a != 0:
            s = np.log((c[None, :] + b / a) / (x0[:, None] + b / a)) / a
        else:
            s = (c[None, :] - x0[:, None]) / b
    s = np.where(holds | ~np.isfinite(s), 0.0, s)
    entry = np.clip(s.max(axis=1, initial=0.0), 0.0, None) + h * 2.0 ** (-BISECTION_STEPS)
    return np.minimum(entry, h)


class _Affine:
    """``X -> X H^T - g`` with ``H^T`` stored contiguous (a faster product than a transposed
    view); ``rows = (H, g)``."""

    def __init__(self, H: np.ndarray, g: np.ndarray):
        self.rows, self.Ht = (H, g), np.ascontiguousarray(H.T)

    def __call__(self, X: np.ndarray) -> np.ndarray:
        return X @ self.Ht - self.rows[1]


def eligible(sim, name: str) -> bool:
    """The block path applies to a mode whose urgent guards and invariant are linear and which
    has no may-transition with a general guard (linear flows by products, nonlinear ones by
    :mod:`reach.model.batch_nonlinear`)."""
    model = sim.model
    mode = model.modes[name]
    return ((name in sim.powers or not mode.timeless) and not sim.exits[name]
            and model.modes[name].invariant_halfspaces is not None
            and all(model.guard_halfspaces(tr) is not None for tr, _ in sim.urgent[name]))


def notify_block(watchers, t, S, seen, m_index, rows, margins=None):
    """Hand visited grid states to the observers: whole blocks to those with ``block`` (with
    ``margins[i]``, the values of the rows watcher ``i`` asked for, where given), the states
    one by one (in time order per run) to the others."""
    plain = [f for f in watchers if not hasattr(f, "block")]
    for i, f in enumerate(watchers):
        if hasattr(f, "block"):
            f.block(t, S, seen, m_index, rows, None if margins is None else margins[i])
    if plain:
        run, j = np.nonzero(seen.T)                    # by run, then time
        if run.size:
            for f in plain:
                f(t[j, run], S[j, :, run], np.full(run.size, m_index), rows[run])


def margin_rows(watchers, m_index: int) -> tuple:
    """``(extra, wanted)``: the rows ``(H, g)`` the watchers ask for in mode ``m_index`` (those
    with ``margin_rows``), and per watcher the index of its rows in ``extra`` or None."""
    extra, wanted = [], []
    for f in watchers:
        rows = f.margin_rows(m_index) if hasattr(f, "margin_rows") else None
        wanted.append(None if rows is None else len(extra))
        if rows is not None:
            extra.append(rows)
    return extra, wanted


def segment_chunk(sim, name, rows, runs, next_kick, horizon, table):
    """Advance ``rows`` (all in mode ``name``; their states, modes and times in ``runs``) to
    their next event, kick or the horizon, in blocks of grid steps (see the module docstring);
    the end of the segment is the general path's (``Simulator._finish``)."""
    from reach.model.simulate import INVARIANT_TOLERANCE

    n, dt = sim.n, sim.dt
    n_rows = rows.size
    X, watchers = runs.X, runs.watchers
    m_index = int(runs.mode[rows[0]])
    t0, k0, end, win_time, stop_at, count = sim.segment_limits(name, rows, runs.t, runs.tau, next_kick, horizon)
    count = max(1, min(count, sim.steps + 2 - int(k0.min())))
    Y0 = table.propagate(X[rows], np.maximum(k0 * dt - t0, 0.0))
    Z = np.vstack([Y0.T, np.ones((1, n_rows))])                          # (n+1, R), at the block start
    extra, wanted = margin_rows(watchers, m_index)
    W, offsets = table.weights(extra)
    K = W.shape[-2]
    spans = [None if i is None else (offsets[i], extra[i][0].shape[0]) for i in wanted]

    event_time = win_time.copy()
    event_tr = np.where(np.isfinite(win_time), 0, -1)
    blocked = np.zeros(n_rows, dtype=bool)
    block_t = np.zeros(n_rows)
    last_t, last_x = t0.copy(), X[rows].copy()                       # last visited grid state
    prev_t, prev_x = t0.copy(), X[rows].copy()                       # grid state before the block
    done = np.zeros(n_rows, dtype=bool)
    longest = MAX_BLOCK_STEPS if table.nonlinear else W.shape[0] - 1
    most = max(1, min(longest, BLOCK_VALUES // (K * n_rows)))
    step_block = min(FIRST_BLOCK, most)                 # doubled each block: short segments stay cheap
    buffer = np.empty(min(most, count) * K * n_rows)    # the block product, reused block after block
    inv_offset, inv_rows = table.invariant
    crossings = sim.crossings[name]
    k0f = k0.astype(float)
    # linear: Z is the state at step r0, a multiple of J; blocks stay within [r0, r0 + J]
    period = count if table.nonlinear else W.shape[0] - 1
    j0 = r0 = 0
    while j0 < count and not done.all():
        j1 = min(count, j0 + step_block, r0 + period)
        act = np.flatnonzero(~done)
        A, B = act.size, j1 - j0
        sel = act if A < n_rows else slice(None)        # the active runs (a view while all are)
        Za = Z[:, sel]
        out = buffer[:B * K * A].reshape(B, K, A)
        gt = (k0f[sel][None, :] + np.arange(j0, j1)[:, None]) * dt        # (B, A) grid times
        valid = gt <= stop_at[sel] + 1e-12
        if table.nonlinear:             # the states from the integrator, the margins from L
            S_next = table.steps.block(Za[:n], B + 1)
            Z[:n, sel] = S_next[B]
            S = S_next[:B]
            O = np.matmul(W[:, :n], S, out=out)
            O += W[:, n][None, :, None]
            valid &= np.isfinite(S).all(axis=1)
        else:                           # [x_j; 1] = P^j z: states and margins in one product
            O = np.matmul(W[j0 - r0:j1 - r0].reshape(B * K, n + 1), Za, out=out.reshape(B * K, A)).reshape(B, K, A)
            S = O[:, :n, :]
            if j1 == r0 + period:
                Z[:n, sel] = W[period, :n] @ Za
                r0 = j1
        for j_tr, (off, m, guard) in enumerate(table.guards, start=1):
            inside = valid & np.all(O[:, off:off + m, :] <= 0, axis=1)
            hit = np.flatnonzero(inside.any(axis=0))
            if hit.size:
                j = inside[:, hit].argmax(axis=0)
                first = j == 0
                p_t = np.where(first, prev_t[act[hit]], gt[np.maximum(j - 1, 0), hit])
                p_x = np.where(first[:, None], prev_x[act[hit]], S[np.maximum(j - 1, 0), :, hit])
                s = table.entry(p_x, gt[j, hit] - p_t, guard)
                when = p_t + s
                rows_hit = act[hit]
                better = when < event_time[rows_hit]
                event_time[rows_hit[better]] = when[better]
                event_tr[rows_hit[better]] = j_tr
            if crossings:
                when = crossings.earliest(j_tr - 1, prev_t[act], prev_x[act], gt.T, S.transpose(2, 0, 1), valid.T,
                                          event_time[act])
                better = when < event_time[act]
                event_time[act[better]], event_tr[act[better]] = when[better], j_tr
        limit_j = np.full(A, B)
        out_any = np.zeros(A, dtype=bool)
        if inv_rows:
            # outside: a margin above INVARIANT_TOLERANCE (1 + m), m the magnitude its row
            # combines (Simulator.inside), so above the tolerance itself; m only for the runs
            # with such a margin
            inv_margins = O[:, inv_offset:inv_offset + inv_rows, :]
            near = (inv_margins.max(axis=1) > INVARIANT_TOLERANCE) & valid & (gt < event_time[sel])
            c = np.flatnonzero(near.any(axis=0))
            if c.size:
                states = S[:, :, c].transpose(0, 2, 1).reshape(-1, n)
                scale = sim.invariant_scale(name)(states).reshape(B, c.size, inv_rows).transpose(0, 2, 1)
                outside = near[:, c] & np.any(inv_margins[:, :, c] > INVARIANT_TOLERANCE * (1.0 + scale), axis=1)
                b = c[outside.any(axis=0)]
                if b.size:
                    jb = outside[:, outside.any(axis=0)].argmax(axis=0)
                    out_any[b] = True
                    limit_j[b] = jb
                    blocked[act[b]] = True
                    block_t[act[b]] = gt[jb, b]
        # the states visited: before the event, before the first grid point outside the invariant
        seen = valid & (gt < event_time[sel]) & (np.arange(B)[:, None] < limit_j)
        notify_block(watchers, gt, S, seen, m_index, rows[sel],
                     [None if sp is None else O[:, sp[0]:sp[0] + sp[1], :] for sp in spans])
        prev_t[sel], prev_x[sel] = gt[-1], S[-1].T
        if seen.all():
            last_t[sel], last_x[sel] = gt[-1], S[-1].T
        else:
            n_seen = seen.sum(axis=0)
            some = np.flatnonzero(n_seen)
            last = n_seen[some] - 1
            last_t[act[some]] = gt[last, some]
            last_x[act[some]] = S[last, :, some]
        done[sel] |= out_any | (gt[-1] >= np.minimum(stop_at[sel], event_time[sel]) - 1e-12) | ~valid.any(axis=0)
        j0 = j1
        step_block = min(2 * step_block, most)
    sim._finish(name, rows, runs, end, event_time, event_tr, blocked, block_t, last_t, last_x, table.propagate)
