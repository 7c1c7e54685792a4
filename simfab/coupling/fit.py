"""Whether a 3D part's tets resolve the interference the object makes with it.

Gmsh remeshes a part's surface at the element size h and cuts its curved faces in chords (sagitta
~ h^2 / 8 r), so the interference the tets see, and the forces with it, depend on the mesh by about
as much as the tets' surface departs from the part's where the object presses. Near the object at
its deepest pose, over the tets' boundary facets' centroids and edge midpoints (their vertices lie on
the surface), the SURFACE_DEVIATION_PERCENTILE of that departure is compared with the object's
overlap with the part there; above SURFACE_DEVIATION_REL of it, a warning says about how many tets
bring it to that fraction (the chords' depth goes as h^2 ~ N^(-2/3)). ``simfab couple new`` checks
the tets it writes with the object at the seat (:mod:`simfab.coupling.author`), ``simfab couple
simulate`` a scene whose part is stored beside its surface, at the insertion's last pose
(:func:`scene_fit_warnings`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from simfab.fem.model import boundary_facets

#: the warning's threshold: the departure over the object's overlap with the part
SURFACE_DEVIATION_REL = 0.1
#: The departure quoted is this percentile over the tets' surface near the object: the typical one where the
#: object presses. (The largest is a spike where a corner too mild for Gmsh's feature detection is cut: on
#: the C-clip 0.10, 0.071, 0.079 mm at 900, 3,000, 12,000 tets, while the 90th percentile falls as h^2:
#: 0.038, 0.018, 0.008 mm.)
SURFACE_DEVIATION_PERCENTILE = 90.0


def surface_deviation(surface, points: np.ndarray, elements: np.ndarray,
                      near: Callable[[np.ndarray], np.ndarray]) -> tuple:
    """How far the tets' boundary departs from the part's surface near the object: over the boundary
    facets' centroids and edge midpoints that ``near`` accepts, the distances' SURFACE_DEVIATION_PERCENTILE
    and largest.

    Args:
        surface: the part's surface (trimesh) [m].
        points: (n, 3) the tets' vertices [m].
        elements: (m, 4) the tets.
        near: (k, 3) points [m] -> (k,) bool: inside the object or within reach of it at the pose checked.

    Returns:
        (the percentile [m], the largest [m]); (0, 0) when no facet is that near.
    """
    import trimesh

    F = boundary_facets(np.asarray(elements), 3)
    P = points[F]  # (f, 3, 3)
    q = np.concatenate([P.mean(axis=1), 0.5 * (P + np.roll(P, -1, axis=1)).reshape(-1, 3)])
    sel = np.asarray(near(q), dtype=bool)
    if not sel.any():
        return 0.0, 0.0
    _, dist, _ = trimesh.proximity.closest_point(surface, q[sel])
    return float(np.percentile(dist, SURFACE_DEVIATION_PERCENTILE)), float(dist.max())


def edge_length(surface, n_tets: int) -> float:
    """The edge length [m] of n_tets regular tets filling the part's volume."""
    return float((6.0 * np.sqrt(2.0) * abs(float(surface.volume)) / n_tets) ** (1.0 / 3.0))


def fit_warnings(surface, points: np.ndarray, elements: np.ndarray, overlap: float,
                 near: Callable[[np.ndarray, float], np.ndarray], *, scale: float = 1e-3, units: str = "mm",
                 flag: str = "--elements", at: str = "at its deepest pose") -> list:
    """[the warning line] when the tets' surface departs from the part's near the object by more than
    SURFACE_DEVIATION_REL of the object's overlap with the part there, else [].

    Args:
        surface: the part's surface (trimesh) [m].
        points: (n, 3) the tets' vertices [m]; elements: (m, 4) the tets.
        overlap: how deep the object reaches into the part at the pose checked [m] (<= 0: a clearance,
            nothing to warn of).
        near: (q (k, 3) [m], reach [m]) -> (k,) bool: inside the object or within reach of it at the pose
            checked (reach: twice the tets' edge length).
        scale, units: the lengths' unit in the message (metres per unit).
        flag: what sets the tets' count (``--elements``, ``[compliant] target_elements``).
        at: where the object is, in the message.

    Returns:
        A list of at most one line.
    """
    if not overlap > 0:  # (a clearance at the seat: no interference for the facets to cut into)
        return []
    h = edge_length(surface, len(elements))
    dev, top = surface_deviation(surface, points, elements, lambda q: near(q, 2.0 * h))
    if dev <= SURFACE_DEVIATION_REL * overlap:
        return []
    need = len(elements) * (dev / (SURFACE_DEVIATION_REL * overlap)) ** 1.5
    pct = f"{SURFACE_DEVIATION_PERCENTILE:.0f}"
    return [f"near the object {at} the tets' surface departs from the part's by {dev / scale:.3g} "
            f"{units} ({pct}th percentile; at most {top / scale:.3g} {units}; the tets' edges are {h / scale:.3g} "
            f"{units}), {100 * dev / overlap:.0f} % of the object's {overlap / scale:.3g} {units} overlap with the "
            f"part there: the forces there depend on the mesh by about as much; about {flag} "
            f"{_round_up(need)} brings it to {100 * SURFACE_DEVIATION_REL:.0f} % (it shrinks as the edges' square)"]


def scene_fit_warnings(cm, surface, s: float) -> list:
    """:func:`fit_warnings` of a 3D coupling model's tets against the part's surface they were meshed from,
    with the object at path length s (where it seats: the insertion's last pose); its overlap with the part
    there is the deepest its field reaches into the surface's vertices (their largest psi).

    Args:
        cm: the :class:`~simfab.coupling.model.CouplingModel` (3D; its linear mesh's tets are checked).
        surface: the part's surface (trimesh) in the scene's frame [m].
        s: the path length [m].

    Returns:
        A list of at most one line (naming ``[compliant] target_elements``).
    """
    fem = cm.fem.linear if cm.fem.element_order == 2 else cm.fem
    pose = cm.pose(float(s))
    overlap = float(cm.field.evaluate(np.asarray(surface.vertices, dtype=np.float64), pose, hessian=False).psi.max())
    return fit_warnings(surface, np.asarray(fem.rest), np.asarray(fem.elements), overlap,
                        lambda q, reach: cm.field.evaluate(q, pose, hessian=False).psi > -reach,
                        flag="[compliant] target_elements", at=f"where it comes to rest (s = {1e3 * s:.4g} mm)")


def _round_up(n: float) -> int:
    """n rounded up to two significant digits."""
    k = 10 ** max(0, int(np.floor(np.log10(max(n, 1.0)))) - 1)
    return int(np.ceil(n / k) * k)
