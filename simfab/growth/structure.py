"""Structural check of a grown support: does the skin carry its load, and how far does it bend?

Model (linear elastostatics on quadratic tetrahedra):

1. the skin (objects carved out) is tetrahedralized by Gmsh
   (:func:`simfab.growth.tetmesh.tetrahedralize_skin`, edges ``EDGE_PER_RMIN`` r_min) and lifted to
   10-node tets (:func:`simfab.fem.p2.to_p2`), which do not lock in bending;
2. boundary nodes within ``FIX_TOL`` D of a *ground* object (one a root stands on) are clamped;
3. loads: each supported object's weight m g shared among the reached targets that touch it, plus
   each target's ``[loads]`` / ``--load`` force, as a uniform traction F / A on the skin facets near
   the target (:func:`simfab.fem.loads.traction_loads`), and the support's own weight rho g
   (:func:`simfab.fem.loads.body_force_loads`);
4. K u = f on the free dofs, K the Neo-Hookean Hessian at the rest shape (the small-strain
   stiffness), by sparse Cholesky (:class:`simfab.solve.linear.SPDSolver`);
5. stress at every element corner (:func:`corner_stress`): eps = sym(grad u), sigma =
   lambda tr(eps) I + 2 mu eps, sigma_vm = sqrt(3/2 s:s), averaged over a ball of radius
   ``critical_distance`` (:mod:`simfab.design.stress`): sigma_bar_q = sum V_p sigma_p / sum V_p;

and reports the safety factor SF = sigma_yield / max_q sigma_bar_q, where the peak is, each
target's deflection (the traction-weighted mean displacement of its loaded facets) and the mass
rho V. :func:`buckling_factor` adds the linearized buckling load factor, :func:`strengthen`
rescales branch radii until the safety factor reaches a target. Full notes: docs/methods.md,
"simfab.growth.structure".
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.spatial import cKDTree

from simfab.errors import ConvergenceError, InputError
from simfab.fem import elastic
from simfab.fem.loads import body_force_loads, traction_loads
from simfab.fem.model import make_model
from simfab.fem.p2 import P2Model, corner_gradients, to_p2
from simfab.growth.config import StructureConfig
from simfab.growth.contact import ground_objects, load_paths, load_points, require_ground, target_contacts
from simfab.growth.masses import object_masses
from simfab.growth.obstacles import Obstacles
from simfab.growth.scene import GrowthScene
from simfab.growth.skeleton import Skeleton
from simfab.growth.skinning import skin_skeleton
from simfab.growth.tetmesh import tetrahedralize_skin
from simfab.io.mjcf import load_mjcf
from simfab.solve.linear import NotPositiveDefinite, SPDSolver

#: tet edge length as a multiple of the thinnest branch radius (:mod:`simfab.growth.tetmesh`;
#: about two P2 tets across the thinnest branch)
EDGE_PER_RMIN = 2.0
#: clamp band: boundary nodes this fraction of the skin's diagonal from a ground object
FIX_TOL = 2e-3
#: standard gravity [m/s^2] when the scene has no MJCF model to read it from
G0 = 9.81


@dataclasses.dataclass(frozen=True, kw_only=True)
class TargetLoad:
    """Force on one load point (a reached target or a surface contact, :func:`load_points`):
    ``force`` (3,) [N] = ``weight`` (its share of the objects it touches) + ``extra`` ([loads] /
    --load); ``objects`` the touched objects' names (none: the point only reports its deflection);
    ``contact`` its :class:`simfab.growth.contact.TargetContact` (None without a skin)."""

    name: str
    force: np.ndarray
    weight: np.ndarray
    extra: np.ndarray
    objects: tuple
    contact: object = None


@dataclasses.dataclass(frozen=True, kw_only=True)
class DroppedWeight:
    """A supported object whose weight the support does not carry (checked with ``best_effort``):
    ``weight_N`` [N] = m |g|, ``targets`` the load points meant to carry it."""

    object: str
    weight_N: float
    targets: tuple


@dataclasses.dataclass(frozen=True, kw_only=True)
class CheckConfig:
    """Mesh and output options of :func:`check_structure`.

    edge_length : target tet edge length [m] (None: ``EDGE_PER_RMIN`` x the smallest radius).
    segments : joint-sphere resolution of the skin (None: the scene's ``skin.segments``).
    self_weight : include the support's own weight.
    """

    edge_length: float | None = None
    segments: int | None = None
    self_weight: bool = True


@dataclasses.dataclass(frozen=True, kw_only=True)
class StructureCheck:
    """Result of :func:`check_structure` (SI units).

    Args:
        safety_factor: yield stress / max_von_mises_Pa [-].
        max_von_mises_Pa: the peak of the critical-distance mean of the von Mises stress [Pa].
        peak_point: (3,) where it is [m].
        max_point_von_mises_Pa: the largest corner value (unaveraged) [Pa].
        deflection_m: load point name -> |mean displacement of its facets| [m] (every reached target and contact).
        mass_kg, volume_m3: of the support [kg], [m^3].
        loads: the :class:`TargetLoad` per loaded target.
        material_name: the material's name; yield_stress_Pa: its yield stress [Pa].
        critical_distance_m: the radius the stress is averaged over [m].
        model: the P2 model.
        u: (n, 3) displacement of its nodes [m].
        fixed: (n,) bool clamped nodes.
        element_von_mises: (m,) per element the largest averaged corner stress [Pa].
        mesh: the skin (``trimesh.Trimesh``) that was meshed.
        tets, nodes: mesh sizes.
        seconds: wall time of skin, mesh, solve and stress [s].
        points, point_von_mises: (4m, 3) rest positions [m] of the element corners and their averaged stress [Pa].
        contacts: per load point its :class:`simfab.growth.contact.TargetContact`.
        object_masses: supported object -> :class:`simfab.growth.masses.ObjectMass`.
        dropped: object -> :class:`DroppedWeight` (``best_effort`` only).
        gravity: (3,) [m/s^2].
        nodal_forces: (n, 3) the consistent load vector [N].
        mesher: the tet mesher used ("gmsh" or a fallback).
    """

    safety_factor: float
    max_von_mises_Pa: float
    peak_point: np.ndarray
    max_point_von_mises_Pa: float
    deflection_m: dict
    mass_kg: float
    volume_m3: float
    loads: tuple
    material_name: str
    yield_stress_Pa: float
    critical_distance_m: float
    model: P2Model
    u: np.ndarray
    fixed: np.ndarray
    element_von_mises: np.ndarray
    mesh: object
    tets: int
    nodes: int
    seconds: float
    points: np.ndarray
    point_von_mises: np.ndarray
    contacts: tuple = ()
    object_masses: dict = dataclasses.field(default_factory=dict)
    dropped: dict = dataclasses.field(default_factory=dict)
    gravity: np.ndarray | None = None
    nodal_forces: np.ndarray | None = None
    mesher: str = "gmsh"

    def summary(self) -> dict:
        """JSON-ready figures (the ``simfab grow check`` keys).

        Returns:
            A dict of JSON values: the :class:`simfab.growth.results.CheckResult` figures.
        """
        return {
            "safety_factor": self.safety_factor,
            "max_von_mises_Pa": self.max_von_mises_Pa,
            "peak_point_m": [float(v) for v in self.peak_point],
            "max_point_von_mises_Pa": self.max_point_von_mises_Pa,
            "deflection_m": dict(self.deflection_m),
            "max_deflection_m": max(self.deflection_m.values(), default=0.0),
            "mass_kg": self.mass_kg,
            "volume_m3": self.volume_m3,
            "material": self.material_name,
            "yield_stress_Pa": self.yield_stress_Pa,
            "critical_distance_m": self.critical_distance_m,
            "target_forces_N": {ld.name: [float(v) for v in ld.force] for ld in self.loads},
            "targets": {ld.name: {"object": ld.contact.object if ld.contact else None,
                                  "touching": bool(ld.contact.touching) if ld.contact else False,
                                  "gap_m": ld.contact.gap_m if ld.contact else None,
                                  "contact_area_m2": ld.contact.contact_area_m2 if ld.contact else 0.0,
                                  "min_contact_area_m2": ld.contact.min_area_m2 if ld.contact else None,
                                  "load_N": [float(v) for v in ld.force]} for ld in self.loads},
            "supported_objects": {n: {"mass_kg": m.mass_kg, "mass_source": m.source,
                                      "weight_N": float(m.mass_kg * np.linalg.norm(self.gravity))
                                      if self.gravity is not None else None,
                                      "carried_by": [ld.name for ld in self.loads if n in ld.objects]}
                                  for n, m in self.object_masses.items()},
            "dropped_weight_N": {o: d.weight_N for o, d in self.dropped.items()},
            "mesher": self.mesher,
            "tets": self.tets,
            "fem_nodes": self.nodes,
            "seconds_check": self.seconds,
        }


def gravity(scene: GrowthScene) -> np.ndarray:
    """The scene's gravity vector (3,) [m/s^2] (MJCF ``<option gravity>``; (0, 0, -G0) without a file)."""
    if scene.path is None:
        return np.array([0.0, 0.0, -G0])

    return np.asarray(load_mjcf(scene.path).model.opt.gravity, np.float64).copy()


def body_masses(scene: GrowthScene) -> dict:
    """Object name -> mass [kg] (MJCF body masses, MuJoCo's inertia from the geoms' density)."""
    return {n: m.mass_kg for n, m in object_masses(scene).items()}


def validate_loads(scene: GrowthScene) -> dict:
    """The masses of the supported objects (:func:`simfab.growth.contact.supported_objects`):
    object name -> :class:`simfab.growth.masses.ObjectMass`. InputError (naming the MJCF file and
    the body) when one has no mass to load the support with, or when the scene has no MJCF file."""
    from simfab.growth.contact import supported_objects

    sup = supported_objects(scene)
    if not sup:
        return {}
    if scene.path is None:
        raise InputError("the supported objects' masses come from the MJCF model: this scene has no MJCF file",
                         where="scene")
    masses = object_masses(scene)
    for name in sup:
        m = masses.get(name)
        if m is None or not (m.mass_kg > 0 and np.isfinite(m.mass_kg)):
            raise InputError(f"supported object {name!r} has no mass (set mass= or density= on its geoms)",
                             where=f"{scene.path}: body {name} mass")
    return {n: masses[n] for n in sup}


def target_loads(scene: GrowthScene, skeleton: Skeleton, extra: dict | None = None, *, contacts=None) -> tuple:
    """The force on every load point of :func:`load_points` (see :class:`TargetLoad`): each
    supported object's weight shared equally among the points touching it
    (:func:`simfab.growth.contact.target_contacts`; ``contacts`` those of the skeleton's skin,
    computed from a fresh skin when None), plus ``extra`` (target name -> (3,) [N]; the scene's
    ``[loads]`` when None). InputError when an extra load names an unreached target."""
    extra = dict(scene.structure.loads) if extra is None else dict(extra)
    points = load_points(skeleton)
    missing = [n for n in extra if n not in points]
    if missing:
        raise InputError(f"load on target(s) {', '.join(missing)} that the support does not reach "
                         f"(reached: {', '.join(points)})", where="loads")
    if contacts is None:
        p = scene.params
        mesh, _ = skin_skeleton(skeleton.nodes, skeleton.parent, skeleton.radius, scene.objects,
                                fixed=skeleton.fixed_mask(), segments=p.skin_segments, subtract=p.subtract_objects)
        contacts = target_contacts(mesh, skeleton, scene)
    g = gravity(scene)
    mass = body_masses(scene)
    paths = load_paths(scene, contacts, mass)
    by_name = {c.name: c for c in contacts}
    out = []
    for t in points:
        objs = tuple(o for o, ts in paths.carriers.items() if t in ts)
        w = sum((mass.get(o, 0.0) * g / len(paths.carriers[o]) for o in objs), np.zeros(3))
        e = np.asarray(extra.get(t, (0.0, 0.0, 0.0)), np.float64)
        out.append(TargetLoad(name=t, force=w + e, weight=w, extra=e, objects=objs, contact=by_name.get(t)))
    return tuple(out)


def check_structure(skeleton: Skeleton, scene: GrowthScene, *, loads: dict | None = None,
                    options: CheckConfig = CheckConfig(), spec: StructureConfig | None = None,
                    best_effort: bool = False) -> StructureCheck:
    """Skin, mesh, load and solve the support ``skeleton`` grown in ``scene`` (module docstring).

    Args:
        skeleton: the support. scene: the scene it was grown in.
        loads: extra target forces name -> (3,) [N] replacing the scene's ``[loads]`` (None: keep).
        options: mesh options. spec: material and critical distance (None: the scene's ``[material]``).
        best_effort: check a support that leaves a supported object's weight without a load path
            (reported under ``dropped``) instead of raising.

    Returns:
        :class:`StructureCheck`. Raises InputError when a supported object has no mass,
        ConvergenceError when a supported object's weight has no load path (unless ``best_effort``).
    """
    t0 = time.perf_counter()
    spec = scene.structure if spec is None else spec
    mat = spec.material
    masses = validate_loads(scene)
    p = scene.params
    mesh, _ = skin_skeleton(skeleton.nodes, skeleton.parent, skeleton.radius, scene.objects,
                            fixed=skeleton.fixed_mask(), segments=options.segments or p.skin_segments,
                            subtract=p.subtract_objects)
    contacts = target_contacts(mesh, skeleton, scene)
    g = gravity(scene)
    paths = load_paths(scene, contacts, {n: m.mass_kg for n, m in masses.items()})
    dropped = {o: DroppedWeight(object=o, weight_N=float(masses[o].mass_kg * np.linalg.norm(g)), targets=tuple(ts))
               for o, ts in paths.dropped.items()}
    if dropped and not best_effort:
        o, d = next(iter(dropped.items()))
        gaps = {c.name: c.gap_m for c in contacts}
        detail = ", ".join(f"{t} (gap {gaps[t] * 1e3:.3g} mm)" if t in gaps else f"{t} (unreached)" for t in d.targets)
        raise ConvergenceError(f"the support carries none of {o}'s weight ({d.weight_N:.3g} N): no target touches "
                               f"it: {detail}; regrow the support or pass --best-effort to check it without that load")
    tl = target_loads(scene, skeleton, loads, contacts=contacts)
    r_min = float(skeleton.radius.min())
    h = options.edge_length if options.edge_length is not None else EDGE_PER_RMIN * r_min
    diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    tm = tetrahedralize_skin(mesh, edge_length=h, r_min=r_min)
    model = to_p2(make_model(tm.vertices, tm.tets, mat))
    X = model.rest
    fixed = _clamped(model, scene, FIX_TOL * diag)
    f = np.zeros_like(X)
    if options.self_weight:
        f += body_force_loads(model, lambda Xq: np.broadcast_to(mat.density * g, Xq.shape))
    share = {}
    tnode = load_points(skeleton)
    for ld in tl:
        i = tnode[ld.name]
        w = _patch_weights(model, skeleton.nodes[i], float(skeleton.radius[i]),
                           scene.objects[ld.contact.object] if ld.objects else None)
        share[ld.name] = w
        f += w[:, None] * ld.force[None, :]
    u = _solve(model, fixed, f)
    x = X + u
    _, vm = corner_stress(model, x)
    cells = X[model.corner_elements].reshape(-1, 3)
    avg = ball_mean(cells, np.repeat(np.abs(model.volume) / 4.0, 4), vm.ravel(), spec.critical_distance)
    k = int(np.argmax(avg))
    peak = float(avg[k])
    defl = {name: float(np.linalg.norm(w @ u)) for name, w in share.items()}
    vol = float(mesh.volume)
    return StructureCheck(
        safety_factor=float(mat.yield_stress / peak) if peak > 0 else float("inf"),
        max_von_mises_Pa=peak, peak_point=cells[k].copy(), max_point_von_mises_Pa=float(vm.max()),
        deflection_m=defl, mass_kg=mat.density * vol, volume_m3=vol, loads=tl, material_name=mat.name,
        yield_stress_Pa=mat.yield_stress, critical_distance_m=spec.critical_distance, model=model, u=u,
        fixed=fixed, element_von_mises=avg.reshape(vm.shape).max(axis=1), mesh=mesh, tets=int(model.n_elements),
        nodes=int(model.n_vertices), seconds=time.perf_counter() - t0, points=cells, point_von_mises=avg,
        contacts=contacts, object_masses=masses, dropped=dropped, gravity=g, nodal_forces=f, mesher=tm.mesher)


def geometric_stiffness(model: P2Model, sigma_corners: np.ndarray):
    """Geometric (stress) stiffness K_G (3n, 3n) [N/m] of the stress field with corner values
    ``sigma_corners`` (m, 4, 3, 3) [Pa] (affine over each element):

        K_G[3a+i, 3b+j] = delta_ij sum_e sum_q w_eq grad N_a(X_q) . sigma(X_q) grad N_b(X_q),

    the second variation of sum_e int sigma : (1/2) grad u^T grad u, with the model's quadrature
    (exact for these products: P2 gradients are linear, sigma is linear)."""
    import scipy.sparse as sp

    sq = np.einsum("qc,mcij->mqij", model.qp_bary, sigma_corners)
    gN = np.asarray(model.grad_N)
    Ge = np.einsum("mq,mqai,mqij,mqbj->mab", np.asarray(model.qp_weight), gN, sq, gN)
    el = np.asarray(model.elements, np.int64)
    k = el.shape[1]
    rows = np.repeat(el[:, :, None], k, axis=2)
    cols = np.repeat(el[:, None, :], k, axis=1)
    n = model.n_vertices
    parts = [sp.coo_matrix((Ge.ravel(), (3 * rows.ravel() + d, 3 * cols.ravel() + d)), shape=(3 * n, 3 * n))
             for d in range(3)]
    return (parts[0] + parts[1] + parts[2]).tocsr()


def buckling_factor(check: StructureCheck) -> float:
    """Linearized buckling: the smallest load factor lambda > 0 with (K + lambda K_G) phi = 0 on
    the free dofs, K the small-strain stiffness and K_G the geometric stiffness of the checked
    stress state (:func:`geometric_stiffness`). Solved as the largest theta of -K_G phi = theta K
    phi (K SPD), lambda = 1 / theta; inf when nothing is compressed (theta <= 0). The loads times
    lambda are the critical loads (slender supports fail by buckling before they yield)."""
    from scipy.sparse.linalg import eigsh

    m = check.model
    _, _, K = elastic.energy_gradient_hessian(m, m.rest, project_psd=False)
    sigma, _ = corner_stress(m, m.rest + check.u)
    free = np.nonzero(np.repeat(~check.fixed, 3))[0]
    Kf = K[free][:, free].tocsc()
    G = (-geometric_stiffness(m, sigma))[free][:, free].tocsc()
    theta = eigsh(G, k=1, M=Kf, which="LA", return_eigenvectors=False, tol=1e-8)[0]
    return float(1.0 / theta) if theta > 0 else float("inf")


def _clamped(model: P2Model, scene: GrowthScene, band: float) -> np.ndarray:
    """(n,) bool: boundary nodes within ``band`` [m] of a ground object's surface."""
    ground = require_ground(scene)
    fixed = np.zeros(model.n_vertices, bool)
    b = np.asarray(model.boundary_vertices)
    for name in ground:
        m = scene.objects[name]
        lo, hi = m.bounds
        near = b[np.all((model.rest[b] >= lo - band) & (model.rest[b] <= hi + band), axis=1)]
        if near.size:
            _, d, _ = m.nearest.on_surface(model.rest[near])
            fixed[near[d <= band]] = True
    if fixed.sum() < 3:
        raise ConvergenceError("the support's skin does not meet the object under its roots: nothing to clamp")
    return fixed


def _patch_weights(model: P2Model, point: np.ndarray, radius: float, obj=None) -> np.ndarray:
    """(n,) nodal weights summing to 1 of a uniform traction on the boundary facets whose
    centroid lies within ``radius`` [m] of ``point`` (at least the 3 nearest facets); with the
    touched object ``obj`` (``trimesh.Trimesh``), on the contact patch instead: the facets within
    the contact reach (:mod:`simfab.growth.contact`) whose corners lie on its surface."""
    from simfab.growth.contact import GAP_PER_R

    c = model.rest[model.boundary_facets[:, :3]].mean(axis=1)
    d = np.linalg.norm(c - point, axis=1)
    on = d <= radius
    if obj is not None:
        _, dist, _ = obj.nearest.on_surface(point[None])
        cand = np.nonzero(d <= float(dist[0]) + 2.0 * radius)[0]
        if len(cand):
            corners = model.boundary_facets[cand, :3]
            _, dv, _ = obj.nearest.on_surface(model.rest[corners.ravel()])
            patch = np.zeros(len(c), bool)
            patch[cand[np.all(dv.reshape(-1, 3) <= GAP_PER_R * radius, axis=1)]] = True
            if patch.sum() >= 3:
                on = patch
    if on.sum() < 3:
        on = np.zeros(len(c), bool)
        on[np.argsort(d)[:3]] = True
    w = traction_loads(model, on, np.array([1.0, 0.0, 0.0]))[:, 0]
    return w / w.sum()


def _solve(model: P2Model, fixed: np.ndarray, f: np.ndarray) -> np.ndarray:
    """u (n, 3) [m] of K u = f on the free nodes (u = 0 on the fixed ones), K the rest stiffness."""
    _, _, K = elastic.energy_gradient_hessian(model, model.rest, project_psd=False)
    free = np.repeat(~fixed, 3)
    idx = np.nonzero(free)[0]
    u = np.zeros(model.n_dofs)
    try:
        u[idx] = SPDSolver().solve_free(K, idx, f.ravel()[idx])
    except NotPositiveDefinite:
        raise ConvergenceError("the stiffness is singular: part of the support is not connected to the clamped "
                               "ground (a floating body)") from None
    if not np.all(np.isfinite(u)):
        raise ConvergenceError("the static solve returned non-finite displacements")
    return u.reshape(-1, 3)


def corner_stress(model: P2Model, x) -> tuple[np.ndarray, np.ndarray]:
    """Small-strain stress at the corners of every element, positions ``x`` (n, 3) [m]: F_c =
    :func:`simfab.fem.p2.corner_gradients`, eps = sym(F_c) - I, sigma = lambda tr(eps) I + 2 mu eps.
    Returns (Cauchy stress (m, 4, 3, 3) [Pa], von Mises (m, 4) [Pa]). The stress is affine over a
    P2 element and the von Mises stress a norm of it, so its largest value over the element is at
    a corner: corners sample the extremes of the discrete field (on the surface, where bending
    stress peaks), which quadrature points, inside the element, would miss."""
    F = corner_gradients(model, x)
    eps = 0.5 * (F + np.swapaxes(F, -1, -2)) - np.eye(3)
    tr = np.einsum("mqii->mq", eps)
    mu = np.asarray(model.mu)[:, None, None, None]
    lam = np.asarray(model.lam)[:, None, None, None]
    sigma = lam * tr[..., None, None] * np.eye(3) + 2.0 * mu * eps
    s = sigma - np.einsum("mqii->mq", sigma)[..., None, None] / 3.0 * np.eye(3)
    return sigma, np.sqrt(1.5 * np.einsum("mqij,mqij->mq", s, s))


def ball_mean(points: np.ndarray, weights: np.ndarray, values: np.ndarray, radius: float) -> np.ndarray:
    """(k,) sum_{|p_j - p_i| <= radius} w_j v_j / sum w_j over cells at ``points`` (k, 3) [m]
    (radius 0: the values themselves)."""
    v = np.asarray(values, np.float64).ravel()
    if not radius > 0:
        return v.copy()
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    num = weights * v
    den = np.asarray(weights, np.float64).copy()
    np.add.at(num, pairs[:, 0], weights[pairs[:, 1]] * v[pairs[:, 1]])
    np.add.at(num, pairs[:, 1], weights[pairs[:, 0]] * v[pairs[:, 0]])
    np.add.at(den, pairs[:, 0], weights[pairs[:, 1]])
    np.add.at(den, pairs[:, 1], weights[pairs[:, 0]])
    return num / den


@dataclasses.dataclass(frozen=True, kw_only=True)
class StrengthenResult:
    """Outcome of :func:`strengthen`.

    Args:
        skeleton: the final skeleton.
        check: its :class:`StructureCheck`.
        target: the safety factor asked for [-].
        history: one (safety factor [-], volume [m^3]) per check run, the first the input's (a
            thinning round that fell below the target is listed but not kept).
        reached: whether the final safety factor is at least ``target``.
    """

    skeleton: Skeleton
    check: StructureCheck
    target: float
    history: tuple
    reached: bool

    def summary(self) -> dict:
        """The strengthening's figures (the ``strengthened`` keys of ``simfab grow check --json``).

        Returns:
            A dict: target_safety_factor, reached, checks, safety factors before/after [-], volumes
            before/after [m^3], volume_change [-].
        """
        sf0, v0 = self.history[0]
        sf1, v1 = self.check.safety_factor, self.check.volume_m3
        return {"target_safety_factor": self.target, "reached": self.reached, "checks": len(self.history),
                "safety_factor_before": sf0, "safety_factor_after": sf1, "volume_before_m3": v0,
                "volume_after_m3": v1, "volume_change": v1 / v0 - 1.0 if v0 > 0 else 0.0}


#: strengthening: the radius factor is the cube root of the stress ratio (bending stress of a
#: round bar ~ M / r^3) times this margin, so that one re-check usually suffices
STRENGTHEN_MARGIN = 1.05
#: thinning lowers a radius by at most this factor per round (stress redistributes as it thins)
THIN_STEP = 0.7


def node_stress(skeleton: Skeleton, check: StructureCheck) -> np.ndarray:
    """(n,) per skeleton node the largest critical-distance mean stress [Pa] of the element corners
    nearest to it (nodes no corner is nearest to take their neighbours' largest)."""
    n = len(skeleton.nodes)
    _, j = cKDTree(skeleton.nodes).query(check.points, k=1)
    s = np.zeros(n)
    np.maximum.at(s, j, check.point_von_mises)
    e = skeleton.edges
    for _ in range(4):  # fill gaps along the chains
        empty = s <= 0
        if not empty.any() or len(e) == 0:
            break
        t = np.zeros(n)
        np.maximum.at(t, e[:, 0], s[e[:, 1]])
        np.maximum.at(t, e[:, 1], s[e[:, 0]])
        s[empty] = t[empty]
    return s


def radius_caps(skeleton: Skeleton, scene: GrowthScene) -> np.ndarray:
    """(n,) largest radius [m] each node may take: the distance to the nearest obstacle sphere's
    surface, and for nodes off the object surfaces the distance to the supported objects (never
    below the current radius), so that thickening stays clear of obstacles and does not fill the
    space between the support and an object it does not touch there. Ground objects (under the
    roots) do not cap: a root thickened into the ground is carved flat and clamped over a larger
    face, which is what a root needs."""

    X = skeleton.nodes
    cap = np.full(len(X), np.inf)
    if len(scene.sphere_radii):
        d = np.linalg.norm(X[:, None, :] - scene.sphere_centers[None], axis=2) - scene.sphere_radii[None]
        cap = np.minimum(cap, d.min(axis=1))
    off = ~skeleton.on_surface_mask()
    ground = set(ground_objects(scene))
    held = [m for n, m in scene.objects.items() if n not in ground]
    if held and off.any():
        obs = Obstacles(held, np.zeros((0, 3)), np.zeros(0), end_trim=0.0)
        _, d = obs.surface_distance(X[off])
        cap[off] = np.minimum(cap[off], d)
    return np.maximum(cap, skeleton.radius)


def strengthen(skeleton: Skeleton, scene: GrowthScene, target: float, *, loads: dict | None = None,
               options: CheckConfig = CheckConfig(), spec: StructureConfig | None = None, thin: bool = False,
               rounds: int = 5, check: StructureCheck | None = None, best_effort: bool = False) -> StrengthenResult:
    """Scale branch radii until the safety factor is at least ``target`` (topology unchanged).

    Each round: the allowed stress sigma_a = yield / target; each node's stress s_i
    (:func:`node_stress`); nodes with s_i > sigma_a get r_i *= STRENGTHEN_MARGIN (s_i /
    sigma_a)^(1/3) (a round bar's bending stress ~ 1/r^3), spread to their neighbours (a
    branch thickens around its overloaded spot, not in a bead); with ``thin``, nodes with s_i <
    sigma_a / STRENGTHEN_MARGIN get r_i *= max(THIN_STEP, (s_i STRENGTHEN_MARGIN / sigma_a)^(1/3)),
    never below the input's thinnest radius (the growth's printable minimum); radii are capped
    by :func:`radius_caps`; then re-skin and re-check. Stops when the target is met (and, with
    ``thin``, when no node is over-strong or nothing changes), or after ``rounds`` rounds.
    """
    if not (target > 0 and np.isfinite(target)):
        raise InputError(f"the safety factor to reach must be a positive number, got {target}", where="--strengthen")
    spec = scene.structure if spec is None else spec
    sigma_a = spec.material.yield_stress / target
    c = check if check is not None else check_structure(skeleton, scene, loads=loads, options=options, spec=spec,
                                                         best_effort=best_effort)
    history = [(c.safety_factor, c.volume_m3)]
    r_floor = float(skeleton.radius.min())
    caps = radius_caps(skeleton, scene)
    sk = skeleton
    for _ in range(rounds):
        s = node_stress(sk, c)
        k = np.ones(len(s))
        over = s > sigma_a
        k[over] = STRENGTHEN_MARGIN * (s[over] / sigma_a) ** (1.0 / 3.0)
        e = sk.edges
        if len(e):  # spread to the neighbours
            up = k.copy()
            np.maximum.at(up, e[:, 0], k[e[:, 1]])
            np.maximum.at(up, e[:, 1], k[e[:, 0]])
            k = np.where(up > 1.0, up, k)
        if thin:
            low = (k <= 1.0) & (s < sigma_a / STRENGTHEN_MARGIN)
            k[low] = np.maximum(THIN_STEP, (np.maximum(s[low], 0.0) * STRENGTHEN_MARGIN / sigma_a) ** (1.0 / 3.0))
        r = np.minimum(np.maximum(sk.radius * k, np.minimum(r_floor, sk.radius)), caps)
        if c.safety_factor >= target and not (thin and np.any(r < sk.radius * (1 - 1e-3))):
            break
        if np.allclose(r, sk.radius, rtol=1e-3):
            break
        cand = sk.replace(radius=r)
        cc = check_structure(cand, scene, loads=loads, options=options, spec=spec, best_effort=best_effort)
        history.append((cc.safety_factor, cc.volume_m3))
        if thin and cc.safety_factor < target <= c.safety_factor:
            break  # thinning went too far: keep the last design that met the target
        sk, c = cand, cc
    return StrengthenResult(skeleton=sk, check=c, target=float(target), history=tuple(history),
                            reached=bool(c.safety_factor >= target))
