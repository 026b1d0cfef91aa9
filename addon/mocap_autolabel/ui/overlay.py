"""Viewport overlay: the labeled markers as dots coloured by finger, uncertain ones ringed, sticks
along each digit. The geometry comes from ``blender.review.overlay_geometry`` (tested headless);
this module only draws it, and never in background mode where ``gpu`` cannot draw."""

from __future__ import annotations

import bpy
import numpy as np

_HANDLE: list = []  # the draw handler, removed on unregister


def _classes(coll, state_token: str, sure: float):
    from ..blender.review import load_state
    from ..blender.session import session
    from ..core.review import marker_classes

    cache = session(coll)
    key = f"{state_token}@{sure}"  # the rings follow Confident at, as the key colours do
    if cache.classes is None or cache.classes[0] != key:
        cache.classes = (key, marker_classes(load_state(coll).labeling, sure))
    return cache.classes[1]


def _shader(names: tuple[str, ...]):
    import gpu

    for name in names:
        try:
            return gpu.shader.from_builtin(name)
        except (ValueError, SystemError):
            continue
    return None


def draw() -> None:
    import gpu
    from gpu_extras.batch import batch_for_shader

    from ..blender.review import has_review, overlay_geometry, sample_index
    from ..core.layout import load_layout

    scene = bpy.context.scene
    settings = getattr(scene, "mocap_autolabel", None)
    if settings is None or not settings.show_overlay or not has_review(settings.take):
        return
    coll = settings.take
    try:
        meta = coll["mocap_settings"]
        layout = load_layout(str(meta["layout"]))
        geo = overlay_geometry(coll, layout, _classes(coll, str(meta.get("token", "")), settings.sure),
                               sample_index(coll, scene.frame_current), settings.show_sticks)
    except Exception:  # a draw callback must never raise
        return
    gpu.state.blend_set("ALPHA")
    gpu.state.depth_test_set("NONE")
    if len(geo["lines"]):
        shader = _shader(("UNIFORM_COLOR",))
        gpu.state.line_width_set(2.0)
        shader.uniform_float("color", (0.85, 0.85, 0.85, 0.6))
        batch_for_shader(shader, "LINES", {"pos": geo["lines"].tolist()}).draw(shader)
    shader = _shader(("POINT_FLAT_COLOR", "FLAT_COLOR"))
    for key, colors, size in (("uncertain", "ring_colors", 16.0), ("points", "colors", 9.0)):
        if len(geo[key]):
            gpu.state.point_size_set(size)
            batch_for_shader(shader, "POINTS", {"pos": geo[key].tolist(),
                                                "color": np.asarray(geo[colors]).tolist()}).draw(shader)
    gpu.state.point_size_set(1.0)
    gpu.state.line_width_set(1.0)
    gpu.state.blend_set("NONE")


def register() -> None:
    if not bpy.app.background:
        _HANDLE.append(bpy.types.SpaceView3D.draw_handler_add(draw, (), "WINDOW", "POST_VIEW"))


def unregister() -> None:
    while _HANDLE:
        bpy.types.SpaceView3D.draw_handler_remove(_HANDLE.pop(), "WINDOW")
