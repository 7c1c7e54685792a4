"""The growth pipeline: attractors → colonization (per stage) → pruning → smoothing → radii.

:func:`grow` mirrors ``simfab grow SCENE``; :func:`skin_result` turns its skeleton into a
printable mesh.

Symmetric growth
----------------
The thesis makes a design mirror-symmetric by placing the attractors symmetrically. With a
symmetric tree, an attractor on one side of the plane is always at least as close to the
mirror images of the nodes on its side as to any node on the other side, so each half of
the tree only ever sees the attractors of its own half. We therefore grow the positive
half (attractors, targets and roots with signed distance >= 0, roots on the plane nudged
by δ to the positive side, the "split root" of the thesis) and mirror it: the result is
exactly symmetric, and the two nudged roots lie 2δ < 2 r_max apart, so their joint spheres
fuse the halves into one solid.
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

import simfab.growth.attractors as attr
import simfab.growth.tolerances as tol
from simfab.errors import InputError
from simfab.growth.colonize import ColonizeConfig, Tree, colonize
from simfab.growth.config import Resolved, SymmetryConfig, resolve
from simfab.growth.contact import aim_targets
from simfab.growth.obstacles import Obstacles
from simfab.growth.scene import GrowthScene, load_growth_scene, validate_scene
from simfab.growth.skeleton import Skeleton, keep_ancestors, radius_by_age, smooth_positions, subset
from simfab.growth.skinning import skin_skeleton

#: root nudge off the symmetry plane, as a fraction of r_max (must stay < 1 to fuse halves)
ROOT_SPLIT = 0.25


@dataclasses.dataclass
class Growth:
    """Everything one growth run produced.

    Args:
        scene: the problem.
        resolved: the distances actually used.
        seed: RNG seed.
        attractors: (m, 3) all random attractors placed (both halves when symmetric) [m].
        attractor_death_step: (m,) growth step at which each attractor died (-1: never).
        history: unpruned tree (replay of the growth; node births are growth steps).
        pruned: skeleton after pruning (before smoothing).
        skeleton: final skeleton with radii.
        reports: one :class:`ColonizeReport` per stage.
        targets_reached, targets_unreached: target names.
        seconds_growth: wall time of placement + colonization + pruning + smoothing [s].
        symmetric: grown with mirror symmetry.
    """

    scene: GrowthScene
    resolved: Resolved
    seed: int
    attractors: np.ndarray
    attractor_death_step: np.ndarray
    history: Tree
    pruned: Skeleton
    skeleton: Skeleton
    reports: list
    targets_reached: list
    targets_unreached: list
    seconds_growth: float
    symmetric: bool = False

    @property
    def steps(self) -> int:
        return int(sum(r.steps for r in self.reports))

    def summary(self) -> dict:
        """The growth's figures (the growth keys of ``simfab grow --json``).

        Returns:
            A dict of JSON values (counts, distances [m], seconds_growth [s]).
        """
        sk = self.skeleton
        return {
            "scene": str(self.scene.path) if self.scene.path else self.scene.name,
            "mode": self.scene.params.mode,
            "symmetric": self.symmetric,
            "seed": self.seed,
            "attractors": len(self.attractors),
            "influence": self.resolved.influence,
            "kill": self.resolved.kill,
            "branch_length": self.resolved.branch_length,
            "steps": self.steps,
            "stop_reasons": [r.stop_reason for r in self.reports],
            "targets_total": len(self.scene.targets),
            "targets_reached": len(self.targets_reached),
            "targets_unreached": list(self.targets_unreached),
            "nodes": len(sk.nodes),
            "segments": int(np.sum(sk.parent >= 0)),
            "nodes_grown": len(self.history),
            "collisions_resolved": int(sum(r.collisions_resolved for r in self.reports)),
            "collisions_unresolved": int(sum(r.collisions_unresolved for r in self.reports)),
            "dead_ends": int(sum(r.dead_ends for r in self.reports)),
            "dropped_oscillating": int(sum(r.dropped_oscillating for r in self.reports)),
            "seconds_growth": self.seconds_growth,
        }


def as_scene(scene_or_path) -> GrowthScene:
    """A validated :class:`GrowthScene` from a scene or an MJCF path (InputError otherwise)."""
    if isinstance(scene_or_path, GrowthScene):
        validate_scene(scene_or_path)
        return scene_or_path
    if isinstance(scene_or_path, (str, os.PathLike)):
        return load_growth_scene(scene_or_path)
    raise InputError(f"expected a scene path or GrowthScene, got {type(scene_or_path).__name__}")


def grow(scene_or_path, *, seed: int | None = None, symmetric: bool | None = None, **overrides) -> Growth:
    """Grow a support structure for a scene. Same seed → identical result.

    Args:
        scene_or_path: the MJCF path, a bundled scene's name or a :class:`GrowthScene`.
        seed: the growth's seed (None: the scene's).
        symmetric: True enables mirror symmetry (plane from the scene's [symmetry] table, else the
            plane x = mean root x); None keeps the scene's setting.
        **overrides: :class:`simfab.growth.config.GrowthSceneConfig` fields (``attractors``, ``influence``,
            ``kill``, ``branch_length``, ``mode``, ...; None = keep).

    Returns:
        The :class:`Growth` (skeletons, attractors, history, reports).
    """
    scene = as_scene(scene_or_path)
    if overrides:  # checked (unknown names too) by GrowthSceneConfig.replace
        scene = scene.with_params(**overrides)
        validate_scene(scene)
    p = scene.params
    if symmetric and p.symmetry is None:
        plane = SymmetryConfig(point=tuple(scene.roots.mean(axis=0)), normal=(1.0, 0.0, 0.0))
        scene = scene.with_params(symmetry=plane)
        p = scene.params
    if symmetric is False:
        scene = dataclasses.replace(scene, params=dataclasses.replace(p, symmetry=None))
        p = scene.params
    seed = p.seed if seed is None else int(seed)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()

    box = np.asarray(p.box, np.float64) if p.box is not None else scene.objects_bbox()
    diag = float(np.linalg.norm(box[1] - box[0]))
    obstacles = Obstacles.of_scene(scene, diag)

    # design-space size for the default distances
    area = None
    if p.mode == "surface":
        _, area = attr.surface(_surface_meshes(scene), max(p.attractors, 500), np.random.default_rng(seed),
                               None, lift=0.0, box=np.asarray(p.box) if p.box is not None else None)
    elif p.mode == "profile":
        _, area = attr.profile(p.profile, p.attractors, np.random.default_rng(seed), obstacles)
    res = resolve(p, box, area=area)
    # targets off their object by more than half the thinnest branch: grow onto its surface instead
    scene = aim_targets(scene, min_offset=0.5 * res.r_min)

    sym = _Symmetry(scene, diag) if p.symmetry is not None else None
    keep = sym.keep if sym else None

    roots = sym.half_roots(res) if sym else scene.roots
    target_ok = sym.half_targets() if sym else np.ones(len(scene.targets), bool)
    stages = _stages(scene)
    settings = ColonizeConfig(influence=res.influence, kill=res.kill, branch_length=res.branch_length,
                                target_influence=p.target_influence, max_steps=res.max_steps,
                                max_nodes=p.max_nodes, max_trials=p.max_trials)

    tree = Tree.from_roots(roots)
    history = None
    reports, placed = [], []
    steps = 0
    for stage_targets in stages:
        A = _place(scene, res, rng, obstacles, box, keep)
        placed.append(A)
        ids = np.array([i for i in stage_targets if target_ok[i]], np.int64)
        rep = colonize(tree, A, scene.targets[ids], ids, obstacles, settings, rng, step0=steps)
        steps += rep.steps
        reports.append(rep)
        history = _merge_history(history, tree)
        tree = _prune(tree, scene, res, obstacles, p.mode)
    A_all = np.concatenate(placed)
    death = np.concatenate([r.attractor_death_step for r in reports])

    sk = _skeleton(tree, scene, res, steps)
    pruned = sk
    V = smooth_positions(sk.nodes, sk.edges, sk.fixed_mask(), lambda1=p.lambda1, lambda2=p.lambda2,
                         iterations=p.smoothing_iterations, obstacles=obstacles, on_surface=sk.on_surface_mask())
    sk = sk.replace(nodes=V)
    if sym:
        pruned = sym.mirror(pruned, obstacles=None)
        sk = sym.mirror(sk, obstacles=obstacles)
        history = sym.mirror_tree(history)
        A_all = np.concatenate([A_all, sym.reflect(A_all)])
        death = np.concatenate([death, death])
    reached_ids = sorted(set(int(t) for t in sk.target[sk.target >= 0]))
    reached = [scene.target_names[i] for i in reached_ids]
    unreached = [n for i, n in enumerate(scene.target_names) if i not in set(reached_ids)]
    return Growth(scene=scene, resolved=res, seed=seed, attractors=A_all, attractor_death_step=death,
                        history=history, pruned=pruned,
                        skeleton=sk, reports=reports, targets_reached=reached, targets_unreached=unreached,
                        seconds_growth=time.perf_counter() - t0, symmetric=sym is not None)


def _stages(scene: GrowthScene) -> list[list[int]]:
    """Target indices per stage (one stage with every target unless [stages] is given).

    Stages are cumulative: a target of an earlier stage stays a target later on.
    """
    if scene.params.stages is None:
        return [list(range(len(scene.targets)))]
    index = {n: i for i, n in enumerate(scene.target_names)}
    out, acc = [], []
    for st in scene.params.stages.targets:
        acc = acc + [index[n] for n in st if index[n] not in acc]
        out.append(list(acc))
    listed = set(acc)
    rest = [i for i in range(len(scene.targets)) if i not in listed]
    if rest:  # targets not named in any stage grow in a last stage
        out.append(acc + rest)
    return out


def _surface_meshes(scene: GrowthScene) -> list:
    names = scene.params.surface_objects or tuple(scene.objects)
    return [scene.objects[n] for n in names]


def _place(scene, res: Resolved, rng, obstacles, box, keep) -> np.ndarray:
    """Random attractors for one stage, in the mode's design space (outside obstacles)."""
    p = scene.params
    n = p.attractors
    if p.mode == "volume":
        return attr.volume(box, n, rng, obstacles, keep=keep)[0]
    if p.mode == "surface":
        return attr.surface(_surface_meshes(scene), n, rng, obstacles, lift=tol.SURFACE_LIFT * res.kill,
                            box=np.asarray(p.box) if p.box is not None else None, keep=keep)[0]
    return attr.profile(p.profile, n, rng, obstacles, keep=keep)[0]


