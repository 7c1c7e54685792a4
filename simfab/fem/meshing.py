"""Simplicial meshing: 2D with Shewchuk's Triangle (quality constrained Delaunay), 3D with Gmsh
(surfaces remeshed at their feature edges, then Delaunay; boxes graded toward a point), fTetWild
where Gmsh cannot load or mesh a surface.

Units are whatever the input is in (SI metres inside simfab).
"""

from __future__ import annotations

import contextlib
import tempfile
import warnings

import numpy as np
import shapely
import triangle

from simfab.errors import InputError
from simfab.fem.tolerances import DEGENERATE_REL
from simfab.io.mesh import MeshWarning

#: Refuse meshing requests that would need more elements than this (the mesher would otherwise
#: run until memory runs out on slivers, near-zero areas or absurd size targets).
MAX_ELEMENTS = 2_000_000
#: dihedral angle [deg] above which a surface edge is a feature the remeshed boundary keeps
FEATURE_ANGLE_DEG = 40.0
#: fTetWild's default edge length, as a fraction of the bounding-box diagonal
TETWILD_EDGE_FAC = 0.05
#: surface simplification tolerances tried in turn, as fractions of the edge length, when Gmsh
#: cannot remesh the surface as given (thin features: edges far shorter than the target size)
SIMPLIFY_RETRY_REL = (0.0, 0.03, 0.1)
#: relative miss of ``target_tets`` above which the edge length is corrected once and the part remeshed
COUNT_TOL = 0.15


