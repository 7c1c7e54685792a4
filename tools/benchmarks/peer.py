"""simfab's insertion beside an IPC reference built on the IPC Toolkit (``ipctk``).

``python tools/bench.py peer [--scenes snapfit2d,cclamp2d] [--frictions 0,0.3] [--refine 1,2]
[--repeat K | --budget SECONDS] [--max-repeat K] [--plot DIR]``

The reference solves the same quasi-static insertion the way the IPC paper (Li et al. 2020) does:

- the part's energy is simfab's Neo-Hookean (simfab.fem.elastic, PSD-projected element Hessians) on
  the same linear mesh, the same supports (the scene's fixed dofs);
- the object is a kinematic collision mesh (its boundary polygon in 2D, triangles in 3D) moved to
  simfab's recorded poses in order (the insertion's steps, its rest search, the removal's), its
  polygonal error below 1 % of d_hat; its vertices are degrees of freedom pulled to their targets by
  IPC's augmented Lagrangian (kappa_A doubled when the constraint's progress stalls, else the
  multipliers updated) and fixed at them once within 1e-3 of the step's motion and the CCD lets them;
- contact is ipctk's log barrier over part-object pairs (self-contact filtered out, as simfab has
  none) with the same d_hat as simfab's, its stiffness from ``initial_barrier_stiffness`` and
  adapted by ``update_barrier_stiffness``; friction through ipctk's tangential collisions and
  friction potential on the step's displacement, lagged (normal forces and bases from the step's
  start, then its solution) until the normal forces change by less than simfab's ``lag_tol``, with
  simfab's stick-slip eps;
- Newton's steps are bounded by ipctk's CCD (Tight Inclusion, its 0.8 conservative rescaling), then
  backtracked until the total energy decreases; the linear solves are simfab's SPDSolver (CHOLMOD,
  symbolic analysis reused while the pattern holds); converged at simfab's force tolerance.

Reported per case: the profile figures of both runs (the support reaction along O's motion;
simfab's analysis of each run's records, F_hold's onset of sliding from simfab's), their
differences, the profiles' largest difference, wall and CPU seconds (both timed warm; the medians of
the timed runs of each, simfab's and the reference's alternating, so both share the machine's slow
and fast moments: K pairs with ``--repeat K``, else pairs until ``--budget`` seconds are spent, at
least one, at most ``--max-repeat``: a sub-second case runs ~15 times, a case of minutes once),
Newton iterations per step and the speed ratio;
``--plot DIR`` draws both profiles. ``--refine`` factors refine each case's mesh by the scene's own
rule (:func:`simfab.coupling.converge.level_mesh`; the snap-fit: cells through its thickness times the
factor's square root).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from benchmarks._repeat import RepeatRule, add_repeat_options, repeat_rule

FIGURES = ("E_max", "F_in", "F_rm", "F_hold")
#: The object's polygonal error (sagitta of its boundary segments) below this fraction of d_hat.
POLY_ERR_REL = 0.01
#: Kinematic dofs are switched from the augmented Lagrangian to fixed once this close (relative to
#: the step's motion), IPC's eta >= 0.999.
AL_SWITCH = 1e-3


@dataclass(frozen=True, kw_only=True)
class PeerOptions:
    """The reference's parameters (see the module docstring). Lengths [m], forces [N]."""

    dhat: float
    grad_tol: float  # free-dof force residual at convergence [N]
    mu: float = 0.0
    eps_v: float = 1e-6  # stick-slip transition of the step's tangential displacement [m]
    lag_tol: float = 3e-2
    max_lag: int = 6
    max_newton: int = 300
    al_kappa_rel: float = 1e3  # kappa_A / mean diagonal stiffness of the part
    density: float = 1240.0  # PLA [kg/m^3]: the mass scale of initial_barrier_stiffness
    psd: str = "CLAMP"  # ipctk's PSD projection of the contact Hessians (CLAMP or ABS)
    kappa_per_step: bool = False  # initial_barrier_stiffness again at each step's start (kept when larger)
    extrapolate: bool = False  # start each step from the last increment repeated (CCD-cut; no gain measured)
    mass_scale: str = "stiffness"  # "mass": lumped mass; "stiffness": mean diag of H_el


@dataclass(frozen=True, kw_only=True)
class PeerStep:
    s: float
    phase: str
    force: float
    energy: float
    iterations: int
    kappa: float


