"""Discrete-time linear systems with i.i.d. velocity kicks, time-invariant or time-varying.

The stochastic models of the forward-stochastic-reach seed (eq. 4, ``x[t+1] = A x[t] + B w[t]``)
arise here from a continuous closed loop ``x' = A x + b`` that receives i.i.d. kicks ``G w[k]``
at the instants ``t_k = k * step`` (``t_k < at``) and flows between them::

    x[k+1] = Phi[k] (x[k] + G w[k]) + c[k],        x[k] = x(t_k) just before the kick,

so the seed's ``B`` is ``Phi[k] G``. For a time-invariant flow ``Phi = expm(A dt)`` and
``c = int_0^dt expm(A s) b ds`` (both from one exponential of the augmented matrix); for an
eccentric target orbit ``Phi[k]`` is the Yamanaka-Ankersen transition matrix of the
Tschauner-Hempel equations (:func:`yamanaka_ankersen`).

Mean and covariance of ``x[k]`` (seed eqs. 12-14) follow by the recursion::

    m[k+1] = Phi[k] (m[k] + G mu) + c[k]
    P[k+1] = Phi[k] (P[k] + G Sigma G^T) Phi[k]^T

which equals ``m[tau] = A^tau x0 + C (1 (x) mu)`` and ``P[tau] = C (I (x) Sigma) C^T`` with the
controllability matrix ``C = [B, A B, ..., A^(tau-1) B]`` (eq. 14) but costs ``O(tau n^3)``
instead of building the ``n x tau p`` matrix. The recursion needs only the first two moments of
``w``, so it holds for non-Gaussian kicks too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

TIME_TOL = 1e-9          # relative tolerance on kick instants (as the simulator uses)


def kick_times(step: float, at: float) -> np.ndarray:
    """``[t_0, ..., t_{K-1}, at]``: the kick instants ``k * step < at`` followed by ``at``."""
    tol = TIME_TOL * max(1.0, at)
    count = max(0, int(np.ceil((at - tol) / step)))
    return np.append(np.arange(count) * step, at)


@dataclass
class KickedLinearSystem:
    """``x[k+1] = Phi[k] (x[k] + G w[k]) + c[k]`` for ``k < K``; ``times[k]`` is the instant of ``x[k]``."""

    Phi: np.ndarray          # (K, n, n)
    c: np.ndarray            # (K, n)
    G: np.ndarray            # (n, p)
    times: np.ndarray        # (K + 1,)

    @classmethod
    def from_continuous(cls, A, b, G, step: float, at: float) -> "KickedLinearSystem":
        """Exact discretisation of ``x' = A x + b`` between the kicks (kicks every ``step`` before ``at``)."""
        A = np.asarray(A, dtype=float)
        n = A.shape[0]
        times = kick_times(step, at)
        M = np.zeros((n + 1, n + 1))
        M[:n, :n] = A
        M[:n, n] = np.zeros(n) if b is None else b
        gaps = np.diff(times)
        E = scipy.linalg.expm(M * step)
        Phi = np.repeat(E[None, :n, :n], gaps.size, axis=0)
        c = np.repeat(E[None, :n, n], gaps.size, axis=0)
        if gaps.size and gaps[-1] != step:          # a shorter last interval up to ``at``
            E = scipy.linalg.expm(M * gaps[-1])
            Phi[-1], c[-1] = E[:n, :n], E[:n, n]
        return cls(Phi, c, np.asarray(G, dtype=float), times)

    @property
    def steps(self) -> int:
        return self.Phi.shape[0]

    @property
    def n(self) -> int:
        return self.G.shape[0]

    def moments(self, mean0, cov0, w_mean, w_cov):
        """Means ``(K+1, n)`` and covariances ``(K+1, n, n)`` of ``x[0..K]`` (eqs. 12-14).

        While the steps are identical (``Phi[k] = Phi``, ``c[k] = c``) the recursion unrolls to
        ``m[k] = Phi^k m[0] + sum_{j<k} Phi^j a`` and ``P[k] = Phi^k P[0] Phi^kT + sum_{j<k} Phi^j Q Phi^jT``
        with ``a = Phi G mu + c``, ``Q = Phi G Sigma G^T Phi^T``, evaluated for all ``k`` at once from
        the powers of ``Phi``; the remaining steps use the recursion.
        """
        n, K = self.n, self.steps
        means, covs = np.zeros((K + 1, n)), np.zeros((K + 1, n, n))
        means[0] = mean0
        covs[0] = np.zeros((n, n)) if cov0 is None else cov0
        kick_mean = self.G @ np.asarray(w_mean, dtype=float)
        kick_cov = self.G @ np.asarray(w_cov, dtype=float) @ self.G.T
        same = 0
        if K:
            same = 1 + int(np.argmin(np.append(np.all(self.Phi[1:] == self.Phi[0], axis=(1, 2))
                                               & np.all(self.c[1:] == self.c[0], axis=1), False)))
            Phi = self.Phi[0]
            powers = _powers(Phi, same + 1)
            a = Phi @ kick_mean + self.c[0]
            Q = Phi @ kick_cov @ Phi.T
            drift = np.concatenate([np.zeros((1, n)), np.cumsum(powers[:-1] @ a, axis=0)])
            spread = np.concatenate([np.zeros((1, n, n)),
                                     np.cumsum(powers[:-1] @ Q @ powers[:-1].transpose(0, 2, 1), axis=0)])
            means[:same + 1] = powers @ means[0] + drift
            covs[:same + 1] = powers @ covs[0] @ powers.transpose(0, 2, 1) + spread
        for k in range(same, K):
            means[k + 1] = self.Phi[k] @ (means[k] + kick_mean) + self.c[k]
            covs[k + 1] = self.Phi[k] @ (covs[k] + kick_cov) @ self.Phi[k].T
        return means, 0.5 * (covs + covs.transpose(0, 2, 1))

    def propagator(self, k: int, j: int) -> np.ndarray:
        """``Psi(k, j) = Phi[k-1] ... Phi[j]`` (identity for ``k == j``)."""
        out = np.eye(self.n)
        for i in range(j, k):
            out = self.Phi[i] @ out
        return out


