"""Deterministic tetrahedral mesh of a support's skin for the structural check.

The skin (a manifold3d solid) is prepared in two exact, deterministic steps and handed to Gmsh's
3D Delaunay mesher (one thread, fixed seed) as its boundary, which Gmsh keeps as is:

1. ``Manifold.simplify(tol)`` collapses the sliver edges the booleans leave (down to 1e-7 m),
   moving the surface by at most ``tol`` (``SIMPLIFY_PER_RMIN`` r_min): Gmsh's boundary
   recovery rejects the raw skin's near-degenerate facets;
2. ``Manifold.refine_to_length(h)`` splits every edge longer than ``h`` (the points stay on the
   simplified surface's own triangles), so that the boundary, and the interior Gmsh grows from
   it, has edges of about ``h``.

The tet mesh conforms to that surface: its boundary facets are exactly the refined triangles.
Same skin and ``h`` give the same mesh, bit for bit, in any process (fTetWild, the mesher of
:func:`simfab.fem.meshing.tetrahedralize`, shuffles its input triangles with a hardware random
seed and does not). When Gmsh rejects a surface, the simplification tolerance grows
(``SIMPLIFY_RETRY``), as it does when Gmsh leaves flat (zero-volume) tets between near-coplanar
boundary facets; at the last tolerance such tets are dropped. Where Gmsh cannot load (its wheel needs the
system's X11/GLU libraries), fTetWild meshes the skin instead and ``SkinTets.mesher`` says so.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from simfab.errors import ConvergenceError

#: simplification tolerance as a fraction of the thinnest branch radius (the surface moves at most this)
SIMPLIFY_PER_RMIN = 0.01
#: tolerance multipliers tried in turn when Gmsh rejects the boundary
SIMPLIFY_RETRY = (1.0, 3.0, 10.0)


@dataclasses.dataclass(frozen=True, kw_only=True)
class SkinTets:
    """A tet mesh of a skin: ``vertices`` (n, 3) [m], ``tets`` (m, 4) int32 positively oriented,
    ``surface`` the meshed boundary (``trimesh.Trimesh``, the simplified and refined skin),
    ``simplify_m`` the simplification tolerance that was used [m] and ``mesher`` "gmsh" or, when
    Gmsh cannot load, "fTetWild (not deterministic: ...)"."""

    vertices: np.ndarray
    tets: np.ndarray
    surface: object
    simplify_m: float
    mesher: str = "gmsh"


def tetrahedralize_skin(mesh, *, edge_length: float, r_min: float) -> SkinTets:
    """Tetrahedralize the closed skin ``mesh`` (``trimesh.Trimesh``) with edges of about
    ``edge_length`` [m] (module docstring); ``r_min`` [m] the thinnest branch radius, the scale of
    the simplification tolerance.

    Returns:
        :class:`SkinTets`. Raises ConvergenceError when no tolerance gives a surface Gmsh meshes.
    """
    from simfab.fem.meshing import flat_tets, gmsh_tets, load_gmsh
    from simfab.growth.skinning import to_manifold, to_trimesh

    try:
        load_gmsh()
    except RuntimeError as e:
        from simfab.fem.meshing import tetrahedralize

        diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
        V, T = tetrahedralize(mesh.vertices, mesh.faces, edge_length_fac=min(1.0, 2.0 * edge_length / diag))
        return SkinTets(vertices=V, tets=T, surface=mesh, simplify_m=0.0,
                        mesher=f"fTetWild (not deterministic: {str(e).split(';')[0]})")
    man = to_manifold(mesh)
    if man is None:
        raise ConvergenceError("the skin is not a closed manifold: it cannot be tetrahedralized")
    last = ""
    for k in SIMPLIFY_RETRY:
        tol_m = k * SIMPLIFY_PER_RMIN * r_min
        surf = to_trimesh(man.simplify(tol_m).refine_to_length(edge_length))
        try:
            V, T = gmsh_tets(np.asarray(surf.vertices, np.float64), np.asarray(surf.faces, np.int64),
                             edge_length, remesh_surface=False)
        except Exception as e:  # noqa: BLE001 - Gmsh raises a bare Exception with its last error
            last = str(e)
            continue
        flat = flat_tets(V, T)
        if flat.any() and k != SIMPLIFY_RETRY[-1]:
            last = f"{int(flat.sum())} flat tetrahedra"
            continue  # a coarser simplification removes the near-coplanar boundary facets behind them
        if flat.any():  # zero-volume slivers between boundary facets: dropping them changes no volume
            T = T[~flat]
            used = np.zeros(len(V), bool)
            used[T.ravel()] = True
            V, T = V[used], (np.cumsum(used) - 1)[T].astype(np.int32)
        return SkinTets(vertices=V, tets=T, surface=surf, simplify_m=tol_m)
    raise ConvergenceError(f"Gmsh could not tetrahedralize the skin ({last})")

