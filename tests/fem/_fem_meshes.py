"""Structured test meshes (conforming, positively oriented)."""

import numpy as np

from simfab.fem.meshing import structured_box


def rect_tri(lx, ly, nx, ny, crossed=True):
    """Rectangle [0,lx]x[0,ly]; crossed: 4 triangles per cell around the cell centre (less stiff in
    bending than 2 per cell), else 2 per cell."""
    xs, ys = np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    pts = [np.c_[X.ravel(), Y.ravel()]]
    vid = lambda i, j: i * (ny + 1) + j  # noqa: E731
    tris = []
    nc = (nx + 1) * (ny + 1)
    if crossed:
        cx, cy = np.meshgrid((xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2, indexing="ij")
        pts.append(np.c_[cx.ravel(), cy.ravel()])
    for i in range(nx):
        for j in range(ny):
            a, b, c, d = vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)
            if crossed:
                m = nc + i * ny + j
                tris += [[a, b, m], [b, c, m], [c, d, m], [d, a, m]]
            else:
                tris += [[a, b, c], [a, c, d]]
    return np.vstack(pts), np.array(tris, dtype=np.int32)


def box_tet(lx, ly, lz, nx, ny, nz):
    """Box [0,lx]x[0,ly]x[0,lz] split into nx*ny*nz cubes of 6 tets each (Freudenthal/Kuhn)."""
    return structured_box((lx, ly, lz), (nx, ny, nz))


def box_tet24(lx, ly, lz, nx, ny, nz):
    """Box split into cubes of 24 tets each (cube centre + face centres): much less stiff in bending
    than the 6-tet split, so beam tests converge at coarser resolution."""
    xs, ys, zs = np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1), np.linspace(0, lz, nz + 1)
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    pts = [np.c_[X.ravel(), Y.ravel(), Z.ravel()]]
    vid = lambda i, j, k: (i * (ny + 1) + j) * (nz + 1) + k  # noqa: E731
    extra = {}

    def point(p):
        key = tuple(np.round(np.asarray(p) * 1e9).astype(np.int64))
        if key not in extra:
            extra[key] = len(pts[0]) + len(extra)
            pts.append(np.asarray(p, float)[None])
        return extra[key]

    tets = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                corner = {(a, b, c): vid(i + a, j + b, k + c) for a in (0, 1) for b in (0, 1) for c in (0, 1)}
                lo = np.array([xs[i], ys[j], zs[k]])
                hi = np.array([xs[i + 1], ys[j + 1], zs[k + 1]])
                cc = point((lo + hi) / 2)
                for axis in range(3):
                    for side in (0, 1):
                        fc = (lo + hi) / 2
                        fc[axis] = (lo, hi)[side][axis]
                        f = point(fc)
                        u, v = [a for a in range(3) if a != axis]
                        quad = []
                        for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                            c = [0, 0, 0]
                            c[axis], c[u], c[v] = side, du, dv
                            quad.append(corner[tuple(c)])
                        for q in range(4):
                            tets.append([quad[q], quad[(q + 1) % 4], f, cc])
    P = np.vstack(pts)
    T = np.array(tets, dtype=np.int64)
    d = P[T[:, 1:]] - P[T[:, :1]]
    neg = np.linalg.det(d) < 0
    T[neg] = T[neg][:, [0, 1, 3, 2]]
    return P, T.astype(np.int32)


def fd_grad_hess(model, x, eps):
    """Central differences of simfab.fem.elastic (linear or P2 model): gradient from energies,
    Hessian from gradients. (n*dim,), (n*dim, n*dim)."""
    from simfab.fem import elastic

    n = x.size
    g = np.zeros(n)
    H = np.zeros((n, n))
    for i in range(n):
        xp, xm = x.ravel().copy(), x.ravel().copy()
        xp[i] += eps
        xm[i] -= eps
        g[i] = (elastic.energy(model, xp) - elastic.energy(model, xm)) / (2 * eps)
        H[:, i] = (elastic.energy_gradient(model, xp)[1].ravel()
                   - elastic.energy_gradient(model, xm)[1].ravel()) / (2 * eps)
    return g, H
