"""Numerical tolerances of the FEM area, in one place."""

#: An element is degenerate when |det Dm| <= DEGENERATE_REL * h^d, h = the model's mean edge length.
DEGENERATE_REL = 1e-10

#: Polar decomposition (scaled Newton iteration, quadratically convergent) stops when the squared
#: Frobenius norm of the update of the rotation falls below this, or after POLAR_MAX_ITER updates
#: (reached only for condition numbers of F far beyond any usable element).
POLAR_STEP_SQ_TOL = 1e-26
POLAR_MAX_ITER = 30
