"""Add-on preferences: which Python packages the engine found (the table is in
``runtime/dependencies.py``), a button that installs the missing ones, and whether a GPU can be
used."""

import sys

import bpy

from .. import __package__ as base_package
from ..runtime import installer
from ..runtime.dependencies import dependency_status, gpu_text


def _draw_install(layout) -> None:
    """The install button, its progress while pip runs, and the result of the last run."""
    running = installer.running_install()
    result = installer.last_result()
    wanted = installer.to_install()
    if running is not None:
        box = layout.box()
        row = box.row(align=True)
        text = f"{running.text}..."
        if hasattr(row, "progress"):
            row.progress(factor=running.fraction, type='BAR', text=text)
        else:
            row.label(text=text)
        box.label(text="Esc cancels. Blender stays usable meanwhile.", icon='INFO')
        return
    if result is not None:
        ok, message = result
        box = layout.box()
        box.alert = not ok
        for line in _lines(message):
            box.label(text=line, icon='CHECKMARK' if ok else 'ERROR')
    if wanted:
        python = f"{sys.version_info.major}.{sys.version_info.minor}"
        box = layout.box()
        box.label(text=f"Missing: {', '.join(wanted)}.", icon='ERROR')
        box.label(text="Install them here (downloads them with pip), or install the extension "
                       f"zip made for your platform and Python {python}.")
        box.operator("udf_reconstruction.install_packages", icon='IMPORT')
        folder = installer.packages_folder()
        if folder:
            box.label(text=f"Installs into {folder}", icon='FILE_FOLDER')


def _lines(message: str) -> list:
    """A message split at its sentences, so each fits a preferences line."""
    return [part.strip() + ("." if not part.strip().endswith(".") else "")
            for part in message.split(". ") if part.strip()]


class UDFR_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = base_package

    def draw(self, context):
        layout = self.layout
        layout.label(text="Python packages")
        column = layout.column(align=True)
        for name, version, purpose, required in dependency_status():
            row = column.row()
            if version is not None:
                row.label(text=f"{name} {version}", icon='CHECKMARK')
            else:
                row.label(text=f"{name}: not found", icon='ERROR' if required else 'DOT')
            row.label(text=gpu_text() if name == "torch" and version is not None else purpose)
        _draw_install(layout)


CLASSES = (UDFR_AddonPreferences,)
