"""Forward stochastic reach for non-Gaussian kicks by characteristic functions (seed eqs. 7-11).

For the kicked system of :mod:`reach.model.ltv` the quantity the target constrains,
``z = T x[K]`` (``d`` rows, the directions of the target box ``lower <= T x <= upper``), is

    z = T Psi(K, 0) x[0] + sum_k T Psi(K, k) G w[k] + z_c,

so its characteristic function is the product of eq. (7) over the independent pieces
(eq. 10 for Gaussian kicks; any law with a known characteristic function here):

    Psi_z(beta) = exp(j beta . z_c) psi_0(Psi(K,0)^T T^T beta) prod_k psi_w(G^T Psi(K,k)^T T^T beta).

The rows ``T Psi(K, k) G`` are the blocks of the controllability matrix of eq. (9) seen through
``T``. The density (eq. 8) is recovered on a periodic window ``[c - R, c + R]`` around the mean
(``c = E z``): by Poisson summation the ``L = 2R``-periodised density is

    f_L(z) = (1/V) sum_{k in Z^d} Psi_z(omega_k) exp(-j omega_k . z),  omega_k = 2 pi k / L,

whose samples on a grid are one FFT (:func:`density_on_grid`). Its integral over the target
(eq. 11) is taken exactly in the Fourier domain,

    P = (1/V) sum_k Psi_z(omega_k) prod_i int_{l_i}^{u_i} exp(-j omega_{k,i} z_i) dz_i,

i.e. the exact integral over the target of the trigonometric interpolant the FFT samples.

Errors: (i) periodisation — at most ``P(z outside the window)``, zero when every law has
bounded support inside it, otherwise bounded by Chernoff's inequality with the laws' moment
generating functions (rigorous); (ii) truncation of the frequency sum at ``|k_i| <= K_i``.
Where the kicks are Gaussian with a covariance ``S`` of ``z`` whose least eigenvalue ``lam`` is
positive, every factor but theirs has modulus at most 1, so ``|Psi_z(omega)| <= exp(-lam |omega|^2
/ 2)``, and with ``|int_{l_i}^{u_i} exp(-j omega z) dz| <= u_i - l_i = w_i`` the omitted terms sum
to at most (a union over the axis on which ``k`` leaves the grid, sums bounded by integrals)

    (prod_i w_i / L_i) sum_i sqrt(pi / a_i) erfc(sqrt(a_i) K_i) prod_{j != i} (1 + sqrt(pi / a_j)),

``a_i = lam (2 pi / L_i)^2 / 2`` (:func:`truncation_bound`, which also uses the box transform's
decay ``2 / |omega_i|`` in the tail): a bound, and ``K_i`` grows by half along
the axes whose term exceeds the tolerance's share until it is met or ``MAX_FREQUENCIES`` is
reached. Without such a factor (no Gaussian kick, or one that leaves a direction of ``z``
unspread, as a uniform initial state alone) the truncation is only estimated, by the magnitude of
the outer shell ``|k_i| > 3 K_i / 4`` of retained terms, and the result says so
(:attr:`Inversion.rigorous`): the sinc factors of a uniform law decay too slowly to bound the
tail at a useful frequency count, and an estimate is no ground for a verdict.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import erfc

from reach.model.ltv import KickedLinearSystem
from reach.sets.gaussian import Probability

MAX_FREQUENCIES = 2 ** 20        # frequency vectors evaluated (half of the symmetric grid)
CHUNK_VALUES = 2 ** 22           # frequency x kick x component values held at once
ROUNDING = 1e-12


# ------------------------------------------------------------------ laws of the kicks

@dataclass(frozen=True)
class GaussianLaw:
    """``N(mean, cov)``: ``psi(v) = exp(j v.mean - v.cov.v / 2)`` (eq. 10)."""

    mean: np.ndarray
    cov: np.ndarray

    @property
    def variance(self):
        return np.asarray(self.cov, dtype=float)

    @property
    def halfwidth(self):
        return None

    def cf_product(self, B, D):
        """``prod_k psi(B D[k])``: the sum of the kicks is ``N(sum_k D[k] mean, sum_k D[k] cov D[k]^T)``."""
        m = np.einsum("kdp,p->d", D, self.mean)
        S = np.einsum("kdp,pq,keq->de", D, self.cov, D)
        return np.exp(1j * B @ m - 0.5 * np.einsum("md,de,me->m", B, S, B))

    def log_mgf(self, S):
        """``log E exp(s.(w - mean))``."""
        return 0.5 * np.einsum("...i,ij,...j->...", S, self.cov, S)

    def sample(self, rng, size):
        return rng.multivariate_normal(self.mean, self.cov, size=size, method="eigh")


@dataclass(frozen=True)
class UniformLaw:
    """Independent components uniform on ``[low_i, high_i]`` (equal bounds: a fixed value)."""

    low: np.ndarray
    high: np.ndarray

    @property
    def mean(self):
        return 0.5 * (np.asarray(self.low, float) + np.asarray(self.high, float))

    @property
    def halfwidth(self):
        return 0.5 * (np.asarray(self.high, float) - np.asarray(self.low, float))

    @property
    def variance(self):
        return np.diag(self.halfwidth ** 2 / 3)

    def cf_product(self, B, D):
        """``prod_k psi(B D[k])`` with ``psi(v) = exp(j v.mean) prod_i sin(h_i v_i) / (h_i v_i)``."""
        phase = np.exp(1j * B @ np.einsum("kdp,p->d", D, self.mean))
        return phase * _real_product(B, D, lambda V: _sinc(V * self.halfwidth))

    def log_mgf(self, S):
        x = np.abs(S) * self.halfwidth
        # log(sinh(x)/x), stable for small and large x
        safe = np.where(x > 1e-6, x, 1.0)
        val = np.where(x > 1e-6, safe + np.log1p(-np.exp(-2 * safe)) - np.log(2 * safe), x ** 2 / 6)
        return np.sum(val, axis=-1)

    def sample(self, rng, size):
        return self.low + (np.asarray(self.high) - np.asarray(self.low)) * rng.random((size, len(self.low)))


@dataclass(frozen=True)
class LaplaceLaw:
    """Independent components Laplace(loc_i, scale_i): ``psi(v) = exp(j v loc) / (1 + scale^2 v^2)``."""

    loc: np.ndarray
    scale: np.ndarray

    @property
    def mean(self):
        return np.asarray(self.loc, dtype=float)

    @property
    def halfwidth(self):
        return None

    @property
    def variance(self):
        return np.diag(2 * np.asarray(self.scale, float) ** 2)

    def cf_product(self, B, D):
        """``prod_k psi(B D[k])`` with ``psi(v) = exp(j v.loc) / prod_i (1 + scale_i^2 v_i^2)``."""
        phase = np.exp(1j * B @ np.einsum("kdp,p->d", D, self.mean))
        return phase / _real_product(B, D, lambda V: 1 + (V * self.scale) ** 2)

    def log_mgf(self, S):
        """``-sum log(1 - scale^2 s^2)``, infinite where some ``|scale s| >= 1``."""
        u = (S * self.scale) ** 2
        inside = np.all(u < 1, axis=-1)
        return np.where(inside, -np.sum(np.log1p(-np.where(u < 1, u, 0.0)), axis=-1), np.inf)

    def sample(self, rng, size):
        return rng.laplace(self.loc, self.scale, size=(size, len(self.loc)))


@dataclass(frozen=True)
class MixtureLaw:
    """A finite mixture ``sum_i weight_i law_i``."""

    weights: np.ndarray
    laws: tuple = field(default_factory=tuple)

    @property
    def mean(self):
        return sum(w * law.mean for w, law in zip(self.weights, self.laws))

    @property
    def halfwidth(self):
        widths = [law.halfwidth for law in self.laws]
        if any(h is None for h in widths):
            return None
        m = self.mean
        return np.max([np.abs(law.mean - m) + h for law, h in zip(self.laws, widths)], axis=0)

    @property
    def variance(self):
        m = self.mean
        return sum(w * (law.variance + np.outer(law.mean - m, law.mean - m))
                   for w, law in zip(self.weights, self.laws))

    def cf_product(self, B, D):
        """``prod_k sum_i weight_i psi_i(B D[k])`` (no factorisation: one kick at a time)."""
        out = np.ones(B.shape[0], dtype=complex)
        for Dk in D:
            out *= sum(w * law.cf_product(B, Dk[None]) for w, law in zip(self.weights, self.laws))
        return out

    def log_mgf(self, S):
        m = self.mean
        terms = [np.log(w) + law.log_mgf(S) + S @ (law.mean - m) for w, law in zip(self.weights, self.laws)]
        return np.logaddexp.reduce(np.stack(terms), axis=0)

    def sample(self, rng, size):
        which = rng.choice(len(self.laws), size=size, p=self.weights)
        out = np.zeros((size, len(self.mean)))
        for i, law in enumerate(self.laws):
            sel = which == i
            if np.any(sel):
                out[sel] = law.sample(rng, int(sel.sum()))
        return out


def _sinc(x):
    """``sin(x) / x`` (1 at 0)."""
    small = np.abs(x) < 1e-8
    return np.where(small, 1.0, np.sin(x) / np.where(small, 1.0, x))


def _real_product(B, D, factor):
    """``prod_{k, i} factor(V)[k, i]`` with ``V[k] = B D[k]``, in chunks of frequencies."""
    K, d, p = D.shape
    flat = D.transpose(1, 0, 2).reshape(d, K * p)
    out = np.ones(B.shape[0])
    chunk = max(1, CHUNK_VALUES // max(1, K * p))
    for start in range(0, B.shape[0], chunk):
        rows = slice(start, start + chunk)
        V = (B[rows] @ flat).reshape(-1, K, p)
        out[rows] = np.prod(factor(V).reshape(V.shape[0], -1), axis=1)
    return out


def point_law(x) -> UniformLaw:
    """A fixed vector as a (degenerate) law."""
    x = np.asarray(x, dtype=float)
    return UniformLaw(x, x)


# ------------------------------------------------------------------ the projected sum

@dataclass
class ProjectedSum:
    """``z = z_c + D0 x0 + sum_k D[k] w[k]`` with ``x0 ~ initial``, ``w[k] ~ kick`` all independent."""

    zc: np.ndarray
    D0: np.ndarray           # (d, n)
    D: np.ndarray            # (K, d, p)
    initial: object
    kick: object

    @classmethod
    def of(cls, system: KickedLinearSystem, T, initial, kick) -> "ProjectedSum":
        T = np.atleast_2d(np.asarray(T, dtype=float))
        K = system.steps
        back = T.copy()                        # T Psi(K, k), from k = K down to 0
        D = np.zeros((K, T.shape[0], system.G.shape[1]))
        zc = np.zeros(T.shape[0])
        for k in range(K - 1, -1, -1):
            zc += back @ system.c[k]
            back = back @ system.Phi[k]
            D[k] = back @ system.G
        return cls(zc, back, D, initial, kick)

    @property
    def mean(self):
        return self.zc + self.D0 @ self.initial.mean + self.D.sum(axis=0) @ self.kick.mean

    @property
    def kick_cov(self):
        """The covariance the kicks alone give ``z``."""
        return np.einsum("kip,pq,kjq->ij", self.D, self.kick.variance, self.D)

    @property
    def cov(self):
        return self.D0 @ self.initial.variance @ self.D0.T + self.kick_cov

    def cf(self, B):
        """``Psi_z`` at the frequency vectors ``B`` (m, d) (eq. 7)."""
        B = np.atleast_2d(B)
        return (np.exp(1j * B @ self.zc) * self.initial.cf_product(B, self.D0[None])
                * self.kick.cf_product(B, self.D))

    def tail(self, direction, r) -> float:
        """Chernoff bound on ``P(direction . (z - E z) >= r)``; exactly 0 beyond bounded support."""
        a0 = direction @ self.D0
        ak = np.einsum("i,kip->kp", direction, self.D)
        h0, hw = self.initial.halfwidth, self.kick.halfwidth
        if h0 is not None and hw is not None:
            reach = np.abs(a0) @ h0 + np.sum(np.abs(ak) @ hw)
            if r > reach:
                return 0.0
        sd = np.sqrt(max(direction @ self.cov @ direction, 1e-300))
        best = 1.0
        for theta in np.geomspace(1e-3, 1e3, 241) / sd:
            log_bound = (-theta * r + self.initial.log_mgf(theta * a0)
                         + np.sum(self.kick.log_mgf(theta * ak)))
            if np.isfinite(log_bound):
                best = min(best, float(np.exp(min(log_bound, 0.0))))
        return best


# ------------------------------------------------------------------ inversion

@dataclass
class _Window:
    centre: np.ndarray
    half: np.ndarray
    alias: float             # bound on P(z outside the window)

    @property
    def period(self):
        return 2 * self.half


def _window(z: ProjectedSum, alias_tol: float) -> _Window:
    centre = z.mean
    sd = np.sqrt(np.maximum(np.diag(z.cov), 1e-300))
    d = centre.size
    half = 6.0 * sd
    total = 0.0
    for i in range(d):
        e = np.eye(d)[i]
        while True:
            bound = z.tail(e, half[i]) + z.tail(-e, half[i])
            if bound <= alias_tol / d or half[i] > 1e3 * sd[i]:
                break
            half[i] *= 1.25
        total += bound
    return _Window(centre, half, min(1.0, total))


def _frequencies(counts):
    """All integer vectors ``k`` with ``|k_i| <= counts[i]``."""
    axes = [np.arange(-c, c + 1) for c in counts]
    grid = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grid], axis=1)


def _half_frequencies(counts):
    """``k = 0`` and the ``k`` whose first non-zero entry is positive, with weights 1 and 2.

    ``Psi_z(-omega)`` and the box transform at ``-omega`` are the conjugates of their values at
    ``omega``, so the real part of the full sum is the weighted sum over this half.
    """
    k = _frequencies(counts)
    first = np.argmax(k != 0, axis=1)
    lead = k[np.arange(k.shape[0]), first]
    keep = lead >= 0
    k = k[keep]
    return k, np.where(np.any(k != 0, axis=1), 2.0, 1.0)


def _box_transform(omega, lower, upper):
    """``int_l^u exp(-j omega z) dz`` elementwise (``u - l`` at ``omega = 0``)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        val = (np.exp(-1j * omega * lower) - np.exp(-1j * omega * upper)) / (1j * omega)
    return np.where(omega == 0, upper - lower + 0j, val)


