"""Geometric tolerances and heuristic constants of the growth pipeline, in one place.

Lengths relative to the scene are multiplied by the design-space diagonal ``D`` [m] or by
the branch length ``L`` [m]; absolute ones are in metres.
"""

#: A segment that starts or ends on an object surface (roots, targets, surface contacts)
#: is tested for collisions with both ends pulled in by this fraction of D, so that
#: touching the surface at an endpoint is not a collision.
SEGMENT_END_TRIM = 1e-3

#: New nodes closer than this fraction of L to an existing node are dropped: a node
#: oscillating between two attractors would otherwise pile up nodes in one place.
MIN_NODE_SPACING = 0.3

#: A node attracted but unable to grow for this many consecutive steps becomes a dead end.
NODE_FAIL_LIMIT = 4

#: Consecutive growth steps without a new node after which growth is declared stalled.
STALL_PATIENCE = 12

#: A target counts as reachable in one step when its nearest growing node is within
#: this multiple of L (the node then lands exactly on the target, v' = t).
TARGET_REACH = 1.0

#: A point is "on the symmetry plane" when closer than this fraction of D; roots and
#: targets are mirror partners when one's reflection is this close to the other.
ON_PLANE_TOL = 1e-4

#: Skeleton nodes count as contained in the skin when inside it, or on its boundary: a ball
#: of CONTAIN_TOL r_min around the node overlaps the skin by at least TOUCH_FRACTION of its
#: volume (nodes on a carved contact face sit exactly on the boundary: overlap 1/2).
CONTAIN_TOL = 0.05
TOUCH_FRACTION = 0.25

#: Surface-mode leaves within this multiple of the kill distance of an object surface are
#: contacts (kept by pruning and snapped onto the surface).
CONTACT_FACTOR = 1.5

#: Surface attractors are lifted off the surface along the face normal by this fraction of
#: the kill distance so that growing towards them does not run into the object.
SURFACE_LIFT = 0.5

#: An object is "ground" (a root stands on it) when a root is within this fraction of the
#: object's diagonal of its surface.
GROUND_CONTACT = 1e-3

#: Skin penetration below this fraction of D is round-off of the float32 STL cleanup, not a
#: real overlap (the skin is carved exactly by the objects).
PENETRATION_ROUNDOFF = 1e-6

#: Structural check: default radius [m] the von Mises stress is averaged over before the yield
#: comparison ([material] critical_distance): half of PLA's critical distance, the coupling's
#: choice (simfab.design.stress.STRESS_RADIUS explains it).
CRITICAL_DISTANCE = 0.5e-3
