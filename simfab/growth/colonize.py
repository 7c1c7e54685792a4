"""Space colonization with target attractors (vectorized per growth step).

One growth step (Runions et al. 2005, with the target attractors of the thesis):

1. every live attractor is associated with its nearest *growing* tree node within its influence
   distance (ordinary attractors: ``influence``; target attractors: ``target_influence``,
   infinite by default so that a target keeps pulling after the ordinary attractors are gone);
2. each attracted node v gets one child v' = v + L n̂, n̂ the normalized sum of the unit vectors
   from v to its attractors; a node within ``TARGET_REACH`` L of its target attractor lands
   exactly on it instead, v' = t, and becomes a tip;
3. a new segment v→v' that crosses an object or enters an obstacle sphere is replaced by the
   best-aligned collision-free direction among ``max_trials`` random unit vectors (none: wait);
4. a new node within ``MIN_NODE_SPACING`` L of an existing node is dropped and the ordinary
   attractors that pulled it are killed; a node that cannot grow for ``NODE_FAIL_LIMIT``
   consecutive steps stops growing;
5. ordinary attractors within the kill distance of a new node die; target attractors die only
   when reached.

Growth stops when every attractor is dead, or reports why it stopped early (step cap, node cap,
stalled). Each step enumerates the pairs (new node, live attractor) closer than the influence
distance R from a k-d tree of the live attractors: O(new nodes x attractors per influence ball);
target attractors (few, unbounded influence) are compared with every new node. Full notes
(nearest-node tracking, :class:`_Nearest`): docs/methods.md, "simfab.growth.colonize".
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

import simfab.growth.tolerances as tol


@dataclasses.dataclass
class Tree:
    """Growth state: the tree grown so far (arrays grow by appending).

    nodes : (n, 3) positions [m]. parent : (n,) parent index (-1 for roots).
    birth : (n,) growth step at which the node was created (roots: 0).
    target : (n,) index of the target the node landed on (-1 otherwise).
    root : (n,) index of the root the node descends from.
    frozen : (n,) True for tips that do not grow (targets reached).
    contact : (n,) True for surface-mode contacts (leaves snapped onto an object surface).
    """

    nodes: np.ndarray
    parent: np.ndarray
    birth: np.ndarray
    target: np.ndarray
    root: np.ndarray
    frozen: np.ndarray
    contact: np.ndarray | None = None

    def __post_init__(self):
        if self.contact is None:
            self.contact = np.zeros(len(self.nodes), bool)

    @classmethod
    def from_roots(cls, roots: np.ndarray) -> "Tree":
        r = np.asarray(roots, dtype=np.float64).reshape(-1, 3)
        k = len(r)
        return cls(nodes=r.copy(), parent=np.full(k, -1, np.int64), birth=np.zeros(k, np.int64),
                   target=np.full(k, -1, np.int64), root=np.arange(k, dtype=np.int64),
                   frozen=np.zeros(k, bool))

    def __len__(self) -> int:
        return len(self.nodes)

    def append(self, pos, parent, birth, target, frozen) -> None:
        self.nodes = np.concatenate([self.nodes, pos])
        self.root = np.concatenate([self.root, self.root[parent]])
        self.parent = np.concatenate([self.parent, parent])
        self.birth = np.concatenate([self.birth, np.full(len(pos), birth, np.int64)])
        self.target = np.concatenate([self.target, target])
        self.frozen = np.concatenate([self.frozen, frozen])
        self.contact = np.concatenate([self.contact, np.zeros(len(pos), bool)])

    def copy(self) -> "Tree":
        return Tree(**{f.name: getattr(self, f.name).copy() for f in dataclasses.fields(self)})

    def take(self, idx, **replace) -> "Tree":
        """The nodes ``idx`` (every per-node field indexed), with fields in ``replace`` set as given
        (e.g. ``parent`` re-indexed by the caller)."""
        return Tree(**{f.name: replace[f.name] if f.name in replace else getattr(self, f.name)[idx]
                       for f in dataclasses.fields(self)})

    def concat(self, other: "Tree") -> "Tree":
        """This tree's nodes followed by ``other``'s (``other.parent`` must already index the result)."""
        return Tree(**{f.name: np.concatenate([getattr(self, f.name), getattr(other, f.name)])
                       for f in dataclasses.fields(self)})


@dataclasses.dataclass(frozen=True, kw_only=True)
class ColonizeConfig:
    """Distances [m] and caps of one colonization run (see :class:`simfab.growth.config.Resolved`)."""

    influence: float
    kill: float
    branch_length: float
    target_influence: float
    max_steps: int
    max_nodes: int
    max_trials: int


@dataclasses.dataclass
class ColonizeReport:
    """What happened: steps taken, why growth stopped, obstacle-avoidance statistics."""

    steps: int = 0
    stop_reason: str = ""
    collisions_resolved: int = 0
    collisions_unresolved: int = 0
    dropped_oscillating: int = 0
    dead_ends: int = 0
    targets_reached: list = dataclasses.field(default_factory=list)
    targets_unreached: list = dataclasses.field(default_factory=list)
    #: (m,) growth step at which each ordinary attractor died (-1: alive at the end)
    attractor_death_step: np.ndarray | None = None


def colonize(tree: Tree, attractors: np.ndarray, targets: np.ndarray, target_ids: np.ndarray, obstacles,
             s: ColonizeConfig, rng: np.random.Generator, *, step0: int = 0) -> ColonizeReport:
    """Grow ``tree`` in place towards ``attractors`` (m, 3) and ``targets`` (t, 3).

    ``target_ids`` (t,) are the indices recorded in ``tree.target`` when a target is reached.
    ``step0`` is the step count of earlier stages (node birth steps continue from it).
    Returns a :class:`ColonizeReport`; unreached targets are listed there, never silently lost.
    """
    A = np.concatenate([np.asarray(attractors, np.float64).reshape(-1, 3),
                        np.asarray(targets, np.float64).reshape(-1, 3)])
    m = len(A) - len(targets)
    is_t = np.zeros(len(A), bool)
    is_t[m:] = True
    tid = np.concatenate([np.full(m, -1, np.int64), np.asarray(target_ids, np.int64).reshape(-1)])
    infl = np.where(is_t, s.target_influence, s.influence)
    alive = np.ones(len(A), bool)
    rep = ColonizeReport()

    # targets already on the tree (e.g. a later stage re-listing a reached target)
    on_tree = np.isin(tid, tree.target[tree.target >= 0]) & is_t
    alive[on_tree] = False
    rep.targets_reached.extend(int(t) for t in tid[on_tree])

    # nearest growing node of every attractor (ordinary ones: only when within influence)
    near = _Nearest(A, is_t, s.influence, s.kill)
    near.absorb(alive, tree.nodes, np.arange(len(tree)), ~tree.frozen)
    near_d, near_i = near.d, near.i
    nodes = _NodeIndex(tree.nodes)

    died = np.full(len(A), -1, np.int64)
    died[~alive] = step0
    idle = 0
    fails = np.zeros(len(tree), np.int64)  # consecutive steps a node was attracted but could not grow
    step = step0
    for step in range(step0 + 1, step0 + s.max_steps + 1):
        live = np.nonzero(alive)[0]
        if live.size == 0:
            rep.stop_reason = "all attractors reached or killed"
            step -= 1
            break
        att = live[near_d[live] <= infl[live]]
        if att.size == 0:
            rep.stop_reason = "stalled: no live attractor within influence of a growing node"
            step -= 1
            break
        pos, parent, target_attr, dropped_attr, stuck = _grow_step(tree, nodes, A, att, near_i, is_t, tid, obstacles, s,
                                                                   rng, rep)
        if dropped_attr.size:
            alive[dropped_attr[~is_t[dropped_attr]]] = False
            died[~alive & (died < 0)] = step
        fails = np.concatenate([fails, np.zeros(len(tree) - len(fails), np.int64)])
        fails[parent] = 0
        fails[stuck] += 1
        dead_end = stuck[fails[stuck] >= tol.NODE_FAIL_LIMIT]
        if dead_end.size:
            tree.frozen[dead_end] = True
            rep.dead_ends += int(dead_end.size)
            near.reassociate(alive, tree, dead_end)
        if len(pos) == 0:
            idle += 1
            if idle >= tol.STALL_PATIENCE:
                rep.stop_reason = "stalled: no collision-free growth possible"
                break
            continue
        idle = 0
        first = len(tree)
        landed = target_attr >= 0
        tree.append(pos, parent, step, np.where(landed, tid[np.maximum(target_attr, 0)], -1), landed)
        alive[target_attr[landed]] = False
        rep.targets_reached.extend(int(tid[a]) for a in target_attr[landed])
        idx = np.arange(first, len(tree))
        nodes.add(pos)
        near.absorb(alive, pos, idx, ~landed)
        died[~alive & (died < 0)] = step
        if len(tree) >= s.max_nodes:
            rep.stop_reason = f"node cap reached ({s.max_nodes} nodes)"
            break
    else:
        rep.stop_reason = f"step cap reached ({s.max_steps} steps)"
    rep.steps = step - step0
    rep.targets_unreached = [int(t) for t in tid[is_t & alive]]
    rep.attractor_death_step = died[:m]
    return rep


class _Nearest:
    """Nearest growing node per attractor, and the kill step, as new nodes appear.

    ``d`` (m,) distance [m] and ``i`` (m,) index of the nearest growing node (inf / -1: none
    known). Target attractors (unbounded influence, few) are compared with every new node.
    Ordinary attractors are looked up in a k-d tree of all of them (built once) within the
    influence distance R of each new node: their ``d`` is exact whenever the nearest growing
    node is within R and is some value > R (or inf) otherwise. That is all a growth step reads
    (an attractor pulls only when ``d <= R``), and it stays so when a node stops growing: its
    attractors are re-queried (:meth:`reassociate`), and a node no nearer than the one lost
    cannot come within R of an attractor whose lost nearest node was beyond R.
    """

    def __init__(self, A: np.ndarray, is_t: np.ndarray, influence: float, kill: float):
        self.A = A
        self.t_idx = np.nonzero(is_t)[0]
        self.R = float(influence)
        self.kill = float(kill)
        self.d = np.full(len(A), np.inf)
        self.i = np.full(len(A), -1, np.int64)
        self._index(np.nonzero(~is_t)[0])

    def _index(self, ordinary: np.ndarray) -> None:
        """k-d tree of the ordinary attractors ``ordinary`` (rebuilt over the live ones once half
        of the indexed ones died, so that the look-ups stay proportional to the live count)."""
        self.o_idx = ordinary
        self.tree = cKDTree(self.A[ordinary]) if ordinary.size else None

    def absorb(self, alive: np.ndarray, pos: np.ndarray, idx: np.ndarray, growing: np.ndarray) -> None:
        """Fold new nodes ``pos`` (k, 3) (tree indices ``idx``; ``growing`` (k,) bool) in: nearer
        growing nodes replace the recorded ones, and ordinary attractors within the kill
        distance of any new node die (``alive`` updated in place)."""
        if len(pos) == 0:
            return
        g = np.nonzero(growing)[0]
        t = self.t_idx[alive[self.t_idx]]
        if t.size and g.size:
            D = cdist(self.A[t], pos[g])
            j = np.argmin(D, axis=1)
            self._update(t, D[np.arange(len(t)), j], idx[g[j]])
        live = alive[self.o_idx]
        if 2 * np.count_nonzero(live) < live.size:
            self._index(self.o_idx[live])
        if self.tree is None:
            return
        pr = cKDTree(pos).sparse_distance_matrix(self.tree, self.R, output_type="ndarray")
        att = self.o_idx[pr["j"]]
        ok = alive[att] & growing[pr["i"]]
        node, a_g, d_g = pr["i"][ok], att[ok], pr["v"][ok]
        if a_g.size:
            # per attractor the nearest new node; the lowest node index among equally near ones
            best = np.full(len(self.A), np.inf)
            np.minimum.at(best, a_g, d_g)
            at_min = d_g == best[a_g]
            first = np.full(len(self.A), np.iinfo(np.int64).max)
            np.minimum.at(first, a_g[at_min], node[at_min])
            u = np.nonzero(best < np.inf)[0]
            self._update(u, best[u], idx[first[u]])
        dead = att[pr["v"] <= self.kill]
        alive[dead] = False

    def _update(self, att, d, node) -> None:
        better = d < self.d[att]
        self.d[att[better]] = d[better]
        self.i[att[better]] = node[better]

    def reassociate(self, alive: np.ndarray, tree: Tree, dead: np.ndarray) -> None:
        """Attractors whose nearest growing node stopped growing look for the next one."""
        affected = np.nonzero(alive & np.isin(self.i, dead))[0]
        self.d[affected] = np.inf
        self.i[affected] = -1
        g = np.nonzero(~tree.frozen)[0]
        if affected.size == 0 or g.size == 0:
            return
        d, j = cKDTree(tree.nodes[g]).query(self.A[affected], k=1)
        self.d[affected] = d
        self.i[affected] = g[j]


def _grow_step(tree, nodes, A, att, near_i, is_t, tid, obstacles, s, rng, rep):
    """Children of the attracted nodes: (pos (k,3), parent (k,), target attractor or -1 (k,),
    attractors of dropped children, attracted nodes that got no child this step)."""
    L = s.branch_length
    node = near_i[att]
    X = tree.nodes
    vec = A[att] - X[node]
    dist = np.linalg.norm(vec, axis=1)
    unit = vec / np.where(dist > 0, dist, 1.0)[:, None]
    uniq, inv = np.unique(node, return_inverse=True)
    inv = inv.reshape(-1)
    acc = np.column_stack([np.bincount(inv, weights=unit[:, k], minlength=len(uniq)) for k in range(3)])
    norm = np.linalg.norm(acc, axis=1)
    # opposite pulls that cancel exactly: follow the first attractor instead
    first_att = np.full(len(uniq), -1)
    first_att[inv[::-1]] = np.arange(len(att))[::-1]
    degenerate = norm < 1e-12
    acc[degenerate] = unit[first_att[degenerate]]
    norm[degenerate] = 1.0
    direction = acc / norm[:, None]
    start = X[uniq]
    cand = start + L * direction
    target_attr = np.full(len(uniq), -1, np.int64)

    # a reachable target: land on it (the closest one if several pull the same node)
    reach = is_t[att] & (dist <= tol.TARGET_REACH * L)
    if reach.any():
        r = np.nonzero(reach)[0]
        order = r[np.lexsort((dist[r], inv[r]))]
        first = np.unique(inv[order], return_index=True)[1]
        pick = order[first]
        target_attr[inv[pick]] = att[pick]
        cand[inv[pick]] = A[att[pick]]

    from_root = tree.parent[uniq] < 0  # roots sit on a surface by design
    hit = obstacles.segment_hits(start, cand, from_root, target_attr >= 0)
    keep = np.ones(len(uniq), bool)
    if hit.any():
        h = np.nonzero(hit)[0]
        target_attr[h] = -1
        ok, new_pos = _avoid(start[h], direction[h], from_root[h], L, obstacles, s.max_trials, rng)
        cand[h[ok]] = new_pos[ok]
        rep.collisions_resolved += int(ok.sum())
        rep.collisions_unresolved += int((~ok).sum())
        keep[h[~ok]] = False

    # oscillation guard: drop children landing on top of existing nodes or of each other
    spacing = tol.MIN_NODE_SPACING * L
    free_cand = keep & (target_attr < 0)
    if free_cand.any():
        fc = np.nonzero(free_cand)[0]
        crowded = fc[nodes.within(cand[fc], spacing)]
        if fc.size > 1:
            pairs = cKDTree(cand[fc]).query_pairs(spacing, output_type="ndarray")
            if len(pairs):
                crowded = np.union1d(crowded, fc[pairs.max(axis=1)])
        keep[crowded] = False
        rep.dropped_oscillating += int(crowded.size)
        dropped_nodes = np.zeros(len(uniq), bool)
        dropped_nodes[crowded] = True
        dropped_attr = att[dropped_nodes[inv]]
    else:
        dropped_attr = np.zeros(0, np.int64)
    return cand[keep], uniq[keep], target_attr[keep], dropped_attr, uniq[~keep]


class _NodeIndex:
    """k-d trees over the tree's nodes as they are appended (a logarithmic method: blocks of
    decreasing size, a new block merged with the last while it is at least as large), so that
    a step's look-up costs O(log² n) per query and building them O(n log² n) in all, instead
    of a new tree over every node each step."""

    def __init__(self, X: np.ndarray):
        self.blocks = []
        self.add(X)

    def add(self, P: np.ndarray) -> None:
        pts = np.asarray(P, np.float64).reshape(-1, 3)
        while self.blocks and len(self.blocks[-1][0]) <= len(pts):
            pts = np.concatenate([self.blocks.pop()[0], pts])
        if len(pts):
            self.blocks.append((pts, cKDTree(pts)))

    def within(self, Q: np.ndarray, r: float) -> np.ndarray:
        """(q,) bool: a node lies closer than ``r`` [m] to ``Q[i]``."""
        out = np.zeros(len(Q), bool)
        for _, t in self.blocks:
            d, _ = t.query(Q, k=1, distance_upper_bound=r)
            out |= d < r
        return out


def _avoid(start, direction, on_surface, L, obstacles, trials, rng):
    """For each blocked branch, the collision-free random direction best aligned with the
    desired one (``trials`` candidates each, tested in one batch). Returns (ok (k,), pos (k, 3))."""
    k = len(start)
    dirs = rng.normal(size=(k, trials, 3))
    dirs /= np.linalg.norm(dirs, axis=2, keepdims=True)
    p = np.repeat(start, trials, axis=0)
    q = p + L * dirs.reshape(-1, 3)
    free = ~obstacles.segment_hits(p, q, np.repeat(on_surface, trials)).reshape(k, trials)
    score = np.where(free, np.einsum("ktj,kj->kt", dirs, direction), -np.inf)
    best = np.argmax(score, axis=1)
    ok = np.isfinite(score[np.arange(k), best])
    return ok, start + L * dirs[np.arange(k), best]
