"""Target families for the defaults' tests and benchmark (issue 42): shapes the bundled scenes do not cover.

:func:`members` names each member ``kind-parameters@rings`` and builds it as a bare mesh would
arrive (a :class:`simfab.deploy.surface.Target`, no scene settings):

- spherical caps of polar angle 30-85 deg on spheres of radius 60-200 mm;
- hyperbolic-paraboloid saddles over a 100 mm disk, curvature radius c from 200 mm down to the
  disk radius (slopes up to 45 deg at the rim), and one between them on a 90 mm disk (c = 110 mm);
- petals: folded along the midrib and curled along the length, and curled only;
- a cylinder patch (developable);
- a mixed-curvature patch (a saddle with an off-centre bump);

each at two triangulation resolutions (``rings``).
"""

from __future__ import annotations

import numpy as np

from simfab.deploy import surface

RESOLUTIONS = (12, 24)


def _shapes(rings: int) -> dict:
    return {
        "cap30-R200": lambda: surface.spherical_cap(0.2, np.radians(30), rings),
        "cap50-R150": lambda: surface.spherical_cap(0.15, np.radians(50), rings),
        "cap70-R100": lambda: surface.spherical_cap(0.1, np.radians(70), rings),
        "cap85-R60": lambda: surface.spherical_cap(0.06, np.radians(85), rings),
        "saddle-c200": lambda: surface.saddle(0.1, 0.2, rings),
        "saddle-c100": lambda: surface.saddle(0.1, 0.1, rings),
        "saddle-c110-a90": lambda: surface.saddle(0.09, 0.11, rings),
        "petal-folded": lambda: surface.petal(0.15, 0.08, 0.8, 0.01, 0.15, rings),
        "petal-curled": lambda: surface.petal(0.15, 0.08, 0.0, 0.01, 0.1, rings),
        "cylinder-R100": lambda: surface.cylinder(0.1, np.radians(90), 0.15, rings),
        "mixed": lambda: surface.mixed(0.1, 0.2, 0.025, 0.04, 0.05, rings),
    }


def names(resolutions=RESOLUTIONS) -> list:
    """Every member's name (``shape@rings``)."""
    return [f"{k}@{r}" for r in resolutions for k in _shapes(r)]


def member(name: str):
    """The target of one member (``shape@rings``, see :func:`names`).

    Args:
        name: the member's name.

    Returns:
        The :class:`simfab.deploy.surface.Target`, named ``name``.
    """
    shape, _, rings = name.partition("@")
    shapes = _shapes(int(rings)) if rings.isdigit() else {}
    if shape not in shapes:
        raise ValueError(f"family member {name!r}: not shape@rings with shape one of {', '.join(_shapes(12))}")
    t = shapes[shape]()
    return surface.Target(V=t.V, F=t.F, name=name)