def object_polygon(cm) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (k, dim) in O's body frame, edges (k, 2) or faces (f, 3)): O's boundary as a
    collision mesh, fine enough that its polygonal error is below POLY_ERR_REL d_hat."""
    from simfab.errors import InputError

    prims = getattr(cm.field, "primitives", None)
    if not prims or len(prims) != 1:
        raise InputError(f"the peer needs an object of one primitive, {cm.name} has another")
    p = prims[0]
    dim = cm.dim
    tol = POLY_ERR_REL * cm.dhat
    if dim == 2 and p.kind == "box":
        ex, ey = p.size[:2]
        Q = np.asarray(p.rotation)[:2, :2]
        c = np.asarray(p.centre)[:2]
        corners = np.array([[-ex, -ey], [ex, -ey], [ex, ey], [-ex, ey]])
        # split each side so the edges are no longer than the part's edges (the barrier's
        # point-edge pairs then resolve the contact as finely as the part does)
        pts = []
        for i in range(4):
            a, b = corners[i], corners[(i + 1) % 4]
            k = max(1, int(np.ceil(np.linalg.norm(b - a) / cm.h)))
            pts += [a + (b - a) * t for t in np.arange(k) / k]
        V = np.asarray(pts) @ Q.T + c
        return V, np.c_[np.arange(len(V)), (np.arange(len(V)) + 1) % len(V)]
    if dim == 2 and p.kind == "sphere":
        R = float(p.size[0])
        k = int(np.ceil(np.pi / np.arccos(1.0 - tol / R)))
        t = 2 * np.pi * np.arange(k) / k
        V = np.c_[R * np.cos(t), R * np.sin(t)] + np.asarray(p.centre)[:2]
        return V, np.c_[np.arange(k), (np.arange(k) + 1) % k]
    if dim == 3 and p.kind == "cylinder":
        R, half = float(p.size[0]), float(p.size[1])
        k = int(np.ceil(np.pi / np.arccos(1.0 - tol / R)))
        t = 2 * np.pi * np.arange(k) / k
        nz = max(1, int(np.ceil(2 * half / cm.h)))
        zs = np.linspace(-half, half, nz + 1)
        ring = np.c_[R * np.cos(t), R * np.sin(t)]
        V = np.vstack([np.c_[ring, np.full(k, z)] for z in zs] + [[[0, 0, -half]], [[0, 0, half]]])
        F = []
        for j in range(nz):
            a, b = j * k, (j + 1) * k
            for i in range(k):
                i1 = (i + 1) % k
                F += [[a + i, a + i1, b + i1], [a + i, b + i1, b + i]]
        c0, c1 = len(V) - 2, len(V) - 1
        F += [[c0, (i + 1) % k, i] for i in range(k)]
        F += [[c1, nz * k + i, nz * k + (i + 1) % k] for i in range(k)]
        V = V @ np.asarray(p.rotation).T + np.asarray(p.centre)
        return V, np.asarray(F)
    raise InputError(f"the peer has no collision mesh for a {dim}D {p.kind}")


class IpcReference:
    """The IPC reference of one coupling model (linear elements; see the module docstring)."""

    def __init__(self, cm, opts: PeerOptions):
        import ipctk

        from simfab.solve.linear import SPDSolver

        self.ipctk, self.cm, self.o = ipctk, cm, opts
        fem = cm.fem
        self.dim, self.n = cm.dim, fem.n_vertices
        facets = np.asarray(cm.contact_facets)
        self.S = np.unique(facets)  # part boundary vertices in the collision mesh
        local = np.full(self.n, -1)
        local[self.S] = np.arange(len(self.S))
        self.Vb, obj = object_polygon(cm)
        self.k = len(self.Vb)
        nS = len(self.S)
        prim = np.r_[local[facets], obj + nS].astype(np.int32)
        rest = np.vstack([fem.rest[self.S], self._object_at(float(cm.s_steps[0]))])
        if self.dim == 2:
            self.mesh = ipctk.CollisionMesh(np.asfortranarray(rest), np.asfortranarray(prim))
            tri = np.c_[prim, prim[:, 1]].astype(np.int32)  # edges as degenerate triangles: components
        else:
            edges = ipctk.edges(np.asfortranarray(prim))
            self.mesh = ipctk.CollisionMesh(np.asfortranarray(rest), edges, np.asfortranarray(prim))
            tri = prim
        # part-object pairs only: each body is one connected component of the collision mesh
        self.mesh.can_collide = ipctk.make_connected_components_filter(np.asfortranarray(tri))
        # collision dofs -> full dofs [part (n dim), object (k dim)]
        cols = np.r_[self.S, self.n + np.arange(self.k)]
        rows = np.arange(len(cols))
        ii = (rows[:, None] * self.dim + np.arange(self.dim)).ravel()
        jj = (cols[:, None] * self.dim + np.arange(self.dim)).ravel()
        self.N = (self.n + self.k) * self.dim
        self.P = sp.csr_matrix((np.ones(len(ii)), (ii, jj)), shape=(len(ii), self.N))
        self.part_free = np.asarray(cm.free, bool).ravel()
        self.solver = SPDSolver()
        self.barrier = ipctk.ClampedLogBarrier()
        self.ccd = ipctk.TightInclusionCCD(conservative_rescaling=0.8)
        self.bp = ipctk.BroadPhase.make_default() if hasattr(ipctk.BroadPhase, "make_default") else None
        lo, hi = rest.min(0), rest.max(0)
        self.diag = float(np.linalg.norm(hi - lo))
        self.mass = opts.density * float(np.sum(fem.volume)) / self.n  # (2D: volume = area x thickness)
        self.kappa = None
        self.kappa_max = None
        self._psd = getattr(ipctk.PSDProjectionMethod, opts.psd)
        self.trace = None  # a list: (AL phase, step length, |g_f|, collisions) per Newton iteration

    # -- geometry ------------------------------------------------------------------------
    def _object_at(self, s: float) -> np.ndarray:
        R, p = self.cm.pose(s)
        V3 = np.zeros((self.k, 3))
        V3[:, : self.dim] = self.Vb
        return (V3 @ R.T + p)[:, : self.dim]

    def _collision_vertices(self, z: np.ndarray) -> np.ndarray:
        Z = z.reshape(-1, self.dim)
        return np.asfortranarray(np.vstack([Z[self.S], Z[self.n:]]))

    # -- energy --------------------------------------------------------------------------
    def _terms(self, z, need_h: bool, al, fric):
        """Total energy, gradient (N,) and Hessian (CSR or None) at z, the barrier's collisions."""
        from simfab.fem.elastic import energy_gradient, energy_gradient_hessian

        ipctk, dim, n = self.ipctk, self.dim, self.n
        X = z[: n * dim].reshape(n, dim)
        if need_h:
            E, g_el, H_el = energy_gradient_hessian(self.cm.fem, X)
        else:
            E, g_el = energy_gradient(self.cm.fem, X)
        V = self._collision_vertices(z)
        col = ipctk.NormalCollisions()
        col.build(self.mesh, V, self.o.dhat)
        B = ipctk.BarrierPotential(self.barrier, self.o.dhat, self.kappa)
        f = float(E) + B(col, self.mesh, V)
        gc = B.gradient(col, self.mesh, V)
        if fric is not None:
            tc, V0, D = fric
            U = np.asfortranarray(V - V0)
            f += D(tc, self.mesh, U)
            gc = gc + D.gradient(tc, self.mesh, U)
        g = np.zeros(self.N)
        g[: n * dim] = np.asarray(g_el).ravel()
        g += self.P.T @ gc
        kA, lam, target = al
        y = z[n * dim:]
        if kA is not None:
            r = y - target
            f += 0.5 * kA * r @ r - lam @ r
            g[n * dim:] += kA * r - lam
        H = None
        if need_h:
            Hc = B.hessian(col, self.mesh, V, self._psd)
            if fric is not None:
                Hc = Hc + D.hessian(tc, self.mesh, U, self._psd)
            Hel = sp.csr_matrix(H_el)
            pad = sp.block_diag([Hel, sp.csr_matrix((self.k * dim, self.k * dim))], format="csr")
            H = pad + self.P.T @ sp.csr_matrix(Hc) @ self.P
            diag = np.zeros(self.N)
            diag[n * dim:] = kA if kA is not None else 0.0
            diag[: n * dim] = self._reg
            H = (H + sp.diags(diag)).tocsr()
        return f, g, H, col, V, E

    def _balance_kappa(self, z):
        """IPC's initial stiffness again at a step's start, from the elastic and barrier gradients
        there (kept when larger): the barrier balances the elastic forces once contact exists."""
        from simfab.fem.elastic import energy_gradient

        ipctk, dim, n = self.ipctk, self.dim, self.n
        V = self._collision_vertices(z)
        col = ipctk.NormalCollisions()
        col.build(self.mesh, V, self.o.dhat)
        if len(col) == 0:
            return
        gb = ipctk.BarrierPotential(self.barrier, self.o.dhat, 1.0).gradient(col, self.mesh, V)
        _, g_el = energy_gradient(self.cm.fem, z[: n * dim].reshape(n, dim))
        ge = self.P @ np.r_[np.asarray(g_el).ravel(), np.zeros(self.k * dim)]
        m = self._kmean if self.o.mass_scale == "stiffness" else self.mass
        k, kmax = ipctk.initial_barrier_stiffness(self.diag, self.barrier, self.o.dhat, m, ge, gb)
        self.kappa, self.kappa_max = max(self.kappa, k), max(self.kappa_max, kmax)

    def _extrapolated(self, z, z_prev):
        """The step's start: the last step's increment repeated (the quasi-static analogue of IPC's
        x + h v initial guess), cut by the CCD so that it stays intersection-free."""
        z1 = 2.0 * z - z_prev
        alpha = self.ipctk.compute_collision_free_stepsize(self.mesh, self._collision_vertices(z),
                                                           self._collision_vertices(z1), narrow_phase_ccd=self.ccd)
        return z + min(1.0, alpha) * (z1 - z)

    # -- one step ------------------------------------------------------------------------
    def _normals(self, z):
        """(tangential collisions, their normal force magnitudes) at state z (IPC's lagged friction)."""
        ipctk = self.ipctk
        V = self._collision_vertices(z)
        col = ipctk.NormalCollisions()
        col.build(self.mesh, V, self.o.dhat)
        tc = ipctk.TangentialCollisions()
        tc.build(self.mesh, V, col, ipctk.BarrierPotential(self.barrier, self.o.dhat, self.kappa), self.o.mu)
        return tc, np.array([c.normal_force_magnitude for c in _tangential(tc)])

    def step(self, z: np.ndarray, s: float) -> tuple[np.ndarray, int]:
        """Solve the step moving O to its pose at s starting from z; (z, Newton iterations)."""
        dim, n = self.dim, self.n
        target = self._object_at(s).ravel()
        move = float(np.linalg.norm(target - z[n * dim:]))
        if self.o.mu == 0:
            return self._solve_al(z, target, move, None)
        V_start = self._collision_vertices(z)
        tc, normals = self._normals(z)
        iters = 0
        for _lag in range(self.o.max_lag):
            fric = (tc, V_start, self.ipctk.FrictionPotential(self.o.eps_v))
            z, it = self._solve_al(z, target, move, fric)
            iters += it
            tc, new = self._normals(z)
            scale = max(new.max(initial=0.0), normals.max(initial=0.0))
            if scale == 0 or (len(new) == len(normals) and np.max(np.abs(new - normals)) <= self.o.lag_tol * scale):
                break
            normals = new
        return z, iters

    def _solve_al(self, z, target, move, fric):
        """The step's augmented-Lagrangian loop, then Newton with O fixed at its target."""
        ipctk, dim, n = self.ipctk, self.dim, self.n
        kA = self.o.al_kappa_rel * self._kmean
        lam = np.zeros_like(target)
        iters = 0
        free_al = np.r_[self.part_free, np.ones(self.k * dim, bool)]
        for _outer in range(30):
            y = z[n * dim:]
            if np.linalg.norm(y - target) <= AL_SWITCH * max(move, 1e-300):
                V0 = self._collision_vertices(z)
                z1 = z.copy()
                z1[n * dim:] = target
                if ipctk.compute_collision_free_stepsize(self.mesh, V0, self._collision_vertices(z1),
                                                         narrow_phase_ccd=self.ccd) >= 1.0:
                    z = z1
                    break
            d_before = float(np.linalg.norm(y - target))
            z, it = self._newton(z, free_al, (kA, lam, target), fric)
            iters += it
            d_after = float(np.linalg.norm(z[n * dim:] - target))
            if d_after <= AL_SWITCH * max(move, 1e-300):
                continue
            if d_before > 0 and 1.0 - d_after / d_before < 0.99:  # IPC: eta below 0.99 -> stiffer
                kA *= 2.0
            else:
                lam = lam - kA * (z[n * dim:] - target)
        else:
            raise RuntimeError("augmented Lagrangian did not reach the object's pose")
        free = np.r_[self.part_free, np.zeros(self.k * dim, bool)]
        z, it = self._newton(z, free, (None, None, None), fric)
        return z, iters + it

    def _newton(self, z, free, al, fric):
        ipctk = self.ipctk
        idx = np.flatnonzero(free)
        f, g, H, col, V, _ = self._terms(z, True, al, fric)
        prev_d = col.compute_minimum_distance(self.mesh, V) if len(col) else np.inf
        for it in range(self.o.max_newton):
            if np.max(np.abs(g[idx]), initial=0.0) <= self.o.grad_tol:
                return z, it
            Hf = H[idx][:, idx]
            dx = np.zeros(self.N)
            dx[idx] = self.solver.solve(Hf, -g[idx])
            z1 = z + dx
            alpha = ipctk.compute_collision_free_stepsize(self.mesh, V, self._collision_vertices(z1),
                                                          narrow_phase_ccd=self.ccd)
            alpha = min(1.0, alpha)
            while True:
                zt = z + alpha * dx
                ft = self._terms(zt, False, al, fric)[0]
                if ft <= f or alpha < 1e-12:
                    break
                alpha *= 0.5
            z = zt
            f, g, H, col, V, _ = self._terms(z, True, al, fric)
            if self.trace is not None:
                self.trace.append((al[0] is not None, alpha, float(np.max(np.abs(g[idx]))), len(col)))
            d = col.compute_minimum_distance(self.mesh, V) if len(col) else np.inf
            if np.isfinite(d) and np.isfinite(prev_d):
                k1 = ipctk.update_barrier_stiffness(prev_d, d, self.kappa_max, self.kappa, self.diag)
                if k1 != self.kappa:
                    self.kappa = k1
                    f, g, H, col, V, _ = self._terms(z, True, al, fric)
            prev_d = d
        raise RuntimeError(f"reference Newton did not converge in {self.o.max_newton} iterations "
                           f"(|g| {np.max(np.abs(g[idx])):.3g} N)")

    # -- the run -------------------------------------------------------------------------
    def run(self, poses: list) -> list:
        """Solve O's poses ``poses`` [(s, phase)] in order from the rest shape; one PeerStep each."""
        from simfab.fem.elastic import energy_gradient_hessian

        ipctk, dim, n = self.ipctk, self.dim, self.n
        z = np.r_[self.cm.fem.rest.ravel(), self._object_at(poses[0][0]).ravel()]
        _, _, H_el = energy_gradient_hessian(self.cm.fem, self.cm.fem.rest)
        self._kmean = float(np.mean(H_el.diagonal()))
        self._reg = 1e-8 * self._kmean
        # IPC's initial barrier stiffness from the elastic and barrier gradients at the start; the
        # mass scale of a quasi-static problem is the elastic stiffness per dof (M / dt^2 in IPC's
        # incremental potential)
        V = self._collision_vertices(z)
        col = ipctk.NormalCollisions()
        col.build(self.mesh, V, self.o.dhat)
        gb = ipctk.BarrierPotential(self.barrier, self.o.dhat, 1.0).gradient(col, self.mesh, V)
        ge = np.zeros(len(gb))
        m = self._kmean if self.o.mass_scale == "stiffness" else self.mass
        self.kappa, self.kappa_max = ipctk.initial_barrier_stiffness(self.diag, self.barrier, self.o.dhat, m, ge, gb)
        out = []
        fixed = np.flatnonzero(~self.part_free)
        z_prev = None
        for s, phase in poses:
            if self.o.kappa_per_step:
                self._balance_kappa(z)
            z_now = z
            if self.o.extrapolate and z_prev is not None and out and out[-1].phase == phase:
                z = self._extrapolated(z, z_prev)
            z, it = self.step(z, s)
            z_prev = z_now
            _, g, _, _, _, E = self._terms(z, False, (None, None, None), None)
            u = self.cm.direction(s)
            gfix = np.zeros(n * dim)
            gfix[fixed] = g[fixed]
            F = float(np.sum(gfix.reshape(n, dim) @ u))
            out.append(PeerStep(s=float(s), phase=phase, force=F, energy=float(E), iterations=it, kappa=self.kappa))
        return out


