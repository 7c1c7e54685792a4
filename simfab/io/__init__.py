"""File formats at simfab's boundary: USD stages, MJCF scenes, meshes, rendering, atomic writes.

- :mod:`simfab.io.usd`    time-sampled USD stages (meshes, curves, points, rigid bodies)
- :mod:`simfab.io.mjcf`   MuJoCo scenes, keyframe trajectories, MJCF generation
- :mod:`simfab.io.mesh`   mesh loading with validation and repair
- :mod:`simfab.io.companion` files a scene refers to (npz, CSV, meshes): any read failure is
  an InputError naming the file
- :mod:`simfab.io.render` offscreen PNGs (MuJoCo EGL, matplotlib fallback)
- :mod:`simfab.io.atomic` temp-file-and-rename writes
"""

from __future__ import annotations

import os
from pathlib import Path

# Headless by default: MuJoCo picks its GL backend when it is first imported.
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])


def inspect_file(path, *, units: str = "m") -> dict:
    """Summary and validation of a mesh, MJCF scene or USD stage (what ``simfab inspect`` prints).

    The format modules are imported here, not at the package's top: every module that writes a file
    imports this package (``simfab.io.atomic``), and MuJoCo, OpenUSD and trimesh take seconds.

    Args:
        path: a mesh (any suffix of :data:`simfab.io.mesh.SUFFIXES`), an MJCF ``.xml`` or a USD stage.
        units: the length unit a mesh file is in ("m", "mm", ...).

    Returns:
        A dict of JSON values: ``kind`` ("mesh", "mjcf" or "usd"), ``file`` and the format's figures
        (a mesh's repairs, problems and extents [m]; a scene's bodies, sites, keyframes and trajectory
        lengths [m]; a stage's prims, up axis, units and compliance errors).

    Raises:
        InputError: the file does not exist or its type is unknown.
    """
    from simfab.errors import InputError

    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", where=str(path))
    suf = path.suffix.lower()
    if suf == ".xml":
        return _inspect_mjcf(path)
    if suf in (".usd", ".usda", ".usdc"):
        return _inspect_usd(path)
    from simfab.io.mesh import SUFFIXES, read_mesh

    if suf in SUFFIXES:
        import dataclasses
        import warnings

        with warnings.catch_warnings():  # the report lists what was repaired
            warnings.simplefilter("ignore")
            mesh, report = read_mesh(path, units=units)
        from simfab.io.mesh import interior_faces, units_warning

        warn = units_warning(mesh.extents, units)
        inside = int(interior_faces(mesh.vertices, mesh.faces).sum()) if mesh.is_watertight else None
        problems = report.problems() + ([f"{inside} faces lie inside the solid (overlapping bodies or a "
                                         "self-intersecting surface)"] if inside else [])
        return {"kind": "mesh", "file": str(path), **dataclasses.asdict(report), "problems": problems,
                "usable_after_repair": bool(mesh.is_watertight) and not inside,
                "extents_m": [float(x) for x in mesh.extents],
                "units": units, "interior_faces": inside, "warnings": [warn] if warn else []}
    raise InputError(f"unknown file type {suf!r} (mesh, .xml or .usd/.usda/.usdc)", where=str(path))


def _inspect_mjcf(path: Path) -> dict:
    import mujoco

    from simfab.io.mjcf import Trajectory, load_mjcf

    s = load_mjcf(path)
    m = s.model
    out = {"kind": "mjcf", "file": str(path), "bodies": m.nbody - 1, "geoms": m.ngeom, "meshes": m.nmesh,
           "sites": sorted(s.sites), "keyframes": m.nkey, "flexes": m.nflex,
           "custom_numeric": sorted(s.custom_numeric), "custom_text": sorted(s.custom_text), "trajectories": {}}
    for b in range(1, m.nbody):
        if m.body_mocapid[b] >= 0 and m.nkey >= 2:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
            out["trajectories"][name] = {"length_m": Trajectory.from_scene(s, name).length}
    return out


def _inspect_usd(path: Path) -> dict:
    from pxr import UsdGeom

    from simfab.io.usd import check_compliance, open_stage

    st = open_stage(path)
    prims = {str(p.GetPath()): p.GetTypeName() for p in st.Traverse()}
    default = st.GetDefaultPrim()
    return {"kind": "usd", "file": str(path), "default_prim": str(default.GetPath()) if default else None,
            "up_axis": str(UsdGeom.GetStageUpAxis(st)), "meters_per_unit": UsdGeom.GetStageMetersPerUnit(st),
            "time_codes_per_second": st.GetTimeCodesPerSecond(), "start_time_code": st.GetStartTimeCode(),
            "end_time_code": st.GetEndTimeCode(), "prims": prims, "compliance_errors": check_compliance(path)}