@dataclass(frozen=True)
class Inversion(Probability):
    """:class:`Probability` from :func:`box_probability`; ``rigorous``: the interval is a bound
    (the truncation bounded), else an estimate; ``shell``: the truncation as the outer shell of
    retained terms estimates it (what the interval's half-width would be on that estimate)."""

    rigorous: bool = True
    shell: float = 0.0


def truncation_bound(lam: float, widths, L, counts) -> np.ndarray | None:
    """Per axis ``i``, the bound of the module docstring on the omitted terms whose ``k`` leaves
    the grid along axis ``i`` (their sum bounds the truncation), or None where ``lam <= 0``. The
    box transform is also at most ``2 / |omega_i| = L_i / (pi |k_i|)``, which beyond ``K_i`` is
    at most ``L_i / (pi (K_i + 1))``: the smaller of the two factors is taken for the tail."""
    if not lam > 0:
        return None
    L, w, K = np.asarray(L, float), np.asarray(widths, float), np.asarray(counts, float)
    a = 0.5 * lam * (2 * np.pi / L) ** 2
    whole = w * (1.0 + np.sqrt(np.pi / a))
    tails = np.minimum(w, L / (np.pi * (K + 1))) * np.sqrt(np.pi / a) * erfc(np.sqrt(a) * K)
    others = np.array([np.prod(np.delete(whole, i)) for i in range(whole.size)])
    return tails * others / np.prod(L) * (1 + ROUNDING)


