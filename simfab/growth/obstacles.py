"""Collision tests of branch segments against object meshes and obstacle spheres.

Segments are tested in batches: the object meshes are merged into one triangle soup and
cast against with Embree (one ray per segment, first hit only, compared with the segment
length; trimesh's ray engine as a fallback), and spheres with a vectorized closest-point test.
"""

from __future__ import annotations

import numpy as np

from simfab.growth.tolerances import SEGMENT_END_TRIM


class Obstacles:
    """Everything a branch may not cross.

    Parameters
    ----------
    meshes : list of ``trimesh.Trimesh`` (world frame).
    centers : (s, 3) sphere centres [m]; radii : (s,) sphere radii [m].
    end_trim : length [m] removed from both ends of a segment before the mesh test, so that
        segments ending on a surface (roots, targets, contacts) are not reported as hits.
    """

    def __init__(self, meshes, centers, radii, *, end_trim: float):
        import trimesh

        meshes = [m for m in meshes if len(m.faces)]
        self.meshes = meshes
        self.mesh = trimesh.util.concatenate(meshes) if meshes else None
        self.centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
        self.radii = np.asarray(radii, dtype=np.float64).reshape(-1)
        self.end_trim = float(end_trim)
        self._embree = None  # built on first use; False when embreex is unavailable

    @classmethod
    def of_scene(cls, scene, diag: float) -> "Obstacles":
        """The objects and obstacle spheres of a :class:`~simfab.growth.scene.GrowthScene`;
        segment ends on a surface are trimmed by ``SEGMENT_END_TRIM`` × ``diag`` (a design-space
        diagonal [m])."""

        return cls(list(scene.objects.values()), scene.sphere_centers, scene.sphere_radii,
                   end_trim=SEGMENT_END_TRIM * diag)

    # ------------------------------------------------------------------ segments
    def segment_hits(self, p: np.ndarray, q: np.ndarray, p_on_surface=None, q_on_surface=None) -> np.ndarray:
        """(k,) bool: segment p[i]→q[i] crosses an object surface, enters a sphere, or leaves
        a surface point into a (watertight) object.

        ``p_on_surface`` / ``q_on_surface`` (k,) bool mark endpoints that lie on an object
        surface by design (roots, targets, contacts): the mesh test ignores ``end_trim`` at
        those ends, and they are not tested for being inside.
        """
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        q = np.asarray(q, dtype=np.float64).reshape(-1, 3)
        k = len(p)
        ps = np.zeros(k, bool) if p_on_surface is None else np.asarray(p_on_surface, bool).reshape(k)
        qs = np.zeros(k, bool) if q_on_surface is None else np.asarray(q_on_surface, bool).reshape(k)
        hit = np.zeros(k, dtype=bool)
        if k == 0:
            return hit
        if len(self.radii):
            hit |= self.sphere_hits(p, q)
        if self.mesh is not None:
            todo = np.nonzero(~hit)[0]
            if todo.size:
                hit[todo] = self.mesh_hits(p[todo], q[todo], ps[todo], qs[todo])
            # a segment that starts outside and crosses no surface ends outside; only one
            # leaving a surface point (the trimmed start may already be inside) needs the test
            todo = np.nonzero(~hit & ps & ~qs)[0]
            if todo.size:
                hit[todo] = self.inside(q[todo])
        return hit

    def mesh_hits(self, p: np.ndarray, q: np.ndarray, p_on_surface: np.ndarray, q_on_surface: np.ndarray) -> np.ndarray:
        """(k,) bool: segment p→q crosses a triangle of the object meshes (ends on a surface
        by design are trimmed by ``end_trim``, other ends by a negligible ``1e-3 end_trim``)."""
        d = q - p
        length = np.linalg.norm(d, axis=1)
        t0 = np.where(p_on_surface, self.end_trim, 1e-3 * self.end_trim)
        t1 = np.where(q_on_surface, self.end_trim, 1e-3 * self.end_trim)
        reach = length - t0 - t1
        usable = reach > 0
        out = np.zeros(len(p), dtype=bool)
        if not usable.any():
            return out
        idx = np.nonzero(usable)[0]
        u = d[idx] / length[idx, None]
        origins = p[idx] + t0[idx, None] * u
        out[idx] = self._first_hit_distance(origins, u) <= reach[idx]
        return out

    def _first_hit_distance(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(k,) distance along each unit ray to the first triangle (inf when none).

        Embree directly (one call, no per-call cache hashing); trimesh's ray engine when
        embreex is not installed.
        """
        if self._embree is None:
            self._embree = _embree_scene(self.mesh)
        if self._embree is not False:
            r = self._embree.run(origins.astype(np.float32), directions.astype(np.float32), output=1)
            return np.where(r["primID"] >= 0, r["tfar"].astype(np.float64), np.inf)
        out = np.full(len(origins), np.inf)
        _, ray_id, loc = self.mesh.ray.intersects_id(origins, directions, multiple_hits=False, return_locations=True)
        if len(ray_id):
            out[ray_id] = np.einsum("ij,ij->i", loc - origins[ray_id], directions[ray_id])
        return out

    def sphere_hits(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """(k,) bool: segment p→q comes closer than the radius to a sphere centre."""
        d = q - p  # (k,3)
        dd = np.einsum("ij,ij->i", d, d)
        w = self.centers[None, :, :] - p[:, None, :]  # (k,s,3)
        t = np.einsum("ksj,kj->ks", w, d) / np.where(dd > 0, dd, 1.0)[:, None]
        t = np.clip(t, 0.0, 1.0)
        closest = p[:, None, :] + t[..., None] * d[:, None, :]
        dist2 = np.sum((closest - self.centers[None]) ** 2, axis=-1)
        return np.any(dist2 < self.radii[None, :] ** 2, axis=1)

    # ------------------------------------------------------------------ points
    def inside(self, points: np.ndarray) -> np.ndarray:
        """(k,) bool: point inside a sphere or inside a watertight object mesh."""
        x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.zeros(len(x), dtype=bool)
        if len(self.radii):
            d2 = np.sum((x[:, None, :] - self.centers[None]) ** 2, axis=-1)
            out |= np.any(d2 < self.radii[None] ** 2, axis=1)
        for m in self.meshes:
            if not m.is_watertight:
                continue
            todo = np.nonzero(~out)[0]
            if todo.size == 0:
                break
            lo, hi = m.bounds
            box = np.all((x[todo] >= lo) & (x[todo] <= hi), axis=1)
            cand = todo[box]
            if cand.size:
                out[cand] = m.contains(x[cand])
        return out

    def surface_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest points (k, 3) on the object meshes and their distances (k,) [m]."""
        x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.mesh is None or len(x) == 0:
            return x.copy(), np.full(len(x), np.inf)
        c, d, _ = self.mesh.nearest.on_surface(x)
        return np.asarray(c), np.asarray(d)


def _embree_scene(mesh):
    """An Embree scene of the mesh triangles (float32), or False without embreex."""
    try:
        from embreex import mesh_construction, rtcore_scene
    except ImportError:
        return False
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene=scene, vertices=np.ascontiguousarray(mesh.triangles, dtype=np.float32))
    return scene
