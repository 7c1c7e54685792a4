import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def require_gmsh():
    """Skip the calling test when Gmsh cannot be loaded (optional: its PyPI wheel needs the system's
    X11/GLU libraries, see simfab.fem.meshing.GMSH_MISSING)."""
    import pytest

    from simfab.fem.meshing import load_gmsh

    try:
        load_gmsh()
    except RuntimeError as e:
        pytest.skip(str(e))
