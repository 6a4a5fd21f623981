"""Add-on preferences: which Python packages the engine found (the table is in
``operators/dependencies.py``), and whether a GPU can be used."""

import bpy

from .. import __package__ as base_package
from ..operators.dependencies import dependency_status, gpu_text


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
            row.label(text=gpu_text() if name == "torch" and version is not None else purpose)
        if missing:
            box = layout.box()
            box.label(text="Some required packages are missing.", icon='ERROR')
            box.label(text="Install the extension zip built for your platform: it bundles them.")


CLASSES = (UDFR_AddonPreferences,)
