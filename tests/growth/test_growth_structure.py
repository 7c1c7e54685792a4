"""Structural check of grown supports (simfab.growth.structure): a straight strut against beam
theory, the load bookkeeping, and the [material] / [loads] tables."""

import numpy as np
import pytest

from simfab.errors import InputError
from simfab.growth.config import StructureConfig
from simfab.growth.scene import load_growth_scene
from simfab.growth.skeleton import Skeleton
from simfab.growth.structure import CheckConfig, buckling_factor, check_structure, corner_stress, target_loads

R, LENGTH, P = 0.004, 0.08, 1.0  # strut radius and length [m], tip load [N]


def _strut_scene(tmp_path, toml: str = ""):
    """A ground box (top face z = 0) with root_0 on it and target_0 straight above at z = LENGTH."""
    xml = tmp_path / "strut.xml"
    xml.write_text('<mujoco><worldbody><body name="ground"><geom type="box" size="0.03 0.03 0.005" '
                   f'pos="0 0 -0.005"/></body><site name="root_0" pos="0 0 0"/><site name="target_0" '
                   f'pos="0 0 {LENGTH}"/></worldbody></mujoco>')
    if toml:
        xml.with_suffix(".toml").write_text(toml)
    return xml


def _strut_skeleton(n: int = 9) -> Skeleton:
    """One chain from the root (z = 0) to the target (z = LENGTH), constant radius R."""
    z = np.linspace(0.0, LENGTH, n)
    return Skeleton(nodes=np.c_[np.zeros(n), np.zeros(n), z], parent=np.arange(-1, n - 1), birth=np.arange(n),
                    target=np.r_[np.full(n - 1, -1), 0], root=np.zeros(n, np.int64), radius=np.full(n, R),
                    target_names=("target_0",))


def _section(mesh, z: float):
    """Area A [m^2], second moment I_y = integral x^2 dA [m^4] and extreme fibre max |x| [m] of the
    skin's cross-section at height z (the polygon the tet mesh fills: the skin's 12-gon)."""
    pts = mesh.section(plane_origin=[0, 0, z], plane_normal=[0, 0, 1]).discrete[0][:, :2]
    x, y, x1, y1 = pts[:-1, 0], pts[:-1, 1], pts[1:, 0], pts[1:, 1]
    cr = x * y1 - x1 * y
    return abs(cr.sum()) / 2, abs((cr * (x * x + x * x1 + x1 * x1)).sum()) / 12, float(np.abs(pts[:, 0]).max())


@pytest.fixture(scope="module")
def strut(tmp_path_factory):
    scene = load_growth_scene(_strut_scene(tmp_path_factory.mktemp("strut")))
    return check_structure(_strut_skeleton(), scene, loads={"target_0": (P, 0.0, 0.0)},
                           options=CheckConfig(self_weight=False))


def test_strut_tip_deflection_matches_timoshenko(strut):
    """Cantilever clamped at z = 0, lateral force P at the tip patch (centroid z_c):

        delta = P z_c^3 / (3 E I) + P z_c / (kappa G A),  kappa = 6 (1 + nu) / (7 + 6 nu) (circle)

    with A and I of the mesh's own section (a 12-gon, 4.5 % / 8.8 % below the circle's). The
    tolerance, 5 %, is the issue's; the mesh the check uses (Gmsh, edge 2R: 836 tets) lands at
    0.969 (fTetWild's earlier meshes within 1 %)."""
    m = strut.model
    E, nu = m.material.youngs_modulus, m.material.poisson_ratio
    G = E / (2 * (1 + nu))
    A, I, _ = _section(strut.mesh, LENGTH / 2)
    zc = _load_centroid(strut)
    kappa = 6 * (1 + nu) / (7 + 6 * nu)
    ref = P * zc**3 / (3 * E * I) + P * zc / (kappa * G * A)
    assert strut.deflection_m["target_0"] == pytest.approx(ref, rel=0.05)
    # the deflection is the load's direction: the other components stay small
    assert strut.safety_factor == pytest.approx(m.material.yield_stress / strut.max_von_mises_Pa)


def _load_centroid(strut) -> float:
    """z [m] of the resultant of the tip load: the load-weighted mean height of its nodes."""
    m = strut.model
    tip = m.rest[:, 2] > LENGTH - 1.5 * R
    u = strut.u
    # the traction patch is every boundary facet within R of the target: its area centroid
    c = m.rest[m.boundary_facets[:, :3]].mean(axis=1)
    on = np.linalg.norm(c - [0, 0, LENGTH], axis=1) <= R
    corners = m.rest[m.boundary_facets[on, :3]]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    assert tip.any() and np.all(np.isfinite(u))
    return float(area @ c[on, 2] / area.sum())


