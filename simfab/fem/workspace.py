"""Recorded kernel launches over the elements of an FEM model, for every element order.

An element order supplies its Warp kernels as an :class:`ElementKernels` record
(:data:`simfab.fem.neohookean.LINEAR`, :data:`simfab.fem.neohookean_p2.QUADRATIC`) and the model
the per-element rest geometry through :meth:`~simfab.fem.model.MeshModel.element_geometry`
(quadrature weights w_q [m^3] and what F is computed from). Every kernel has the same argument list,

    inputs:  first, x, elements, geometry, weights, mu, lam  [, hessian mode, scatter, CSR slots]
    outputs: energy (m,), det F (m,), nodal gradient (m,) [, blocks (m, kd, kd), data, data2]
             (the stress kernel: det F (m,), von Mises stress (m,))

with one thread per element ``first + tid``; what a launch computes is a :class:`Launch` code, the
Hessian's treatment of d2Psi/dF2 a :class:`Hessian` mode. The :class:`Workspace` (one per model)
holds persistent device buffers and records each launch once, then replays it; on the CPU the
Hessian launches of a large mesh run as two half launches on two threads, each adding into its
own CSR buffer. Details: docs/methods.md, "simfab.fem.workspace".
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np
import scipy.sparse as sp

from simfab._parallel import submit
from simfab._sparse import csr_matvec
from simfab._warp import RECORD_LOCK, Replay, wp


class Launch(IntEnum):
    """What one launch over all elements computes."""

    ENERGY = 0  # energy and det F per element
    GRADIENT = 1  # ... and the nodal gradient
    HESSIAN = 2  # ... and the Hessian added into the CSR values of the model's pattern
    BLOCKS = 3  # ... and the Hessian kept as per-element blocks (m, kd, kd)
    STRESS = 4  # det F and the von Mises stress per element


class Hessian(IntEnum):
    """How the Hessian kernel treats the stress-space Hessian d2Psi/dF2."""

    EXACT = 0  # exact
    PROJECT = 1  # PSD-projected: closed-form twist projection where valid, SVD eigensystem elsewhere
    PROJECT_SVD = 2  # PSD-projected, always through the SVD eigensystem (the reference route)
    BOTH = 3  # exact into ``data`` and PROJECT into ``data2``, from one launch


@dataclass(frozen=True, kw_only=True)
class ElementKernels:
    """The Warp kernels of one element order (argument lists in the module docstring).

    Args:
        hessian: dim -> the Hessian kernel of that dimension's elements (one generic kernel may serve both)
        grad_dtype: dim -> Warp vector type of one element's nodal gradient (length k d)
        geometry_dtype: dim -> Warp type of the entries of ``model.element_geometry()[0]``
        split_elements: dim -> CPU meshes of that dimension with at least this many elements run their
            Hessian launches as two halves on two threads (None, or a dimension missing: always one launch)
    """

    energy: Any
    gradient: Any
    hessian: dict
    stress: Any
    grad_dtype: dict
    geometry_dtype: dict
    split_elements: dict | None = None


class Workspace:
    """Device copies of one model's arrays, persistent output buffers and recorded launches."""

    def __init__(self, model, kernels: ElementKernels):
        d, m, k = model.dim, model.n_elements, model.elements.shape[1]
        self.dim = d
        dev = self.device = model.device
        self.kernels = kernels
        self.cpu = wp.get_device(dev).is_cpu
        half = m // 2
        split = None if kernels.split_elements is None else kernels.split_elements.get(d)
        self.parts = ((0, half), (half, m - half)) if self.cpu and split is not None and m >= split else ((0, m),)
        self.m, self.kd = m, k * d
        self.pattern = model.pattern
        self.x_np = np.zeros((model.n_vertices, d))
        self.x = self._wrap(self.x_np, wp.vec3d if d == 3 else wp.vec2d)
        geometry, weights = model.element_geometry()
        self.inputs = [wp.array(model.elements, dtype=wp.int32, device=dev),
                       wp.array(geometry, dtype=kernels.geometry_dtype[d], device=dev),
                       wp.array(weights, dtype=wp.float64, device=dev),
                       wp.array(model.mu, dtype=wp.float64, device=dev),
                       wp.array(model.lam, dtype=wp.float64, device=dev)]
        self.energy = wp.zeros(m, dtype=wp.float64, device=dev)
        self.det_F = wp.zeros(m, dtype=wp.float64, device=dev)
        self.von_mises = wp.zeros(m, dtype=wp.float64, device=dev)
        self.grad = wp.zeros(m, dtype=kernels.grad_dtype[d], device=dev)
        # host arrays of the per-element outputs: on the CPU views of the Warp arrays' memory (no copy)
        self._host = (self.energy.numpy(), self.det_F.numpy(), self.grad.numpy()) if self.cpu else None
        self._host_vm = self.von_mises.numpy() if self.cpu else None
        self.hess = None  # element blocks (m, kd, kd), allocated on the first BLOCKS launch
        self.slots = None  # model.pattern.element_slots as int32, on the first HESSIAN launch
        self.csr: dict = {}  # (0: data / 1: data2, part) -> (warp array, numpy alias on the CPU or None)
        self.dummy3 = wp.zeros((1, 1, 1), dtype=wp.float64, device=dev)
        self.dummy_slots = wp.zeros((1, 1, 1), dtype=wp.int32, device=dev)
        self.dummy_data = wp.zeros(1, dtype=wp.float64, device=dev)
        # gradient scatter: (n*d, m*k*d) sparse sum over the element copies of each dof
        dofs = (model.elements.astype(np.int64)[:, :, None] * d + np.arange(d)).ravel()
        self.scatter = sp.csr_matrix((np.ones(dofs.size), (dofs, np.arange(dofs.size))),
                                     shape=(model.n_dofs, dofs.size))
        self.commands: dict = {}

    def _wrap(self, arr: np.ndarray, dtype):
        """Warp view of a numpy array (alias on the CPU, a device copy elsewhere)."""
        if self.cpu:
            return wp.array(arr, dtype=dtype, device=self.device, copy=False)
        return wp.array(arr, dtype=dtype, device=self.device)

    def set_positions(self, x: np.ndarray) -> None:
        self.x_np[...] = x
        if not self.cpu:
            self.x.assign(self.x_np)

    def _buffer(self, which: int, part: int):
        """CSR value buffer ``which`` (0: data, 1: data2) of launch part ``part``, created on first use."""
        buf = self.csr.get((which, part))
        if buf is None:
            if self.slots is None:
                if self.pattern.nnz >= 2**31:
                    raise ValueError("Hessian too large for int32 slots")
                self.slots = wp.array(self.pattern.element_slots.astype(np.int32), dtype=wp.int32,
                                      device=self.device)
            arr_np = np.zeros(self.pattern.nnz)
            buf = self.csr[(which, part)] = (self._wrap(arr_np, wp.float64), arr_np if self.cpu else None)
        return buf[0]

    def zero_csr(self, both: bool) -> None:
        """Zero the CSR values the Hessian launches add into (``data``, and ``data2`` with ``both``)."""
        for (which, _), (arr, arr_np) in self.csr.items():
            if which == 0 or both:
                if arr_np is not None:
                    arr_np.fill(0.0)
                else:
                    arr.zero_()

    def csr_values(self, second: bool = False) -> np.ndarray:
        """A fresh array (nnz,) of the CSR values of the last Hessian launch (``data2`` with
        ``second``), the parts' buffers summed (callers keep and modify the matrices built on it)."""
        vals = []
        for part in range(len(self.parts)):
            arr, arr_np = self.csr[(int(second), part)]
            vals.append(arr_np if arr_np is not None else arr.numpy())
        if len(vals) == 1:
            return vals[0].copy()
        return np.add(vals[0], vals[1]) if len(vals) == 2 else np.sum(vals, axis=0)  # one pass, one new array

    def command(self, what: Launch, mode: Hessian) -> tuple:
        """The recorded launches (one per part) for ``what`` and ``mode``, created on first use."""
        cmds = self.commands.get((what, mode))
        if cmds is not None:
            return cmds
        kern = self.kernels
        cmds = []
        # only the Hessian launches are split: the others take a fraction of a millisecond, less
        # than waking the second thread costs (and far less when the cores are busy)
        parts = self.parts if what in (Launch.HESSIAN, Launch.BLOCKS) else ((0, self.m),)
        for part, (first, count) in enumerate(parts):
            inputs = [first, self.x, *self.inputs]
            if what == Launch.ENERGY:
                kernel, outputs = kern.energy, [self.energy, self.det_F]
            elif what == Launch.GRADIENT:
                kernel, outputs = kern.gradient, [self.energy, self.det_F, self.grad]
            elif what == Launch.HESSIAN:  # added straight into this part's CSR values
                data = self._buffer(0, part)
                data2 = self._buffer(1, part) if mode == Hessian.BOTH else self.dummy_data
                kernel, inputs = kern.hessian[self.dim], inputs + [int(mode), 1, self.slots]
                outputs = [self.energy, self.det_F, self.grad, self.dummy3, data, data2]
            elif what == Launch.BLOCKS:
                if self.hess is None:
                    self.hess = wp.zeros((self.m, self.kd, self.kd), dtype=wp.float64, device=self.device)
                kernel, inputs = kern.hessian[self.dim], inputs + [int(mode), 0, self.dummy_slots]
                outputs = [self.energy, self.det_F, self.grad, self.hess, self.dummy_data, self.dummy_data]
            else:
                kernel, outputs = kern.stress, [self.det_F, self.von_mises]
            with RECORD_LOCK:  # the first launch loads the module: one thread at a time
                cmds.append(Replay(wp.launch(kernel, dim=count, device=self.device, inputs=inputs,
                                              outputs=outputs, record_cmd=True)))
        cmds = self.commands[(what, mode)] = tuple(cmds)
        return cmds

    def outputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(energy (m,), det F (m,), nodal gradient blocks (m, kd)) of the last launch as host arrays
        (views on the CPU: read before the next launch)."""
        if self._host is not None:
            return self._host
        return self.energy.numpy(), self.det_F.numpy(), self.grad.numpy()

    def stresses(self) -> tuple[np.ndarray, np.ndarray]:
        """(det F (m,), von Mises stress (m,)) of the last STRESS launch as host arrays (views on the
        CPU: read before the next launch)."""
        if self._host_vm is not None:
            return self._host[1], self._host_vm
        return self.det_F.numpy(), self.von_mises.numpy()

    def total_energy(self) -> float:
        """Sum of the element energies [J] of the last launch; +inf if any det F <= 0."""
        energy, det_F, _ = self.outputs()
        if np.minimum.reduce(det_F) <= 0.0:  # (ndarray.min / .sum without their Python wrappers)
            return float("inf")
        return float(np.add.reduce(energy))

    def gradient(self) -> np.ndarray:
        """The assembled nodal gradient (n, dim) [N] of the last GRADIENT / HESSIAN / BLOCKS launch
        (:func:`simfab._sparse.csr_matvec`: the same sums, without the operator's dispatch)."""
        return csr_matvec(self.scatter, self.outputs()[2].reshape(-1)).reshape(self.x_np.shape)


def launch(model, kernels: ElementKernels, x, what: Launch, mode: Hessian = Hessian.EXACT) -> Workspace:
    """Run ``what`` over all elements of ``model`` at positions x (n, dim) [m] (validated by
    ``model.check_positions``): one launch, or two halves on two threads. Returns the model's
    workspace holding the outputs."""
    x = model.check_positions(x)
    ws = model._cache.get("workspace")
    if ws is None:
        ws = model._cache["workspace"] = Workspace(model, kernels)
    ws.set_positions(x)
    cmds = ws.command(what, mode)
    if what == Launch.HESSIAN:
        ws.zero_csr(mode == Hessian.BOTH)
    other = [submit(c.launch) for c in cmds[1:]]
    cmds[0].launch()
    for o in other:
        o.result()
    return ws
