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

    nodes : (n, 3) positions [m]. parent : (n,) parent index (-1 for roots).
    birth : (n,) growth step of creation (the node's age α in the radius law).
    target : (n,) index of the target the node lies on (-1 otherwise).
    root : (n,) index of the root the node descends from.
    radius : (n,) skin radius [m].
    target_names : names of the targets (index -> name).
    contact : (n,) bool, surface-mode contacts (leaves on an object surface), or None.
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
        return np.zeros(len(self.nodes), bool) if self.contact is None else np.asarray(self.contact, bool)

    @property
    def edges(self) -> np.ndarray:
        """(e, 2) segments as (parent, child) node indices."""
        c = np.nonzero(self.parent >= 0)[0]
        return np.column_stack([self.parent[c], c])

    def degree(self) -> np.ndarray:
        """(n,) number of segments at each node."""
        e = self.edges
        return np.bincount(e.ravel(), minlength=len(self.nodes))

    def on_surface_mask(self) -> np.ndarray:
        """(n,) nodes lying on an object surface by design: roots, targets and contacts."""
        return (self.parent < 0) | (self.target >= 0) | self.contact_mask()

    def segment_hits(self, obstacles) -> np.ndarray:
        """(e,) bool per segment of :attr:`edges`: crosses an object or sphere."""
        e = self.edges
        s = self.on_surface_mask()
        return obstacles.segment_hits(self.nodes[e[:, 0]], self.nodes[e[:, 1]], s[e[:, 0]], s[e[:, 1]])

    def fixed_mask(self) -> np.ndarray:
        """(n,) nodes held fixed by smoothing and sketch edits: roots, targets and leaves."""
        return (self.parent < 0) | (self.target >= 0) | (self.degree() <= 1)

    def target_nodes(self) -> dict:
        """target name -> node index of the (first) node lying on it."""
        out = {}
        for i in np.nonzero(self.target >= 0)[0]:
            name = self.target_names[self.target[i]] if self.target[i] < len(self.target_names) else str(self.target[i])
            out.setdefault(name, int(i))
        return out

    def replace(self, **kw) -> "Skeleton":
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
    """Iterate v_i += λ1 Δv_i + λ2 Δ(Δv_i) on the free nodes (fixed (n,) bool held in place).

    With ``obstacles`` every iteration is checked: nodes of segments that would cross an
    object or sphere go back to their previous (collision-free) position (``on_surface``
    (n,) bool marks nodes lying on a surface by design, see ``Obstacles.segment_hits``).
    Returns the new (n, 3) positions.
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
    try:
        V = np.asarray(d["nodes"], np.float64).reshape(-1, 3)
        n = len(V)
        par = np.asarray(d["parent"], np.int64).reshape(n)
        sk = Skeleton(nodes=V, parent=par, birth=np.asarray(d["birth_step"], np.int64).reshape(n),
                      target=np.asarray(d["target"], np.int64).reshape(n),
                      root=np.asarray(d["root"], np.int64).reshape(n),
                      radius=np.asarray(d["radius"], np.float64).reshape(n),
                      target_names=tuple(d.get("target_names", ())),
                      contact=np.asarray(d.get("contact", np.zeros(n, bool)), bool).reshape(n))
    except (KeyError, ValueError, TypeError) as e:
        raise InputError(f"malformed skeleton ({type(e).__name__}: {e})", where=str(path)) from None
    if not np.all(np.isfinite(V)) or np.any(par >= np.arange(n)) or np.any(par < -1) or not np.all(sk.radius > 0):
        raise InputError("malformed skeleton (non-finite nodes, bad parent order or radii)", where=str(path))
    return sk, d
