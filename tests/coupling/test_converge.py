"""Convergence-study helper: Richardson extrapolation recovers the limit of a sequence with a known
order, and the study refuses scenes whose part is only a ready mesh file."""

import numpy as np
import pytest

from simfab.coupling.converge import extrapolate, plain_log_ticks, run_levels
from simfab.errors import InputError


def test_extrapolation_recovers_the_limit_of_a_power_law():
    # f(N) = 3 + 5 h^2, h = N^(-1/2) (2D): three levels give the limit and the order exactly
    N = np.array([500, 1000, 2000, 4000])
    f = 3.0 + 5.0 * N ** (-1.0)
    f_inf, p = extrapolate(N, f, dim=2)
    assert f_inf == pytest.approx(3.0, rel=1e-9) and p == pytest.approx(2.0, rel=1e-6)


def test_scenes_with_only_a_ready_mesh_cannot_be_refined(tmp_path):
    # a part given only as a ready mesh file (no generator to mesh it again) cannot be refined
    import re
    import shutil

    from simfab.coupling.scene import load_coupling_scene, scene_paths
    from simfab.fem.meshing import extrude_triangles, triangulate_polygon

    xml, toml = scene_paths("clip3d")
    shutil.copy(xml, tmp_path / xml.name)
    V, T = extrude_triangles(*triangulate_polygon(np.array([[-0.0163, -0.01], [-0.012, -0.01], [-0.012, 0.01],
                                                            [-0.0163, 0.01]])), -0.004, 0.004)
    np.savez(tmp_path / "part.npz", points=V, elements=T)
    # the [compliant] table holds only the mesh file (a generator's parameters would be unknown keys)
    text = re.sub(r"\[compliant\][^\[]*", '[compliant]\ntarget_elements = 2700\nmesh_file = "part.npz"\n\n',
                  toml.read_text())
    (tmp_path / "clip3d.toml").write_text(text)
    assert load_coupling_scene(tmp_path / "clip3d.toml").fem.n_elements == len(T)  # the file is used
    with pytest.raises(InputError, match="target_elements"):
        run_levels(tmp_path / "clip3d.toml", (1, 2))


def test_figures_that_are_zero_report_errors_relative_to_their_peak():
    """An ejecting clip's F_rm (~1e-8 N: zero up to the solver's tolerances) and a loose coupling's
    E_ss are judged against F_in and E_max, not against themselves (which would read 99 % noise)."""
    from simfab.coupling.converge import Level, report

    N = [500, 1000, 2000, 4000]
    h2 = [1.0 / n for n in N]
    figs = [dict(E_max=4.5 + 10 * h, E_ss=1e-10 * (1 + (-1) ** i), F_in=1.7e4 + 1e5 * h,
                 F_rm=[8e-11, 2.4e-8, 2.2e-9, 1.9e-8][i], F_grip=9e3 + 1e4 * h) for i, h in enumerate(h2)]
    rep = report("x", [Level(factor=f, elements=n, seconds=1.0, figures=g, category="ejects")
                       for f, n, g in zip((0.5, 1, 2, 4), N, figs)], 2)
    F = rep.figures
    assert F["F_rm"].relative_of == "F_in" and F["E_ss"].relative_of == "E_max"
    assert max(abs(e) for e in F["F_rm"].relative_error) < 1e-11
    assert F["F_in"].relative_of == "F_in"
    assert F["F_in"].relative_error[0] == pytest.approx(1e5 / 500 / 1.7e4, rel=1e-6)  # exact power law: exact limit


