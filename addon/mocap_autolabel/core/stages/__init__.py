"""The labeling stages, in the order :mod:`..pipeline` runs them over one :class:`.run.LabelRun`:

1. ``find_hands``  (:mod:`.hands`): which trajectories belong to which hand; points the file
   names otherwise (a labeled body) stay out.
2. ``score``       (:mod:`.scoring`): per-frame scores of every sample by the labeler.
3. ``decide``      (:mod:`.decide`): the temporal mode's decision (trajectory voting, N-best
   Viterbi, none) with the confidence calibration.
4. ``refine``      (:mod:`.refine`): the hands' second look; hands that traded places; IK validation.
5. ``name_sides``  (:mod:`.hands`): left and right, the labels' names.
6. ``checks``      (:mod:`.refine`): two hands against one; rigid props.
7. ``finger order`` (:mod:`.refine`): a sparse set's fingers over the whole take, by the template hand.

A stage that needs another pass returns a :class:`.run.Retry` (what to change) to the pipeline's
loop; no stage calls the pipeline.
"""