def _tangential(tc) -> list:
    out = []
    for name in ("vv_collisions", "ev_collisions", "ee_collisions", "fv_collisions"):
        out += list(getattr(tc, name, []))
    return out


# -- the comparison ---------------------------------------------------------------------------
SCENES = ("snapfit2d", "cclamp2d", "clip3d")
SNAPFIT_ALPHA = 30.0


#: The peer's meshes at refinement 1 (clip3d: linear tets near the original's size; the snap-fit's
#: beam cells through its thickness).
CLIP3D_PART = {"target_elements": 1040, "layers": 1, "segments": 48}
SNAPFIT_CELLS_T = 3
MAX_REFINE = 64.0
#: Records within this many d_hat of the seat (the deepest pose) are left out of
#: ``profile_difference_off_seat``: there O is within d_hat of the part's base in clip3d, where each
#: barrier's own force law sets the force.
SEAT_DHATS = 5.0


def parse_refine(text: str) -> list[float]:
    """The ``--refine`` factors: comma-separated element-count factors in [1, MAX_REFINE].

    Args:
        text: e.g. ``"1,2,4"``.

    Returns:
        The factors in the given order.
    """
    from simfab.errors import InputError

    try:
        out = [float(f) for f in text.split(",")]
    except ValueError:
        raise InputError(f"--refine must be comma-separated numbers, got {text!r}") from None
    for f in out:
        if not 1.0 <= f <= MAX_REFINE:
            raise InputError(f"--refine factors must be in [1, {MAX_REFINE:g}], got {f:g}")
    return out


