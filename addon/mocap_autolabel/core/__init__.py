"""Blender-free core of mocap_autolabel: data model, file formats and algorithms.

Nothing below this package imports ``bpy``; it runs in any Python with numpy.
"""
