"""Recorded Warp launches replayed through ``simfab._warp.Replay`` (the argument struct built once)
give the same bits as Warp's own replay, and the FEM workspace's Hessians share their pattern."""

import functools

import numpy as np
from _fem_meshes import rect_tri

from simfab._warp import Replay, wp
from simfab.fem.elastic import energy_gradient, energy_gradient_hessian
from simfab.fem.model import make_model


@wp.kernel
def _affine(a: wp.array(dtype=wp.float64), v: wp.array(dtype=wp.vec2d), s: wp.float64, k: int,
            out: wp.array(dtype=wp.float64), vout: wp.array(dtype=wp.vec2d)):
    i = wp.tid()
    out[i] = a[i] * s + wp.float64(k) + v[i][0] * v[i][1]
    vout[i] = v[i] * s


def test_replay_gives_warps_own_replay_bits():
    rng = np.random.default_rng(0)
    n = 37
    a_np, v_np = rng.standard_normal(n), rng.standard_normal((n, 2))
    a = wp.array(a_np, dtype=wp.float64, device="cpu", copy=False)
    v = wp.array(v_np, dtype=wp.vec2d, device="cpu", copy=False)
    out, vout = wp.zeros(n, dtype=wp.float64, device="cpu"), wp.zeros(n, dtype=wp.vec2d, device="cpu")
    cmd = wp.launch(_affine, dim=n, inputs=[a, v, 1.7, 3], outputs=[out, vout], device="cpu", record_cmd=True)
    fast = Replay(cmd)
    assert isinstance(fast.launch, functools.partial)  # the CPU fast path, not Launch.launch
    for _ in range(2):  # new inputs in the same buffers between replays
        a_np[:] = rng.standard_normal(n)
        v_np[:] = rng.standard_normal((n, 2))
        fast.launch()
        mine = (out.numpy().copy(), vout.numpy().copy())
        out.zero_()
        vout.zero_()
        cmd.launch()
        assert np.array_equal(mine[0], out.numpy()) and np.array_equal(mine[1], vout.numpy())
        np.testing.assert_allclose(mine[0], a_np * 1.7 + 3 + v_np[:, 0] * v_np[:, 1], rtol=1e-15)


def test_workspace_hessians_share_the_pattern_and_match_a_fresh_model():
    """Every Hessian of a model shares one set of CSR index arrays (the pattern's), with values of
    its own; energy, gradient and Hessian equal those of a fresh model (a first, recording launch)."""
    P, T = rect_tri(1.0, 0.5, 4, 3)
    rng = np.random.default_rng(1)
    x1, x2 = (P + 0.01 * rng.standard_normal(P.shape) for _ in range(2))
    model = make_model(P, T, material="PLA")
    E1, g1, H1 = energy_gradient_hessian(model, x1, project_psd=False)
    E2, g2, H2 = energy_gradient_hessian(model, x2, project_psd=False)
    assert H1.indices is H2.indices and H1.indptr is H2.indptr and H1.data is not H2.data
    assert H1.has_canonical_format and H1.shape == model.pattern.shape
    fresh = make_model(P, T, material="PLA")
    E, g, H = energy_gradient_hessian(fresh, x2, project_psd=False)
    assert E == E2 and np.array_equal(g, g2) and np.array_equal(H.toarray(), H2.toarray())
    assert not np.array_equal(H1.toarray(), H2.toarray())
    Eg, gg = energy_gradient(model, x1)
    assert Eg == E1 and np.array_equal(gg, g1)