def _as_loop(poly, where: str) -> np.ndarray:
    p = np.asarray(poly, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
        raise InputError(f"polygon must be a (k>=3, 2) array, got shape {p.shape}", where=where)
    if not np.all(np.isfinite(p)):
        raise InputError("polygon contains NaN or inf", where=where)
    if np.allclose(p[0], p[-1]):  # closed explicitly: drop the repeated vertex
        p = p[:-1]
    return p


def triangulate_polygon(outline, *, holes=(), max_area: float | None = None, min_angle: float = 30.0):
    """Quality triangulation of a polygon with holes.

    Args:
        outline: (k, 2) vertices of the outer boundary (either orientation, not self-intersecting)
        holes: sequence of (k_i, 2) hole boundaries lying inside the outline
        max_area: maximum triangle area [units^2]; None: no area constraint
        min_angle: minimum angle [deg] (Triangle guarantees termination for <= ~33 deg)

    Returns V (n, 2) float64 and F (m, 3) int32, counter-clockwise (positive) triangles. The
    polygon's boundary segments are kept (Steiner points may split them).
    """
    outer = _as_loop(outline, "outline")
    loops = [outer] + [_as_loop(h, f"holes[{i}]") for i, h in enumerate(holes)]
    poly = shapely.Polygon(outer, [h for h in loops[1:]])
    if not poly.is_valid:
        raise InputError(f"polygon is not valid ({shapely.is_valid_reason(poly)}): self-intersecting, "
                         "collinear or with repeated vertices", where="outline")
    if max_area is not None and not (np.isfinite(max_area) and max_area > 0):
        raise InputError(f"max_area must be > 0, got {max_area}", where="max_area")
    check_polygon_size(poly, max_area)
    if not (0.0 <= min_angle <= 34.0):
        raise InputError(f"min_angle must be in [0, 34] degrees, got {min_angle}", where="min_angle")

    verts, segs, offset = [], [], 0
    for loop in loops:
        k = len(loop)
        verts.append(loop)
        segs.append(np.stack([np.arange(k), (np.arange(k) + 1) % k], 1) + offset)
        offset += k
    data = {"vertices": np.vstack(verts), "segments": np.vstack(segs)}
    if len(loops) > 1:
        # a point strictly inside each hole tells Triangle which regions to carve out
        data["holes"] = np.array([shapely.Polygon(h).representative_point().coords[0] for h in loops[1:]])
    opts = f"pq{min_angle:g}"
    if max_area is not None:
        opts += "a" + np.format_float_positional(float(max_area), trim="-")  # Triangle cannot parse 1e-6
    out = triangle.triangulate(data, opts + "Q")
    V = np.asarray(out["vertices"], dtype=np.float64)
    F = np.asarray(out["triangles"], dtype=np.int32)
    # drop vertices Triangle leaves unreferenced (none expected; keep the mesh valid regardless)
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    if not used.all():
        remap = np.cumsum(used) - 1
        V, F = V[used], remap[F].astype(np.int32)
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    neg = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    F[neg] = F[neg][:, [0, 2, 1]]
    return V, F


def check_polygon_size(poly, max_area: float | None = None) -> None:
    """Fail fast on polygons a quality mesher cannot finish: zero area, slivers whose quality
    mesh needs more than :data:`MAX_ELEMENTS` triangles, vertices/edges closer than roundoff,
    or an area bound asking for too many triangles.

    A quality (minimum-angle) triangulation of a strip of width w and length L needs about
    L / w triangles; with w ~ 2 A / P and L ~ P / 2 that is ~ P^2 / (4 A).
    """
    A, P = float(poly.area), float(poly.length)
    lo, hi = np.asarray(poly.bounds[:2]), np.asarray(poly.bounds[2:])
    diag = float(np.linalg.norm(hi - lo))
    if not A > 1e-12 * diag * diag:
        raise InputError(f"polygon has (near) zero area ({A:.3g}); collinear or degenerate outline", where="outline")
    if P * P / (4.0 * A) > MAX_ELEMENTS:
        raise InputError(f"polygon is a sliver (mean width {2 * A / P:.3g} vs perimeter {P:.3g}); a quality mesh "
                         f"would need more than {MAX_ELEMENTS} triangles", where="outline")
    clearance = float(shapely.minimum_clearance(poly))
    if clearance < 1e-9 * diag:
        raise InputError(f"polygon has vertices or edges {clearance:.3g} apart (bounding box {diag:.3g}); "
                         "remove near-duplicate vertices", where="outline")
    if max_area is not None and A / max_area > MAX_ELEMENTS:
        raise InputError(f"element size asks for about {A / max_area:.3g} triangles (limit {MAX_ELEMENTS})",
                         where="max_area")


def tetrahedralize(vertices, faces, *, edge_length_fac: float | None = None, target_tets: int | None = None,
                   coarsen: bool = False):
    """Tetrahedral mesh of the volume enclosed by a triangle surface, the same in every process.

    Gmsh remeshes the surface patch by patch between its feature edges and fills it by Delaunay
    (:func:`gmsh_tets`), deterministic on one thread; where it rejects the surface as given (thin
    features whose edges are far shorter than the target size), the surface is first simplified
    (``SIMPLIFY_RETRY_REL``: vertices move by at most 3 %, then 10 %, of the edge length). Where
    Gmsh cannot load (its wheel needs the system's X11/GLU libraries) or mesh the surface, or
    leaves flat tets, fTetWild (pytetwild) meshes it instead, with a
    :class:`~simfab.io.mesh.MeshWarning`: fTetWild shuffles its input with a hardware random seed,
    so its mesh varies from run to run.

    Args:
        vertices: (n, 3) surface vertices; faces : (f, 3) triangles (closed surface)
        edge_length_fac: target edge length as a fraction of the bounding-box diagonal (0.05,
            fTetWild's default, when both this and ``target_tets`` are None)
        target_tets: approximate number of tetrahedra wanted; sets the absolute edge length from the
            enclosed volume assuming regular tets (V_tet = l^3 / (6 sqrt 2)), corrected once from
            the count the first mesh has when it misses by more than ``COUNT_TOL``.
        coarsen: (fTetWild only) let it coarsen the result as far as its quality bound allows.

    Returns:
        V (n, 3) float64 and T (m, 4) int32 positively oriented tets.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4 or not np.all(np.isfinite(v)):
        raise InputError(f"vertices must be a finite (n>=4, 3) array, got shape {v.shape}", where="surface")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 4 or f.min() < 0 or f.max() >= len(v):
        raise InputError(f"faces must be an (f>=4, 3) array of vertex indices, got shape {f.shape}", where="surface")
    if edge_length_fac is not None and target_tets is not None:
        raise InputError("give edge_length_fac or target_tets, not both", where="tetrahedralize")
    kwargs: dict = {}
    vol = _enclosed_volume(v, f)
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    if not vol > 1e-12 * diag**3:
        raise InputError(f"surface encloses (near) no volume ({vol:.3g}): open, flat or inward-facing", where="surface")
    if target_tets is not None:
        if not 1 <= target_tets <= MAX_ELEMENTS:
            raise InputError(f"target_tets must be in 1 .. {MAX_ELEMENTS}, got {target_tets}", where="target_tets")
        kwargs["edge_length_abs"] = float((6.0 * np.sqrt(2.0) * vol / target_tets) ** (1.0 / 3.0))
    elif edge_length_fac is not None:
        if not (0 < edge_length_fac <= 1):
            raise InputError(f"edge_length_fac must be in (0, 1], got {edge_length_fac}", where="edge_length_fac")
        # regular tets of edge l fill V with V / (l^3 / (6 sqrt 2)) elements
        n_est = vol / ((edge_length_fac * diag) ** 3 / (6.0 * np.sqrt(2.0)))
        if n_est > MAX_ELEMENTS:
            raise InputError(f"edge length asks for about {n_est:.3g} tetrahedra (limit {MAX_ELEMENTS})",
                             where="edge_length_fac")
        kwargs["edge_length_fac"] = float(edge_length_fac)
    if target_tets is not None:
        h = float(kwargs["edge_length_abs"])
    else:
        h = float(kwargs.get("edge_length_fac", TETWILD_EDGE_FAC)) * diag
    reason = ""
    for rel in SIMPLIFY_RETRY_REL:
        try:
            sv, sf = (v, f) if rel == 0 else _simplified(v, f, rel * h)
            X, T = gmsh_tets(sv, sf, h, remesh_surface=True)
            if target_tets is not None and abs(len(T) / target_tets - 1) > COUNT_TOL:
                # one secant step on the count ~ h^-3 (thin parts and Delaunay's own tet shapes
                # move it away from the regular-tet estimate)
                X, T = gmsh_tets(sv, sf, h * (len(T) / target_tets) ** (1 / 3), remesh_surface=True)
            if flat_tets(X, T).any():
                raise RuntimeError(f"{int(flat_tets(X, T).sum())} flat tetrahedra")
        except Exception as e:  # noqa: BLE001 - Gmsh raises a bare Exception with its last error
            reason = str(e).split(";")[0]
        else:
            return X, T
    warnings.warn(f"surface: Gmsh could not mesh it ({reason}); fTetWild meshed it instead, whose mesh (and "
                  "every figure computed on it) varies from run to run", MeshWarning, stacklevel=2)
    import pytetwild  # deferred for start-up time: importing it loads pyvista (~0.4 s)

    # fTetWild drops a scratch file (__tracked_surface.stl) into the working directory: run it
    # from a private temporary directory so callers' folders stay clean.
    with tempfile.TemporaryDirectory(prefix="simfab-tetwild-") as scratch, contextlib.chdir(scratch):
        V, T = pytetwild.tetrahedralize(v, f.astype(np.int32), quiet=True, coarsen=bool(coarsen), **kwargs)
    V = np.asarray(V, dtype=np.float64)
    T = np.asarray(T, dtype=np.int32)
    if len(T) == 0:
        raise InputError("fTetWild produced no tetrahedra (is the surface closed?)", where="surface")
    return V, _positive(V, T)


def _positive(V: np.ndarray, T: np.ndarray) -> np.ndarray:
    """T (m, 4) int32 with each negatively oriented tet's last two vertices swapped."""
    T = np.asarray(T, dtype=np.int32)
    neg = np.linalg.det(V[T[:, 1:]] - V[T[:, :1]]) < 0
    T[neg] = T[neg][:, [0, 1, 3, 2]]
    return T


def _simplified(v: np.ndarray, f: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The surface (v, f) with edges shorter than its features collapsed (manifold3d's
    ``simplify``: vertices move by at most ``tol``); raises RuntimeError if it is not a manifold."""
    import manifold3d  # deferred: only the retry after Gmsh rejected the raw surface needs it

    man = manifold3d.Manifold(manifold3d.Mesh(np.asarray(v, np.float32), np.asarray(f, np.uint32)))
    if man.status() != manifold3d.Error.NoError:
        raise RuntimeError(f"the surface is not a closed manifold ({man.status()})")
    m = man.simplify(float(tol)).to_mesh()
    return np.asarray(m.vert_properties[:, :3], np.float64), np.asarray(m.tri_verts, np.int64)


def flat_tets(V: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(m,) bool: the tets of (V, T) the FEM model would reject as degenerate (|det| <=
    ``DEGENERATE_REL`` h^3, h the mean edge length)."""
    i, j = np.triu_indices(4, 1)
    h = float(np.linalg.norm(V[T[:, i]] - V[T[:, j]], axis=-1).mean())
    return np.abs(np.linalg.det(V[T[:, 1:]] - V[T[:, :1]])) <= DEGENERATE_REL * h**3


def gmsh_tets(V: np.ndarray, F: np.ndarray, h: float, *, remesh_surface: bool) -> tuple[np.ndarray, np.ndarray]:
    """Tets of the volume bounded by the closed triangle surface (V, F): Gmsh's 3D Delaunay with
    interior edges of about ``h``, on one thread with a fixed seed (the same mesh, bit for bit, in
    every process).

    Args:
        V: (n, 3) surface vertices; F: (f, 3) outward triangles.
        h: target edge length, in V's units.
        remesh_surface: split the surface into patches at its feature edges (dihedral angle above
            ``FEATURE_ANGLE_DEG``), remesh each patch with edges of about ``h`` (points on the input
            triangles) and mesh the volume inside; False keeps the triangles as the boundary.

    Returns:
        (X (N, 3) float64, T (M, 4) int32 positively oriented), unused nodes dropped. Raises
        RuntimeError when Gmsh cannot load or mesh the surface, or leaves no tetrahedra.
    """
    with gmsh_session("volume") as gmsh:
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay: sequential and deterministic
        gmsh.option.setNumber("Mesh.MeshSizeMax", float(h))
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        s = gmsh.model.addDiscreteEntity(2)
        gmsh.model.mesh.addNodes(2, s, np.arange(1, len(V) + 1), np.asarray(V, np.float64).ravel())
        gmsh.model.mesh.addElementsByType(s, 2, [], (np.asarray(F, np.int64) + 1).ravel())
        if remesh_surface:
            gmsh.option.setNumber("Mesh.MeshSizeMin", float(h) / 3)
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
            gmsh.model.mesh.classifySurfaces(np.radians(FEATURE_ANGLE_DEG), True, True, np.pi)
            gmsh.model.mesh.createGeometry()
            loop = gmsh.model.geo.addSurfaceLoop([tag for _, tag in gmsh.model.getEntities(2)])
        else:
            gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
            loop = gmsh.model.geo.addSurfaceLoop([s])
        gmsh.model.geo.addVolume([loop])
        gmsh.model.geo.synchronize()
        gmsh.model.mesh.generate(3)
        X, T = gmsh_elements(gmsh, 4, 4)
    used = np.zeros(len(X), bool)
    used[T.ravel()] = True
    X, T = np.ascontiguousarray(X[used], np.float64), (np.cumsum(used) - 1)[T]
    if len(T) == 0:
        raise RuntimeError("no tetrahedra")
    return X, _positive(X, T)


def _enclosed_volume(v: np.ndarray, f: np.ndarray) -> float:
    """Signed volume enclosed by an outward-oriented triangle surface (divergence theorem)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def structured_box(lengths, cells):
    """Tetrahedral mesh of the box [0, lx] x [0, ly] x [0, lz]: nx*ny*nz cubes of 6 tets each
    (Freudenthal/Kuhn split along the main diagonal, conforming across cubes).

    Args:
        lengths: (lx, ly, lz) [m]; cells : (nx, ny, nz) >= 1. Returns V ((nx+1)(ny+1)(nz+1), 3) float64
    and T (6 nx ny nz, 4) int32, positively oriented.
    """
    lx, ly, lz = (float(v) for v in lengths)
    nx, ny, nz = (int(c) for c in cells)
    if min(nx, ny, nz) < 1 or not min(lx, ly, lz) > 0:
        raise InputError(f"box needs positive lengths and >= 1 cell per axis, got {lengths}, {cells}", where="box")
    g = np.stack(np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1), np.linspace(0, lz, nz + 1),
                             indexing="ij"), axis=-1).reshape(-1, 3)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))

    def vid(di, dj, dk):
        return ((i + di) * (ny + 1) + (j + dj)) * (nz + 1) + (k + dk)

    tets = []
    # the 6 monotone lattice paths from corner (0,0,0) to (1,1,1) of each cube
    for path in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        c = [0, 0, 0]
        verts = [vid(0, 0, 0)]
        for axis in path:
            c[axis] += 1
            verts.append(vid(*c))
        tets.append(np.stack(verts, axis=1))
    T = np.concatenate(tets).astype(np.int64)
    neg = np.linalg.det(g[T[:, 1:]] - g[T[:, :1]]) < 0
    T[neg] = T[neg][:, [0, 1, 3, 2]]
    return g, T.astype(np.int32)


GMSH_MISSING = ("graded meshes need Gmsh: pip install gmsh (an optional dependency: pip install -e '.[bench]'); "
                "its wheel also needs the system libraries libGLU, libXcursor, libXft and libXinerama "
                "(Debian: apt install libglu1-mesa libxcursor1 libxft2 libxinerama1)")


def load_gmsh():
    """The ``gmsh`` module, or RuntimeError(GMSH_MISSING) when it is not installed or cannot load
    its library (a bare system lacks the X11/GLU libraries the PyPI wheel links against)."""
    try:
        import gmsh  # deferred: optional, and its library may fail to load (handled here)
    except (ImportError, OSError) as e:
        raise RuntimeError(f"{GMSH_MISSING} ({type(e).__name__}: {e})") from None
    return gmsh


@contextlib.contextmanager
def gmsh_session(name: str):
    """A Gmsh session (``with gmsh_session("name") as gmsh:``) with one model ``name``, quiet and on one
    thread (deterministic: Gmsh's fixed seed), finalized on exit; RuntimeError(GMSH_MISSING) without Gmsh."""
    gmsh = load_gmsh()
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add(name)
        yield gmsh
    finally:
        gmsh.finalize()


def gmsh_elements(gmsh, element_type: int, nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """The generated mesh of a :func:`gmsh_session`: (X (N, 3) every node's coordinates, E (M, nodes)
    int64 rows into X) of its elements of Gmsh type ``element_type`` (3: 4-node quadrangles, 4:
    4-node tetrahedra)."""
    tags, coords, _ = gmsh.model.mesh.getNodes()
    _, conn = gmsh.model.mesh.getElementsByType(element_type)
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    return coords.reshape(-1, 3), index[conn.astype(np.int64)].reshape(-1, nodes)


def graded_box(lo, hi, *, centre, h0: float, growth: float, h_max: float | None = None):
    """Tetrahedral mesh of the box [lo, hi] graded toward a point (Gmsh, Delaunay + optimization).

    The target edge length grows linearly with the distance r to ``centre``:
    h(r) = min(h_max, h0 + growth * r) (growth ~ 0.1-0.3: each element about that fraction larger
    than its neighbour closer to the centre), so the elements stay well shaped (no needles, unlike a
    graded tensor grid) and a box many times the fine zone costs a few thousand elements more.

    Args:
        lo, hi: (3,) opposite corners [m]; centre : (3,) point the mesh is refined toward [m];
        h0: edge length at the centre [m]; growth : dh/dr; h_max : largest edge length (default: a
    quarter of the box's smallest side). Returns V (n, 3) float64 and T (m, 4) int32 positively
    oriented tets. Deterministic (Gmsh's fixed seed, one thread).
    """
    lo, hi, c = (np.asarray(a, dtype=np.float64).reshape(3) for a in (lo, hi, centre))
    size = hi - lo
    if not (np.all(np.isfinite(size)) and np.all(size > 0)):
        raise InputError(f"box corners must satisfy lo < hi, got {lo} and {hi}", where="box")
    h0, growth = float(h0), float(growth)
    h_max = 0.25 * float(size.min()) if h_max is None else float(h_max)
    if not (h0 > 0 and growth > 0 and h_max >= h0):
        raise InputError(f"graded mesh needs h0 > 0, growth > 0 and h_max >= h0 (got {h0}, {growth}, {h_max})",
                         where="graded_box")
    # elements: the integral of 6 sqrt(2) / h^3 (regular tets of edge h) over the box, by the midpoint
    # rule on a grid graded toward the centre along each axis (exact enough for a guard)
    def axis(a, b, x0):
        t = np.geomspace(1.0, 1e6, 48) - 1.0
        pts = np.unique(np.clip(np.r_[x0 - t * h0, x0 + t * h0, a, b], a, b))
        return 0.5 * (pts[1:] + pts[:-1]), np.diff(pts)

    (xm, dx), (ym, dy), (zm, dz) = (axis(lo[i], hi[i], c[i]) for i in range(3))
    r = np.sqrt((xm[:, None, None] - c[0]) ** 2 + (ym[None, :, None] - c[1]) ** 2 + (zm[None, None, :] - c[2]) ** 2)
    h = np.minimum(h_max, h0 + growth * r)
    n_est = float(np.sum(6 * np.sqrt(2) / h**3 * dx[:, None, None] * dy[None, :, None] * dz[None, None, :]))
    if n_est > MAX_ELEMENTS:
        raise InputError(f"graded mesh asks for about {n_est:.3g} tetrahedra (limit {MAX_ELEMENTS})", where="h0")
    with gmsh_session("graded_box") as gmsh:
        gmsh.model.occ.addBox(*lo, *size)
        gmsh.model.occ.synchronize()
        f = gmsh.model.mesh.field.add("MathEval")
        num = "{:.17g}".format
        r = f"sqrt((x-({num(c[0])}))^2+(y-({num(c[1])}))^2+(z-({num(c[2])}))^2)"
        gmsh.model.mesh.field.setString(f, "F", f"min({num(h_max)}, {num(h0)} + {num(growth)}*{r})")
        gmsh.model.mesh.field.setAsBackgroundMesh(f)
        for k in ("MeshSizeExtendFromBoundary", "MeshSizeFromPoints", "MeshSizeFromCurvature"):
            gmsh.option.setNumber(f"Mesh.{k}", 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)
        V, T = gmsh_elements(gmsh, 4, 4)  # 4-node tetrahedra
    used = np.unique(T)  # drop nodes of lower-dimensional entities not used by any tet (none, normally)
    remap = np.full(len(V), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    V, T = V[used], remap[T].astype(np.int32)
    neg = np.linalg.det(V[T[:, 1:]] - V[T[:, :1]]) < 0
    T[neg] = T[neg][:, [0, 1, 3, 2]]
    return V, T


def extrude_triangles(points, triangles, z0: float, z1: float, layers: int = 1):
    """Tetrahedral mesh of a 2D triangle mesh extruded along z over [z0, z1] in ``layers`` layers:
    each prism is split into 3 tets, the diagonal of each side quad running from the lower-index
    vertex's bottom to the other's top, so neighbouring prisms conform.

    A displacement that does not vary along z is represented exactly (it is the 2D linear triangle
    field), so in-plane bending is resolved as finely as by the 2D mesh: an extruded part bending
    in its plane needs layers only for what varies along z (e.g. the Poisson thickening).

    Args:
        points: (n, 2) [m]; triangles : (m, 3); layers >= 1. Returns V (n (layers + 1), 3) float64
    (layer-major: V[l * n + i] is point i at layer l) and T (3 m layers, 4) int32 positively oriented.
    """
    P = np.asarray(points, dtype=np.float64)
    F = np.asarray(triangles, dtype=np.int64)
    layers = int(layers)
    if layers < 1 or not z1 > z0:
        raise InputError(f"extrusion needs layers >= 1 and z1 > z0 (got {layers}, {z0}, {z1})", where="extrude")
    n = len(P)
    z = np.linspace(z0, z1, layers + 1)
    V = np.c_[np.tile(P, (layers + 1, 1)), np.repeat(z, n)]
    a, b, c = np.sort(F, axis=1).T  # a < b < c: the diagonal rule depends on the edge's two indices only
    T = []
    for lay in range(layers):
        o0, o1 = lay * n, (lay + 1) * n
        T += [np.c_[a + o0, b + o0, c + o0, c + o1], np.c_[a + o0, b + o0, b + o1, c + o1],
              np.c_[a + o0, a + o1, b + o1, c + o1]]
    T = np.vstack(T).astype(np.int32)
    neg = np.linalg.det(V[T[:, 1:]] - V[T[:, :1]]) < 0
    T[neg] = T[neg][:, [0, 1, 3, 2]]
    return V, T