def _merge_history(history: Tree | None, tree: Tree) -> Tree:
    """Append the nodes grown in the last stage to the replay history."""
    if history is None:
        return tree.copy()
    # nodes of `tree` born after the last history step are new this stage
    last = int(history.birth.max()) if len(history) else 0
    new = np.nonzero(tree.birth > last)[0]
    if new.size == 0:
        return history
    # map tree indices -> history indices: old (pruned) nodes are found by position
    from scipy.spatial import cKDTree

    old = np.nonzero(tree.birth <= last)[0]
    mapping = np.full(len(tree), -1, np.int64)
    if old.size:
        _, j = cKDTree(history.nodes).query(tree.nodes[old])
        mapping[old] = j
    mapping[new] = len(history) + np.arange(new.size)
    return history.concat(tree.take(new, parent=mapping[tree.parent[new]]))


def _contacts(tree: Tree, scene, res: Resolved, obstacles) -> np.ndarray:
    """Surface mode: leaves near an object surface, snapped onto it (positions updated in place)."""
    n = len(tree)
    has_child = np.zeros(n, bool)
    has_child[tree.parent[tree.parent >= 0]] = True
    leaves = np.nonzero(~has_child & (tree.parent >= 0) & (tree.target < 0))[0]
    if leaves.size == 0 or obstacles.mesh is None:
        return np.zeros(0, np.int64)
    meshes = _contact_meshes(scene, obstacles)
    if not meshes:
        return np.zeros(0, np.int64)
    surf = Obstacles(meshes, np.zeros((0, 3)), np.zeros(0), end_trim=obstacles.end_trim)
    c, d = surf.surface_distance(tree.nodes[leaves])
    near = d <= tol.CONTACT_FACTOR * res.kill
    leaves, c = leaves[near], c[near]
    if leaves.size == 0:
        return leaves
    free = ~obstacles.segment_hits(tree.nodes[tree.parent[leaves]], c, None, np.ones(len(c), bool))
    tree.nodes[leaves[free]] = c[free]
    tree.contact[leaves[free]] = True
    return leaves