def test_an_extrusion_is_refined_through_its_height_with_its_section():
    # uniform refinement: 8x the elements is 2x the layers and 4x the section's triangles
    from simfab.coupling.converge import level_mesh

    comp = {"generator": "extruded_clamp", "target_elements": 2700, "layers": 2}
    # the arcs' default sampling (96 points) follows the section: 4x its triangles, 2x the points on an arc
    assert level_mesh(comp, 8.0) == {"target_elements": 21600, "layers": 4, "segments": 192}
    assert level_mesh(comp, 1.0) == {"target_elements": 2700, "layers": 2}
    assert level_mesh(comp, 0.125)["layers"] == 1
    # a given sampling is the part's polygon: kept
    assert level_mesh(comp | {"segments": 48}, 8.0) == {"target_elements": 21600, "layers": 4}
    # the factor multiplies the elements the scene's mesh has where the generator's floor made more than asked
    assert level_mesh(comp, 2.0, elements=4692)["target_elements"] == 9384
    assert level_mesh(comp, 1.0, elements=4692) == {"target_elements": 2700, "layers": 2}  # the scene's own mesh
    # a shipped mesh is kept at factor 1 only; a generator that is not an extrusion has no layers
    shipped = {"generator": "cross_claw", "target_elements": 1000, "mesh_file": "part.npz"}
    assert level_mesh(shipped, 1.0) == {"target_elements": 1000}
    assert level_mesh(shipped, 2.0) == {"target_elements": 2000, "mesh_file": None}
    assert level_mesh(shipped, 2.0, elements=1300)["target_elements"] == 2000  # a tet mesher's count is its own


def test_clip3d_levels_have_the_element_counts_of_their_factors():
    # clip3d's section sits on the triangulation's floor (782 triangles for a target of 450): with the arcs'
    # sampling fixed, factors 0.5 and 1 gave 4,668 and 4,692 tets and factor 2 only 1.6x; the levels' counts
    # now follow the factors (within the rounding of the layers and the floor left under coarse sections)
    from simfab.coupling.converge import level_mesh
    from simfab.coupling.scene import load_coupling_scene, read_scene_toml, scene_paths

    comp = read_scene_toml(scene_paths("clip3d")[1])["compliant"]
    n1 = load_coupling_scene("clip3d").fem.n_elements
    ratios = [load_coupling_scene("clip3d", overrides={"compliant": level_mesh(comp, f, elements=n1)}).fem.n_elements
              / n1 for f in (0.5, 2.0)]
    assert 0.45 < ratios[0] < 0.65 and 1.8 < ratios[1] < 2.3, ratios



def test_the_report_warns_of_levels_that_are_the_same_mesh_and_of_fits_that_are_no_rate():
    # the mesher's floor gave factors 0.5 and 1 nearly the same mesh (as clip3d's section does): the report
    # says so, and a fit driven to the end of the order range by it is flagged; a clean h^2 sequence is not
    from simfab.coupling.converge import Level, report

    def levels(N, figs):
        return [Level(factor=f, elements=n, seconds=1.0, figures=g, category="tight")
                for f, n, g in zip((0.5, 1, 2, 4), N, figs)]

    def fig(h2):
        return dict(E_max=4.5 + 10 * h2, E_ss=1.0 + 3 * h2, F_in=17.0 + 100 * h2, F_rm=19.0 + 80 * h2,
                    F_grip=9.0 + 10 * h2)

    N = [500, 1000, 2000, 4000]
    clean = report("x", levels(N, [fig(1.0 / n) for n in N]), 2)
    assert clean.warnings == ()
    floored = [4668, 4692, 7389]
    rep = report("x", levels(floored, [fig(1.0 / 4668), fig(1.0 / 4668), fig(1.0 / 7389)]), 3)
    assert any("factors 0.5 and 1 have nearly the same mesh" in w for w in rep.warnings)
    assert any("F_in's fitted order is at the end" in w for w in rep.warnings)


