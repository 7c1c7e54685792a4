"""Independent cross-check of the structural check with scikit-fem (pip install scikit-fem).

The same P2 tet mesh, the same clamped nodes and the same consistent nodal loads (the plate's
weight through the strut's contact patch, a side load and the strut's own weight) are solved by
scikit-fem's linear elasticity (its own P2 basis, assembly and Lame parameters from E and nu);
displacements and corner von Mises stresses must agree with simfab's within 1 %."""

import numpy as np
import pytest
from test_grow_check_contact import _plate_scene
from test_growth_structure import _strut_skeleton

from simfab.growth.scene import load_growth_scene
from simfab.growth.structure import check_structure

skfem = pytest.importorskip("skfem")


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    xml = _plate_scene(tmp_path_factory.mktemp("plate"), 0.001)
    scene = load_growth_scene(xml)
    return check_structure(_strut_skeleton(), scene, loads={"target_0": (0.5, 0.2, 0.0)})


def _skfem_solution(c):
    """(u (n, 3) at simfab's P2 nodes, von Mises (m, 4) at the element corners) from scikit-fem."""
    from scipy.sparse.linalg import spsolve
    from skfem import Basis, ElementTetP2, ElementVector, MeshTet, asm, condense
    from skfem.helpers import ddot, eye, sym_grad, trace
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    m = c.model
    nc = m.n_corners
    corners = np.asarray(m.corner_elements, np.int64)
    mesh = MeshTet(np.ascontiguousarray(m.rest[:nc].T), np.ascontiguousarray(corners.T))
    basis = Basis(mesh, ElementVector(ElementTetP2()))
    E, nu = m.material.youngs_modulus, m.material.poisson_ratio
    lam, mu = lame_parameters(E, nu)
    K = asm(linear_elasticity(lam, mu), basis)
    # simfab node -> scikit-fem node: corners are mesh vertices; midpoints are matched by their edge
    edges = np.sort(np.asarray(mesh.edges, np.int64).T, axis=1)
    key = {int(a) * nc + int(b): i for i, (a, b) in enumerate(edges)}
    se = np.sort(np.asarray(m.edges, np.int64), axis=1)
    node = np.r_[np.arange(nc), [mesh.p.shape[1] + key[int(a) * nc + int(b)] for a, b in se]]
    table = np.hstack([basis.nodal_dofs, basis.edge_dofs])  # (3, n_vertices + n_edges): x, y, z dofs per node
    dofs = table[:, node].T  # (n, 3) scikit-fem dof of simfab node i, component d
    f = np.zeros(basis.N)
    f[dofs.ravel()] = c.nodal_forces.ravel()
    fixed_dofs = dofs[c.fixed].ravel()
    x = np.zeros(basis.N)
    A, b, _, I = condense(K, f, D=fixed_dofs)
    x[I] = spsolve(A.tocsc(), b)
    u = x[dofs]
    # von Mises at the element corners: sigma = lam tr(eps) I + 2 mu eps, s = dev(sigma)
    cb = Basis(mesh, basis.elem, quadrature=(np.array([[0.0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), np.ones(4)))
    eps = sym_grad(cb.interpolate(x))
    sig = lam * trace(eps) * eye(np.ones_like(eps[0, 0]), 3) + 2.0 * mu * eps
    s = sig - trace(sig) / 3.0 * eye(np.ones_like(eps[0, 0]), 3)
    vm = np.sqrt(1.5 * ddot(s, s))
    return u, vm


def test_displacement_and_stress_match_scikit_fem(solved):
    c = solved
    assert c.loads[0].objects == ("plate",) and c.nodal_forces is not None
    u_ref, vm_ref = _skfem_solution(c)
    from simfab.growth.structure import corner_stress

    _, vm = corner_stress(c.model, c.model.rest + c.u)
    umax = np.abs(u_ref).max()
    assert umax > 0
    # the largest nodal difference relative to the largest displacement
    assert np.abs(c.u - u_ref).max() / umax < 0.01
    tip = np.argmax(np.linalg.norm(u_ref, axis=1))
    assert np.linalg.norm(c.u[tip] - u_ref[tip]) / np.linalg.norm(u_ref[tip]) < 0.01
    # corner von Mises stress: everywhere within 1 % of the peak, and the peak itself within 1 %
    assert np.abs(vm - vm_ref).max() / vm_ref.max() < 0.01
    assert vm.max() == pytest.approx(vm_ref.max(), rel=0.01)