def _contact_meshes(scene, obstacles) -> list:
    """Surface mode: the sampled objects except those a root stands on (the ground): a branch
    that ends on the ground supports nothing."""
    out = []
    for name in scene.params.surface_objects or tuple(scene.objects):
        m = scene.objects[name]
        _, d, _ = m.nearest.on_surface(scene.roots)
        if not np.any(d <= tol.GROUND_CONTACT * float(np.linalg.norm(m.extents))):
            out.append(m)
    return out


def _prune(tree: Tree, scene, res: Resolved, obstacles, mode: str) -> Tree:
    """Keep only the branches leading to a reached target (or, in surface mode, a surface contact)."""
    anchors = np.nonzero(tree.target >= 0)[0]
    if mode == "surface":
        anchors = np.union1d(anchors, _contacts(tree, scene, res, obstacles))
    keep = keep_ancestors(tree.parent, anchors)
    keep[tree.parent < 0] = True  # roots stay (growth of later stages starts there)
    idx, par = subset(tree.parent, keep)
    # dead ends may grow again in a later stage; targets stay tips
    return tree.take(idx, parent=par, frozen=tree.target[idx] >= 0)


def node_age(birth: np.ndarray, convention: str, last_step: int) -> np.ndarray:
    """Age α per node for the radius law: ``front`` → birth step; ``since_birth`` → last step − birth."""
    b = np.asarray(birth, np.int64)
    return b if convention == "front" else np.maximum(last_step - b, 0)