def _powers(Phi: np.ndarray, count: int) -> np.ndarray:
    """``[Phi^0, ..., Phi^(count-1)]`` by doubling (``O(log count)`` batched products)."""
    out = np.eye(Phi.shape[0])[None]
    while out.shape[0] < count:
        out = np.concatenate([out, out @ (out[-1] @ Phi)])
    return out[:count]


# ------------------------------------------------------------------ relative orbital motion

def cwh_matrix(n: float) -> np.ndarray:
    """The CWH state matrix of seed eq. (3), state ``[x, y, z, vx, vy, vz]`` (x radial, y along-track)."""
    A = np.zeros((6, 6))
    A[0:3, 3:6] = np.eye(3)
    A[3, 0], A[3, 4] = 3 * n ** 2, 2 * n
    A[4, 3] = -2 * n
    A[5, 2] = -n ** 2
    return A


def true_anomaly(mean_anomaly, e: float):
    """True anomaly from the mean anomaly (Kepler's equation by Newton's method)."""
    M = np.asarray(mean_anomaly, dtype=float)
    E = M + e * np.sin(M) if e < 0.8 else np.pi + 0.0 * M
    for _ in range(50):
        delta = (E - e * np.sin(E) - M) / (1 - e * np.cos(E))
        E = E - delta
        if np.all(np.abs(delta) < 1e-15 * np.maximum(1.0, np.abs(E))):
            break
    return 2 * np.arctan2(np.sqrt(1 + e) * np.sin(E / 2), np.sqrt(1 - e) * np.cos(E / 2))


def mean_anomaly(theta, e: float):
    """Mean anomaly of the true anomaly ``theta``."""
    E = 2 * np.arctan2(np.sqrt(1 - e) * np.sin(theta / 2), np.sqrt(1 + e) * np.cos(theta / 2))
    return E - e * np.sin(E)