def _gaussian_floor(z: ProjectedSum) -> float:
    """The least eigenvalue of the covariance the Gaussian kicks give ``z`` (0 without them),
    lowered by a relative 1e-9 against rounding."""
    if not isinstance(z.kick, GaussianLaw) or not z.D.size:
        return 0.0
    S = z.kick_cov
    values = np.linalg.eigvalsh(0.5 * (S + S.T))
    return max(0.0, float(values[0]) - 1e-9 * float(np.abs(values).max(initial=0.0)))


def box_probability(z: ProjectedSum, lower, upper, tol: float = 1e-6,
                    max_frequencies: int = MAX_FREQUENCIES) -> Inversion:
    """``P(lower <= z <= upper)`` by Fourier inversion over a periodic window (module docstring).

    ``max_frequencies`` caps the frequency vectors evaluated; the interval is honest either way
    where it is ``rigorous``, an estimate otherwise.
    """
    window = _window(z, tol / 4)
    lo = np.maximum(np.asarray(lower, float), window.centre - window.half) - window.centre
    hi = np.minimum(np.asarray(upper, float), window.centre + window.half) - window.centre
    if np.any(lo >= hi):
        return Inversion(0.0, 0.0, min(1.0, window.alias))
    L = window.period
    sd = np.sqrt(np.maximum(np.diag(z.cov), 1e-300))
    counts = np.maximum(8, np.ceil(9.0 * L / (2 * np.pi * sd))).astype(int)
    zc = ProjectedSum(z.zc - window.centre, z.D0, z.D, z.initial, z.kick)
    lam = _gaussian_floor(z)
    while True:
        k, weight = _half_frequencies(counts)
        omega = 2 * np.pi * k / L
        terms = weight * zc.cf(omega) * np.prod(_box_transform(omega, lo, hi), axis=1) / np.prod(L)
        value = float(np.real(terms.sum()))
        outer = np.abs(k) > 0.75 * counts                    # the outer shell, axis by axis
        shell = float(np.abs(terms[np.any(outer, axis=1)]).sum())
        per_axis = truncation_bound(lam, hi - lo, L, counts)
        if per_axis is None:
            per_axis = np.array([np.abs(terms[outer[:, i]]).sum() for i in range(counts.size)])
            truncation = shell
        else:
            truncation = float(per_axis.sum())
        grow = per_axis > tol / (2 * counts.size)
        larger = np.where(grow, np.ceil(1.5 * counts), counts).astype(int)
        if truncation <= tol / 2 or not np.any(grow) or np.prod(2 * larger + 1) // 2 > max_frequencies:
            break
        counts = larger
    half = window.alias + truncation + ROUNDING
    value = float(np.clip(value, 0.0, 1.0))
    return Inversion(value, max(0.0, value - half), min(1.0, value + half), 0, int(2 * k.shape[0] - 1),
                     rigorous=lam > 0, shell=window.alias + shell + ROUNDING)


def density_on_grid(z: ProjectedSum, points: int = 64, tol: float = 1e-9):
    """Density of ``z`` on a regular grid over its window by one FFT (eq. 8).

    Returns ``(axes, density)``: ``axes[i]`` the grid coordinates along ``z_i`` and ``density`` of
    shape ``(points,) * d``. Frequencies ``|k_i| < points / 2`` are used.
    """
    window = _window(z, tol)
    L = window.period
    d = L.size
    counts = np.full(d, (points - 1) // 2)
    k = _frequencies(counts)
    omega = 2 * np.pi * k / L
    start = window.centre - window.half
    coef = z.cf(omega) * np.exp(-1j * omega @ start) / np.prod(L)
    grid = np.zeros((points,) * d, dtype=complex)
    grid[tuple((k % points).T)] = coef
    density = np.real(np.fft.fftn(grid))
    axes = [start[i] + np.arange(points) * L[i] / points for i in range(d)]
    return axes, density
