"""What a labeling run is asked to do, in one frozen object that every front end builds once.

The CLI builds it from its flags, batch from its TOML and flags, Blender from the panel; the
pipeline's stages read it and never change it (a pass that needs other settings makes a copy with
:func:`dataclasses.replace`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

#: Frames a take may have before it is labeled in windows (:mod:`.windows`): the peak memory of a
#: 30,000-frame window is about 0.5 GB with one hand and 2 GB with two.
WINDOW_FRAMES = 30_000


@dataclass(frozen=True)
class LabelSettings:
    """How to label a take. Every field keeps its value as given; None means "the default for this
    method and layout" where a field says so.

    Attributes:
        method: per-frame labeler, a name of :data:`.labelers.LABELERS` (``set``, ``perm``,
            ``cnn``, ``gmm``, ``nearest``).
        temporal: temporal mode, a name of :data:`.temporal.modes.TEMPORAL_MODES` (``vote``,
            ``viterbi``, ``none``).
        model: ONNX model file for the ONNX labelers; None: the shipped one for the layout.
        vote_score: the vote's per-sample score, ``likelihood`` (ours) or ``power`` (Ghorbani's,
            with ``power_p`` and ``power_q``).
        n_best: hypotheses per frame for ``viterbi``.
        split_swaps: cut trajectories where their evidence flips for good or where two that pass
            close may have traded markers (``vote`` only).
        calibrate_confidence: map raw segment confidences through the shipped calibration.
        validate: IK validation (``vote`` only): fit the hand to the labels, vote again with the
            fit's evidence and downgrade segments the hand cannot explain.
        validate_hand: the performer's :class:`.hand.calibrate.Calibration` for ``validate``;
            None calibrates on the take.
        null_prior, switch_cost, partner, continuity: the vote's fitted settings, nats
            ``(a, b)`` each (see :func:`.temporal.voting.vote`); None: the shipped fit for this
            method and layout.
        occlusion_prior: ``(knee, slope)``: where the take's trajectories break more often than
            ``knee`` times a second (:func:`.tracklets.break_rate`), every sample's null weight
            falls by ``slope`` nats per break a second above it; None: the shipped fit.
        hand_count: ``"auto"`` finds how many hands of the layout the take holds; 1 or 2 force it.
        sides: the side of each hand found, in the order hands are found; None decides them from
            the markers' handedness.
        naming: a :class:`.hands.HandNaming` pattern for the labels' names; None: plain names for
            one hand, ``L_``/``R_`` prefixes for two.
        keep_named: points the file already names that are no marker of the layout (a labeled
            body, a named prop) stay out of the hands.
        props: look for rigid props among the trajectories and label again without them.
        window: label a longer take in overlapping windows of this many frames; None: whole.
        stride: score every ``stride``-th frame of a trajectory (``vote``); None: every 1/30 s
            for labelers that allow it, every frame otherwise.
        exact_pairs: the vote's clashes of more candidate (segment, label) pairs than this are
            settled by its integer programme's rounded linear relaxation (``vote``): a quick
            reading of a take, as the layout check's; None: always by the integer programme.
    """

    method: str = "set"
    temporal: str = "vote"
    model: str | None = None
    vote_score: str = "likelihood"
    power_p: float = 2.0
    power_q: float = -0.5
    n_best: int = 5
    split_swaps: bool = True
    calibrate_confidence: bool = True
    validate: bool = False
    validate_hand: Any = field(default=None, compare=False)
    null_prior: tuple[float, float] | None = None
    switch_cost: tuple[float, float] | None = None
    partner: tuple[float, float] | None = None
    continuity: tuple[float, float] | None = None
    occlusion_prior: tuple[float, float] | None = None
    hand_count: str | int = "auto"
    sides: tuple[str, ...] | None = None
    naming: str | None = None
    keep_named: bool = True
    props: bool = True
    window: int | None = WINDOW_FRAMES
    stride: int | None = None
    exact_pairs: int | None = None

    def __post_init__(self) -> None:
        # Sequences are stored as tuples so that settings compare (and hash) by value.
        if self.sides is not None and not isinstance(self.sides, tuple):
            object.__setattr__(self, "sides", tuple(self.sides))
        for name in ("null_prior", "switch_cost", "partner", "continuity", "occlusion_prior"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, tuple):
                object.__setattr__(self, name, tuple(float(v) for v in value))
        naming = self.naming
        if naming is not None and not isinstance(naming, str):  # a HandNaming: its pattern
            object.__setattr__(self, "naming", naming.template)

    def but(self, **changes: Any) -> LabelSettings:
        """A copy with ``changes`` (:func:`dataclasses.replace`)."""
        return replace(self, **changes)



@dataclass(frozen=True)
class Corrections:
    """What a reviewer (or an earlier pass) fixed on a take, honoured exactly by a labeling.

    Attributes:
        constraints: :class:`.labeling.Constraint` locks (slot, frames, label).
        splits: ``(slot, frame)`` points where a trajectory is cut and decided in two parts.
        hand_swaps: ``[start, stop)`` frame ranges where the two hands found trade places; None:
            found from a first labeling's handedness; ``()``: none.
        exclude: bool ``(F, P)`` samples kept out of the hands (null), e.g. a prop's; None: none.
    """

    constraints: Sequence = ()
    splits: Sequence[tuple[int, int]] = ()
    hand_swaps: Sequence[Sequence[int]] | None = None
    exclude: Any = field(default=None, compare=False)

    def but(self, **changes: Any) -> Corrections:
        return replace(self, **changes)