def _fundamental(theta: float, e: float, J: float) -> np.ndarray:
    """Fundamental solutions of the Tschauner-Hempel equations in true anomaly.

    Transformed state ``[x~, y~, z~, x~', y~', z~']`` with ``x~ = rho x``, ``rho = 1 + e cos(theta)``
    and ``' = d/dtheta``; the equations are ``x~'' = 3 x~/rho + 2 y~'``, ``y~'' = -2 x~'``,
    ``z~'' = -z~``. The in-plane columns are Yamanaka and Ankersen's (2002) solutions, with
    their along-track/radial-down axes mapped to radial/along-track; ``J = k^2 (t - t0)``.
    """
    rho = 1 + e * np.cos(theta)
    s, c = rho * np.sin(theta), rho * np.cos(theta)
    ds = np.cos(theta) + e * np.cos(2 * theta)
    dc = -(np.sin(theta) + e * np.sin(2 * theta))
    F = np.zeros((6, 6))
    # in plane: rows x~, y~, x~', y~' ; columns c1..c4
    F[0, :4] = [0.0, -s, -c, -(2 - 3 * e * s * J)]
    F[1, :4] = [1.0, -c * (1 + 1 / rho), s * (1 + 1 / rho), 3 * rho ** 2 * J]
    F[3, :4] = [0.0, -ds, -dc, 3 * e * (ds * J + s / rho ** 2)]
    F[4, :4] = [0.0, 2 * s, 2 * c - e, 3 * (1 - 2 * e * s * J)]
    # out of plane: rows z~, z~' ; columns c5, c6
    F[2, 4:] = [np.cos(theta), np.sin(theta)]
    F[5, 4:] = [-np.sin(theta), np.cos(theta)]
    return F


def _to_transformed(theta: float, e: float, k2: float) -> np.ndarray:
    """``[x~; x~'] = T [x; x_dot]``: ``x~ = rho x``, ``x~' = -e sin(theta) x + x_dot / (k^2 rho)``."""
    rho = 1 + e * np.cos(theta)
    T = np.zeros((6, 6))
    T[:3, :3] = rho * np.eye(3)
    T[3:, :3] = -e * np.sin(theta) * np.eye(3)
    T[3:, 3:] = np.eye(3) / (k2 * rho)
    return T


def _from_transformed(theta: float, e: float, k2: float) -> np.ndarray:
    """Inverse of :func:`_to_transformed`: ``x = x~/rho``, ``x_dot = k^2 (e sin(theta) x~ + rho x~')``."""
    rho = 1 + e * np.cos(theta)
    T = np.zeros((6, 6))
    T[:3, :3] = np.eye(3) / rho
    T[3:, :3] = k2 * e * np.sin(theta) * np.eye(3)
    T[3:, 3:] = k2 * rho * np.eye(3)
    return T


def yamanaka_ankersen(e: float, a: float, mu: float, theta0: float, dt: float) -> np.ndarray:
    """Transition matrix of relative motion about a Keplerian target orbit over ``[t0, t0 + dt]``.

    ``e``, ``a``, ``mu``: the target orbit; ``theta0``: its true anomaly at ``t0``. State
    ``[x, y, z, vx, vy, vz]`` in the rotating frame of eq. (1) (x radial, y along-track, z along
    the angular momentum). ``Phi = T(theta)^-1 F(theta, J) F(theta0, 0)^-1 T(theta0)``; at ``e = 0``
    it is the CWH transition matrix ``expm(A dt)`` of eq. (3) with ``n = sqrt(mu/a^3)``.
    """
    n = np.sqrt(mu / a ** 3)
    p = a * (1 - e ** 2)
    k2 = np.sqrt(mu * p) / p ** 2
    theta = float(true_anomaly(mean_anomaly(theta0, e) + n * dt, e))
    end = _from_transformed(theta, e, k2) @ _fundamental(theta, e, k2 * dt)
    return end @ np.linalg.solve(_fundamental(theta0, e, 0.0), _to_transformed(theta0, e, k2))


def eccentric_orbit_system(e: float, a: float, mu: float, theta0: float, G, step: float,
                           at: float) -> KickedLinearSystem:
    """The uncontrolled relative motion about an eccentric orbit as a :class:`KickedLinearSystem`."""
    times = kick_times(step, at)
    n = np.sqrt(mu / a ** 3)
    M0 = mean_anomaly(theta0, e)
    Phi = np.array([yamanaka_ankersen(e, a, mu, float(true_anomaly(M0 + n * t0, e)), t1 - t0)
                    for t0, t1 in zip(times[:-1], times[1:])]).reshape(-1, 6, 6)
    return KickedLinearSystem(Phi, np.zeros((times.size - 1, 6)), np.asarray(G, dtype=float), times)
