"""The label index of "null", below both the labeler protocol (:mod:`.base`) and the shared
assignment step (:mod:`.assign`) that turns scores into labels."""

#: Label index meaning "no marker of the layout" (a ghost, a distractor, a merged pair).
NULL = -1