def case_model(scene: str, mu: float, refine: float = 1.0):
    """The coupling model of a peer case on linear elements (the reference's elements), its mesh
    refined to ``refine`` times the element count (see the module docstring)."""
    from simfab.errors import InputError

    if scene == "snapfit2d":
        from simfab.verification.snapfit import snapfit_model

        return snapfit_model(SNAPFIT_ALPHA, mu, cells_t=max(1, int(round(SNAPFIT_CELLS_T * refine ** 0.5))))
    from simfab.coupling.converge import level_mesh
    from simfab.coupling.scene import load_coupling_scene, read_scene_toml, scene_paths

    # the support held in every axis (for both solvers): the scene's support holds the insertion axis
    # only and leaves the part's sideways rigid motion to contact, which simfab pins by a Woodbury
    # update while IPC has no counterpart (its Newton then wanders along the unresisted mode)
    over = {"simulation": {"element_order": 1, "fix_all_axes": True}, "contact": {"friction": mu}}
    if scene not in SCENES:
        raise InputError(f"--scenes: unknown peer scene {scene!r} (choose from {', '.join(SCENES)})")
    comp = dict(read_scene_toml(scene_paths(scene)[1])["compliant"])
    if scene == "clip3d":
        comp.update(CLIP3D_PART)
    over["compliant"] = {**({"segments": comp["segments"]} if scene == "clip3d" else {}), **level_mesh(comp, refine)}
    return load_coupling_scene(scene, overrides=over)


