"""Lagged Coulomb friction as an incremental potential (IPC: Li et al. 2020, "Incremental Potential
Contact", sec. 5), with energy, gradient and Hessian per contact point in one Warp launch.

Per contact point j, with the normal force lambda_j >= 0 [N] and tangent basis T_j lagged (held
during a Newton solve), u_j = T_j^T dy_j [m] is the tangential slip over the step and

    D = sum_j mu lambda_j f0(|u_j|)   [J]
    f0(y) = -y^3 / (3 eps^2) + y^2 / eps + eps / 3    (y < eps),   f0(y) = y   (y >= eps)

so the friction force has magnitude mu lambda_j once the point slips by more than eps, and is a
spring of stiffness 2 mu lambda_j / eps at sticking. The Hessian is positive semi-definite without
projection. One kernel serves 2D and 3D (points as vec3, z = 0 and t2 = 0 in 2D). The derivatives
in full: docs/methods.md, "simfab.contact.friction".
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from simfab._warp import RECORD_LOCK, Replay, wp


@wp.func
def _f0(y: wp.float64, eps: wp.float64) -> wp.float64:
    if y < eps:
        return -y * y * y / (wp.float64(3.0) * eps * eps) + y * y / eps + eps / wp.float64(3.0)
    return y


@wp.func
def _f1_over_y(y: wp.float64, eps: wp.float64) -> wp.float64:
    if y < eps:
        return wp.float64(2.0) / eps - y / (eps * eps)
    return wp.float64(1.0) / y


@wp.func
def _curvature(y: wp.float64, eps: wp.float64) -> wp.float64:
    """(f1'(y) y - f1(y)) / y^3, times u u^T (|u| = y) it vanishes as y -> 0."""
    if y <= wp.float64(0.0):
        return wp.float64(0.0)
    if y < eps:
        return -wp.float64(1.0) / (eps * eps * y)
    return -wp.float64(1.0) / (y * y * y)


@wp.kernel
def _friction_kernel(
    dy: wp.array(dtype=wp.vec3d),  # (a,) relative displacement over the step [m]
    t1: wp.array(dtype=wp.vec3d),  # (a,) first tangent
    t2: wp.array(dtype=wp.vec3d),  # (a,) second tangent (zero in 2D)
    mu_lambda: wp.array(dtype=wp.float64),  # (a,) mu * lambda [N]
    eps: wp.array(dtype=wp.float64),  # (a,) mollifier width [m]
    want_hessian: wp.int32,
    energy: wp.array(dtype=wp.float64),  # (a,) [J]
    grad: wp.array(dtype=wp.vec3d),  # (a,) dD/ddy [N]
    hess: wp.array(dtype=wp.mat33d),  # (a,) d2D/ddy2 [N/m]
):
    j = wp.tid()
    a = t1[j]
    b = t2[j]
    d = dy[j]
    u1 = wp.dot(a, d)
    u2 = wp.dot(b, d)
    y = wp.sqrt(u1 * u1 + u2 * u2)
    e = eps[j]
    ml = mu_lambda[j]
    energy[j] = ml * _f0(y, e)
    fy = _f1_over_y(y, e)
    w = u1 * a + u2 * b  # T u: the tangential slip in world coordinates
    grad[j] = (ml * fy) * w
    if want_hessian != 0:
        hess[j] = ml * (_curvature(y, e) * wp.outer(w, w) + fy * (wp.outer(a, a) + wp.outer(b, b)))


@dataclass(frozen=True, eq=False)
class FrictionEval:
    """energy (a,) [J]; gradient (a, dim) [N] dD/ddy_j; hessian (a, dim, dim) [N/m] or None;
    slip (a,) [m] the tangential slip |u_j|."""

    energy: np.ndarray
    gradient: np.ndarray
    hessian: np.ndarray | None
    slip: np.ndarray


class FrictionPoints:
    """The lagged friction data of ``a`` contact points, for repeated evaluations at changing
    relative displacements (a Newton solve evaluates one lag tens of times): tangent bases
    ``tangents`` (a, dim, dim - 1), ``mu_lambda`` (a,) = mu lambda_j [N] and mollifier widths ``eps``
    (a,) [m]. The device buffers and the recorded launches (with and without the Hessian) belong to
    a pool per thread, device, ``a`` and ``dim`` (:class:`_Slots`), which a set of points loads its data
    into when another set used them last: an insertion builds a new lag per solve, and building
    the buffers and recording the launches cost ten evaluations (on the CPU the buffers alias numpy
    arrays)."""

    def __init__(self, tangents: np.ndarray, mu_lambda: np.ndarray, eps: np.ndarray, *, device: str = "cpu"):
        tangents = np.asarray(tangents, dtype=np.float64)
        a, dim = tangents.shape[0], tangents.shape[1]
        self.a, self.dim, self.device = a, dim, device
        t = np.zeros((a, 3, 2))
        t[:, :dim, : dim - 1] = tangents
        self._t = t
        self._data = (np.ascontiguousarray(t[:, :, 0]), np.ascontiguousarray(t[:, :, 1]),
                      np.asarray(mu_lambda, dtype=np.float64).reshape(a).copy(),
                      np.asarray(eps, dtype=np.float64).reshape(a).copy())

    def evaluate(self, dy: np.ndarray, *, hessian: bool = True) -> FrictionEval:
        """The potential at relative displacements ``dy`` (a, dim) [m] (the module docstring)."""
        dy = np.asarray(dy, dtype=np.float64)
        a, dim = self.a, self.dim
        if dy.shape != (a, dim):
            raise ValueError(f"dy has shape {dy.shape}, expected ({a}, {dim})")
        if a == 0:
            return FrictionEval(np.zeros(0), np.zeros((0, dim)), np.zeros((0, dim, dim)) if hessian else None,
                                np.zeros(0))
        slots = _Slots.get(a, dim, self.device)
        if slots.owner is not self:
            slots.load(self._data)
            slots.owner = self
        slots.dy[:, :dim] = dy
        energy, grad, hess = slots.launch(hessian)
        t_dy = np.einsum("kdt,kd->kt", self._t, slots.dy)
        slip = np.sqrt(np.add.reduce(t_dy * t_dy, axis=1))  # (np.linalg.norm(t_dy, axis=1)'s sums)
        H = hess[:a, :dim, :dim].copy() if hessian else None
        return FrictionEval(energy[:a].copy(), grad[:a, :dim].copy(), H, slip)


_POOL = threading.local()  # per thread: (a, dim, device) -> _Slots
_POOL_MAX = 32


class _Slots:
    """Device buffers of ``a`` points (displacements, tangents, mu lambda, eps, outputs; on the CPU
    aliasing numpy arrays) and their recorded launches, loaded by one :class:`FrictionPoints` at a
    time (``owner``)."""

    def __init__(self, a: int, dim: int, device: str):
        self.cpu = wp.get_device(device).is_cpu
        self.device, self.owner = device, None
        self.dy = np.zeros((a, 3))  # (z = 0 in 2D: only the first dim columns are ever written)
        host = (np.zeros((a, 3)), np.zeros((a, 3)), np.zeros(a), np.zeros(a))
        dtypes = (wp.vec3d, wp.vec3d, wp.float64, wp.float64)
        self._host = host if self.cpu else None
        self._dy_wp = wp.array(self.dy, dtype=wp.vec3d, device=device, copy=not self.cpu)
        self._inputs = [self._dy_wp, *(wp.array(h, dtype=d, device=device, copy=not self.cpu)
                                       for h, d in zip(host, dtypes))]
        self._outputs = [wp.zeros(max(a, 1), dtype=wp.float64, device=device),
                         wp.zeros(max(a, 1), dtype=wp.vec3d, device=device),
                         wp.zeros(max(a, 1), dtype=wp.mat33d, device=device)]
        self._views = tuple(o.numpy() for o in self._outputs) if self.cpu else None
        self.a = a
        self._commands: dict = {}

    @staticmethod
    def get(a: int, dim: int, device: str) -> "_Slots":
        pool = getattr(_POOL, "slots", None)
        if pool is None:
            pool = _POOL.slots = {}
        key = (a, dim, str(device))
        slots = pool.get(key)
        if slots is None:
            if len(pool) >= _POOL_MAX:
                pool.pop(next(iter(pool)))
            slots = pool[key] = _Slots(a, dim, device)
        return slots

    def load(self, data: tuple) -> None:
        """Copy (t1 (a, 3), t2 (a, 3), mu lambda (a,), eps (a,)) into the input buffers."""
        if self.cpu:
            for h, d in zip(self._host, data):
                h[...] = d
        else:
            for arr, d in zip(self._inputs[1:], data):
                arr.assign(d)

    def launch(self, hessian: bool) -> tuple:
        """Run the kernel on the loaded data and ``dy``: (energy (a,), grad (a, 3), hess (a, 3, 3)) as
        host arrays (views on the CPU: read before the next launch)."""
        if not self.cpu:
            self._dy_wp.assign(self.dy)
        cmd = self._commands.get(hessian)
        if cmd is None:
            with RECORD_LOCK:  # the first launch loads the module: one thread at a time
                cmd = self._commands[hessian] = Replay(wp.launch(
                    _friction_kernel, dim=self.a, inputs=[*self._inputs, int(hessian)], outputs=self._outputs,
                    device=self.device, record_cmd=True))
        cmd.launch()
        return self._views if self.cpu else tuple(o.numpy() for o in self._outputs)


def friction_potential(dy: np.ndarray, tangents: np.ndarray, mu_lambda: np.ndarray, eps: np.ndarray, *,
                       hessian: bool = True, device: str = "cpu") -> FrictionEval:
    """The friction potential of points with relative displacements ``dy`` (a, dim) [m], tangent
    bases ``tangents`` (a, dim, dim - 1), ``mu_lambda`` (a,) = mu lambda_j [N] and mollifier widths
    ``eps`` (a,) [m] (see the module docstring), in one Warp launch (:class:`FrictionPoints` for
    repeated evaluations of the same points)."""
    dy = np.asarray(dy, dtype=np.float64)
    a, dim = dy.shape
    tangents = np.asarray(tangents, dtype=np.float64).reshape(a, dim, dim - 1)
    return FrictionPoints(tangents, mu_lambda, eps, device=device).evaluate(dy, hessian=hessian)


def tangent_bases(normals: np.ndarray) -> np.ndarray:
    """(a, dim, dim - 1) orthonormal bases of the planes normal to unit ``normals`` (a, dim)."""
    a, dim = normals.shape
    if dim == 2:
        return np.stack([-normals[:, 1], normals[:, 0]], axis=1)[:, :, None]
    axis = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    t1 = np.cross(normals, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return np.stack([t1, np.cross(normals, t1)], axis=2)
