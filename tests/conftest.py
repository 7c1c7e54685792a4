import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


@pytest.fixture(scope="session")
def require_gmsh():
    """Skip the requesting test when Gmsh cannot be loaded (optional: its PyPI wheel needs the
    system's X11/GLU libraries, see simfab.fem.meshing.GMSH_MISSING)."""
    from simfab.fem.meshing import load_gmsh

    try:
        load_gmsh()
    except RuntimeError as e:
        pytest.skip(str(e))


@pytest.fixture
def spd_solvers(monkeypatch):
    """Every :class:`simfab.solve.linear.SPDSolver` (and subclass) built while the test runs, in
    order; a test that runs twice clears the list in between."""
    from simfab.solve import linear

    solvers = []
    init = linear.SPDSolver.__init__

    def registered(self, *args, **kwargs):
        init(self, *args, **kwargs)
        solvers.append(self)

    monkeypatch.setattr(linear.SPDSolver, "__init__", registered)
    return solvers