def compare(scene: str, mu: float, refine: float = 1.0, *, warm: bool = True, repeat: int | RepeatRule = 1) -> dict:
    """simfab's run and the reference's on one case: figures, differences, seconds, iterations.

    Args:
        scene: one of SCENES.
        mu: friction coefficient.
        refine: element-count factor of the case's mesh (:func:`case_model`).
        warm: time both solvers after an untimed first run (else the first, simfab's, pays the
            process's one-off costs that the reference then reuses).
        repeat: timed runs of each solver, alternating (simfab, reference, simfab, ...): a count, or
            a rule (pairs until its budget of both solvers' wall seconds is spent); the seconds
            reported are their medians, with the fastest and slowest run beside them. A run of the
            snap-fit takes ~0.05 s, where one run's timing varies by +-30 % with the machine's load.

    Returns:
        The case's row (see :func:`run`).
    """
    from simfab.coupling import config as C
    from simfab.coupling.profile import analyze_run
    from simfab.coupling.simulate import simulate_insertion

    # both timed warm: a first run of each (simfab's whole run, the reference's first two poses)
    # loads the Warp kernels (of the elastic energy both use), CHOLMOD and ipctk untimed
    if warm:
        simulate_insertion(case_model(scene, mu, refine))
    rule = repeat if isinstance(repeat, RepeatRule) else RepeatRule(repeat=repeat)
    if rule.repeat is not None and rule.repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {rule.repeat}")
    times_s, times_r, pairs, res, steps, ref = [], [], [], None, None, None
    while len(pairs) < rule.wanted(pairs):
        cm = case_model(scene, mu, refine)
        t0, c0 = time.perf_counter(), time.process_time()
        run_s = simulate_insertion(cm)
        times_s.append((time.perf_counter() - t0, time.process_time() - c0))
        if res is None:
            res = run_s
            poses = [(float(r.s), "insert") for r in res.steps] + [(float(r.s), "remove") for r in res.removal]
            opts = PeerOptions(dhat=float(cm.dhat), grad_tol=C.NEWTON_GRAD_TOL_REL * float(cm.force_scale),
                               mu=float(mu), eps_v=float(cm.contact.friction_eps_rel) * float(cm.h),
                               lag_tol=float(cm.contact.lag_tol), max_lag=int(cm.contact.max_lag_iterations))
            if warm:
                IpcReference(cm, opts).run(poses[:2])
        elif _forces(run_s) != _forces(res):
            raise RuntimeError(f"{scene}: simfab's repeated run gave other records (not reproducible)")
        t0, c0 = time.perf_counter(), time.process_time()
        ref_k = IpcReference(cm, opts)
        steps_k = ref_k.run(poses)
        times_r.append((time.perf_counter() - t0, time.process_time() - c0))
        pairs.append(times_s[-1][0] + times_r[-1][0])
        if steps is None:
            steps, ref = steps_k, ref_k
    (t_s, c_s), (t_r, c_r) = _medians(times_s), _medians(times_r)
    ins, rem = steps[: len(res.steps)], steps[len(res.steps):]
    peer_res = dataclasses.replace(
        res, steps=[dataclasses.replace(r, force=p.force, energy=p.energy) for r, p in zip(res.steps, ins)],
        removal=[dataclasses.replace(r, force=p.force, energy=p.energy) for r, p in zip(res.removal, rem)])
    a, b = analyze_run(res), analyze_run(peer_res)
    fs = {k: float(getattr(a, k)) for k in FIGURES}
    fr = {k: float(getattr(b, k)) for k in FIGURES}
    peak_f = max(abs(fs["F_in"]), abs(fs["F_rm"]), 1e-300)
    rel = {k: ((fr[k] - fs[k]) / (abs(fs[k]) if k == "E_max" else peak_f)) for k in FIGURES}
    f_s = np.array([float(r.force) for r in [*res.steps, *res.removal]])
    f_r = np.array([p.force for p in steps])
    s_all = np.array([p.s for p in steps])
    off_seat = s_all < s_all.max() - SEAT_DHATS * float(cm.dhat)
    n_s = len(res.steps) - 1 + len(res.removal)
    it_s = int(sum(r.iterations for r in res.steps[1:]) + sum(r.iterations for r in res.removal))
    it_r = int(sum(p.iterations for p in steps[1:]))
    return {
        "scene": scene, "friction": mu, "refine": refine, "elements": int(cm.fem.n_elements), "element_order": 1,
        "object_collision_vertices": int(ref.k), "dhat": float(cm.dhat), "records": n_s,
        "repeat": len(pairs),
        "simfab": {**fs, "category": a.category, "seconds": round(t_s, 3), "cpu_seconds": round(c_s, 3),
                   "seconds_range": _range(times_s),
                   "newton_iterations": it_s, "iterations_per_step": round(it_s / max(1, n_s), 2)},
        "ipc": {**fr, "category": b.category, "seconds": round(t_r, 3), "cpu_seconds": round(c_r, 3),
                "seconds_range": _range(times_r),
                "newton_iterations": it_r, "iterations_per_step": round(it_r / max(1, n_s), 2),
                "kappa_final": float(ref.kappa), "max_iterations_in_a_step": int(max(p.iterations for p in steps))},
        # relative to E_max for E_max, to the larger of simfab's F_in and F_rm for the forces
        "relative_difference": {k: round(v, 4) for k, v in rel.items()},
        # the largest force difference of the whole profile, and of the records farther than
        # SEAT_DHATS d_hat along the path from the deepest pose (the seat; see docs/benchmarks.md)
        "profile_difference": round(float(np.max(np.abs(f_r - f_s))) / peak_f, 4),
        "profile_difference_off_seat": round(float(np.max(np.abs(f_r - f_s)[off_seat], initial=0.0)) / peak_f, 4),
        "speed_ratio": round(t_r / t_s, 2), "speed_ratio_cpu": round(c_r / c_s, 2),
        "profile": {"s": [p.s for p in steps], "phase": [p.phase for p in steps],
                    "force_simfab": f_s.tolist(), "force_ipc": f_r.tolist()},
    }


