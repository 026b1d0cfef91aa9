"""The procedural hand: skeleton and pose (:mod:`.skeleton`), skin and linear blend skinning (:mod:`.skin`)."""

from .skeleton import BONE_NAMES, DOF_NAMES, JOINT_NAMES, N_DOF, HandModel, sample_hand_size
from .skin import Binding, Mesh, blend, build_mesh

__all__ = ["BONE_NAMES", "DOF_NAMES", "JOINT_NAMES", "N_DOF", "Binding", "HandModel", "Mesh", "blend",
           "build_mesh", "sample_hand_size"]
