"""Two-grid warm start: a finished insertion of the same part on a coarser discretization guides the
warm starts of a finer one (:func:`simfab.design.verify.mesh_check`'s refined level, from its P2 level).

The coarse run's insertion records (s_k, x_k) are interpolated linearly in s and mapped to the
fine nodes by a prolongation P (n_fine, n_coarse), sparse; P2 on a mesh -> P2 on its uniform
subdivision is exact interpolation of the quadratic field, :func:`simfab.design.verify.p2_prolongation`.
A step from the fine state x_f at s_a to s_b is offered two candidates beside the
extrapolations of :func:`simfab.coupling.predictor.warm_start`:

    x_coarse  = P x_c(s_b)                              (the coarse equilibrium itself)
    x_incr    = x_f + P (x_c(s_b) - x_c(s_a))           (the fine state moved by the coarse step)

with points that sit inside O lifted out (:func:`simfab.coupling.predictor.lift_points`); the
warm start is the feasible candidate of lowest objective, as without a guide. Newton then solves
the fine level's own step to its own tolerance, so the records are the fine level's equilibria:
the guide changes where Newton starts, not where it stops.

**Where the guide is not offered.** A start can decide which of two equilibria Newton finds. While
the part loads (the coarse elastic energy does not fall over the step) the equilibrium along the
path is unique in practice; where it falls, the coarse run may have snapped or seated, and it does
so at a path length that moves with the mesh: a coarse state past its snap could pull the fine
run over a snap it has not reached. So the guide is offered only on steps over which the coarse
energy is non-decreasing (every coarse record inside the step and both interpolated ends), only
forward along the insertion, without friction (whose steps depend on the state they start from)
and within the coarse run's range of s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True, eq=False)
class CoarseGuide:
    """A coarse insertion that guides a fine one's warm starts (see the module docstring).

    s : (K,) [m] path lengths of the coarse insertion records, strictly increasing
    x : (K, n_coarse, dim) [m] their converged positions
    energy : (K,) [J] their elastic energies
    prolong : (n_fine, n_coarse) sparse prolongation (fine positions = prolong @ coarse positions)
    """

    s: np.ndarray
    x: np.ndarray
    energy: np.ndarray
    prolong: sp.csr_matrix

    @classmethod
    def from_records(cls, records, prolong) -> CoarseGuide:
        """The guide of a coarse run's insertion records (:class:`simfab.coupling.record.StepResult`,
        phase "insert"; the rest search's records included, in any order; at a repeated s the later
        record is kept) and the prolongation ``prolong`` (n_fine, n_coarse)."""
        recs = [r for r in records if r.phase == "insert"]
        by_s = {float(r.s): r for r in recs}
        s = np.array(sorted(by_s))
        P = sp.csr_matrix(prolong)
        x = np.stack([np.asarray(by_s[v].x, float) for v in s]) if len(s) else np.zeros((0, P.shape[1], 1))
        if len(s) and x.shape[1] != P.shape[1]:
            raise ValueError(f"prolong has {P.shape[1]} columns, the coarse records {x.shape[1]} nodes")
        return cls(s=s, x=x, energy=np.array([by_s[v].energy for v in s], float), prolong=P)

    def coarse_at(self, s: float) -> np.ndarray | None:
        """The coarse positions (n_coarse, dim) interpolated linearly to s [m]; None outside the records' range."""
        k = self._segment(s)
        if k is None:
            return None
        if k == len(self.s) - 1:
            return self.x[k]
        t = (s - self.s[k]) / (self.s[k + 1] - self.s[k])
        return (1.0 - t) * self.x[k] + t * self.x[k + 1]

    def loading(self, s_a: float, s_b: float) -> bool:
        """Whether the coarse elastic energy is non-decreasing from s_a to s_b > s_a (its
        interpolated values at both ends and every record between)."""
        if self._segment(s_a) is None or self._segment(s_b) is None or not s_b > s_a:
            return False
        inner = (self.s > s_a) & (self.s < s_b)
        e = np.concatenate([[np.interp(s_a, self.s, self.energy)], self.energy[inner],
                            [np.interp(s_b, self.s, self.energy)]])
        return bool(np.all(np.diff(e) >= 0.0))

    def candidates(self, x_fine: np.ndarray, s_a: float, s_b: float) -> list:
        """The warm-start candidates of the fine step from ``x_fine`` (n_fine, dim) at s_a to s_b [m]:
        [P x_c(s_b), x_fine + P (x_c(s_b) - x_c(s_a))]; empty where the guide is not offered
        (the coarse run not loading over the step, or the step outside its range)."""
        if not self.loading(s_a, s_b):
            return []
        xa, xb = self.coarse_at(s_a), self.coarse_at(s_b)
        fine_b = self.prolong @ xb
        return [fine_b, x_fine + (fine_b - self.prolong @ xa)]

    def _segment(self, s: float) -> int | None:
        """Index k of the record interval [s_k, s_k+1) holding s (the last record for s == s_K); None outside."""
        if not len(self.s) or s < self.s[0] or s > self.s[-1]:
            return None
        return int(min(np.searchsorted(self.s, s, side="right") - 1, len(self.s) - 1))
