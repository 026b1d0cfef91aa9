"""``synth``: a synthetic raw take of a procedural hand (or two), with its ground truth."""

from __future__ import annotations

import sys

from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE, _bpy_or_none, _fail


def _synth(args) -> int:
    import dataclasses

    from ..core.layout import load_layout
    from ..core.synth.generate import GHOST, SynthConfig, clean_config, save_synth, synthesize

    try:
        layout = load_layout(args.layout)
    except Exception as exc:
        return _fail(args.layout, exc)
    if args.hands == 2:
        return _synth_two(args, layout)
    if args.prop:
        print("mocap_autolabel synth: error: --prop needs --hands 2", file=sys.stderr)
        return EXIT_USAGE
    config = dataclasses.replace(clean_config() if args.clean else SynthConfig(), rate=args.rate, side=args.side)
    synth = synthesize(layout, args.frames, seed=args.seed, config=config)
    try:
        take_path, truth_path = save_synth(synth, args.output)
    except OSError as exc:
        print(f"error: {args.output}: cannot write ({exc.strerror or exc})", file=sys.stderr)
        return EXIT_FAILED
    labels = synth.labels
    print(f"{take_path}: {layout.name} ({len(layout)} markers), {args.frames} frames at {args.rate:g} Hz, "
          f"{synth.hand.side} hand {synth.hand.length * 1000:.0f} x {synth.hand.breadth * 1000:.0f} mm, "
          f"{synth.take.n_points} slots, {100 * synth.take.missing_fraction:.1f} % of slot samples empty, "
          f"{(labels == GHOST).sum() / args.frames:.2f} ghosts per frame")
    print(f"  truth    {truth_path}")
    if args.blend:
        return _synth_blend(synth, args.blend)
    return EXIT_OK


def _synth_two(args, layout) -> int:
    """``synth --hands 2``: two interacting hands (left and right, sizes of their own)."""
    from ..core.synth.generate import GHOST
    from ..core.synth.two_hands import TwoHandConfig, save_two_hands, two_hand_take

    if args.clean or args.side or args.blend:
        print("mocap_autolabel synth: error: --hands 2 takes no --clean, --side or --blend", file=sys.stderr)
        return EXIT_USAGE
    if args.frames < 1:
        print(f"mocap_autolabel synth: error: --frames must be positive, got {args.frames}", file=sys.stderr)
        return EXIT_USAGE
    if args.prop and not 3 <= args.prop <= 6:
        print(f"mocap_autolabel synth: error: --prop takes 3 to 6 markers, got {args.prop}", file=sys.stderr)
        return EXIT_USAGE
    config = TwoHandConfig(prop_markers=args.prop)
    two = two_hand_take(layout, args.frames, seed=args.seed, config=config, rate=args.rate)
    try:
        take_path, truth = save_two_hands(two, args.output, config)
    except OSError as exc:
        print(f"error: {args.output}: cannot write ({exc.strerror or exc})", file=sys.stderr)
        return EXIT_FAILED
    sizes = ", ".join(f"{h.hand.side} {h.hand.length * 1000:.0f} x {h.hand.breadth * 1000:.0f} mm" for h in two.hands)
    print(f"{take_path}: two hands of {layout.name} ({2 * len(layout)} markers), {args.frames} frames at "
          f"{args.rate:g} Hz ({sizes}), hands within 5 cm in {100 * (two.gap < 0.05).mean():.0f} % of frames, "
          f"{two.take.n_points} slots, {(two.labels == GHOST).sum() / args.frames:.2f} ghosts per frame")
    if len(two.prop_slots):
        print(f"  prop     {len(two.prop_slots)} markers in the left hand, slots "
              f"{', '.join(two.take.names[s] for s in two.prop_slots)} (ghosts in the truth)")
    print(f"  truth    {truth}")
    return EXIT_OK


def _synth_blend(synth, path: str) -> int:
    """The raw take as empties beside the hand that made it, keyed over the same frames."""
    bpy = _bpy_or_none("synth --blend")
    if bpy is None:
        return EXIT_FAILED
    from ..blender.armature import build_hand, key_poses
    from ..blender.export import save_blend
    from ..blender.scene import ImportOptions, build_take
    from ..core.quiet import silenced_stdout

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    build_take(synth.take, scene, ImportOptions())
    truth = bpy.data.collections.new("Truth")
    scene.collection.children.link(truth)
    objs = build_hand(synth.hand, name="TrueHand", collection=truth, layout=synth.layout)
    key_poses(objs["armature"], synth.hand, synth.poses, first_frame=synth.take.first_frame)
    with silenced_stdout():
        save_blend(path)
    print(f"  blend    {path}")
    return EXIT_OK
