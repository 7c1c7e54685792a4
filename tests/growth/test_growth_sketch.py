"""Sketch edits: the chain moves onto the surface of rays through the stroke."""

import numpy as np
import pytest

from simfab.errors import InputError
from simfab.growth.skeleton import Skeleton
from simfab.growth.sketch import Camera, edit_chain, ray_surface, skeleton_chains


def _two_chains():
    # root at the origin, a junction at z = 0.2, two branches up to two targets
    a = [[0, 0, 0], [0, 0, 0.1], [0, 0, 0.2]]
    left = [[-0.02 * k, 0, 0.2 + 0.1 * k] for k in range(1, 9)]
    right = [[0.05 + 0.02 * k, 0, 0.2 + 0.05 * k] for k in range(1, 6)]
    nodes = np.array(a + left + right, float)
    parent = np.array([-1, 0, 1] + [2] + list(range(3, 10)) + [2] + list(range(11, 15)))
    target = np.full(len(nodes), -1)
    target[10], target[15] = 0, 1
    return Skeleton(nodes=nodes, parent=parent, birth=np.arange(len(nodes)), target=target,
                    root=np.zeros(len(nodes), int), radius=np.full(len(nodes), 0.01), target_names=("t0", "t1"))


def _camera():
    return Camera(eye=(0.0, -2.0, 0.5), target=(0.0, 0.0, 0.5), up=(0, 0, 1), fovy_deg=40, width=800, height=600)


def _dist_to_polyline(p, P):
    a, b = P[:-1], P[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
    return np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1))


def test_projection_round_trip():
    cam = _camera()
    X = np.random.default_rng(0).uniform([-0.3, -0.3, 0.2], [0.3, 0.3, 0.8], size=(20, 3))
    px = cam.project(X)
    d = cam.rays(px)
    v = X - np.array(cam.eye)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    assert np.allclose(d, v, atol=1e-12)
    # the view centre projects to the image centre
    assert np.allclose(cam.project(np.array([cam.target])), [[400, 300]])


def test_edit_moves_the_chain_onto_the_stroke_ray_surface():
    sk = _two_chains()
    cam = _camera()
    chains = skeleton_chains(sk)
    left = [i for i, c in enumerate(chains) if c[-1] == 10][0]
    P = cam.project(sk.nodes[chains[left]])
    # the stroke bulges 60 px to the left of the drawn chain
    s = np.linspace(0, 1, 30)
    stroke = P[0] + s[:, None] * (P[-1] - P[0]) + np.column_stack([-60 * np.sin(np.pi * s), np.zeros_like(s)])
    edited, rep = edit_chain(sk, cam, stroke)
    assert rep["chain"] == left  # picked automatically: the chain drawn nearest the stroke
    idx = chains[left]
    inner = idx[1:-1]
    # ends fixed, other nodes untouched
    assert np.array_equal(edited.nodes[[idx[0], idx[-1]]], sk.nodes[[idx[0], idx[-1]]])
    others = np.setdiff1d(np.arange(len(sk.nodes)), inner)
    assert np.array_equal(edited.nodes[others], sk.nodes[others])
    # moved nodes lie on the ray surface: on screen they lie on the stroke...
    q = cam.project(edited.nodes[inner])
    assert max(_dist_to_polyline(p, stroke) for p in q) < 1e-6
    # ... and each is the closest point of that surface to where the node was
    surf = ray_surface(cam, stroke, far=10.0)
    samples = surf.sample(20000, seed=0)
    for i in inner:
        best = np.linalg.norm(samples - sk.nodes[i], axis=1).min()
        assert np.linalg.norm(edited.nodes[i] - sk.nodes[i]) <= best + 1e-12
    assert rep["nodes_moved"] == len(inner) and rep["max_move"] > 0.01


def test_bad_strokes_and_chains():
    sk = _two_chains()
    with pytest.raises(InputError):
        edit_chain(sk, _camera(), np.array([[1.0, 2.0]]))
    with pytest.raises(InputError):
        edit_chain(sk, _camera(), np.array([[1.0, 2.0], [3.0, 4.0]]), chain=99)
