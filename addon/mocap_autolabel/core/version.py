"""The package's version, low in core so that the writers (a C3D's SOFTWARE parameter) never import the
package's ``__init__`` (the Blender registration above everything)."""

__version__ = "0.1.0"
