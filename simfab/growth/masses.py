"""The masses of a growth scene's objects and where each comes from (the loads of the structural check).

MuJoCo computes a body's mass from its ``<inertial mass=...>``, else from its geoms: a geom's
``mass=``, else its ``density=`` (kg/m^3) times its volume, a ``<default>`` class supplying
either; without any of them MuJoCo's default density, 1000 kg/m^3 (water), applies.
:func:`object_masses` reports the mass MuJoCo computed and which of these set it.
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET

from simfab.errors import InputError

#: MuJoCo's default geom density [kg/m^3]
MUJOCO_DEFAULT_DENSITY = 1000.0


@dataclasses.dataclass(frozen=True, kw_only=True)
class ObjectMass:
    """``mass_kg`` [kg] of one object and its ``source``: "inertial mass=", "mass=",
    "density=<rho> kg/m^3", "default class" or "MuJoCo default density 1000 kg/m^3" (several
    joined by " + " when its geoms differ)."""

    name: str
    mass_kg: float
    source: str


def _sources(body, top_default) -> str:
    if body.find("inertial") is not None and body.find("inertial").get("mass") is not None:
        return "inertial mass="
    out = []
    for g in body.findall("geom"):
        if g.get("type") == "plane":
            continue
        if g.get("mass") is not None:
            s = "mass="
        elif g.get("density") is not None:
            s = f"density={float(g.get('density')):g} kg/m^3"
        elif g.get("class") is not None or (top_default is not None and (top_default.get("mass") is not None or
                                                                           top_default.get("density") is not None)):
            s = "default class"
        else:
            s = f"MuJoCo default density {MUJOCO_DEFAULT_DENSITY:g} kg/m^3"
        if s not in out:
            out.append(s)
    return " + ".join(out) or "none"


def object_masses(scene) -> dict:
    """Object name -> :class:`ObjectMass` (the MJCF model's body masses; the world's geoms have none).

    Args:
        scene: a :class:`simfab.growth.scene.GrowthScene` read from an MJCF file.

    Returns:
        dict name -> ObjectMass for every object of the scene ({} for a scene built in Python).
    """
    if scene.path is None:
        return {}
    from simfab.io.mjcf import load_mjcf

    sc = load_mjcf(scene.path)
    mass = {n: float(m) for n, m in zip(sc.body_names(), sc.model.body_mass)}
    try:
        root = ET.parse(scene.path).getroot()
    except ET.ParseError as e:  # MuJoCo read it, so this is not expected
        raise InputError(f"cannot read the MJCF for the mass sources: {e}", where=str(scene.path)) from None
    d = root.find("default")
    top_default = d.find("geom") if d is not None else None
    bodies = {b.get("name"): b for b in root.iter("body")}
    out = {}
    for name in scene.objects:
        b = bodies.get(name)
        src = _sources(b, top_default) if b is not None else "world (static, no mass)"
        out[name] = ObjectMass(name=name, mass_kg=mass.get(name, 0.0), source=src)
    return out
