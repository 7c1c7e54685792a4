"""Outputs of a deployment: USD timeline, MJCF of the deployed state, PNG preview.

- USD (:func:`write_usd`): rods as linear basis curves with widths, one time code per increment
  (0 = flat); each insert an animated rigid mesh.
- MJCF (:func:`write_mjcf`): the insert at its final pose; the rods as static capsule chains
  (``rods="capsules"``, default), as MuJoCo 1D ``flexcomp`` cables through the deployed nodes
  (``rods="flexcomp"``: edge lengths kept by equality constraints, no bending stiffness, no
  gravity; MuJoCo takes the initial shape as rest shape, so the file carries the deployed geometry,
  not simfab's stresses), or the mechanically faithful scene of :mod:`simfab.deploy.mjcf_sim`
  (``rods="chain"``: opens on the deployed state, hinge springs at rest in the flat state).
- PNG (:func:`write_png`): the deployed MJCF rendered offscreen (:mod:`simfab.io.render`).

Why the flexcomp cable carries no elasticity: docs/methods.md, "simfab.deploy.export".
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simfab.deploy import mjcf_sim
from simfab.io.mjcf import MJCFBuilder
from simfab.io.render import render_mjcf
from simfab.io.usd import StageWriter
from simfab.rods.model import material_curvatures
from simfab.rotations import matrix_to_quat

FLEX_TIMESTEP = 2e-3  # [s] time step of the flexcomp export


def rod_polylines(model, state) -> list[np.ndarray]:
    """The rods' centerlines.

    Args:
        model: the :class:`simfab.rods.model.RodModel`.
        state: its state.

    Returns:
        One (k+1, 3) [m] polyline per rod.
    """
    return [state.x[r.nodes] for r in model.rods]


def bending_strain(model, state) -> np.ndarray:
    """Largest bending fibre strain per node: ``|dk1| t/2 + |dk2| w/2`` over the Voronoi length, with
    ``dk`` the change of material curvature from the rest shape; 0 at rod ends.

    Args:
        model: the :class:`simfab.rods.model.RodModel`.
        state: its state.

    Returns:
        (N,) [-].
    """

    out = np.zeros(model.n_nodes)
    if model.n_hinges == 0:
        return out
    dk = np.abs(material_curvatures(model, state) - model.kappa_bar) / model.vor_len[:, None]
    half = np.zeros((model.n_edges, 2))
    for r in model.rods:
        half[r.edges] = r.section.half_extents()
    h = half[model.hinge_edges[:, 0]]
    out[model.hinge_nodes[:, 1]] = dk[:, 0] * h[:, 0] + dk[:, 1] * h[:, 1]
    return out


def write_usd(path, deployment) -> Path:
    """The deployment's timeline as USD; rods carry a per-vertex ``bending_strain`` primvar (colour scale
    0 .. the largest strain of the whole timeline).

    Args:
        path: the ``.usda`` file.
        deployment: the :class:`simfab.deploy.unitcell.CellDeployment`.

    Returns:
        The path.
    """

    d = deployment
    model = d.cell.model
    w = StageWriter(path, up_axis="Z", meters_per_unit=1.0)
    w.add_curves("deploy/rods", color=(0.9, 0.85, 0.7))
    widths = [np.full(len(r.nodes), r.section.draw_width()) for r in model.rods]
    ins = d.insert
    V = np.asarray(ins.mesh.vertices)
    F = np.asarray(ins.mesh.faces)
    w.add_rigid("deploy/insert", V, F, color=(0.85, 0.45, 0.2))
    strains = [bending_strain(model, st) for st in d.states]
    smax = max(float(np.max(e)) for e in strains) or 1.0
    for t, st in enumerate(d.states):
        w.set_curves("deploy/rods", rod_polylines(model, st), widths, t)
        w.set_scalar("deploy/rods", "bending_strain", strains[t], t, vmin=0.0, vmax=smax, units="-")
        b = d.cell.insert_body
        w.set_pose("deploy/insert", st.body_pos[b], matrix_to_quat(st.body_rot[b]), t)
    return w.save()


def write_mjcf(path, deployment, *, name: str = "deployed", rods: str = "capsules") -> Path:
    """The deployed state as MJCF (see the module doc).

    Args:
        path: the file.
        deployment: the :class:`simfab.deploy.unitcell.CellDeployment`.
        name: the model's name.
        rods: "capsules", "flexcomp" or "chain".

    Returns:
        The path.
    """
    if rods not in ("flexcomp", "capsules", "chain"):
        raise ValueError(f"rods must be 'flexcomp', 'capsules' or 'chain' (got {rods!r})")
    d = deployment
    if rods == "chain":

        ins = d.insert
        geoms = {ins.name: dict(mesh=(np.asarray(ins.mesh.vertices), np.asarray(ins.mesh.faces)),
                                mass=max(ins.mass, 1e-6))}
        sim = mjcf_sim.build(d.cell.model, d.states[0], d.states[-1], density=1200.0, cfg=mjcf_sim.SimConfig(),
                             name=name, body_geoms=geoms)
        return sim.save(path)
    model = d.cell.model
    st = d.states[-1]
    b = MJCFBuilder(name, timestep=FLEX_TIMESTEP if rods == "flexcomp" else None,
                    gravity=[0, 0, 0] if rods == "flexcomp" else None)
    if rods == "flexcomp":
        b.root.find("option").set("integrator", "discrete")
    b.floor(z=float(np.min(st.x[:, 2])) - 0.01, size=0.3)
    ins = d.insert
    ib = d.cell.insert_body
    body = b.body(ins.name, pos=st.body_pos[ib], quat=matrix_to_quat(st.body_rot[ib]))
    b.mesh_asset(f"{ins.name}_mesh", ins.mesh.vertices, ins.mesh.faces)
    b.geom(body, type="mesh", mesh=f"{ins.name}_mesh", mass=max(ins.mass, 1e-6), rgba=[0.85, 0.45, 0.2, 1])
    holder = b.body("rods") if rods == "capsules" else None
    for r in model.rods:
        P = st.x[r.nodes]
        rad = r.section.half_extents()[0]  # half the sheet thickness
        if rods == "capsules":
            for i in range(len(P) - 1):
                b.geom(holder, type="capsule", fromto=np.concatenate([P[i], P[i + 1]]), size=[rad], contype=0,
                       conaffinity=0, mass=0, rgba=[0.95, 0.9, 0.75, 1], name=f"{r.name}_{i}")
            continue
        k = len(P) - 1
        young, poisson = d.materials.get(r.name, (None, None))
        fc = b.add(b.worldbody, "flexcomp", name=r.name, type="direct", dim=1, radius=rad, point=P.ravel(),
                   element=np.stack([np.arange(k), np.arange(1, k + 1)], axis=1).ravel(), rgba=[0.95, 0.9, 0.75, 1],
                   mass=max(1e-6, rad * 1e-3))
        del young, poisson  # see the module doc: MuJoCo's 1D flex elasticity is unstable for these strips
        b.add(fc, "edge", equality="true")
        b.add(fc, "contact", contype=0, conaffinity=0)
        b.add(fc, "pin", id=[0, k])
    return b.save(path)


def write_png(png, mjcf_path) -> Path:
    """An MJCF rendered offscreen (:func:`simfab.io.render.render_mjcf`, 640 x 480).

    Args:
        png: the image file.
        mjcf_path: the MJCF.

    Returns:
        The image's path.
    """
    return render_mjcf(mjcf_path, png, width=640, height=480)
