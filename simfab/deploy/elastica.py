"""The inextensible elastica: exact first symmetric buckling mode of a beam pushed into a gap.

A beam of length L and bending stiffness B is pushed into a gap g < L. With the modulus
``k = sin(alpha/2)`` (alpha: end angle for pinned ends, inflection angle for clamped ends) and
the complete elliptic integrals ``K(k)``, ``E(k)``:

    g / L     = 2 E(k) / K(k) - 1             (both supports)
    delta / L = k / K(k)                      (midspan rise, both supports)
    P         = 4 K^2 B / L^2  (pinned),  16 K^2 B / L^2  (clamped)   (axial force)
    P_euler   = pi^2 B / L^2   (pinned),  4 pi^2 B / L^2  (clamped)

Shapes (tangent angle theta, sin(theta/2) = k sn(u, k), lambda = sqrt(P/B)):
pinned ``u = lambda s + K``, clamped ``u = lambda s``;
``x(s) = (2 (E(am u) - E(am u0)) - (u - u0)) / lambda``, ``z(s) = 2k (cn(u0) - cn(u)) / lambda``.

SciPy's elliptic functions take the parameter ``m = k^2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.special import ellipe, ellipj, ellipk, elliprd, elliprf

from simfab.errors import InputError

SUPPORTS = ("pinned", "clamped")


def _force_factor(support: str) -> float:
    if support not in SUPPORTS:
        raise InputError(f"support must be one of {SUPPORTS} (got {support!r})")
    return 1.0 if support == "pinned" else 4.0


@dataclass(frozen=True)
class ElasticaSolution:
    """The exact elastica for one gap ratio (:func:`solve`).

    Args:
        support: "pinned" or "clamped".
        g_over_L: the gap ratio [-].
        k: the elliptic modulus [-].
        alpha: the end (pinned) or inflection (clamped) angle [rad].
        K: the complete elliptic integral of the first kind K(k) [-].
        E: that of the second kind E(k) [-].
        delta_over_L: the rise over the length [-].
        force_factor: the dimensionless force P L^2 / B [-].
    """

    support: str
    g_over_L: float
    k: float
    alpha: float
    K: float
    E: float
    delta_over_L: float
    force_factor: float  # P L^2 / B

    def shape(self, L: float = 1.0, num: int = 201) -> np.ndarray:
        """The buckled centerline.

        Args:
            L: its length [m].
            num: points.

        Returns:
            (num, 2) [m] points (x, z).
        """
        m = self.k**2
        s = np.linspace(0.0, L, num)
        lam = np.sqrt(self.force_factor) / L
        u0 = self.K if self.support == "pinned" else 0.0
        u = lam * s + u0
        sn, cn, dn, ph = ellipj(u, m)
        _, cn0, _, ph0 = ellipj(np.array([u0]), m)
        x = (2.0 * (_ellipeinc(ph, m) - _ellipeinc(ph0, m)[0]) - (u - u0)) / lam
        z = 2.0 * self.k * (cn0[0] - cn) / lam
        return np.stack([x, z], axis=1)


def _ellipeinc(phi, m: float) -> np.ndarray:
    """Incomplete elliptic integral of the second kind E(phi | m) for any real phi.

    Carlson form on [-pi/2, pi/2] plus quasi-periodicity E(phi + n pi) = E(phi) + 2 n E(m).
    (scipy.special.ellipeinc returns wrong values for some phi > pi/2 in SciPy 1.17.)
    """
    phi = np.asarray(phi, dtype=np.float64)
    n = np.round(phi / np.pi)
    r = phi - n * np.pi
    s, c = np.sin(r), np.cos(r)
    y = 1.0 - m * s * s
    er = s * elliprf(c * c, y, 1.0) - m / 3.0 * s**3 * elliprd(c * c, y, 1.0)
    return er + 2.0 * n * ellipe(m)


def check_ratio(g_over_L: float) -> float:
    """A gap ratio checked.

    Args:
        g_over_L: the ratio.

    Returns:
        It as a float; InputError unless 0 < g/L < 1.
    """
    r = float(g_over_L)
    if not 0.0 < r < 1.0:
        raise InputError(f"g/L must lie strictly between 0 and 1 (got {g_over_L})", where="--g-over-L")
    return r


def solve_elastica(g_over_L: float, support: str = "pinned") -> ElasticaSolution:
    """The exact first-mode elastica (brentq on g/L = 2E/K - 1).

    Args:
        g_over_L: the gap ratio, 0 < g/L < 1.
        support: "pinned" or "clamped".

    Returns:
        The :class:`ElasticaSolution`.
    """
    mult = _force_factor(support)
    r = check_ratio(g_over_L)

    def residual(k):
        m = k * k
        return 2.0 * ellipe(m) / ellipk(m) - 1.0 - r

    # g/L decreases monotonically from 1 (k=0) to -1 (k->1); g/L > 0 needs k < 0.9089 (alpha < 130.7 deg)
    k = brentq(residual, 1e-12, 1.0 - 1e-15, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    m = k * k
    K, E = float(ellipk(m)), float(ellipe(m))
    return ElasticaSolution(support=support, g_over_L=r, k=k, alpha=2.0 * np.arcsin(k), K=K, E=E,
                            delta_over_L=k / K, force_factor=4.0 * mult * K * K)


def euler_load_factor(support: str) -> float:
    """The critical load P_cr L^2 / B.

    Args:
        support: "pinned" (pi^2) or "clamped" (4 pi^2).

    Returns:
        The factor [-].
    """
    return _force_factor(support) * np.pi**2
