"""Triangle meshes' own BVHs, every bounding volume of the seed, and the two-tree descent.

``tree``: a mesh's BVH in its local frame with sphere, AABB and OBB volumes per node;
``pose``: where a mesh sits; ``volumes``: the node tests; ``tritri``: the triangle test;
``descent``: mesh against mesh by simultaneous descent (with the brute-force reference).
"""

from .descent import OUTCOME_NAMES, Descent, brute_force, descend
from .rigid_motion import Pose, rotation_from_degrees
from .tree import VOLUME_NAMES, MeshTree, build_mesh_tree

__all__ = ["OUTCOME_NAMES", "VOLUME_NAMES", "Descent", "MeshTree", "Pose", "brute_force", "build_mesh_tree",
           "descend", "rotation_from_degrees"]
