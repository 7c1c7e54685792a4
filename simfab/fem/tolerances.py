"""Numerical tolerances of the FEM area, in one place."""

#: An element is degenerate when |det Dm| <= DEGENERATE_REL * h^d, h = the model's mean edge length.
DEGENERATE_REL = 1e-10

#: Meshing: relative tolerance on the reconstructed area/volume when validating mesher output.
MESH_MEASURE_REL = 1e-9
