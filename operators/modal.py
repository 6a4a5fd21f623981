"""What the two long-running operators share: a worker thread watched by a modal timer.

From a button (``invoke``) the work runs on a worker thread while a timer event, a few times a
second, lets the operator show its progress and Blender stays usable; from scripts and
``blender -b`` (``execute``) it runs to the end before returning.
"""

import bpy


def redraw(context, area_type=None, region_type=None) -> None:
    """Redraw the areas of ``area_type`` (all when None), or only their regions of
    ``region_type``."""
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area_type is not None and area.type != area_type:
                continue
            if region_type is None:
                area.tag_redraw()
                continue
            for region in area.regions:
                if region.type == region_type:
                    region.tag_redraw()


class WorkerModal:
    """Mixin of an operator whose work runs on a worker thread.

    The operator defines ``start_work(context)``, which returns the work (an object with
    ``start_thread()``) or, when the work cannot start, the operator's result (reported), and
    ``execute``, ``modal`` and ``cancel``; ``timer_seconds`` is how often ``modal`` gets a timer
    event.
    """

    timer_seconds = 0.25

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        work = self.start_work(context)
        if isinstance(work, set):
            return work
        work.start_thread()
        self._timer = context.window_manager.event_timer_add(self.timer_seconds,
                                                             window=context.window)
        context.window_manager.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def stop_timer(self, context) -> None:
        """End the timer and clear the status bar."""
        context.window_manager.event_timer_remove(self._timer)
        context.workspace.status_text_set(None)
