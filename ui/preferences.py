"""Add-on preferences: which Python packages the engine found.

Nothing is imported to find out (``importlib.util.find_spec`` and the installed metadata only), so
opening the preferences stays instant and a broken package cannot break the panel.
"""

import importlib.metadata
import importlib.util

import bpy

from .. import __package__ as base_package

# (import name, distribution name, what it is for, required)
DEPENDENCIES = (
    ("numpy", "numpy", "arrays (ships with Blender)", True),
    ("scipy", "scipy", "neighbour search", True),
    ("skimage", "scikit-image", "marching cubes", True),
    ("maxflow", "PyMaxflow", "min-cut that splits the double surface", True),
    ("laspy", "laspy", "reading LAS/LAZ scans (optional)", False),
    ("torch", "torch", "running on an NVIDIA GPU (optional)", False),
)


def dependency_status() -> list:
    """One ``(name, version or None, purpose, required)`` per dependency; None = not found."""
    rows = []
    for module, distribution, purpose, required in DEPENDENCIES:
        try:
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):
            found = False
        version = None
        if found:
            try:
                version = importlib.metadata.version(distribution)
            except importlib.metadata.PackageNotFoundError:
                version = "found"
        rows.append((distribution, version, purpose, required))
    return rows


class UDFR_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = base_package

    def draw(self, context):
        layout = self.layout
        layout.label(text="Python packages")
        missing = False
        column = layout.column(align=True)
        for name, version, purpose, required in dependency_status():
            row = column.row()
            if version is not None:
                row.label(text=f"{name} {version}", icon='CHECKMARK')
            else:
                missing = missing or required
                row.label(text=f"{name}: not found", icon='ERROR' if required else 'DOT')
            row.label(text=purpose)
        if missing:
            box = layout.box()
            box.label(text="Some required packages are missing.", icon='ERROR')
            box.label(text="Install the extension zip built for your platform: it bundles them.")


CLASSES = (UDFR_AddonPreferences,)