def test_the_report_warns_of_levels_that_converge_slower_than_h():
    # a user's C-clip on linear triangles converged like h^0.8 (errors 17-22 % at its own mesh, the
    # limit 6 % off the quadratic study's): pre-asymptotic levels, flagged with the way out; figures
    # converging like h^1.3 (cclamp2d's P2 study) or h^2 are not
    from simfab.coupling.converge import Level, report

    N = [500, 1000, 2000, 4000]

    def rep(p, order=1, slow=("F_in",)):
        def fig(n):
            h = n ** -0.5
            return {k: (17.0 + 100 * h ** p if k in slow else 17.0 + 100 * h * h) for k in
                    ("E_max", "E_ss", "F_in", "F_rm", "F_grip")}

        return report("clip", [Level(factor=f, elements=n, seconds=1.0, figures=fig(n), category="tight",
                                     element_order=order) for f, n in zip((0.5, 1, 2, 4), N)], 2)

    r = rep(0.8)
    assert r.figures["F_in"].order == pytest.approx(0.8, abs=0.02)
    (w,) = [w for w in r.warnings if "slower than h" in w]
    assert "clip: F_in converges slower than h (fitted order 0.80)" in w and "--element-order 2" in w
    (w,) = [w for w in rep(0.8, order=2, slow=("E_max", "F_in")).warnings if "slower than h" in w]
    assert "E_max, F_in" in w and "0.80, 0.80" in w and "element_order" not in w  # (already quadratic)
    assert rep(1.3).warnings == () and rep(2.0).warnings == ()


def test_the_report_warns_when_whole_layers_make_the_levels_no_uniform_refinement():
    # an extrusion of one layer refined 2x and 4x keeps 1 and gets 2 layers (uniform: 1.26, 1.59): the
    # section and the height are refined unequally, and the report says which factors are uniform;
    # factors 1 and 8 (1 and 2 layers) are uniform refinements and get no such warning
    from simfab.coupling.converge import Level, level_mesh, report

    comp = {"generator": "extruded_clamp", "target_elements": 2700, "layers": 1}  # the study's own layer rule

    def level(f, n):
        h2 = n ** (-2.0 / 3.0)
        return Level(factor=f, elements=n, seconds=1.0, category="tight",
                     figures=dict(E_max=4.5 + 10 * h2, E_ss=1.0 + 3 * h2, F_in=17.0 + 100 * h2, F_rm=19.0 + 80 * h2,
                                  F_grip=9.0 + 10 * h2),
                     layers=level_mesh(comp, f)["layers"], scene_layers=1)

    rep = report("clip", [level(f, int(4700 * f)) for f in (1, 2, 4, 8)], 3)
    off = [w for w in rep.warnings if "whole layers" in w]
    assert len(off) == 1 and "factors 2, 4 it has 1, 2" in off[0] and "factors 1, 8, 27 refine uniformly" in off[0]
    assert [lv["layers"] for lv in rep.to_json()["levels"]] == [1, 1, 2, 2]
    rep = report("clip", [level(f, int(4700 * f)) for f in (1, 8, 27)], 3)
    assert not any("whole layers" in w for w in rep.warnings)


@pytest.mark.parametrize("span, labelled, wide", [
    ((1.5, 9.5), {"2", "3", "4", "5", "6", "7", "8", "9"}, False),  # within a decade: every minor tick
    ((2.0, 300.0), {"2", "5", "20", "50", "200"}, False),  # two to three decades: 2 and 5 x 10^k
    ((1e-3, 10.0), set(), False),  # beyond: none (their labels would run into each other)
    ((7425.0, 43725.0), {"20000"}, True),  # wide labels (dofs): 2 and 5 x 10^k within a decade too
])
def test_log_axis_minor_labels_follow_the_span(span, labelled, wide):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.loglog([1.0, 2.0], span)
    ax.set_ylim(*span)
    plain_log_ticks(ax.yaxis, wide=wide)
    fig.canvas.draw()

    def shown(which):  # the labels of the ticks inside the axis's span
        ticks = getattr(ax.yaxis, f"get_{which}_ticks")()
        return {t.label1.get_text() for t in ticks if span[0] <= t.get_loc() <= span[1]} - {""}

    minor, major = shown("minor"), shown("major")
    plt.close(fig)
    assert minor == labelled, minor
    assert all("10^" not in t and "times" not in t for t in major | minor)  # plain numbers
