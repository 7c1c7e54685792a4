"""Log barrier: derivatives against finite differences, smoothness at d_hat, and the chain rule
through the IMLS field (energy of points near a sphere)."""

import numpy as np
import trimesh

from simfab.contact.barrier import barrier, barrier_gradient, barrier_hessian, point_barrier, project_psd
from simfab.contact.imls import build_imls, evaluate_imls

DHAT = 1e-5


def test_scalar_derivatives_match_finite_differences():
    d = np.random.default_rng(0).uniform(0.01, 0.99, 200) * DHAT
    h = 1e-6 * DHAT
    fd1 = (barrier(d + h, DHAT) - barrier(d - h, DHAT)) / (2 * h)
    fd2 = (barrier_gradient(d + h, DHAT) - barrier_gradient(d - h, DHAT)) / (2 * h)
    assert np.allclose(barrier_gradient(d, DHAT), fd1, rtol=1e-6)
    assert np.allclose(barrier_hessian(d, DHAT), fd2, rtol=1e-6)


def test_barrier_is_c2_at_dhat_positive_convex_and_infinite_at_contact():
    eps = 1e-9 * DHAT
    for fn in (barrier, barrier_gradient, barrier_hessian):
        assert abs(fn(np.array([DHAT - eps]), DHAT)[0]) < 1e-6 * max(1.0, DHAT)
        assert fn(np.array([DHAT + eps]), DHAT)[0] == 0.0
    d = np.linspace(0.001, 0.999, 100) * DHAT
    assert np.all(barrier(d, DHAT) > 0) and np.all(barrier_gradient(d, DHAT) < 0)
    assert np.all(barrier_hessian(d, DHAT) > 0)
    assert barrier(np.array([0.0, -1.0]), DHAT).tolist() == [np.inf, np.inf]


def test_point_barrier_chain_rule_through_imls():
    # B(y) = kappa sum b(-psi(y)) for points y near a sphere: gradient and (unprojected) Hessian vs FD.
    R = 0.01
    m = trimesh.creation.icosphere(subdivisions=3, radius=R)
    v = np.asarray(m.vertices)
    f = build_imls(v, v / R)
    dhat = 0.2 * f.sigma
    kappa = 3.0e4
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(30, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    y = dirs * (R + f.sigma**2 / R + rng.uniform(0.1, 0.6, 30)[:, None] * dhat)

    def energy(yy):
        e = evaluate_imls(f, yy)
        return np.array([point_barrier(-e.psi[i:i + 1], -e.grad[i:i + 1], None, dhat, kappa)[0]
                         for i in range(len(yy))])

    e = evaluate_imls(f, y)
    assert np.all(-e.psi > 0) and np.all(-e.psi < dhat)
    _, g, H = point_barrier(-e.psi, -e.grad, -e.hess, dhat, kappa, psd=False)
    h = 1e-4 * dhat
    for a in range(3):
        dy = np.zeros(3)
        dy[a] = h
        fd = (energy(y + dy) - energy(y - dy)) / (2 * h)
        assert np.allclose(g[:, a], fd, rtol=1e-5, atol=1e-8 * np.abs(g).max())
        ep, em = evaluate_imls(f, y + dy), evaluate_imls(f, y - dy)
        gp = point_barrier(-ep.psi, -ep.grad, None, dhat, kappa)[1]
        gm = point_barrier(-em.psi, -em.grad, None, dhat, kappa)[1]
        assert np.allclose(H[:, :, a], (gp - gm) / (2 * h), rtol=1e-4, atol=1e-6 * np.abs(H).max())


def test_psd_projection_clamps_only_negative_eigenvalues():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(20, 3, 3))
    A = A + np.swapaxes(A, 1, 2)
    P = project_psd(A)
    w, V = np.linalg.eigh(A)
    assert np.all(np.linalg.eigvalsh(P) >= -1e-12)
    assert np.allclose(P, np.einsum("kij,kj,klj->kil", V, np.maximum(w, 0), V))
