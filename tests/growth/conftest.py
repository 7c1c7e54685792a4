import pathlib

import numpy as np
import pytest

SCENES = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "growth"


@pytest.fixture(scope="session")
def scenes_dir():
    return SCENES


def segment_penetrations(nodes, edges, on_surface, meshes, centers, radii, *, samples=24, trim=1e-4):
    """Count segments with a sample point strictly inside a watertight object or a sphere.

    Points are sampled along each segment; ends that lie on a surface by design (roots,
    targets) are trimmed by ``trim`` [m] so that touching the surface is allowed.
    """
    e = np.asarray(edges)
    p, q = nodes[e[:, 0]], nodes[e[:, 1]]
    d = q - p
    length = np.linalg.norm(d, axis=1)
    t0 = np.where(on_surface[e[:, 0]], trim, 0.0) / np.maximum(length, 1e-300)
    t1 = 1.0 - np.where(on_surface[e[:, 1]], trim, 0.0) / np.maximum(length, 1e-300)
    s = np.linspace(0.0, 1.0, samples)
    t = t0[:, None] + (t1 - t0)[:, None] * s[None, :]
    X = p[:, None, :] + t[..., None] * d[:, None, :]
    flat = X.reshape(-1, 3)
    bad = np.zeros(len(flat), bool)
    for m in meshes:
        assert m.is_watertight
        bad |= m.contains(flat)
    for c, r in zip(centers, radii):
        bad |= np.linalg.norm(flat - c, axis=1) < r
    return int(bad.reshape(len(e), samples).any(axis=1).sum())


@pytest.fixture(scope="session")
def penetrations():
    return segment_penetrations
