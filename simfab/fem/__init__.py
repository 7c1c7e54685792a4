"""Finite-element elasticity: linear and quadratic triangles (2D plane strain) and tetrahedra (3D).

- :mod:`simfab.fem.materials` - isotropic materials (Young's modulus, Poisson ratio, yield stress)
- :mod:`simfab.fem.model` - the immutable :class:`FemModel` (rest shape, Dm^-1, volumes, Lame parameters)
  and :class:`MeshModel`, the methods every element order provides
- :mod:`simfab.fem.p2` - quadratic elements: :class:`P2Model` (6-node triangles, 10-node tets) from a
  linear mesh (``to_p2``)
- :mod:`simfab.fem.assembly` - fixed-pattern sparse Hessian assembly
- :mod:`simfab.fem.elastic` - compressible Neo-Hookean energy, gradient and (PSD-projected) Hessian of a
  model of either element order: the public functions
- :mod:`simfab.fem.neohookean`, :mod:`simfab.fem.neohookean_p2` - their Warp kernels (linear; P2 with
  quadrature)
- :mod:`simfab.fem.workspace` - the recorded kernel launches both element orders share
- :mod:`simfab.fem.loads` - consistent nodal loads (body force, traction) for linear and P2 models
- :mod:`simfab.fem.stress` - Cauchy and von Mises stress
- :mod:`simfab.fem.meshing` - Triangle (2D) and Gmsh (3D; fTetWild as the fallback) meshing, structured tet boxes
- :mod:`simfab.fem.tolerances` - the area's numerical tolerances

The shared Newton solver lives in :mod:`simfab.solve.newton`.

Submodules are imported on demand so that ``import simfab.fem`` stays cheap (Warp is imported
by :mod:`simfab.fem.workspace` and the kernel modules only).
"""
