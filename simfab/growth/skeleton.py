"""The grown skeleton: pruning, smoothing, radius by age, mirroring, chains, JSON.

A skeleton is a forest stored as parent indices: node i is joined to ``parent[i]`` by a
segment (roots have parent -1). Positions are metres.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from simfab.errors import InputError


@dataclasses.dataclass(frozen=True, kw_only=True)
class Skeleton:
    """A pruned/smoothed tree with radii.

    Args:
        nodes: (n, 3) positions [m].
        parent: (n,) parent index (-1 for roots).
        birth: (n,) growth step of creation (the node's age α in the radius law).
        target: (n,) index of the target the node lies on (-1 otherwise).
        root: (n,) index of the root the node descends from.
        radius: (n,) skin radius [m].
        target_names: names of the targets (index -> name).
        contact: (n,) bool, surface-mode contacts (leaves on an object surface), or None.
    """

    nodes: np.ndarray
    parent: np.ndarray
    birth: np.ndarray
    target: np.ndarray
    root: np.ndarray
    radius: np.ndarray
    target_names: tuple = ()
    contact: np.ndarray | None = None

    def contact_mask(self) -> np.ndarray:
        """(n,) bool surface-mode contacts (all False without them).

        Returns:
            A (n,) bool array.
        """
        return np.zeros(len(self.nodes), bool) if self.contact is None else np.asarray(self.contact, bool)

    @property
    def edges(self) -> np.ndarray:
        """(e, 2) segments as (parent, child) node indices."""
        c = np.nonzero(self.parent >= 0)[0]
        return np.column_stack([self.parent[c], c])

    def degree(self) -> np.ndarray:
        """Number of segments at each node.

        Returns:
            A (n,) int array.
        """
        e = self.edges
        return np.bincount(e.ravel(), minlength=len(self.nodes))

    def on_surface_mask(self) -> np.ndarray:
        """Nodes lying on an object surface by design: roots, targets and contacts.

        Returns:
            A (n,) bool array.
        """
        return (self.parent < 0) | (self.target >= 0) | self.contact_mask()

    def segment_hits(self, obstacles) -> np.ndarray:
        """Which segments of :attr:`edges` cross an object or sphere.

        Args:
            obstacles: the scene's :class:`simfab.growth.obstacles.Obstacles`.

        Returns:
            An (e,) bool array, one per segment.
        """
        e = self.edges
        s = self.on_surface_mask()
        return obstacles.segment_hits(self.nodes[e[:, 0]], self.nodes[e[:, 1]], s[e[:, 0]], s[e[:, 1]])

    def fixed_mask(self) -> np.ndarray:
        """Nodes held fixed by smoothing and sketch edits: roots, targets and leaves.

        Returns:
            A (n,) bool array.
        """
        return (self.parent < 0) | (self.target >= 0) | (self.degree() <= 1)

    def target_nodes(self) -> dict:
        """Where the skeleton meets its targets.

        Returns:
            A dict target name -> node index of the (first) node lying on it.
        """
        out = {}
        for i in np.nonzero(self.target >= 0)[0]:
            name = self.target_names[self.target[i]] if self.target[i] < len(self.target_names) else str(self.target[i])
            out.setdefault(name, int(i))
        return out

    def replace(self, **kw) -> "Skeleton":
        """A copy with some fields replaced (:func:`dataclasses.replace`).

        Args:
            **kw: field name -> new value.

        Returns:
            A new :class:`Skeleton`.
        """
        return dataclasses.replace(self, **kw)


# --------------------------------------------------------------------------- pruning
def keep_ancestors(parent: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """(n,) bool: nodes on the path from a root to any anchor node (anchors included)."""
    keep = np.zeros(len(parent), bool)
    frontier = np.unique(np.asarray(anchors, np.int64))
    keep[frontier] = True
    while frontier.size:
        p = parent[frontier]
        p = np.unique(p[p >= 0])
        p = p[~keep[p]]
        keep[p] = True
        frontier = p
    return keep


def subset(parent: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Re-index a forest to the kept nodes (closed under parents). Returns (index (k,), parent (k,))."""
    idx = np.nonzero(keep)[0]
    new = np.full(len(parent), -1, np.int64)
    new[idx] = np.arange(len(idx))
    par = parent[idx]
    return idx, np.where(par >= 0, new[np.maximum(par, 0)], -1)


# --------------------------------------------------------------------------- radius
def radius_by_age(age: np.ndarray, r_min: float, r_max: float, decay: float) -> np.ndarray:
    """r = r_min + (r_max - r_min) exp(-k α) per node (α = age in growth steps, k = decay).

    ``age`` comes from :func:`simfab.growth.pipeline.node_age`. By default (``radius.age =
    "front"``) it is counted along the growth front: roots have α = 0 and every growth step
    adds 1, so a node born at step s has α = s and the radius goes from r_max at the roots to
    r_min at the youngest tips (the thesis: "from the root to the targets between maximum
    radius and minimum radius"; a support is thickest at its base). ``"since_birth"`` counts
    the steps a node has lived until growth ended, which makes the roots the thinnest.
    """
    return r_min + (r_max - r_min) * np.exp(-decay * np.asarray(age, np.float64))


# --------------------------------------------------------------------------- smoothing
def umbrella(n: int, edges: np.ndarray) -> sp.csr_matrix:
    """Graph Laplacian Δ (n, n) with (Δv)_i = mean over neighbours j of (v_j - v_i).

    On a chain this is Δv_i = ½(v_{i+1} - v_i) + ½(v_{i-1} - v_i).
    """
    e = np.asarray(edges, np.int64).reshape(-1, 2)
    rows = np.concatenate([e[:, 0], e[:, 1]])
    cols = np.concatenate([e[:, 1], e[:, 0]])
    W = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    deg = np.asarray(W.sum(axis=1)).ravel()
    inv = np.where(deg > 0, 1.0 / np.where(deg > 0, deg, 1.0), 0.0)
    return (sp.diags(inv) @ W - sp.diags((deg > 0).astype(float))).tocsr()


def smooth_positions(nodes: np.ndarray, edges: np.ndarray, fixed: np.ndarray, *, lambda1: float = 0.2,
                     lambda2: float = 0.1, iterations: int = 10, obstacles=None, on_surface=None) -> np.ndarray:
    """Iterate v_i += λ1 Δv_i + λ2 Δ(Δv_i) on the free nodes (fixed nodes held in place).

    With ``obstacles`` every iteration is checked: nodes of segments that would cross an
    object or sphere go back to their previous (collision-free) position.

    Args:
        nodes: (n, 3) positions [m].
        edges: (e, 2) segments as node indices.
        fixed: (n,) bool, nodes held in place.
        lambda1, lambda2: the Laplacian and bi-Laplacian step weights [-].
        iterations: smoothing iterations.
        obstacles: the scene's obstacles (None: no collision check).
        on_surface: (n,) bool, nodes lying on a surface by design (see ``Obstacles.segment_hits``).

    Returns:
        The new (n, 3) positions [m].
    """
    V = np.asarray(nodes, np.float64).copy()
    e = np.asarray(edges, np.int64).reshape(-1, 2)
    if len(e) == 0 or iterations <= 0:
        return V
    Lap = umbrella(len(V), e)
    free = ~np.asarray(fixed, bool)
    for _ in range(int(iterations)):
        d1 = Lap @ V
        # Dirichlet condition: Δ := 0 on fixed nodes. Otherwise Δ(Δv) next to a fixed node
        # sees the fixed node's one-sided difference, which amplifies zig-zags (measured:
        # the roughness of a 7-node arc goes up, not down, with λ2 = 0.1).
        d1[~free] = 0.0
        d2 = Lap @ d1
        W = V.copy()
        W[free] += lambda1 * d1[free] + lambda2 * d2[free]
        if obstacles is not None:
            W = revert_collisions(V, W, e, obstacles, on_surface)
        V = W
    return V


def revert_collisions(V_old, V_new, e, obstacles, on_surface, passes: int = 8):
    """Move the endpoints of colliding segments back to their previous positions.

    V_old, V_new : (n, 3) positions [m] before / after a move (V_old collision-free).
    e : (k, 2) segments. on_surface : (n,) bool, nodes on a surface by design (or None).
    Returns (n, 3): V_new with the nodes of colliding segments reset, repeated for up to
    ``passes`` rounds (a reset can expose a new collision); V_old if collisions remain.
    """
    W = V_new.copy()
    moved = np.any(W != V_old, axis=1)
    for _ in range(passes):
        check = moved[e[:, 0]] | moved[e[:, 1]]
        if not check.any():
            return W
        ec = e[check]
        surf = np.zeros(len(V_old), bool) if on_surface is None else np.asarray(on_surface, bool)
        bad = obstacles.segment_hits(W[ec[:, 0]], W[ec[:, 1]], surf[ec[:, 0]], surf[ec[:, 1]])
        if not bad.any():
            return W
        nodes = np.unique(ec[bad].ravel())
        W[nodes] = V_old[nodes]
        moved[nodes] = False
    return V_old.copy()


# --------------------------------------------------------------------------- chains
def chains(parent: np.ndarray, breaks: np.ndarray) -> list[np.ndarray]:
    """Maximal paths (node index arrays, parent end first) whose interior nodes have degree 2
    and are not in ``breaks`` (n,) bool. Each segment belongs to exactly one chain."""
    n = len(parent)
    children = [[] for _ in range(n)]
    for c in np.nonzero(parent >= 0)[0]:
        children[parent[c]].append(int(c))
    interior = np.array([parent[i] >= 0 and len(children[i]) == 1 and not breaks[i] for i in range(n)], bool)
    out = []
    for s in np.nonzero(~interior)[0]:
        for c in children[s]:
            path = [int(s), c]
            while interior[path[-1]]:
                path.append(children[path[-1]][0])
            out.append(np.array(path, np.int64))
    return out


# --------------------------------------------------------------------------- JSON
def to_json_dict(sk: Skeleton, **extra) -> dict:
    """Plain-JSON form: nodes, radii, parents, births, target per node and name -> node."""
    d = {
        "format": "simfab.growth.skeleton/1",
        "units": "m",
        "nodes": sk.nodes,
        "radius": sk.radius,
        "parent": sk.parent,
        "birth_step": sk.birth,
        "target": sk.target,
        "root": sk.root,
        "contact": sk.contact_mask(),
        "target_names": list(sk.target_names),
        "target_nodes": sk.target_nodes(),
    }
    d.update(extra)
    return d


def load_skeleton_json(path) -> tuple[Skeleton, dict]:
    """Read a skeleton JSON written by :func:`to_json_dict`; InputError when unusable."""
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", where=str(path))
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"not valid JSON: {e}", where=str(path)) from None
    if not isinstance(d, dict) or d.get("format") != "simfab.growth.skeleton/1":
        raise InputError("not a simfab growth skeleton (format simfab.growth.skeleton/1)", where=str(path))

    def field(key, dtype, default=None):
        if key not in d and default is None:
            raise InputError("missing", where=f"{path}: {key}")
        try:
            return np.asarray(d.get(key, default), dtype)
        except (ValueError, TypeError) as e:
            raise InputError(f"not an array of numbers ({type(e).__name__}: {e})", where=f"{path}: {key}") from None

    V = field("nodes", np.float64)
    if V.size == 0:
        raise InputError("empty skeleton: no nodes", where=f"{path}: nodes")
    if V.ndim != 2 or V.shape[1] != 3:
        raise InputError(f"expected a list of [x, y, z] points, got shape {V.shape}", where=f"{path}: nodes")
    if not np.all(np.isfinite(V)):
        raise InputError("non-finite node coordinates", where=f"{path}: nodes")
    n = len(V)
    arrays = {}
    for key, dtype, default in (("parent", np.float64, None), ("birth_step", np.float64, None),
                                ("target", np.float64, None), ("root", np.float64, None),
                                ("radius", np.float64, None), ("contact", bool, np.zeros(n, bool))):
        a = field(key, dtype, default)
        if a.shape != (n,):
            raise InputError(f"expected {n} values (one per node), got shape {a.shape}", where=f"{path}: {key}")
        if dtype is np.float64 and not np.all(np.isfinite(a)):
            raise InputError(f"non-finite value at node {int(np.nonzero(~np.isfinite(a))[0][0])}",
                             where=f"{path}: {key}")
        if key != "radius" and dtype is np.float64:
            if np.any(a != np.round(a)):
                raise InputError("expected integers", where=f"{path}: {key}")
            a = a.astype(np.int64)
        arrays[key] = a
    par, radius = arrays["parent"], arrays["radius"]
    bad = np.nonzero((par >= np.arange(n)) | (par < -1))[0]
    if len(bad):
        raise InputError(f"node {int(bad[0])} has parent {int(par[bad[0]])} (parents come first; -1 for roots)",
                         where=f"{path}: parent")
    if not np.all(radius > 0):
        raise InputError(f"radius {radius[radius <= 0][0]:g} at node {int(np.nonzero(radius <= 0)[0][0])} "
                         "(radii are positive)", where=f"{path}: radius")
    names = d.get("target_names", [])
    if not isinstance(names, list) or not all(isinstance(t, str) for t in names) or len(set(names)) != len(names):
        raise InputError("expected a list of distinct site names", where=f"{path}: target_names")
    tgt = arrays["target"]
    bad = np.nonzero((tgt < -1) | (tgt >= len(names)))[0]
    if len(bad):
        raise InputError(f"node {int(bad[0])} names target index {int(tgt[bad[0]])}, but there are {len(names)} "
                         "target names", where=f"{path}: target")
    tn = d.get("target_nodes")
    if tn is not None:
        want = {names[int(t)]: int(i) for i, t in enumerate(tgt) if t >= 0}
        if not isinstance(tn, dict) or any(k not in want for k in tn):
            raise InputError(f"lists targets {sorted(tn) if isinstance(tn, dict) else tn!r} that no node reaches "
                             f"(reached: {sorted(want)})", where=f"{path}: target_nodes")
    sk = Skeleton(nodes=V, parent=par, birth=arrays["birth_step"], target=tgt, root=arrays["root"], radius=radius,
                  target_names=tuple(names), contact=arrays["contact"])
    return sk, d