def test_strut_root_stress_matches_beam_theory(strut):
    """Bending stress sigma_zz = M(z) x / I with M(z) = P (z_c - z): the least-squares fit of
    sigma_zz = x (a + b z) over the corners between 2R from the clamp and 2R from the load gives
    the root stress a c (c the extreme fibre) within 5 % of P z_c c / I.

    The check's peak is the mean over a ball of radius r_c = 0.5 mm (the default critical
    distance) at the root's surface: beam theory's mean over that half ball is the root stress
    times 1 - 3 r_c / (8 c) (the mean depth of a half ball is 3 r_c / 8). The check's is within
    10 % of it, at the clamped root, and below the largest unaveraged corner value: the ball is
    smaller than the elements here, so the peak is nearly the corner value at the clamp's edge,
    where the clamp's restraint of the Poisson contraction adds stress that depends on the mesh
    (the Gmsh mesh: 0.956 of beam theory; fTetWild's meshes gave 1.00-1.07 over six runs)."""
    m = strut.model
    _, I, c = _section(strut.mesh, LENGTH / 2)
    zc = _load_centroid(strut)
    root = P * zc * c / I
    sigma, _ = corner_stress(m, m.rest + strut.u)
    X = m.rest[m.corner_elements].reshape(-1, 3)
    szz = sigma[..., 2, 2].ravel()
    sel = (X[:, 2] > 2 * R) & (X[:, 2] < LENGTH - 2 * R)
    (a, b), *_ = np.linalg.lstsq(np.c_[X[sel, 0], X[sel, 0] * X[sel, 2]], szz[sel], rcond=None)
    assert abs(a) * c == pytest.approx(root, rel=0.05)
    assert abs(b) == pytest.approx(P / I, rel=0.05)
    rc = strut.critical_distance_m
    assert rc == 5e-4
    assert strut.max_von_mises_Pa == pytest.approx(root * (1 - 3 * rc / (8 * c)), rel=0.10)
    assert strut.peak_point[2] < 2 * R  # at the clamped root
    assert strut.max_von_mises_Pa < strut.max_point_von_mises_Pa


def test_column_buckling_load_matches_euler(tmp_path):
    """The strut as a column, clamped at its foot and pushed down at its top by P: the linearized
    buckling factor times P is Euler's critical load of a clamped-free column,
    P_cr = pi^2 E I / (4 z_c^2), within 10 % (the issue's tolerance; L / d = 10 is slender enough
    that shear adds < 1 %). Pulled instead, only local compression near the clamp and the load
    patch is left to buckle: the factor is many times larger.

    Mesh: edge 2R, the check's default (2 r_min): 1.014 of Euler's (fTetWild's meshes at its old
    default, 4 r_min, ranged 0.88-1.00 over repeated runs)."""
    scene = load_growth_scene(_strut_scene(tmp_path))
    opts = CheckConfig(self_weight=False, edge_length=2 * R)
    res = check_structure(_strut_skeleton(), scene, loads={"target_0": (0.0, 0.0, -P)}, options=opts)
    E = res.model.material.youngs_modulus
    _, I, _ = _section(res.mesh, LENGTH / 2)  # the 12-gon's I is the same about every axis
    zc = _load_centroid(res)
    lam = buckling_factor(res)
    assert lam * P == pytest.approx(np.pi**2 * E * I / (4 * zc**2), rel=0.10)
    pulled = check_structure(_strut_skeleton(), scene, loads={"target_0": (0.0, 0.0, P)}, options=opts)
    assert buckling_factor(pulled) > 5 * lam


def test_strut_self_weight_and_mass(tmp_path):
    """Self-weight alone of a vertical strut: axial, so the stress stays of the order of the root's
    rho g L (5x allows for the clamp's edge), the mass is rho V of the skin, and the top sinks."""
    scene = load_growth_scene(_strut_scene(tmp_path))
    res = check_structure(_strut_skeleton(), scene, loads={})
    rho = scene.structure.material.density
    assert res.mass_kg == pytest.approx(rho * res.mesh.volume, rel=1e-12)
    assert res.model.volume.sum() == pytest.approx(res.mesh.volume, rel=0.01)  # the simplified skin's
    assert res.max_point_von_mises_Pa < 5 * rho * 9.81 * LENGTH
    assert set(res.deflection_m) == {"target_0"}  # reported at every reached target
    top = res.model.rest[:, 2] > LENGTH
    assert np.all(res.u[top, 2] < 0)


