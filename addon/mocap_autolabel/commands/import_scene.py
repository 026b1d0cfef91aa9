"""``import``: a take into a new .blend (needs Blender or the bpy module)."""

from __future__ import annotations

import json
import os

from .common import EXIT_FAILED, EXIT_OK, _bpy_or_none, _fail


def _import(args) -> int:
    bpy = _bpy_or_none("the import command")
    if bpy is None:
        return EXIT_FAILED
    from ..blender.export import save_blend
    from ..blender.scene import ImportOptions, build_take, check_options
    from ..core.atomic import atomic_output
    from ..core.quiet import silenced_stdout
    from ..core.take import read_take

    options = ImportOptions(scale=args.scale, frame_offset=args.frame_offset, name_filter=args.names,
                            as_point_cloud=args.point_cloud)
    try:
        check_options(options)  # a bad --scale, before the file is read
        take = read_take(args.file)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        collection = build_take(take, scene, options)  # nothing to import: one line, not a traceback
        with silenced_stdout():
            save_blend(args.blend)
    except Exception as exc:
        return _fail(args.file, exc)
    from ..blender.pointcloud import CLOUD, is_cloud

    cloud = next((o for o in collection.objects if is_cloud(o)), None)
    summary = take.summary() | {
        "blend": os.path.abspath(args.blend),
        "collection": collection.name,
        "empties": len(collection.objects) if cloud is None else 0,
        "point_cloud": None if cloud is None else {"object": cloud.name, "markers": int(cloud[CLOUD])},
        "scene_frames": [scene.frame_start, scene.frame_end],
        "scene_fps": scene.render.fps / scene.render.fps_base,
    }
    if args.summary:
        try:
            with atomic_output(args.summary) as tmp, open(tmp, "w") as fh:
                json.dump(summary, fh, indent=2)
        except OSError as exc:  # names the summary (atomic_output), not the take
            return _fail(args.summary, exc)
    shown = summary["empties"] if cloud is None else f"{summary['point_cloud']['markers']} point-cloud"
    print(f"{args.file}: {shown} markers x {take.n_frames} frames -> {args.blend}")
    for warning in take.warnings:
        print(f"  warning  {warning}")
    return EXIT_OK
