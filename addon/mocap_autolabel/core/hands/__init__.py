"""Hands in a take: how many of a layout's hands it holds, which trajectories belong to which, and
which hand is the left one.

The decision is made over whole trajectories, not frame by frame: a fixed per-frame radius (Han
et al. 2018 cluster markers within 200 mm) fails exactly where hands touch, while a trajectory
that was seen on one hand before the hands met stays on it through the contact.

1. Two hand centres are tracked through the take (2-means seeded on the best separated frame,
   carried frame to frame; a hand that leaves the volume is re-found where points appear far
   from the hand that stayed).
2. Each tracklet goes to the hand whose centre it stays nearer on average (refined twice with
   centres recomputed from the tracklets); one that is nearly as near to both is offered to both
   hands, and the joint vote (:func:`..pipeline.label_take`) decides it with the labels.
3. Where a trajectory truly passes from one hand to the other (a capture-system swap while the
   hands touch), it is cut there.
4. A hand counts when it holds at least a third of the layout's markers in at least a tenth of
   the frames with points (ghosts and stray body markers never do).

Sides: the ``set`` labeler is mirror-blind by design, so handedness is decided afterwards from each
hand's labeled markers: the turn of the layout's most chiral marker tetrahedron, which a mirror
image flips (:func:`chiral_tetrahedron`, :func:`side_evidence`), jointly for two hands (one left,
one right).

Names: a two-hand labeling names its points with a side token (:class:`HandNaming`, e.g.
``L_ThumbTip``); reading a labeled file back (:func:`split_hands`) understands the same
convention.

Modules: :mod:`.tracking` (the hands' centres and which samples are whose: :func:`find_hands`),
:mod:`.sides` (handedness, :func:`decide_sides`, hands that traded places), :mod:`.naming` (how
labeled names carry a hand's side: :class:`HandNaming`, :func:`split_hands`) and :mod:`.relabel`
(what a new labeling of a labeled take keeps of its hands). Everything public is re-exported here.
"""

from .naming import (
    DEFAULT_NAMING,
    NAMINGS,
    SIDES,
    HandNaming,
    hands_in_names,
    labeled_layout,
    sided_layout_names,
    sided_path,
    split_hands,
)
from .relabel import (
    labeling_sides,
    relabel_options,
    relabel_plan,
)
from .sides import (
    FRAME_NATS,
    TRADE_DISTANCE,
    TRADE_NATS,
    SideEvidence,
    body_side,
    body_side_evidence,
    chiral_tetrahedron,
    decide_sides,
    handedness,
    identity_swaps,
    shape_tells_sides,
    side_evidence,
    swap_frames,
    swap_ranges,
    traded_text,
)
from .tracking import (
    AMBIGUOUS,
    APART,
    CROWDED,
    HAND_RADIUS,
    HANDS,
    LOST_SECONDS,
    PRESENT_FRAMES,
    PRESENT_SHARE,
    SWAP_MARGIN,
    SWAP_SECONDS,
    Hands,
    HandTracks,
    add_warning,
    find_hands,
    replace_valid,
    track_hands,
)

__all__ = [
    "add_warning",
    "body_side",
    "body_side_evidence",
    "shape_tells_sides",
    "AMBIGUOUS",
    "APART",
    "CROWDED",
    "DEFAULT_NAMING",
    "FRAME_NATS",
    "HANDS",
    "HAND_RADIUS",
    "HandNaming",
    "HandTracks",
    "Hands",
    "LOST_SECONDS",
    "NAMINGS",
    "PRESENT_FRAMES",
    "PRESENT_SHARE",
    "SIDES",
    "SWAP_MARGIN",
    "SWAP_SECONDS",
    "SideEvidence",
    "TRADE_DISTANCE",
    "TRADE_NATS",
    "chiral_tetrahedron",
    "decide_sides",
    "find_hands",
    "handedness",
    "hands_in_names",
    "identity_swaps",
    "labeled_layout",
    "labeling_sides",
    "relabel_options",
    "relabel_plan",
    "replace_valid",
    "side_evidence",
    "sided_layout_names",
    "sided_path",
    "split_hands",
    "swap_frames",
    "swap_ranges",
    "track_hands",
    "traded_text",
]
