"""Continuous-time flowpipes of affine flows: step maps, grid chains, segments (chord hull
plus interpolation error), the input effect, timed (constant-flow) segments and the cheap
bounds the exploration screens with. See :mod:`reach.backends.star` for the argument."""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from reach import lp
from reach.backends.star.options import DEPTH_LP_TOLERANCE, HIGHS_DEFAULT_TOLERANCE
from reach.sets import Box, Star, chord_hull
from reach.sets.hpolytope import HPolytope

#: coefficients whose extent is at most this fraction of the largest one's are folded into a
#: box (:func:`folded`)
FOLD_RATIO = 1e-6
MAX_SUBSAMPLES = 4096        # sub-samples of one cell for its curvature bound (the suite needs at most 56)
SUBSAMPLE_BYTES = 1 << 28    # and at most this many bytes of their n x n matrices (a 300-state flow: 372)


#: sub-cells of the input bound per sub-sample of :meth:`AffineFlow.curvature` (accuracy)
INPUT_SUBSTEPS = 4

#: at most this many numbers per block of sampled input maps (memory of :meth:`AffineFlow.deviation`)
DEVIATION_CHUNK = 4_000_000


class AffineFlow:
    """``x' = A x + b + B (u - u_c)`` of one mode: step maps, stacked powers, the curvature
    data and, with a bounded input ``|u - u_c| <= u_r`` (componentwise, any measurable
    signal), the bound of its effect.

    Input effect. Split every run as ``x = x_free + d`` with ``x_free`` the run of
    ``x' = A x + b`` (``b`` holds ``B u_c``) from the same state and
    ``d(t) = int_0^t e^{A (t - s)} B (u(s) - u_c) ds``. Then ``|d(t)| <= R(t) =
    int_0^t |e^{A tau} B| u_r dtau`` (componentwise; equality for the bang-bang signal of
    each component), non-decreasing in ``t``. ``R`` is bounded on sub-cells of length
    ``delta = h / q`` (``q`` as in :meth:`curvature`, times ``INPUT_SUBSTEPS``):
    ``G(tau) = e^{A tau} B`` is replaced by
    its chord between the samples ``G_l = e^{A l delta} B``, off by at most
    ``lam (1 - lam) delta^2 / 2 sup |G''|``, and ``G'' = A^2 G`` is bounded on the sub-cell by
    the closure argument of :meth:`curvature` (``sup |Y| <= F max(|Y_l|, |Y_{l+1}|)``,
    ``Y = A^2 G``, ``F = (I - delta^2/8 |A^2|)^{-1}``). With ``int_0^1 lam (1 - lam) = 1/6``:

        int_{sub-cell} |G| <= int |chord| + delta^3 / 12 F max(|Y_l|, |Y_{l+1}|),

    ``int |chord|`` in closed form (:func:`_abs_chord_integral`),
    summed over sub-cells and weighted by ``u_r`` (:meth:`deviation`). The chord keeps the
    cancellations inside ``e^{A tau} B``, so the bound is the exact support up to
    ``O(delta^2)``."""

    def __init__(self, A: np.ndarray, b: np.ndarray, B: np.ndarray | None = None,
                 u_radius: np.ndarray | None = None):
        self.A, self.b = A, b
        self.B, self.u_radius = B, u_radius
        self.inputs = B is not None and B.size > 0 and bool(np.any(np.abs(B) @ u_radius > 0))
        self.n = A.shape[0]
        self.A2 = A @ A
        self.Ab = A @ b
        self.drift = not np.any(A)          # constant flow: exact segments, no refinement
        self.rho = float(np.max(np.abs(np.linalg.eigvals(np.abs(self.A2))))) if self.n else 0.0
        self._steps: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._powers: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._curvature: dict[float, tuple] = {}
        self._deviation: dict = {}
        self._blocks: dict[tuple[float, int], tuple[np.ndarray, np.ndarray]] = {}
        self._growth: dict[float, np.ndarray] = {}

    def deviation(self, h: float, count: int, C: np.ndarray | None = None) -> np.ndarray | None:
        """``R_j >= sup_{t <= j h} |d(t)|`` for ``j = 0..count`` (``(count + 1, n)``), or None
        without inputs (see the class doc). With rows ``C`` (``(r, n)``), the same bound of
        ``|C d(t)|`` (``(count + 1, r)``): ``int_0^t |C e^{A tau} B| u_r dtau``, the chord of
        ``C G`` per sub-cell plus ``|C|`` times the componentwise curvature bound. Along a
        row that mixes components, this is the exact support of the input effect up to
        ``O(delta^2)`` (Le Guernic and Girard's support functions), where ``|C| R`` adds up
        each component's worst signal as if they could all be worst at once."""
        if not self.inputs:
            return None
        key = h if C is None else (h, C.shape, C.tobytes())
        R = self._deviation.get(key)
        if R is None or R.shape[0] <= count:
            D, _, F, q = self.curvature(h)
            q = q * INPUT_SUBSTEPS
            delta = h / q
            F = np.linalg.inv(np.eye(self.n) - delta ** 2 / 8 * np.abs(self.A2))
            Phi_delta = self.step(delta)[0]
            G = [self.B]
            for _ in range(q):                                   # G_l = e^{A l delta} B, l <= q
                G.append(Phi_delta @ G[-1])
            Phis, _ = self.powers(h, count)
            G, Y = np.array(G), np.array([self.A2 @ g for g in G])
            chunk = max(1, DEVIATION_CHUNK // (G.size * (1 if C is None else max(1, C.shape[0]))))
            steps = []
            for first in range(0, count, chunk):                 # cells first .. first + chunk
                P = Phis[first:min(count, first + chunk)]
                Gs = np.einsum("jab,lbp->jlap", P, G)              # (cells, q + 1, n, p)
                absY = np.abs(np.einsum("jab,lbp->jlap", P, Y))
                curv = delta ** 3 / 12 * np.einsum("ab,jbp->jap", F,
                                                    np.maximum(absY[:, :-1], absY[:, 1:]).sum(axis=1))
                if C is not None:                                  # along the rows of C
                    Gs = np.einsum("ra,jlap->jlrp", C, Gs)
                    curv = np.einsum("ra,jap->jrp", np.abs(C), curv)
                chord = _abs_chord_integral(Gs[:, :-1], Gs[:, 1:], delta).sum(axis=1)  # (cells, n or r, p)
                steps.append((chord + curv) @ self.u_radius)
            steps = np.concatenate(steps)
            R = np.vstack([np.zeros(steps.shape[1]), np.cumsum(steps, axis=0)])
            self._deviation[key] = R
        return R[:count + 1]

    def input_block(self, h: float, cells: int):
        """``(S, eps)`` for a block of ``cells`` cells of length ``h``: the block's input effect
        ``v = int_0^T G(r) (u(T - r) - u_c) dr`` (``G(r) = e^{A r} B``, ``T = cells h``, any
        measurable signal in the input box) lies in ``{S w} + [-eps, eps]``, ``w = (x, y)``
        per input with ``|x| + |y| <= 1``, ``|y| <= 1/2`` (``S``: ``(n, 2 p)``, the ``x``
        columns first).

        ``G`` is split as its Legendre fit ``c0 + c1 phi(r)`` (``phi = (2 r - T) / T``,
        ``c0`` its mean, ``c1 = (3/T) int G phi``) plus a residual:
        ``v = c0 int ũ + c1 int phi ũ + int (G - c0 - c1 phi) ũ`` with ``ũ = u(T - .) - u_c``.
        Per input, ``x = int ũ / (T u_r)`` and ``y = int phi ũ / (T u_r)`` satisfy
        ``s1 x + s2 y = int (s1 + s2 phi) ũ / (T u_r) <= int (1 + s1 s2 phi) / T = 1`` for all
        signs (``|phi| <= 1``, ``int phi = 0``) and ``|y| <= int |phi| / T = 1/2``; the columns
        are ``T u_r c0`` and ``T u_r c1``. The residual is at most ``eps = int |G - c0 - c1 phi|
        dr u_r`` per component, bounded as :meth:`deviation` bounds ``int |G|``: chords on
        sub-cells plus the closure bound on the residual's curvature ``A^2 G`` (``phi`` is
        linear). The fit is exact to first order, so ``eps = O(T^3 |A^2 B| u_r)``, and the
        coupling row keeps the support exact where ``G``'s component keeps its sign."""
        key = (h, cells)
        if key not in self._blocks:
            q = self.curvature(h)[3] * INPUT_SUBSTEPS
            delta, total = h / q, cells * h
            n, p = self.B.shape
            aug = np.zeros((n + 2 * p, n + 2 * p))      # int_0^T G and int_0^T r G by expm
            aug[:n, :n], aug[:n, n:n + p], aug[n:n + p, n + p:] = self.A, self.B, np.eye(p)
            E = expm(aug * total)
            integral, moment = E[:n, n:n + p], E[:n, n + p:]           # int G, int (T - r) G
            c0 = integral / total
            c1 = 3 / total * (2 * (total * integral - moment) / total - integral)  # (3/T) int G phi
            F = np.linalg.inv(np.eye(n) - delta ** 2 / 8 * np.abs(self.A2))
            Phi_delta = self.step(delta)[0]
            chord, curv, G = 0.0, 0.0, [self.B]
            for cell in range(cells):                # one cell's sub-samples at a time (memory)
                for _ in range(q):
                    G.append(Phi_delta @ G[-1])
                samples = np.array(G)
                phi = (2 * delta * np.arange(cell * q, (cell + 1) * q + 1) - total) / total
                residual = samples - c0 - phi[:, None, None] * c1
                absY = np.abs(np.einsum("ab,lbp->lap", self.A2, samples))
                chord = chord + _abs_chord_integral(residual[:-1], residual[1:], delta).sum(axis=0)
                curv = curv + delta ** 3 / 12 * F @ np.maximum(absY[:-1], absY[1:]).sum(axis=0)
                G = G[-1:]
            S = np.hstack([total * c0 * self.u_radius, total * c1 * self.u_radius])
            self._blocks[key] = (S, (chord + curv) @ self.u_radius)
        return self._blocks[key]

    def cell_growth(self, h: float) -> np.ndarray:
        """``K >= 0`` with ``sup_{0 <= tau <= h} |e^{A tau} e| <= K |e|`` componentwise for
        every ``e``: on each sub-cell of :meth:`curvature`, ``|y| <= max(|y_l|, |y_{l+1}|) +
        delta^2/8 sup |y''|`` for ``y = e^{A tau} e`` (chord plus interpolation error) and
        ``sup |y''| <= F max(|A^2 y_l|, |A^2 y_{l+1}|)`` (closure), with ``y_l = P_l e``."""
        if h not in self._growth:
            D, _, F, q = self.curvature(h)
            P = self.powers(h / q, q)[0]                         # P_l = e^{A l delta}
            self._growth[h] = np.abs(P).max(axis=0) + (h / q) ** 2 / 8 * F @ np.abs(D).max(axis=0)
        return self._growth[h]

    def step(self, h: float):
        """``(Phi, psi)`` with ``x(t + h) = Phi x(t) + psi``."""
        if h not in self._steps:
            n = self.n
            aug = np.zeros((n + 1, n + 1))
            aug[:n, :n], aug[:n, n] = self.A, self.b
            E = expm(aug * h)
            self._steps[h] = (E[:n, :n], E[:n, n])
        return self._steps[h]

    def powers(self, h: float, count: int):
        """``Phi_j, psi_j`` for ``j = 0..count`` (``x(t + j h) = Phi_j x + psi_j``)."""
        Phis, psis = self._powers.get(h, (np.eye(self.n)[None], np.zeros((1, self.n))))
        if Phis.shape[0] <= count:
            Phi, psi = self.step(h)
            P, p = list(Phis), list(psis)
            while len(P) <= count:
                P.append(Phi @ P[-1])
                p.append(Phi @ p[-1] + psi)
            Phis, psis = np.array(P), np.array(p)
            self._powers[h] = (Phis, psis)
        return Phis[:count + 1], psis[:count + 1]

    def curvature(self, h: float):
        """Sub-sample data for ``M >= sup |x''|`` on a cell of length ``h``.

        Returns ``(D, d, F, q)``: ``x''(s_l) = D_l x + d_l`` at ``s_l = l h / q``, the
        closure factor ``F = (I - delta^2/8 |A^2|)^{-1}`` and ``q``, the least number of
        sub-steps with spectral radius of ``delta^2/8 |A^2|`` at most 1/4.
        """
        if h not in self._curvature:
            ratio = 0.0 if self.rho == 0 else h / np.sqrt(2.0 / self.rho)
            most = min(MAX_SUBSAMPLES, max(1, SUBSAMPLE_BYTES // (8 * self.n * self.n)))
            if not ratio <= most:
                raise ArithmeticError(f"a cell of length {h:.3g} is {ratio:.3g} times the flow's time scale "
                                      f"(at most {most} sub-samples at {self.n} states): set a shorter step, "
                                      f"-o step={h * most / ratio:.3g} or less")
            q = max(1, int(np.ceil(ratio)))
            delta = h / q
            Phi, psi = self.step(delta)
            D, d = [], []
            P, p = np.eye(self.n), np.zeros(self.n)
            for _ in range(q + 1):
                D.append(self.A2 @ P)
                d.append(self.A2 @ p + self.Ab)
                P, p = Phi @ P, Phi @ p + psi
            F = np.linalg.inv(np.eye(self.n) - delta ** 2 / 8 * np.abs(self.A2))
            self._curvature[h] = (np.array(D), np.array(d), F, q)
        return self._curvature[h]


class ChainInputs:
    """The effect of time-varying inputs along a chain of ``count`` cells of length ``h`` from
    its start (:meth:`.explorer._Explorer._flow_chain`), split into generators and boxes.

    The chain is cut into ``nb = floor(count / L)`` blocks of ``L`` cells (``L = 0``: one box
    from the chain's start, no generators). A completed block's effect is
    ``S w_b + e_b`` (:meth:`AffineFlow.input_block`, ``|w_b| <= 1``, ``|e_b| <= eps``), carried
    to grid point ``j`` by ``Phi_{j - (b+1) L}``: the generators enter the grid stars as new
    coefficients (``columns``, ``(count + 1, n, nb p)``, zero before the block ends), so a
    successor keeps the input's directions instead of a box around them. What is left is a box:

    * ``grid[j] = R(j - s_j) + E_j`` at grid point ``j``, with ``s_j`` the start of the block
      in progress, ``R`` the exact-support bound of :meth:`AffineFlow.deviation` (the block in
      progress) and ``E_j = sum_b |Phi_{j - (b+1) L}| eps`` (the completed blocks' remainders);
    * ``cell[j] = R(j + 1 - s_j) + K E_j`` over cell ``j`` (``K``: :meth:`AffineFlow.cell_growth`,
      the remainders moving with the flow inside the cell; ``R`` non-decreasing);
    * ``since[j] = (j - s_j) h`` and ``carried[j] = K E_j``: for bisected cells, whose first
      half takes ``carried + R(since + h/2)`` (:meth:`.explorer._Explorer._half_spread`);
    * ``directed = (C, bounds)`` for rows ``C`` along which the box is loose (the mode's unsafe
      pieces and guards): ``bounds[j] = R_C(j + 1 - s_j) + |C| K E_j`` bounds ``|C rest|`` over
      cell ``j`` (:meth:`AffineFlow.deviation` with ``C``), which the cell's box meets
      (:func:`_plus_box`).

    Every run is ``x_free + sum_b Phi S w_b + rest`` with ``x_free`` the run at the input's
    centre from the same state and ``|rest|`` within the box, so grid stars plus ``grid`` and
    segments (hulls of grid stars, which hold the generators) plus ``cell`` cover it."""

    def __init__(self, flow: AffineFlow, h: float, count: int, cells: int, directions: np.ndarray | None = None):
        n = flow.n
        L = self._cells(count, cells)
        nb, p = count // L, flow.B.shape[1]
        self.count = 2 * nb * p                  # (x, y) per block and input, x columns first
        k = nb * p                               # |x| + |y| <= 1 for each pair
        signs = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]], dtype=float)
        self.rows = np.zeros((4 * k, self.count))
        for i in range(k):
            self.rows[4 * i:4 * i + 4, [i, k + i]] = signs
        self.high = np.concatenate([np.ones(k), np.full(k, 0.5)])
        starts = L * np.minimum(np.arange(count + 1) // L, nb)   # block in progress at grid j
        R = flow.deviation(h, min(L, count))
        self.columns = np.zeros((count + 1, n, self.count))
        E = np.zeros((count + 1, n))
        if nb:
            S, eps = flow.input_block(h, L)
            Phis, _ = flow.powers(h, count)
            for b in range(nb):
                end = (b + 1) * L
                moved = Phis[:count + 1 - end]
                self.columns[end:, :, b * p:(b + 1) * p] = moved @ S[:, :p]
                self.columns[end:, :, k + b * p:k + (b + 1) * p] = moved @ S[:, p:]
                E[end:] += np.abs(moved) @ eps
        j = np.arange(count + 1)
        self.grid = R[j - starts] + E
        carried = E[:-1] @ flow.cell_growth(h).T if nb else E[:-1]
        self.cell = R[j[:-1] + 1 - starts[:-1]] + carried
        self.carried, self.since = carried, (j[:-1] - starts[:-1]) * h
        self.directed = None
        if directions is not None and directions.shape[0]:
            R_C = flow.deviation(h, min(L, count), directions)
            self.directed = (directions, R_C[j[:-1] + 1 - starts[:-1]] + carried @ np.abs(directions).T)

    @staticmethod
    def _cells(count: int, cells: int) -> int:
        """Cells per block (``count + 1``, no completed block, when ``cells`` is 0)."""
        return cells if cells else count + 1

    @staticmethod
    def generators(flow: AffineFlow, count: int, cells: int) -> int:
        """How many coefficients the generators add to a chain of ``count`` cells."""
        return 2 * (count // ChainInputs._cells(count, cells)) * flow.B.shape[1]

    def extend(self, star: Star) -> Star:
        """``star`` with the generators' coefficients (zero columns: the same set; the chain
        adds the columns to its images), their box and coupling rows."""
        A, m = star.predicate.A, star.nvars
        rows = np.vstack([np.hstack([A, np.zeros((A.shape[0], self.count))]),
                          np.hstack([np.zeros((self.rows.shape[0], m)), self.rows])])
        predicate = HPolytope(rows, np.concatenate([star.predicate.b, np.ones(self.rows.shape[0])]))
        box = Box(np.append(star.box.low, -self.high), np.append(star.box.high, self.high))
        return Star(star.center, np.hstack([star.basis, np.zeros((star.dim, self.count))]), predicate, box)


def _abs_chord_integral(a, b, delta):
    """``int_0^delta |a + (b - a) s / delta| ds`` elementwise: ``delta (|a| + |b|) / 2`` without
    a sign change, ``delta (a^2 + b^2) / (2 (|a| + |b|))`` across one."""
    total = np.abs(a) + np.abs(b)
    with np.errstate(invalid="ignore", divide="ignore"):
        crossing = np.where(total > 0, (a * a + b * b) / total, 0.0)
    return delta / 2 * np.where(a * b < 0, crossing, total)


def _chain_bounds(center, basis, box, W):
    """Support bounds ``max_{x in Y_j} w^T x`` for every grid star ``j`` and row ``w`` of
    ``W`` from the coefficient box: ``(J, rows)``; ``center (J, n)``, ``basis (J, n, m)``."""
    G = np.matmul(W, basis)                                      # (J, rows, m)
    return center @ W.T + G @ box.center + np.abs(G) @ box.radius


#: bytes of the products ``D_l V_j`` that :func:`_chain_abs_bounds` holds at once
PRODUCT_BYTES = 16 * 2 ** 20


def _abs_at_centres(center, basis, box, D, d):
    """``|D_l (c_j + V_j m) + d_l|``, ``m`` the coefficient box's centre: ``(J, L, n)``."""
    shifted = center + basis @ box.center                                     # (J, n)
    return np.abs(np.swapaxes(np.matmul(shifted[None], np.swapaxes(D, 1, 2)), 0, 1) + d[None])


def chunk_cells(D, n: int, m: int) -> int:
    """Grid stars per chunk of :func:`_chain_abs_bounds` for ``n`` states, ``m`` coefficients."""
    return max(1, PRODUCT_BYTES // (8 * D.shape[0] * n * max(m, 1)))


def _chain_abs_bounds(center, basis, box, D, d, tick=None):
    """``max |D_l x + d_l|`` over each ``Y_j``, per sample ``l`` and component: ``(J, L, n)``;
    ``tick()`` (if given) is called before each chunk (the caller's time and memory guards).

    Exact support of each component over the coefficient box (radius ``r``):
    ``|D_l (c_j + V_j m) + d_l| + |D_l V_j| r``. The products ``D_l V_j`` are formed a few
    grid stars at a time (:data:`PRODUCT_BYTES`): all at once they take ``J L n m`` numbers,
    600 MB for a 273-state model over 60 cells, and are slower for it."""
    J, (L, n, _) = center.shape[0], D.shape
    step = chunk_cells(D, n, basis.shape[2])
    spread = np.empty((J, L, n))
    for s in range(0, J, step):
        if tick is not None:
            tick()
        spread[s:s + step] = np.abs(np.matmul(D[None], basis[s:s + step, None])) @ box.radius
    return _abs_at_centres(center, basis, box, D, d) + spread


def _hull_abs_bounds(center, basis, box, D, d):
    """An upper bound of :func:`_chain_abs_bounds` at a fraction of its cost: each ``Y_j``
    replaced by its interval hull, ``|D_l (c_j + V_j m) + d_l| + |D_l| (|V_j| r)``, which
    takes ``L n^2`` operations per grid star instead of ``L n^2 m``. Equal to the exact
    bound where ``V_j`` is diagonal; looser where the flow has turned the star."""
    hull = np.abs(basis) @ box.radius                                         # (J, n)
    spread = np.swapaxes(np.matmul(hull[None], np.swapaxes(np.abs(D), 1, 2)), 0, 1)
    return _abs_at_centres(center, basis, box, D, d) + spread


def _segment(flow: AffineFlow, start: Star, h: float, error=None):
    """The segment of the cell ``[0, h]`` from ``start``: ``(segment, end star, error)``.

    ``error_i = h^2/8 M_i`` is the interpolation error at mid-cell; ``M`` bounds
    ``|x''|`` on the cell from the sub-samples of :meth:`AffineFlow.curvature`. A chain that
    has already computed it for ``start`` and ``h`` passes it as ``error``.
    """
    end = start.affine_map(*flow.step(h))
    if flow.drift:
        return _drift_segment(start, flow.b, h), end, np.zeros(flow.n)
    if error is not None:
        return chord_hull(start, end.center, end.basis, error), end, error
    D, d, F, _ = flow.curvature(h)
    if np.all(np.isfinite(start.box.radius)):
        samples = _chain_abs_bounds(start.center[None], start.basis[None], start.box, D, d)[0]
    else:
        n = flow.n
        upper = start.support_bounds(np.concatenate([D, -D]).reshape(-1, n))
        samples = np.maximum(*(upper.reshape(2, -1) + np.concatenate([d, -d]).reshape(2, -1))).reshape(-1, n)
    error = h * h / 8 * (F @ samples.max(axis=0))
    return chord_hull(start, end.center, end.basis, error), end, error


def _tightened(star: Star, rows: int, rounds: int = 3) -> Star | None:
    """``star`` with its coefficient box shrunk by bound propagation over the predicate rows
    (None if that proves it empty); the set is unchanged.

    For a row ``sum_j A_ij a_j <= b_i`` with finite activity bounds, every ``a_k`` with
    ``A_ik > 0`` satisfies ``a_k <= (b_i - sum_{j != k} min(A_ij a_j)) / A_ik`` (and the mirror
    bound when ``A_ik < 0``), minima over the current box. Each bound is relaxed by ``1e-9``
    times ``1 + |bound| + (|b_i| + sum_j |A_ij| max(|lo_j|, |hi_j|)) / |A_ik|``: relative to the
    magnitudes of the row's terms, not only to the result, since a row whose terms cancel (a
    thin invariant sliver far from the origin; ``b = g - H c`` is itself rounded) loses
    digits in them. So rounding never cuts a point of the set. Cheap support bounds then see the
    guards and invariants that pin a coefficient (a dwell fixed by guard and invariant).
    Only the last ``rows`` rows (those just added by an intersection) are used: the box is
    already consistent with the older ones, and scanning them all again costs too much.
    """
    A, b = star.predicate.A[-rows:] if rows else star.predicate.A[:0], star.predicate.b[-rows:] if rows else star.predicate.b[:0]
    lo, hi = star.box.low.copy(), star.box.high.copy()
    if A.shape[0] == 0 or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return star
    pos, neg = np.maximum(A, 0.0), np.minimum(A, 0.0)
    for _ in range(rounds):
        least = pos * lo + neg * hi                                   # min of A_ij a_j
        rest = b[:, None] - (least.sum(axis=1)[:, None] - least)      # room left for a_k
        size = np.abs(b) + np.abs(A) @ np.maximum(np.abs(lo), np.abs(hi))    # the row's magnitudes
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            bound = rest / A
            slack = 1e-9 * (1.0 + np.abs(bound) + size[:, None] / np.abs(A))
            upper = np.where((A > 0) & ~np.isnan(bound), bound + slack, np.inf).min(axis=0)
            lower = np.where((A < 0) & ~np.isnan(bound), bound - slack, -np.inf).max(axis=0)
        new_lo, new_hi = np.maximum(lo, lower), np.minimum(hi, upper)
        if np.any(new_lo > new_hi):
            return None
        if np.array_equal(new_lo, lo) and np.array_equal(new_hi, hi):
            break
        lo, hi = new_lo, new_hi
    return Star(star.center, star.basis, star.predicate, Box(lo, hi))


def _plus_box(star: Star, radius, directed=None) -> Star:
    """``star + [-radius, radius]`` (Minkowski sum): one new coefficient ``a_i`` in ``[-1, 1]``
    per positive component of ``radius``; with ``directed = (C, bounds)``, ``star + {e :
    |e| <= radius, |C e| <= bounds}`` (rows ``|C_k diag(radius) a| <= bounds_k`` on the new
    coefficients, kept where they cut the box)."""
    radius = np.asarray(radius, dtype=float)
    if not np.all(np.isfinite(radius)):   # NaN would read as "no error" below
        raise lp.LPError("a non-finite error radius (the flow overflows)")
    free = np.flatnonzero(radius > 0)
    if not free.size:
        return star
    E = np.zeros((star.dim, free.size))
    E[free, np.arange(free.size)] = radius[free]
    A, b = star.predicate.A, star.predicate.b
    rows = np.hstack([A, np.zeros((A.shape[0], free.size))])
    if directed is not None:
        C, bounds = directed
        M = C[:, free] * radius[free]
        cut = np.abs(M).sum(axis=1) > bounds * (1 + 1e-9)
        if cut.any():
            M, bounds = M[cut], bounds[cut]
            rows = np.vstack([rows, np.hstack([np.zeros((2 * M.shape[0], star.nvars)), np.vstack([M, -M])])])
            b = np.concatenate([b, bounds, bounds])
    predicate = HPolytope(rows, b)
    box = Box(np.append(star.box.low, -np.ones(free.size)), np.append(star.box.high, np.ones(free.size)))
    return Star(star.center, np.hstack([star.basis, E]), predicate, box)


def _equalities(H, g) -> list[tuple[int, int]]:
    """Pairs ``(i, j)`` of rows of ``H x <= g`` that are opposite (unit normals summing to at
    most 1e-12) and bound a slab of zero width (up to 1e-12 of the bound): an equality."""
    norms = np.linalg.norm(H, axis=1)
    pairs, used = [], set()
    for i in range(H.shape[0]):
        for j in range(i + 1, H.shape[0]):
            if i in used or j in used or not (norms[i] > 0 and norms[j] > 0):
                continue
            if np.abs(H[i] / norms[i] + H[j] / norms[j]).max() <= 1e-12 and \
                    abs(g[i] / norms[i] + g[j] / norms[j]) <= 1e-12 * (1.0 + abs(g[i] / norms[i])):
                pairs.append((i, j))
                used |= {i, j}
    return pairs


def folded(star: Star, keep: int, ratio: float = FOLD_RATIO) -> Star:
    """``star`` with its small coefficients folded into a box: the columns past the first
    ``keep`` whose extent ``|V_j| r_j`` is at most ``ratio`` of the largest column's (the
    spread boxes an instant jump adds at each tick, :meth:`.explorer._Explorer._at_instant`)
    are replaced by at most ``n`` axis columns, so a run of such jumps keeps a bounded number
    of coefficients. It contains ``star``: with ``F`` the folded columns (box midpoints
    ``a_F0``, radii ``r_F``), ``V_F a_F`` lies in ``V_F a_F0 + [-|V_F| r_F, |V_F| r_F]`` and
    each predicate row ``A_K a_K + A_F a_F <= b`` implies ``A_K a_K <= b - A_F a_F0 +
    |A_F| r_F``; the new radius is padded against the rounding of those sums. Returns
    ``star`` itself where that would not reduce the count."""
    lo, hi = star.box.low, star.box.high
    finite = np.isfinite(lo) & np.isfinite(hi)
    extent = np.abs(star.basis).sum(axis=0) * np.where(finite, (hi - lo) / 2, np.inf)
    if star.nvars <= keep or not np.any(np.isfinite(extent)):
        return star
    small = np.zeros(star.nvars, dtype=bool)
    small[keep:] = finite[keep:] & (extent[keep:] <= ratio * extent[np.isfinite(extent)].max())
    V_F = star.basis[:, small]
    radius = np.abs(V_F) @ ((hi - lo)[small] / 2)
    if np.count_nonzero(small) <= np.count_nonzero(radius > 0):
        return star
    mid = (hi + lo)[small] / 2
    shift = V_F @ mid
    center = star.center + shift
    eps = np.finfo(float).eps
    radius = radius * (1 + 1e-12) + 4 * eps * (np.abs(center) + np.abs(V_F) @ np.abs(mid) + radius)
    A, b = star.predicate.A, star.predicate.b
    A_F = A[:, small]
    relaxed = b - A_F @ mid + np.abs(A_F) @ ((hi - lo)[small] / 2)
    relaxed = relaxed + 4 * eps * (np.abs(b) + np.abs(A_F) @ (np.abs(mid) + (hi - lo)[small] / 2))
    A_K = A[:, ~small]
    rows = np.any(A_K != 0, axis=1) | (relaxed < 0)
    free = np.flatnonzero(radius > 0)
    E = np.zeros((star.dim, free.size))
    E[free, np.arange(free.size)] = radius[free]
    predicate = HPolytope(np.hstack([A_K[rows], np.zeros((int(rows.sum()), free.size))]), relaxed[rows])
    box = Box(np.append(lo[~small], -np.ones(free.size)), np.append(hi[~small], np.ones(free.size)))
    return Star(center, np.hstack([star.basis[:, ~small], E]), predicate, box)


def _drift_segment(start: Star, b: np.ndarray, h: float) -> Star:
    """``start + [0, h] b`` exactly: every run of ``x' = b`` from ``start`` over the cell.
    One new coefficient ``s in [0, 1]`` (column ``h b``); the old ones keep their meaning."""
    A = start.predicate.A
    predicate = HPolytope(np.hstack([A, np.zeros((A.shape[0], 1))]), start.predicate.b)
    box = Box(np.append(start.box.low, 0.0), np.append(start.box.high, 1.0))
    basis = np.hstack([start.basis, (h * np.asarray(b, dtype=float))[:, None]])
    return Star(start.center, basis, predicate, box)


def flowpipe(A, b, initial: Star, step: float, duration: float, B=None, u_low=None,
             u_high=None) -> list[Star]:
    """Segments covering every trajectory of ``x' = A x + b + B u`` from ``initial`` over
    ``[0, duration]`` in continuous time (one star per cell of length ``step``), for every
    input signal with values in ``[u_low, u_high]`` (no input if ``B`` is None)."""
    A, b = np.asarray(A, dtype=float), np.asarray(b, dtype=float)
    if B is None:
        flow = AffineFlow(A, b)
    else:
        B, lo, hi = np.atleast_2d(np.asarray(B, dtype=float)), np.asarray(u_low, float), np.asarray(u_high, float)
        flow = AffineFlow(A, b + B @ ((lo + hi) / 2), B, (hi - lo) / 2)
    count = max(1, int(np.ceil(duration / step - 1e-9)))
    dev = flow.deviation(step, count)
    segments, star = [], initial
    for j in range(count):
        seg, star, _ = _segment(flow, star, step)
        segments.append(seg if dev is None else _plus_box(seg, dev[j + 1]))
    return segments


def _block_spreads(seg: Star, H: np.ndarray, blocks: tuple[int, ...], cut_from: int | None = None):
    """Per block ``b`` (coefficients from ``blocks[b]`` to the next start) and row ``r``:
    the spread ``sum |H_r . V_col| * radius_col`` the block is responsible for, and the
    part of it due to the block's interpolation-error coefficients. A cell block starting
    at ``s`` holds ``s`` hull coefficients, the chord weight, then the error coefficients
    (see :func:`reach.sets.star.chord_hull`); the last block's error ends at ``cut_from``
    when given (the columns after it are not error)."""
    contribution = np.abs(H @ seg.basis) * seg.box.radius                # (rows, vars)
    ends = blocks[1:] + (seg.nvars,)
    error_ends = ends[:-1] + (seg.nvars if cut_from is None else cut_from,)
    spread = np.array([contribution[:, a:b].sum(axis=1) for a, b in zip(blocks, ends)])
    error = np.array([contribution[:, 2 * a + 1:b].sum(axis=1) if a else np.zeros(len(H))
                      for a, b in zip(blocks, error_ends)])
    return spread, error


def _depth(seg: Star, H, g, piece_rows: int, touch: float = 0.0):
    """``Star.depth`` on the piece rows, with further rows (the horizon) as hard limits:
    ``(depth, coefficients, tolerance)``, ``tolerance`` the primal feasibility tolerance the LP
    was solved to -- ``DEPTH_LP_TOLERANCE``, or where HiGHS fails at it 100 times that, then
    its default (about 1e-7); an :class:`reach.lp.LPError` if all fail.

    An equality of the piece (two opposite rows of zero width, ``t == 4.15``) caps every depth at
    0, so the deepest point would be any point of the slice, however shallow in the other rows:
    such pairs are hard limits too, each relaxed by ``touch (1 + |g|)`` (as a depth of
    ``-touch`` still meets the piece), and the depth is taken over the other rows. A star farther
    than that from the equality misses the piece, as its depth would say; one within it is as
    deep as its points on the slice reach into the other rows."""
    pairs = _equalities(H[:piece_rows], g[:piece_rows])
    if pairs and len(pairs) * 2 < piece_rows:
        rows = sorted(i for pair in pairs for i in pair)
        norms = np.linalg.norm(H[rows], axis=1)
        slack = touch * (1.0 + np.abs(g[rows]) / norms) * norms
        hard = np.vstack([H[rows], H[piece_rows:]]), np.concatenate([g[rows] + slack, g[piece_rows:]])
        keep = [i for i in range(piece_rows) if i not in rows]
        H = np.vstack([H[keep], H[piece_rows:]])
        g = np.concatenate([g[keep], g[piece_rows:]])
        piece_rows = len(keep)
    else:
        hard = H[piece_rows:], g[piece_rows:]
    star = seg.intersect_halfspaces(*hard)
    for tolerance in (DEPTH_LP_TOLERANCE, 100 * DEPTH_LP_TOLERANCE, None):
        try:
            return (*star.depth(H[:piece_rows], g[:piece_rows], tolerance=tolerance),
                    HIGHS_DEFAULT_TOLERANCE if tolerance is None else tolerance)
        except lp.LPError:
            if tolerance is None:
                raise
