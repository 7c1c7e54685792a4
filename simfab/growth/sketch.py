"""Sketch modification of a skeleton chain (after Kara & Shimada's sketch-based curve editing).

The user draws a 2D stroke over a view of the skeleton. The rays from the eye through the
stroke points sweep a surface (a fan of triangles with its apex at the eye); the chosen
chain's interior nodes move to their closest points on that surface, so that from the
camera the chain now follows the stroke while staying as close as possible to where it
was in depth. Chain end nodes (roots, targets, branch points) stay put, so the skeleton
stays connected.

Screen coordinates are pixels: x to the right, y down, origin at the top-left corner.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from simfab.errors import InputError
from simfab.growth.skeleton import Skeleton, chains, revert_collisions
from simfab.io.companion import read_csv_numbers, reading


@dataclasses.dataclass(frozen=True, kw_only=True)
class Camera:
    """Pinhole camera.

    Args:
        eye, target: (3,) the camera's position and the point it looks at [m].
        up: (3,) the up direction.
        fovy_deg: vertical field of view [deg].
        width, height: the image's size [px].
    """

    eye: tuple
    target: tuple
    up: tuple = (0.0, 0.0, 1.0)
    fovy_deg: float = 45.0
    width: int = 640
    height: int = 480

    def frame(self):
        """The camera's orthonormal frame.

        Returns:
            A tuple (forward, right, up) of (3,) unit vectors.
        """
        e, t, u = (np.asarray(a, np.float64) for a in (self.eye, self.target, self.up))
        f = t - e
        f /= np.linalg.norm(f)
        r = np.cross(f, u)
        r /= np.linalg.norm(r)
        return f, r, np.cross(r, f)

    def _scale(self):
        h = np.tan(np.radians(self.fovy_deg) / 2.0)
        return h * self.width / self.height, h

    def project(self, X: np.ndarray) -> np.ndarray:
        """Project world points onto the image.

        Args:
            X: (n, 3) world points [m].

        Returns:
            (n, 2) pixel coordinates [px].
        """
        f, r, u = self.frame()
        d = np.asarray(X, np.float64).reshape(-1, 3) - np.asarray(self.eye, np.float64)
        z = d @ f
        sx, sy = self._scale()
        x = (d @ r) / z / sx
        y = (d @ u) / z / sy
        return np.column_stack([(x + 1.0) * 0.5 * self.width, (1.0 - y) * 0.5 * self.height])

    def rays(self, px: np.ndarray) -> np.ndarray:
        """The rays through image points.

        Args:
            px: (m, 2) pixel coordinates [px].

        Returns:
            (m, 3) unit ray directions from the eye.
        """
        f, r, u = self.frame()
        p = np.asarray(px, np.float64).reshape(-1, 2)
        sx, sy = self._scale()
        x = (2.0 * p[:, 0] / self.width - 1.0) * sx
        y = (1.0 - 2.0 * p[:, 1] / self.height) * sy
        d = f[None] + x[:, None] * r[None] + y[:, None] * u[None]
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def ray_surface(camera: Camera, stroke: np.ndarray, far: float):
    """The fan of triangles (eye, eye + far d_j, eye + far d_{j+1}) swept by the stroke rays."""
    import trimesh

    d = camera.rays(stroke)
    eye = np.asarray(camera.eye, np.float64)
    V = np.concatenate([eye[None], eye + far * d])
    m = len(d)
    F = np.column_stack([np.zeros(m - 1, np.int64), np.arange(1, m), np.arange(2, m + 1)])
    return trimesh.Trimesh(V, F, process=False)


def pick_chain(sk: Skeleton, camera: Camera, stroke: np.ndarray) -> int:
    """Index (into :func:`skeleton_chains`) of the chain drawn closest to the stroke on screen."""
    ch = skeleton_chains(sk)
    best, best_d = -1, np.inf
    for i, c in enumerate(ch):
        if len(c) < 3:
            continue
        P = camera.project(sk.nodes[c])
        d = np.mean([_point_polyline_distance(s, P) for s in stroke]) + \
            np.mean([_point_polyline_distance(q, stroke) for q in P])
        if d < best_d:
            best, best_d = i, d
    if best < 0:
        raise InputError("the skeleton has no chain with interior nodes to edit")
    return best


def skeleton_chains(sk: Skeleton) -> list[np.ndarray]:
    """Chains between roots, targets, branch points and leaves (node index arrays)."""
    return chains(sk.parent, sk.fixed_mask())


def edit_chain(sk: Skeleton, camera: Camera, stroke, *, chain: int | None = None,
               obstacles=None) -> tuple[Skeleton, dict]:
    """Move one chain of a skeleton onto the ray surface of a stroke drawn on screen.

    Args:
        sk: the skeleton.
        camera: the camera the stroke was drawn in.
        stroke: (m, 2) the stroke's pixel points [px], m >= 2.
        chain: index into :func:`skeleton_chains` (None: the chain closest to the stroke on screen).
        obstacles: the scene's obstacles; nodes whose new segments would cross an object keep their
            old position (None: no check).

    Returns:
        A tuple (the edited :class:`Skeleton`, a report dict: chain index, nodes moved, nodes kept
        because of collisions, largest move [m], segments colliding after the edit).

    Raises:
        InputError: a stroke of fewer than 2 finite points, or an unknown chain.
    """
    stroke = np.asarray(stroke, np.float64)
    if stroke.ndim != 2 or stroke.shape[1] != 2 or len(stroke) < 2 or not np.all(np.isfinite(stroke)):
        raise InputError("a stroke needs at least 2 finite (x, y) pixel points", where="stroke")
    ch = skeleton_chains(sk)
    if chain is None:
        chain = pick_chain(sk, camera, stroke)
    if not 0 <= chain < len(ch):
        raise InputError(f"chain index {chain} out of range (the skeleton has {len(ch)} chains)", where="--chain")
    idx = ch[chain]
    inner = idx[1:-1]
    if inner.size == 0:
        raise InputError(f"chain {chain} has no interior nodes to move", where="--chain")
    far = 4.0 * float(np.max(np.linalg.norm(sk.nodes - np.asarray(camera.eye), axis=1)))
    surf = ray_surface(camera, stroke, far)
    closest, dist, _ = surf.nearest.on_surface(sk.nodes[inner])
    V = sk.nodes.copy()
    V[inner] = closest
    reverted = 0
    if obstacles is not None:
        # a node whose new segments would cross an object keeps its old position
        W = revert_collisions(sk.nodes, V, sk.edges, obstacles, sk.on_surface_mask())
        reverted = int(np.sum(np.any(W[inner] != V[inner], axis=1)))
        V = W
    out = sk.replace(nodes=V)
    moved = np.any(V[inner] != sk.nodes[inner], axis=1)
    rep = {"chain": int(chain), "nodes_moved": int(moved.sum()), "nodes_kept_for_collisions": reverted,
           "max_move": float(np.max(np.linalg.norm(V[inner] - sk.nodes[inner], axis=1)))}
    if obstacles is not None:
        rep["segments_colliding"] = int(out.segment_hits(obstacles).sum())
    return out, rep


def _point_polyline_distance(p, P) -> float:
    a, b = P[:-1], P[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0, 1)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))


# --------------------------------------------------------------------------- files
def load_camera(arg: str) -> Camera:
    """Camera from a JSON file or an inline JSON object (keys: eye, target, up, fovy_deg, width, height)."""
    where = "--camera"
    text = arg
    if not arg.lstrip().startswith("{"):
        path = Path(arg)
        if not path.is_file():
            raise InputError("file not found", where=f"--camera {arg}")
        with reading(path, "camera JSON"):
            text, where = path.read_text(encoding="utf-8"), str(path)
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON: {e}", where=where) from None
    if not isinstance(d, dict) or "eye" not in d or "target" not in d:
        raise InputError("a camera needs at least 'eye' and 'target'", where=where)
    extra = set(d) - {"eye", "target", "up", "fovy_deg", "width", "height"}
    if extra:
        raise InputError(f"unknown camera key(s) {sorted(extra)}", where=where)
    try:
        vec = {k: tuple(float(x) for x in d[k]) for k in ("eye", "target", "up") if k in d}
        if any(len(v) != 3 for v in vec.values()):
            raise ValueError("eye, target, up need 3 numbers")
        cam = Camera(**vec, fovy_deg=float(d.get("fovy_deg", 45.0)), width=int(d.get("width", 640)),
                     height=int(d.get("height", 480)))
    except (TypeError, ValueError) as e:
        raise InputError(f"bad camera: {e}", where=where) from None
    f = np.asarray(cam.target) - np.asarray(cam.eye)
    if not (0 < cam.fovy_deg < 180 and cam.width > 0 and cam.height > 0 and np.linalg.norm(f) > 0
            and np.linalg.norm(np.cross(f, cam.up)) > 0):
        raise InputError("bad camera: need eye != target, up not parallel to the view, 0 < fovy < 180, positive size",
                         where=where)
    return cam


def load_stroke(path: str) -> np.ndarray:
    """(m, 2) stroke pixels from a JSON file ({"points": [[x, y], ...]} or a bare list) or a CSV of x,y rows."""
    p = Path(path)
    if not p.is_file():
        raise InputError("file not found", where=f"--stroke {path}")
    if p.suffix.lower() != ".json":
        S = read_csv_numbers(p, 2, what="stroke CSV (x,y pixels per row)")
    else:
        with reading(p, "stroke JSON") as f:
            text = f.read_text(encoding="utf-8")
        try:
            d = json.loads(text)
            S = np.asarray(d["points"] if isinstance(d, dict) else d, np.float64)
        except (json.JSONDecodeError, KeyError, ValueError, TypeError) as e:
            raise InputError(f"cannot read stroke points ({e})", where=str(p)) from None
    if S.ndim != 2 or S.shape[1] != 2 or len(S) < 2 or not np.all(np.isfinite(S)):
        raise InputError("a stroke needs at least 2 finite (x, y) points", where=str(p))
    return S