def node_radius(birth: np.ndarray, convention: str, last_step: int, res: Resolved) -> np.ndarray:
    """(n,) skin radius [m] per node: :func:`radius_by_age` at the age :func:`node_age` gives."""
    return radius_by_age(node_age(birth, convention, last_step), res.r_min, res.r_max, res.radius_decay)


def _skeleton(tree: Tree, scene, res: Resolved, last: int) -> Skeleton:
    """Skeleton with radii by age (``last`` = final growth step); roots that grew nothing are dropped."""
    has_child = np.zeros(len(tree), bool)
    has_child[tree.parent[tree.parent >= 0]] = True
    keep = (tree.parent >= 0) | has_child
    if not keep.any():
        keep[:] = True
    idx, par = subset(tree.parent, keep)
    return Skeleton(nodes=tree.nodes[idx].copy(), parent=par, birth=tree.birth[idx], target=tree.target[idx],
                    root=tree.root[idx], radius=node_radius(tree.birth[idx], scene.params.radius_age, last, res),
                    contact=tree.contact[idx],
                    target_names=tuple(scene.target_names))


class _Symmetry:
    """Half-space bookkeeping for mirror-symmetric growth (see the module docstring)."""

    def __init__(self, scene: GrowthScene, diag: float):
        s = scene.params.symmetry
        self.p0 = np.asarray(s.point, np.float64)
        self.n = np.asarray(s.normal, np.float64) / np.linalg.norm(s.normal)
        self.scene = scene
        self.on_plane = tol.ON_PLANE_TOL * diag
        where = f"{scene.path}: symmetry" if scene.path else "symmetry"
        # targets and roots must come in mirror pairs (or lie on the plane)
        self.target_mirror = self._pairs(scene.targets, "target", where)
        self._pairs(scene.roots, "root", where)

    def _pairs(self, X, what, where) -> np.ndarray:
        if len(X) == 0:
            return np.zeros(0, np.int64)
        R = self.reflect(X)
        d = np.linalg.norm(R[:, None, :] - X[None, :, :], axis=2)
        j = np.argmin(d, axis=1)
        bad = d[np.arange(len(X)), j] > self.on_plane
        if bad.any():
            raise InputError(f"{what} sites are not mirror-symmetric about the plane (no mirror partner for "
                             f"{int(bad.sum())} of them)", where=where)
        return j

    def signed(self, X) -> np.ndarray:
        return (np.asarray(X) - self.p0) @ self.n

    def reflect(self, X) -> np.ndarray:
        X = np.asarray(X, np.float64)
        return X - 2.0 * self.signed(X)[..., None] * self.n

    def keep(self, X) -> np.ndarray:
        return self.signed(X) >= 0.0

    def half_targets(self) -> np.ndarray:
        return self.signed(self.scene.targets) >= -self.on_plane

    def half_roots(self, res: Resolved) -> np.ndarray:
        R = self.scene.roots
        d = self.signed(R)
        out = []
        for r, di in zip(R, d):
            if abs(di) <= self.on_plane:
                out.append(r + (ROOT_SPLIT * res.r_max - di) * self.n)  # split root: nudge to the + side
            elif di > 0:
                out.append(r)
        return np.array(out).reshape(-1, 3)

    def _image(self, nodes, parent, target, root) -> dict:
        """Per-node fields of the mirror image of a forest appended after its ``len(nodes)``
        nodes: reflected positions, shifted parents and roots, targets renamed to their partners."""
        return dict(nodes=self.reflect(nodes), parent=np.where(parent >= 0, parent + len(nodes), -1),
                    target=np.where(target >= 0, self.target_mirror[np.maximum(target, 0)], -1),
                    root=root + int(root.max(initial=0)) + 1)

    def mirror(self, sk: Skeleton, *, obstacles) -> Skeleton:
        """Skeleton plus its mirror image (targets renamed to their mirror partners)."""
        img = self._image(sk.nodes, sk.parent, sk.target, sk.root)
        if obstacles is not None and np.any(sk.parent >= 0):
            if sk.replace(nodes=img["nodes"]).segment_hits(obstacles).any():
                raise InputError("the objects are not mirror-symmetric: the mirrored half of the structure "
                                 "collides with them", where="symmetry")
        both = {name: np.concatenate([a, img.get(name, a)]) for name, a in
                (("nodes", sk.nodes), ("parent", sk.parent), ("birth", sk.birth), ("target", sk.target),
                 ("root", sk.root), ("radius", sk.radius), ("contact", sk.contact_mask()))}
        return Skeleton(**both, target_names=sk.target_names)

    def mirror_tree(self, t: Tree) -> Tree:
        """Tree plus its mirror image (see :meth:`mirror`)."""
        return t.concat(t.take(slice(None), **self._image(t.nodes, t.parent, t.target, t.root)))


def skin_result(result: Growth, *, segments: int | None = None, subtract: bool | None = None):
    """Skin the final skeleton of a growth.

    Args:
        result: the :class:`Growth`.
        segments: joint-sphere resolution (None: the scene's).
        subtract: carve the objects out of the skin (None: the scene's).

    Returns:
        A tuple (``trimesh.Trimesh`` [m], :class:`simfab.growth.skinning.SkinReport`, seconds [s]).
    """

    p = result.scene.params
    t0 = time.perf_counter()
    sk = result.skeleton
    mesh, rep = skin_skeleton(sk.nodes, sk.parent, sk.radius, result.scene.objects, fixed=sk.fixed_mask(),
                     segments=segments or p.skin_segments,
                     subtract=p.subtract_objects if subtract is None else subtract)
    return mesh, rep, time.perf_counter() - t0

