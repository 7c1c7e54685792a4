"""Skins are printable: watertight after an STL round trip, one body, carved by the objects."""

import pathlib

import numpy as np
import pytest
import trimesh

from simfab.growth import grow, skin_result
from simfab.growth.skinning import skin_skeleton

SCENES = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "growth"
SCENE_NAMES = sorted(p.stem for p in SCENES.glob("*.xml"))


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_skin_is_printable(name, tmp_path):
    r = grow(SCENES / f"{name}.xml", seed=0)
    mesh, rep, seconds = skin_result(r)
    assert rep.ok, rep
    # independent round trip through a file, vertices merged as a slicer would
    path = tmp_path / "skin.stl"
    mesh.export(path)
    rt = trimesh.load(path, process=True)
    assert rt.is_watertight and rt.is_volume
    assert len(rt.split(only_watertight=False)) == 1
    assert rt.volume > 0
    # the volume is what the tubes suggest: between the thinnest and the thickest tube
    sk = r.skeleton
    e = sk.edges
    length = np.linalg.norm(sk.nodes[e[:, 0]] - sk.nodes[e[:, 1]], axis=1).sum()
    assert rt.volume < np.pi * sk.radius.max() ** 2 * length + len(sk.nodes) * 4.2 * sk.radius.max() ** 3
    # every skeleton node is inside the skin (or on a carved contact face)
    inside = rt.contains(sk.nodes)
    assert inside.sum() >= 0.8 * len(sk.nodes)
    assert rep.nodes_contained == len(sk.nodes)
    # the objects are carved out: no skin inside them (volume of the intersection ~ 0)
    assert rep.objects_subtracted and not rep.objects_not_manifold
    assert rep.overlap_volume <= 1e-9 * rt.volume


def test_skin_does_not_penetrate_objects(tmp_path):
    """Points well inside each object are outside the skin (independent of the carve)."""
    r = grow(SCENES / "phone_stand.xml", seed=2)
    mesh, rep, _ = skin_result(r)
    for name, obj in r.scene.objects.items():
        # sample inside the object: shrink its surface samples towards the centroid a little
        pts = obj.sample(2000, seed=0)
        inner = obj.centroid + 0.98 * (pts - obj.centroid)
        inner = inner[obj.contains(inner)]
        assert len(inner) > 100
        assert not mesh.contains(inner).any(), name


def test_without_carving_the_skin_overlaps_the_objects():
    r = grow(SCENES / "phone_stand.xml", seed=0)
    _, rep, _ = skin_result(r, subtract=False)
    assert rep.overlap_volume > 0  # so the carve in the default path is doing real work


def test_non_manifold_objects_are_reported_not_silently_ignored():
    nodes = np.array([[0.0, 0, 0], [0.0, 0, 0.05], [0.02, 0, 0.08]])
    parent = np.array([-1, 0, 1])
    radius = np.array([0.006, 0.004, 0.003])
    open_box = trimesh.creation.box(extents=[0.1, 0.1, 0.01])
    open_box = trimesh.Trimesh(open_box.vertices, open_box.faces[:-2])  # a hole: not a closed manifold
    mesh, rep = skin_skeleton(nodes, parent, radius, {"broken": open_box})
    assert rep.objects_not_manifold == ["broken"] and rep.objects_subtracted == []
    assert rep.watertight and rep.bodies == 1 and rep.nodes_contained == 3
