"""Thin Blender layer: converts core objects to Blender data and back. No algorithms here."""
