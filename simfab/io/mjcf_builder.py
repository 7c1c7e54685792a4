"""Generating MJCF from Python: :class:`MJCFBuilder` (saved validated by MuJoCo, atomically)."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from simfab.io.atomic import atomic_path
from simfab.io.mjcf_load import mujoco_module

__all__ = ["MJCFBuilder", "format_attribute"]


def format_attribute(v) -> str:
    """An MJCF attribute value as text.

    Args:
        v: a string (as it is), a boolean (true/false), a number or an array (space-separated; floats
            to 9 significant digits).

    Returns:
        The attribute text.
    """
    if isinstance(v, str):
        return v
    if isinstance(v, bool):
        return "true" if v else "false"
    a = np.asarray(v)
    if a.ndim == 0:
        return f"{float(a):.9g}" if a.dtype.kind == "f" else str(a.item())
    return " ".join(f"{x:.9g}" if a.dtype.kind == "f" else str(int(x)) for x in a.ravel())


class MJCFBuilder:
    """Build an MJCF model in Python and save it (validated by MuJoCo, atomically).

    Example::

        b = MJCFBuilder("deployed")
        b.mesh_asset("part", V, F)
        body = b.body("part", pos=[0, 0, 0])
        b.geom(body, type="mesh", mesh="part", rgba=[0.8, 0.6, 0.3, 1])
        b.save("out/deployed.xml")

    Attribute values may be strings, numbers, booleans or arrays (space-separated).

    Args:
        model_name: the ``<mujoco model>`` name.
        timestep: ``<option timestep>`` [s] (None: MuJoCo's default).
        gravity: ``<option gravity>`` (3,) [m/s^2] (None: MuJoCo's default).
    """

    def __init__(self, model_name: str = "simfab", *, timestep: float | None = None, gravity=None):
        self.root = ET.Element("mujoco", model=model_name)
        self.compiler = ET.SubElement(self.root, "compiler", angle="radian", autolimits="true")
        opt = ET.SubElement(self.root, "option")
        if timestep is not None:
            opt.set("timestep", format_attribute(timestep))
        if gravity is not None:
            opt.set("gravity", format_attribute(gravity))
        vis = ET.SubElement(self.root, "visual")
        ET.SubElement(vis, "global", offwidth="1280", offheight="960")
        ET.SubElement(vis, "headlight", ambient="0.35 0.35 0.35", diffuse="0.6 0.6 0.6")
        self.asset = ET.SubElement(self.root, "asset")
        ET.SubElement(self.asset, "texture", name="sky", type="skybox", builtin="gradient", rgb1=".55 .65 .75",
                      rgb2=".12 .12 .15", width="256", height="1536")
        ET.SubElement(self.asset, "texture", name="grid", type="2d", builtin="checker", rgb1=".72 .72 .72",
                      rgb2=".62 .62 .62", width="256", height="256")
        ET.SubElement(self.asset, "material", name="grid", texture="grid", texrepeat="8 8", reflectance="0")
        self.worldbody = ET.SubElement(self.root, "worldbody")
        ET.SubElement(self.worldbody, "light", name="top", pos="0 0 3", dir="0 0 -1", directional="true")
        self._sections: dict[str, ET.Element] = {}

    def section(self, tag: str) -> ET.Element:
        """The model's top-level section ``tag`` (e.g. ``"actuator"``), made on first use.

        Args:
            tag: the section's element name.

        Returns:
            Its element (children are added with :meth:`add`).
        """
        if tag not in self._sections:
            self._sections[tag] = ET.SubElement(self.root, tag)
        return self._sections[tag]

    _section = section  # the earlier name

    def add(self, parent: ET.Element, tag: str, **attrs) -> ET.Element:
        """A child element with formatted attributes (None values are skipped).

        Args:
            parent: the parent element.
            tag: the child's tag.
            **attrs: its attributes (see :func:`format_attribute`).


        Returns:
            The new element.
        """
        return ET.SubElement(parent, tag, {k: format_attribute(v) for k, v in attrs.items() if v is not None})

    def mesh_asset(self, name: str, vertices, faces) -> ET.Element:
        """An inline mesh asset (the MJCF stays self-contained).

        Args:
            name: the asset's name.
            vertices: (n, 3) [m].
            faces: (m, 3) triangle vertex indices.


        Returns:
            The new element.
        """
        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
            raise ValueError("mesh_asset needs vertices (n,3) and triangle faces (m,3)")
        return self.add(self.asset, "mesh", name=name, vertex=V, face=F)

    def body(self, name: str, parent: ET.Element | None = None, *, pos=(0, 0, 0), quat=(1, 0, 0, 0),
             mocap: bool = False, freejoint: bool = False, **attrs) -> ET.Element:
        """A body (mocap bodies must be children of the world).

        Args:
            name: the body's name.
            parent: its parent (None: the worldbody).
            pos: position (3,) [m] in the parent's frame.
            quat: orientation (w, x, y, z).
            mocap: a mocap body.
            freejoint: give it a free joint ``<name>_free``.
            **attrs: further attributes.


        Returns:
            The new element.
        """
        el = self.add(self.worldbody if parent is None else parent, "body", name=name, pos=pos, quat=quat,
                      mocap=True if mocap else None, **attrs)
        if freejoint:
            ET.SubElement(el, "freejoint", name=f"{name}_free")
        return el

    def geom(self, body: ET.Element, *, sdf: str | None = None, **attrs) -> ET.Element:
        """A geom in ``body``.

        Args:
            body: its body.
            sdf: the name of an :meth:`sdf_asset` (an SDF geom of that plugin instance); None: a plain geom.
            **attrs: type, size, mesh, rgba, pos, quat, contype, ...


        Returns:
            The new element.
        """
        if sdf is None:
            return self.add(body, "geom", **attrs)
        el = self.add(body, "geom", type="sdf", mesh=sdf, **attrs)
        ET.SubElement(el, "plugin", instance=sdf)
        return el

    def sdf_asset(self, name: str, plugin: str, **config) -> ET.Element:
        """An SDF plugin instance and the mesh asset MuJoCo renders it with; geoms use it through
        ``geom(body, sdf=name)``.

        Args:
            name: the instance's (and the mesh asset's) name.
            plugin: the plugin, e.g. ``"mujoco.sdf.torus"``.
            **config: the plugin's configuration (e.g. radius1, radius2 [m]).

        Returns:
            The mesh asset element.
        """
        ext = self.add(self.section("extension"), "plugin", plugin=plugin)
        inst = ET.SubElement(ext, "instance", name=name)
        for k, v in config.items():
            ET.SubElement(inst, "config", key=k, value=format_attribute(v))
        mesh = self.add(self.asset, "mesh", name=name)
        ET.SubElement(mesh, "plugin", instance=name)
        return mesh

    def site(self, body: ET.Element, name: str, pos, size=0.005, **attrs) -> ET.Element:
        """A named site (roots, targets, regions).

        Args:
            body: its body.
            name: the site's name.
            pos: position (3,) [m] in the body's frame.
            size: MuJoCo site size [m].
            **attrs: further attributes (type, rgba, ...).


        Returns:
            The new element.
        """
        return self.add(body, "site", name=name, pos=pos, size=size, **attrs)

    def floor(self, z: float = 0.0, size: float = 1.0) -> ET.Element:
        """A checkered ground plane.

        Args:
            z: its height [m].
            size: its half extent [m].


        Returns:
            The new element.
        """
        return self.geom(self.worldbody, name="floor", type="plane", pos=[0, 0, z], size=[size, size, 0.01],
                         material="grid")

    def key(self, name: str | None = None, **attrs) -> ET.Element:
        """A keyframe.

        Args:
            name: the key's name (None: unnamed).
            **attrs: ``mpos``, ``mquat``, ``qpos``, ``time``...


        Returns:
            The new element.
        """
        return self.add(self.section("keyframe"), "key", name=name, **attrs)

    def equality(self, tag: str, **attrs) -> ET.Element:
        """An equality constraint.

        Args:
            tag: ``"weld"`` (body1, body2, relpose) or ``"connect"`` (body1, body2, anchor).
            **attrs: its attributes.


        Returns:
            The new element.
        """
        return self.add(self.section("equality"), tag, **attrs)

    def custom_numeric(self, name: str, data) -> ET.Element:
        """A custom ``<numeric>`` parameter.

        Args:
            name: its name.
            data: a number or an array of numbers.


        Returns:
            The new element.
        """
        return self.add(self.section("custom"), "numeric", name=name, data=np.atleast_1d(np.asarray(data, float)))

    def custom_text(self, name: str, data: str) -> ET.Element:
        """A custom ``<text>`` parameter.

        Args:
            name: its name.
            data: its text.


        Returns:
            The new element.
        """
        return self.add(self.section("custom"), "text", name=name, data=data)

    def to_xml(self) -> str:
        """The MJCF document.

        Returns:
            The document as an indented string.
        """
        tree = ET.ElementTree(self.root)
        ET.indent(tree, space="  ")
        return ET.tostring(self.root, encoding="unicode") + "\n"

    def compile(self):
        """The current document compiled by MuJoCo.

        Returns:
            ``mujoco.MjModel`` (ValueError if MuJoCo rejects the document).
        """
        return mujoco_module().MjModel.from_xml_string(self.to_xml())

    def save(self, path: str | os.PathLike) -> Path:
        """Write the MJCF atomically after checking that MuJoCo loads it.

        Args:
            path: the file to write.

        Returns:
            The path written.
        """
        path = Path(path)
        with atomic_path(path) as tmp:
            tmp.write_text(self.to_xml(), encoding="utf-8")
            mujoco_module().MjModel.from_xml_path(str(tmp))  # raises before the rename if invalid
        return path
