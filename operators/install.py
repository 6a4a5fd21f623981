"""The Install Missing Packages operator of the preferences (the pip run: runtime/installer.py)."""

import time

import bpy

from ..runtime.installer import (end_install, packages_folder, running_install, start_install,
                                 to_install)
from .modal import WorkerModal, redraw


def _finish(operator, install) -> set:
    end_install(install)
    operator.report({'INFO'} if install.ok else {'ERROR'}, install.message)
    return {'FINISHED'} if install.ok else {'CANCELLED'}


class UDFR_OT_install_packages(WorkerModal, bpy.types.Operator):
    bl_idname = "udf_reconstruction.install_packages"
    bl_label = "Install Missing Packages"
    bl_description = ("Download the missing Python packages with pip and install them into this "
                      "extension's own folder (needs an internet connection)")
    timer_seconds = 0.2

    @classmethod
    def poll(cls, context):
        if running_install() is not None:
            cls.poll_message_set("Installing already")
            return False
        if not to_install():
            cls.poll_message_set("Nothing is missing")
            return False
        if packages_folder() is None:
            cls.poll_message_set("Install the extension from a zip (Install from Disk) to use "
                                 "this button")
            return False
        return True

    def start_work(self, context):
        return start_install()

    def execute(self, context):
        install = start_install()
        install.run()
        return _finish(self, install)

    def modal(self, context, event):
        install = running_install()
        if event.type == 'ESC' and event.value == 'PRESS':
            install.cancel()
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        if install.running:
            context.workspace.status_text_set(
                f"Installing packages: {install.text}, "
                f"{time.perf_counter() - install.started:.0f} s - Esc to cancel")
            redraw(context, 'PREFERENCES')
            return {'PASS_THROUGH'}
        self.stop_timer(context)
        redraw(context)  # the panel's red lines go once the packages are there
        return _finish(self, install)

    def cancel(self, context):
        install = running_install()
        if install is not None:
            install.cancel()
            end_install(install)
        context.window_manager.event_timer_remove(self._timer)


CLASSES = (UDFR_OT_install_packages,)