def _forces(res) -> list:
    """The records' forces and energies of an insertion run (equal lists: the same run)."""
    return [(float(r.force), float(r.energy)) for r in [*res.steps, *res.removal]]


def _medians(times: list) -> tuple:
    """(median wall seconds, median CPU seconds) of (wall, cpu) pairs."""
    return float(np.median([t for t, _ in times])), float(np.median([c for _, c in times]))


def _range(times: list) -> list:
    """[fastest, slowest] wall seconds of (wall, cpu) pairs."""
    return [round(min(t for t, _ in times), 3), round(max(t for t, _ in times), 3)]


def plot(row: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pr = row["profile"]
    s, ph = np.asarray(pr["s"]) * 1e3, np.asarray(pr["phase"])
    fig, ax = plt.subplots(figsize=(6.4, 4))
    for phase, style in (("insert", "-"), ("remove", "--")):
        m = ph == phase
        if m.any():
            ax.plot(s[m], np.asarray(pr["force_simfab"])[m], "o" + style, ms=3, label=f"simfab ({phase})")
            ax.plot(s[m], np.asarray(pr["force_ipc"])[m], "x" + style, ms=4, label=f"IPC reference ({phase})")
    # the y-range of simfab's profile: a reference record far outside it (the stiff contact at the
    # seat, see docs/benchmarks.md) is marked at the edge and its value given in the legend
    fs, fi = np.asarray(pr["force_simfab"]), np.asarray(pr["force_ipc"])
    lo, hi = float(min(fs.min(), 0.0)), float(max(fs.max(), 0.0))
    pad = 0.15 * (hi - lo)
    lo, hi = lo - pad, hi + pad
    off = (fi < lo) | (fi > hi)
    if off.any():
        k = int(np.argmax(np.abs(fi) * off))
        ax.plot(s[off], np.clip(fi[off], lo, hi), "v" if fi[k] < lo else "^", color="k", ms=6,
                label=f"IPC off scale ({off.sum()}; extreme {fi[k]:.0f} N at s = {s[k]:.3f} mm)")
        ax.set_ylim(lo, hi)
    ax.set_xlabel("path length s [mm]")
    ax.set_ylabel("insertion force F [N] (resisting < 0)")
    ref = f", refined x{row['refine']:g}" if row.get("refine", 1.0) != 1.0 else ""
    ax.set_title(f"{row['scene']}, mu = {row['friction']:g}, {row['elements']:,} linear elements{ref}:\n"
                 "simfab vs ipctk IPC reference", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def format_table(rows: list) -> str:
    head = (f"{'scene':10s} {'mu':>4s} {'elems':>6s} {'fig':6s} {'simfab':>10s} {'IPC':>10s} {'rel.diff':>9s}")
    lines = [head]
    for r in rows:
        for k in FIGURES:
            lines.append(f"{r['scene']:10s} {r['friction']:>4g} {r['elements']:>6d} {k:6s} {r['simfab'][k]:>10.4g} "
                         f"{r['ipc'][k]:>10.4g} {100 * r['relative_difference'][k]:>8.2f}%")
        lines.append(f"{r['scene']:10s} {r['friction']:>4g} {r['elements']:>6d} wall s {r['simfab']['seconds']:>10.2f} "
                     f"{r['ipc']['seconds']:>10.2f}  ratio {r['speed_ratio']:.1f} (cpu {r['speed_ratio_cpu']:.1f}"
                     f"{'' if r.get('repeat', 1) == 1 else ', medians of %d' % r['repeat']}); "
                     f"it/step {r['simfab']['iterations_per_step']} vs {r['ipc']['iterations_per_step']}")
    return "\n".join(lines)


def run(argv) -> dict:
    """The bench's entry point (``python tools/bench.py peer ...``; options in the module docstring).

    Args:
        argv: the command line after ``peer``.

    Returns:
        {"benchmark", "reference", "rows": one :func:`compare` row per scene, friction and refinement
        factor, "table": the printed table}. Raises InputError on a bad option before any case runs.
    """
    from simfab.errors import InputError
    from simfab.io.outpaths import check_out_dir

    ap = argparse.ArgumentParser(prog="bench peer", description="The same quasi-static insertions solved by simfab "
                                 "and by an IPC reference on ipctk: both force profiles, F_in / F_rm / F_hold / E_max "
                                 "and their differences, wall and CPU seconds, Newton iterations, the speed ratio. "
                                 "Table on stderr, one JSON object on stdout.")
    ap.add_argument("--scenes", default=",".join(SCENES),
                    help=f"comma-separated, from {', '.join(SCENES)} (default all)")
    ap.add_argument("--frictions", default="0,0.3", help="Coulomb friction coefficients (default 0,0.3)")
    ap.add_argument("--refine", default="1", help="element-count factors of each case's mesh, e.g. 1,2,4")
    add_repeat_options(ap, what="pairs of runs (one of each solver)",
                       repeat_help="timed runs of each solver, alternating; the medians are reported (default: "
                                   "pairs until --budget seconds are spent, at least one)")
    ap.add_argument("--plot", default=None, help="directory for the force-profile PNGs")
    a = ap.parse_args(argv)
    factors = parse_refine(a.refine)
    rule = repeat_rule(a, min_runs=1)
    try:
        frictions = [float(f) for f in a.frictions.split(",")]
    except ValueError:
        raise InputError("--frictions must be comma-separated numbers") from None
    if not all(0.0 <= f < 10.0 for f in frictions):
        raise InputError(f"--frictions must lie in [0, 10), got {a.frictions!r}")
    scenes = a.scenes.split(",")
    for sc in scenes:
        if sc not in SCENES:
            raise InputError(f"--scenes: unknown peer scene {sc!r} (choose from {', '.join(SCENES)})")
    if a.plot is not None:  # before any case runs (each case's plot is drawn after it)
        check_out_dir(a.plot, where="--plot")
    rows = []
    for sc in scenes:
        for mu in frictions:
            for f in factors:
                row = compare(sc, mu, f, repeat=rule)
                if a.plot:
                    os.makedirs(a.plot, exist_ok=True)
                    p = os.path.join(a.plot, f"peer_{sc}_mu{mu:g}" + (f"_r{f:g}" if f != 1.0 else "") + ".png")
                    plot(row, p)
                    row["plot"] = p
                rows.append(row)
    table = format_table(rows)
    print(table, file=sys.stderr)  # for the reader; the JSON on stdout carries it too
    return {"benchmark": "peer", "reference": "IPC (Li et al. 2020) on ipctk", "rows": rows, "table": table}