def test_phone_weight_is_shared_among_its_targets(scenes_dir):
    """phone_stand: the phone (MJCF mass from its box and MuJoCo's default density 1000 kg/m^3)
    rests on all five targets; each carries a fifth of m g, straight down. The desk under the
    root is ground, not load."""
    from simfab.growth import grow

    scene = load_growth_scene(scenes_dir / "phone_stand.xml")
    sk = grow(scene, seed=0).skeleton
    loads = target_loads(scene, sk)
    m = 1000.0 * 0.075 * 0.008 * 0.15
    assert len(loads) == 5
    for ld in loads:
        assert ld.objects == ("phone",)
        np.testing.assert_allclose(ld.force, [0, 0, -m * 9.81 / 5], rtol=1e-9, atol=1e-12)
    extra = {ld.name: ld for ld in target_loads(scene, sk, {"target_0": (1.0, 0.0, 0.0)})}
    np.testing.assert_allclose(extra["target_0"].force, [1.0, 0, -m * 9.81 / 5])
    with pytest.raises(InputError):
        target_loads(scene, sk.replace(target=np.where(sk.target == 0, -1, sk.target)), {"target_0": (1, 0, 0)})


def test_surface_contacts_carry_the_egg(scenes_dir):
    """egg_holder_surface has no targets: the egg rests on the surface-mode contacts, which share
    its weight."""
    from simfab.growth import grow
    from simfab.growth.structure import body_masses

    scene = load_growth_scene(scenes_dir / "egg_holder_surface.xml")
    sk = grow(scene, seed=0).skeleton
    loads = target_loads(scene, sk)
    carrying = [ld for ld in loads if ld.objects]
    assert carrying and all(ld.name.startswith("contact_") and ld.objects == ("egg",) for ld in carrying)
    total = sum(ld.force for ld in carrying)
    np.testing.assert_allclose(total, [0, 0, -9.81 * body_masses(scene)["egg"]], rtol=1e-9)


def test_material_and_loads_tables(tmp_path):
    xml = _strut_scene(tmp_path, '[material]\nname = "VeroWhite"\nyield_stress = 4e7\ncritical_distance = 0.001\n'
                                 '[loads]\ntarget_0 = [0.0, 1.0, 0.0]\n')
    s = load_growth_scene(xml)
    assert isinstance(s.structure, StructureConfig)
    assert s.structure.material.name == "VeroWhite" and s.structure.material.yield_stress == 4e7
    assert s.structure.material.youngs_modulus == 2.5e9 and s.structure.critical_distance == 1e-3
    assert s.structure.loads == (("target_0", (0.0, 1.0, 0.0)),)


@pytest.mark.parametrize("toml, where", [
    ("[material]\nstiffness = 1.0\n", "[material]"),
    ("[material]\nname = \"steel\"\n", "material.name"),
    ("[material]\npoisson_ratio = 0.5\n", "material.poisson_ratio"),
    ("[material]\ndensity = -1\n", "material.density"),
    ("[loads]\ntarget_0 = [1, 2]\n", "loads.target_0"),
    ("[loads]\ntarget_9 = [1, 2, 3]\n", "[loads]"),
])
def test_bad_structure_tables_name_file_and_key(tmp_path, toml, where):
    xml = _strut_scene(tmp_path, toml)
    with pytest.raises(InputError) as e:
        load_growth_scene(xml)
    assert "strut.toml" in str(e.value) and where in str(e.value)


def test_geometric_stiffness_is_the_second_variation(strut):
    """u . K_G u = sum_q w_q sigma_q : (grad u_q^T grad u_q) for any u (the quadratic form of the
    stress stiffness), checked with a random u against the quadrature written out."""
    from simfab.growth.structure import geometric_stiffness

    m = strut.model
    sigma, _ = corner_stress(m, m.rest + strut.u)
    KG = geometric_stiffness(m, sigma)
    u = np.random.default_rng(0).normal(size=m.rest.shape) * 1e-4
    gu = np.einsum("mai,mqaj->mqij", u[m.elements], m.grad_N)  # (grad u)_ij = du_i / dX_j
    sq = np.einsum("qc,mcij->mqij", m.qp_bary, sigma)
    direct = np.einsum("mq,mqjk,mqij,mqik->", m.qp_weight, sq, gu, gu)
    assert u.ravel() @ (KG @ u.ravel()) == pytest.approx(direct, rel=1e-10)
    assert abs(KG - KG.T).max() <= 1e-12 * abs(KG).max()
