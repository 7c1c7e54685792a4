"""Ground truth of the structural survey: strength of 2D bracket designs by simfab's FEM.

Each design is a planar shape (outline with holes, metres) inside an L x H envelope, bolted
to a wall along x = 0 (all nodes there clamped) and loaded downward at its free end: a total
force P spread evenly over the end-face nodes (x = L) within ``load_radius`` of the load
point (L, y_load); the tip deflection is their mean downward displacement.
The shape is meshed with Triangle, modelled as a plane-strain Neo-Hookean plate of the given
thickness (:mod:`simfab.fem`), and brought to static equilibrium (min E(x) - f.x) by projected
Newton. The load is small enough (tip deflection ~1e-4 L for the solid design, ~1e-2 L for
the weakest) that the answer is essentially the linear-elastic compliance. "Strength" as the
survey defines it is the tip deflection under that load; scores map log deflections linearly
onto 1..5, 5 = stiffest.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from simfab.crowd.config import TOL
from simfab.crowd.plots import pyplot
from simfab.crowd.truth import scale_to_survey
from simfab.errors import InputError
from simfab.fem import elastic as nh
from simfab.fem.materials import material_by_name
from simfab.fem.meshing import triangulate_polygon
from simfab.fem.model import make_model
from simfab.io.atomic import save_figure
from simfab.solve.newton import minimize


@dataclasses.dataclass(frozen=True, kw_only=True)
class BracketSetup:
    """Envelope, load and discretization shared by all designs (SI units)."""

    length: float = 0.20  #: L, m, wall to load point
    height: float = 0.10  #: H, m, envelope height at the wall
    thickness: float = 0.01  #: out-of-plane thickness, m
    load: float = 20.0  #: total downward force P, N (small: linear-elastic regime)
    load_y: float = 0.09  #: height of the load point at x = L, m
    load_radius: float = 0.006  #: end-face nodes within this distance of the load point share the load, m
    material: str = "PLA"
    max_area: float = 8.0e-6  #: largest triangle, m^2 (edge ~ 4 mm, >= 3 across members)


def _circle(cx, cy, r, n=32):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def designs(s: BracketSetup = BracketSetup()) -> dict[str, tuple[np.ndarray, list[np.ndarray]]]:
    """Eight candidate brackets: name -> (outline (k, 2), holes [(k_i, 2)]), metres.

    All reach from the wall (x = 0) to the load point at (L, load_y) and carry the load
    across different topologies, from a solid plate to slender trusses.
    """
    L, H, y = s.length, s.height, s.load_y
    top = H  # flange top
    t = 0.012  # member width
    d = {}
    d["solid"] = (np.array([[0, 0], [L, 0], [L, H], [0, H]], float), [])
    d["tapered"] = (np.array([[0, 0], [L, y - t], [L, top], [0, top]], float), [])
    d["holes"] = (np.array([[0, 0], [L, 0], [L, H], [0, H]], float),
                  [_circle(0.04 + 0.05 * k, 0.05, 0.022) for k in range(3)])
    # shelf bracket: top flange plus a diagonal strut from the wall's foot
    strut = np.array([[0, 0], [t * 1.4, 0], [L - t, top - t], [L - t * 2.2, top - t]], float)
    import shapely

    flange = shapely.box(0, top - t, L, top)
    wall = shapely.box(0, 0, t, top)
    shelf = shapely.unary_union([flange, wall, shapely.Polygon(strut)])
    d["shelf"] = (np.array(shelf.exterior.coords)[:-1], [np.array(i.coords)[:-1] for i in shelf.interiors])
    # truss: tapered plate with three triangular openings
    outline = np.array([[0, 0], [L, y - t], [L, top], [0, top]], float)
    tri = []
    xs = np.linspace(0.0, L, 5)
    for a, b in zip(xs[:-1], xs[1:]):
        lo_a = (y - t) * a / L + t
        tri.append(np.array([[a + t, lo_a + 0.004], [b - t * 0.5, top - t], [a + t, top - t]], float))
    d["truss"] = (outline, [p for p in tri if shapely.Polygon(p).area > 1e-5])
    # L-shape: only a flange and a thin wall strip (weak: the flange bends as a cantilever)
    lshape = shapely.unary_union([shapely.box(0, top - 1.5 * t, L, top), shapely.box(0, 0, 1.5 * t, top)])
    d["l_shape"] = (np.array(lshape.exterior.coords)[:-1], [])
    # arch: quarter annulus from the wall's foot up to the tip
    ang = np.linspace(0, np.pi / 2, 40)
    R_out, R_in = L, L - 1.5 * t
    outer = np.column_stack([R_out * np.sin(ang), top - R_out * np.cos(ang) * (top / L)])
    inner = np.column_stack([R_in * np.sin(ang[::-1]), top - R_in * np.cos(ang[::-1]) * (top / L)])
    arch = shapely.unary_union([shapely.Polygon(np.vstack([outer, inner])).buffer(0), shapely.box(0, top - t, L, top),
                                shapely.box(0, 0, t, top)])
    d["arch"] = (np.array(arch.exterior.coords)[:-1], [np.array(i.coords)[:-1] for i in arch.interiors])
    # inverted taper: deep at the tip, shallow at the wall (the worst use of material)
    d["inverted"] = (np.array([[0, top - 2 * t], [L, 0], [L, top], [0, top]], float), [])
    for name, (o, holes) in d.items():
        if abs(o[:, 0].min()) > TOL.span_rel * L or abs(o[:, 0].max() - L) > TOL.span_rel * L:
            raise AssertionError(f"design {name} does not span the wall to the load point")
    return d


@dataclasses.dataclass(frozen=True, kw_only=True)
class BracketDeflection:
    name: str
    deflection: float  #: mean downward displacement of the loaded nodes, m
    area: float  #: design area, m^2
    n_triangles: int
    newton_iterations: int
    points: np.ndarray  #: (n, 2) rest positions, m
    triangles: np.ndarray  #: (m, 3)
    displacement: np.ndarray  #: (n, 2) equilibrium minus rest, m


def tip_deflection(outline, holes=(), *, setup: BracketSetup = BracketSetup(),
                   name: str = "design") -> BracketDeflection:
    """Mesh, clamp at x = 0, load at (L, load_y), solve statics; return the tip deflection."""

    P, T = triangulate_polygon(outline, holes=holes, max_area=setup.max_area)
    mat = material_by_name(setup.material)
    model = make_model(P, T, mat, thickness=setup.thickness)
    X = model.rest
    clamped = X[:, 0] <= TOL.span_rel * setup.length
    if clamped.sum() < 2:
        raise InputError(f"design {name!r} touches the wall (x = 0) at fewer than 2 nodes", where=name)
    # load on the free end face x = L only (nodes within load_radius of the load point there)
    on_tip = X[:, 0] >= setup.length * (1 - TOL.span_rel)
    loaded = on_tip & (np.abs(X[:, 1] - setup.load_y) <= setup.load_radius)
    if not loaded.any():
        raise InputError(f"design {name!r} has no end face at x = L within {setup.load_radius} m of the load point",
                         where=name)
    f = np.zeros_like(X)
    f[loaded, 1] = -setup.load / loaded.sum()
    fv = f.ravel()

    def fun(x, need_h):
        if need_h:
            E, g, H = nh.energy_gradient_hessian(model, x)
            return E - fv @ x, g.ravel() - fv, H
        E, g = nh.energy_gradient(model, x)
        return E - fv @ x, g.ravel() - fv, None

    res = minimize(fun, X.ravel().copy(), free=np.repeat(~clamped, 2),
                   admissible=lambda x: bool(np.all(nh.det_F(model, x) > 0)))
    x = res.x.reshape(-1, 2)
    u = x - X
    area = float(model.volume.sum()) / setup.thickness  # plane strain: element volume = area * thickness
    return BracketDeflection(name=name, deflection=float(-u[loaded, 1].mean()), area=area, n_triangles=len(T),
                         newton_iterations=res.iterations, points=P, triangles=T, displacement=u)


def bracket_survey(setup: BracketSetup = BracketSetup(), *, names=None) -> list[BracketDeflection]:
    """Tip deflection of every design (or of ``names``)."""
    d = designs(setup)
    names = list(d) if names is None else list(names)
    bad = [n for n in names if n not in d]
    if bad:
        raise InputError(f"unknown bracket design {bad[0]!r}; known: {', '.join(d)}", where="--designs")
    return [tip_deflection(*d[n], setup=setup, name=n) for n in names]


def strength_scores(results, *, lo: float = 1.0, hi: float = 5.0) -> np.ndarray:
    """Survey scores: linear in log tip deflection (compliances of candidate designs span
    orders of magnitude; linear scaling would crowd all but the weakest at the top),
    ``hi`` = smallest deflection (strongest), ``lo`` = largest."""

    return scale_to_survey(np.log([r.deflection for r in results]), lo=lo, hi=hi, higher_is_more=False)


def plot_brackets(results, scores, path) -> str:
    """Each design's mesh coloured by displacement magnitude |u| [mm] on one shared logarithmic
    colour scale (so the designs compare), deformation exaggerated by one common factor."""
    from matplotlib import cm, colors


    plt = pyplot()
    n = len(results)
    cols = min(4, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols + 1.0, 2.3 * rows + 0.6), constrained_layout=True)
    axes = np.atleast_1d(axes).ravel()
    umax = max(max(float(np.linalg.norm(r.displacement, axis=1).max()) for r in results), 1e-300)
    L = max(float(r.points[:, 0].max()) for r in results)
    k = 0.05 * L / umax  # the largest displacement of all designs drawn as 5 % of the length
    # the designs' displacements span orders of magnitude: a shared logarithmic scale over 3 decades
    norm = colors.LogNorm(vmin=umax * 1e3 * 1e-3, vmax=umax * 1e3, clip=True)
    for ax, r, s in zip(axes, results, scores):
        mag = np.maximum(np.linalg.norm(r.displacement, axis=1) * 1e3, norm.vmin)
        xy = r.points + k * r.displacement
        ax.tripcolor(xy[:, 0], xy[:, 1], r.triangles, mag, shading="gouraud", cmap="viridis", norm=norm)
        ax.set_title(f"{r.name}: tip {r.deflection * 1e3:.3g} mm, score {s:.1f}", fontsize=8)
        ax.set_aspect("equal")
        ax.axis("off")
    for ax in axes[n:]:
        ax.axis("off")
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap="viridis"), ax=axes.tolist(), shrink=0.8,
                 label="displacement |u| [mm] (log scale)")
    fig.suptitle(f"Bracket designs under the tip load (deformation x{k:.3g}; score 5 = stiffest)", fontsize=9)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return str(path)
