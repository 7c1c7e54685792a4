"""Isotropic linear-elastic material constants for the Neo-Hookean model.

Values are representative datasheet figures for 3D-printing materials (SI units):

- PLA: NatureWorks Ingeo 4043D technical data sheet - tensile modulus ~3.6 GPa, tensile yield
  strength ~60 MPa, density 1.24 g/cm^3; Poisson ratio ~0.36 (common literature value for
  printed PLA). We use E = 3.5 GPa.
- VeroWhite (Stratasys VeroWhitePlus RGD835 PolyJet photopolymer) datasheet - tensile
  strength 50-65 MPa, modulus of elasticity 2.0-3.0 GPa, density 1.17-1.18 g/cm^3; Poisson ratio
  ~0.33 (typical of glassy acrylate photopolymers). We use E = 2.5 GPa, yield 60 MPa.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simfab.errors import InputError


@dataclass(frozen=True, kw_only=True)
class Material:
    """Isotropic elastic material of an FEM body.

    Args:
        name: identifier.
        youngs_modulus: E [Pa], > 0.
        poisson_ratio: nu [-], in (-1, 0.5).
        yield_stress: von Mises yield / failure stress [Pa], > 0.
        density: [kg/m^3], > 0.
    """

    name: str
    youngs_modulus: float
    poisson_ratio: float
    yield_stress: float
    density: float

    def __post_init__(self):
        def bad(field, why):
            raise InputError(f"{field}={getattr(self, field)!r} {why}", where=f"material {self.name!r}")

        for f in ("youngs_modulus", "yield_stress", "density"):
            v = getattr(self, f)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                bad(f, "must be a finite number > 0")
        nu = self.poisson_ratio
        if not isinstance(nu, (int, float)) or not math.isfinite(nu) or not (-1.0 < nu < 0.5):
            bad("poisson_ratio", "must lie in (-1, 0.5)")

    def lame(self) -> tuple[float, float]:
        """Lame parameters from E and nu (3D relations, also used for plane strain).

        mu = E / (2 (1 + nu)),  lambda = E nu / ((1 + nu)(1 - 2 nu)).

        Returns:
            (mu, lambda) [Pa].
        """
        E, nu = float(self.youngs_modulus), float(self.poisson_ratio)
        return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


PLA = Material(name="PLA", youngs_modulus=3.5e9, poisson_ratio=0.36, yield_stress=60e6, density=1240.0)
VEROWHITE = Material(name="VeroWhite", youngs_modulus=2.5e9, poisson_ratio=0.33, yield_stress=60e6, density=1175.0)

_BY_NAME = {m.name.lower(): m for m in (PLA, VEROWHITE)}


def material_by_name(name: str) -> Material:
    """A built-in material by (case-insensitive) name.

    Args:
        name: "PLA" or "VeroWhite".

    Returns:
        The :class:`Material`; InputError naming the choices otherwise.
    """
    try:
        return _BY_NAME[str(name).strip().lower()]
    except KeyError:
        raise InputError(f"unknown material {name!r}; known: {', '.join(m.name for m in _BY_NAME.values())}",
                         where="material") from None
