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
