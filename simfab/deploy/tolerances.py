"""Validation tolerances of the deployment area (the one place they live).

They are tied to the discretization at the validation resolution ``VALIDATION_N`` segments:
pinned ends converge second order in the segment length (error ~ (L/n)^2), clamped ends
only first order because the clamped end edge is held rigid (the effective free length is
short by about one segment).
"""

VALIDATION_N = 80  # segments at which the elastica table is checked
PINNED_RISE_RTOL = 1e-3  # |delta - delta_exact| / delta_exact, pinned ends
CLAMPED_RISE_RTOL = 1e-2  # same, clamped ends
FORCE_RTOL = 1e-2  # |P - P_exact| / P_exact, both supports
CRITICAL_LOAD_RTOL = 5e-3  # |P_cr - pi^2 B / L^2| / (pi^2 B / L^2), pinned ends
INSERT_VS_DIRECT_RTOL = 1e-6  # rise through the rigid-insert path vs direct end displacement
CRITICAL_LOAD_BISECTION_RTOL = 1e-7  # bracket width of the stability bisection

RISE_RTOL = {"pinned": PINNED_RISE_RTOL, "clamped": CLAMPED_RISE_RTOL}
