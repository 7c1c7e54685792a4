"""Outputs of a deployment: USD timeline, MJCF of the deployed state, PNG preview.

- USD: rods as linear basis curves with widths (the beam width), one time code per
  increment (0 = flat); each insert as an animated rigid mesh (its MuJoCo geometry); junction
  frames are not drawn.
- MJCF: the insert as a body at its final pose with its MuJoCo geom and mass, the rods as
  static capsule chains (one capsule per edge, radius = half the beam thickness, so the
  viewer shows the deployed shape; the rods are not re-simulated by MuJoCo).
- PNG: the deployed MJCF rendered offscreen (simfab.io.render).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simfab.rods import frames as fr


def rod_polylines(model, state) -> list[np.ndarray]:
    """One (k+1, 3) polyline per rod [m]."""
    return [state.x[r.nodes] for r in model.rods]


def write_usd(path, deployment) -> Path:
    from simfab.io.usd import StageWriter

    d = deployment
    model = d.cell.model
    w = StageWriter(path, up_axis="Z", meters_per_unit=1.0)
    w.add_curves("deploy/rods", color=(0.9, 0.85, 0.7))
    widths = [np.full(len(r.nodes), r.section.draw_width()) for r in model.rods]
    ins = d.insert
    V = np.asarray(ins.mesh.vertices)
    F = np.asarray(ins.mesh.faces)
    w.add_rigid("deploy/insert", V, F, color=(0.85, 0.45, 0.2))
    for t, st in enumerate(d.states):
        w.set_curves("deploy/rods", rod_polylines(model, st), widths, t)
        b = d.cell.insert_body
        w.set_pose("deploy/insert", st.body_pos[b], fr.matrix_to_quat(st.body_rot[b]), t)
    return w.save()


def write_mjcf(path, deployment, *, name: str = "deployed") -> Path:
    from simfab.io.mjcf import MJCFBuilder

    d = deployment
    model = d.cell.model
    st = d.states[-1]
    b = MJCFBuilder(name)
    b.floor(z=float(np.min(st.x[:, 2])) - 0.01, size=0.3)
    ins = d.insert
    ib = d.cell.insert_body
    body = b.body(ins.name, pos=st.body_pos[ib], quat=fr.matrix_to_quat(st.body_rot[ib]))
    b.mesh_asset(f"{ins.name}_mesh", ins.mesh.vertices, ins.mesh.faces)
    b.geom(body, type="mesh", mesh=f"{ins.name}_mesh", mass=max(ins.mass, 1e-6), rgba=[0.85, 0.45, 0.2, 1])
    rods = b.body("rods")
    for r in model.rods:
        P = st.x[r.nodes]
        rad = 0.5 * (r.section.thickness if r.section.shape == "rect" else 2 * r.section.radius)
        for i in range(len(P) - 1):
            b.geom(rods, type="capsule", fromto=np.concatenate([P[i], P[i + 1]]), size=[rad], contype=0,
                   conaffinity=0, mass=0, rgba=[0.95, 0.9, 0.75, 1], name=f"{r.name}_{i}")
    return b.save(path)


def write_png(png, mjcf_path) -> Path:
    from simfab.io.render import render_mjcf

    return render_mjcf(mjcf_path, png, width=640, height=480)
