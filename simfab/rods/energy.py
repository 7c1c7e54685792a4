"""Total elastic energy of a rod network with gradient and sparse Hessian (full DOFs).

Full DOF vector: ``[x (3N, node-major), theta (E)]``. The per-energy kernels (stretch.py,
bend.py, twist.py) scatter straight into a gradient array and into the data array of a CSR
matrix whose pattern (and the position of every local entry in it) is computed once per
model, so one evaluation is three kernel launches plus a CSR wrap.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from simfab._warp import wp
from simfab.rods import bend, stretch, twist
from simfab.rods.model import RodModel, RodState

TERMS = ("stretch", "bend", "twist")
_LAUNCH = {"stretch": stretch.launch_stretch, "bend": bend.launch_bend, "twist": twist.launch_twist}


def _hinge_dofs(model: RodModel) -> np.ndarray:
    N = model.n_nodes
    hn, he = model.hinge_nodes.astype(np.int64), model.hinge_edges.astype(np.int64)
    cols = [3 * hn[:, 0], 3 * hn[:, 0] + 1, 3 * hn[:, 0] + 2, 3 * N + he[:, 0],
            3 * hn[:, 1], 3 * hn[:, 1] + 1, 3 * hn[:, 1] + 2, 3 * N + he[:, 1],
            3 * hn[:, 2], 3 * hn[:, 2] + 1, 3 * hn[:, 2] + 2]
    return np.stack(cols, axis=1) if len(hn) else np.zeros((0, 11), dtype=np.int64)


def _edge_dofs(model: RodModel) -> np.ndarray:
    e = model.edges.astype(np.int64)
    return np.stack([3 * e[:, 0], 3 * e[:, 0] + 1, 3 * e[:, 0] + 2,
                     3 * e[:, 1], 3 * e[:, 1] + 1, 3 * e[:, 1] + 2], axis=1)


class DeviceBuffers:
    """Warp arrays of one model (constants), the current state and the outputs."""

    def __init__(self, model: RodModel, device: str, terms: tuple):
        self.device = device
        self.terms = terms
        self.n_nodes, self.n_edges, self.n_hinges = model.n_nodes, model.n_edges, model.n_hinges
        self.n_dofs = 3 * model.n_nodes + model.n_edges
        n = self.n_dofs
        edofs, hdofs = _edge_dofs(model), _hinge_dofs(model)
        blocks = []
        if "stretch" in terms:
            blocks.append(edofs)
        if "bend" in terms or "twist" in terms:
            blocks.append(hdofs)
        # CSR pattern = union of all local (row, col) pairs
        keys = [(b[:, :, None] * n + b[:, None, :]).ravel() for b in blocks if len(b)]
        keys = np.unique(np.concatenate(keys)) if keys else np.zeros(0, dtype=np.int64)
        rows, cols = keys // n, keys % n
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))]).astype(np.int32)
        self.indices = cols.astype(np.int32)
        self.nnz = len(keys)

        def slots(b):
            k = (b[:, :, None] * n + b[:, None, :]).reshape(len(b), -1)
            return np.searchsorted(keys, k).astype(np.int32) if len(b) else np.zeros((0, b.shape[1] ** 2), np.int32)

        a = lambda v, dt=wp.float64: wp.array(np.ascontiguousarray(v), dtype=dt, device=device)  # noqa: E731
        self.edges = a(model.edges.astype(np.int32), wp.int32)
        self.rest_len = a(model.rest_len)
        self.stretch_stiff = a(model.stretch_stiff)
        self._stretch_full = self.stretch_stiff
        self._stretch_scaled = {}
        self._model_EA = model.stretch_stiff
        self.edge_dofs = a(edofs.astype(np.int32), wp.int32)
        self.edge_slots = a(slots(edofs), wp.int32)
        self.hinge_nodes = a(model.hinge_nodes.reshape(-1, 3).astype(np.int32), wp.int32)
        self.hinge_edges = a(model.hinge_edges.reshape(-1, 2).astype(np.int32), wp.int32)
        self.kappa_bar = a(model.kappa_bar.reshape(-1, 2))
        self.bend_stiff = a(model.bend_stiff.reshape(-1, 2))
        self.twist_stiff = a(model.twist_stiff)
        self.twist_bar = a(model.twist_bar)
        self.vor_len = a(model.vor_len)
        self.hinge_dofs = a(hdofs.astype(np.int32), wp.int32)
        self.hinge_slots = a(slots(hdofs), wp.int32)
        self.x = wp.zeros(self.n_nodes, dtype=wp.vec3d, device=device)
        self.theta = wp.zeros(self.n_edges, dtype=wp.float64, device=device)
        self.d1 = wp.zeros(self.n_edges, dtype=wp.vec3d, device=device)
        self.ref_twist = wp.zeros(self.n_hinges, dtype=wp.float64, device=device)
        self.e_stretch = wp.zeros(self.n_edges, dtype=wp.float64, device=device)
        self.e_bend = wp.zeros(self.n_hinges, dtype=wp.float64, device=device)
        self.e_twist = wp.zeros(self.n_hinges, dtype=wp.float64, device=device)
        self.grad = wp.zeros(n, dtype=wp.float64, device=device)
        self.hess = wp.zeros(max(self.nnz, 1), dtype=wp.float64, device=device)

    def set_stretch_scale(self, scale: float) -> None:
        """Multiply every edge's EA by ``scale`` (1.0 restores the model's values)."""
        if scale == 1.0:
            self.stretch_stiff = self._stretch_full
            return
        if scale not in self._stretch_scaled:
            self._stretch_scaled[scale] = wp.array(self._model_EA * scale, dtype=wp.float64, device=self.device)
        self.stretch_stiff = self._stretch_scaled[scale]

    def upload(self, state: RodState) -> None:
        self.x.assign(np.ascontiguousarray(state.x))
        self.theta.assign(np.ascontiguousarray(state.theta))
        self.d1.assign(np.ascontiguousarray(state.d1))
        if self.n_hinges:
            self.ref_twist.assign(np.ascontiguousarray(state.ref_twist))


class Evaluator:
    """Energy, gradient and Hessian of a rod network in full DOFs.

    ``ev(state, need_grad, need_hess) -> (energy [J], grad (3N+E,), H scipy CSR (3N+E, 3N+E) or None)``.
    ``ev.parts`` holds the last energies per term. Gradient units: N for positions, N m for
    angles. ``terms`` selects energies (tests check each one alone).
    """

    def __init__(self, model: RodModel, *, device: str = "cpu", terms: tuple = TERMS):
        unknown = set(terms) - set(TERMS)
        if unknown:
            raise ValueError(f"unknown energy terms {sorted(unknown)}")
        self.model = model
        self.buf = DeviceBuffers(model, device, tuple(terms))
        self.parts: dict = {}

    @property
    def n_dofs(self) -> int:
        return self.buf.n_dofs

    def __call__(self, state: RodState, need_grad: bool = True, need_hess: bool = True):
        b = self.buf
        b.upload(state)
        if need_grad:
            b.grad.zero_()
        if need_hess:
            b.hess.zero_()
        for name in b.terms:
            _LAUNCH[name](b, need_grad, need_hess)
        parts = {}
        for name, arr in (("stretch", b.e_stretch), ("bend", b.e_bend), ("twist", b.e_twist)):
            parts[name] = float(np.sum(arr.numpy())) if name in b.terms else 0.0
        self.parts = parts
        E = parts["stretch"] + parts["bend"] + parts["twist"]
        g = b.grad.numpy().copy() if need_grad else None
        H = None
        if need_hess:
            H = sp.csr_matrix((b.hess.numpy()[: b.nnz].copy(), b.indices, b.indptr), shape=(b.n_dofs, b.n_dofs))
        return E, g, H
