"""The Reconstruct and Cancel operators.

One job (``runtime/job.py``) runs the engine on numpy copies of the object's points. From the
N-panel (``invoke``) it runs on a worker thread that never touches bpy, while a 0.25 s modal timer
shows its progress and Esc or the Cancel button sets its stop flag; from scripts and
``blender -b`` (``execute``) it runs to the end before returning. Either way the new object is
made on the main thread only once the engine has finished, so a cancel or an error leaves the
scene untouched.
"""

import time
import traceback

import bpy

from ..engine.errors import Cancelled, InputError
from ..runtime import bridge, dependencies, wording
from ..runtime.job import Job, end_job, running_job, start_job
from .modal import WorkerModal, redraw


def _missing_dependency(error: BaseException):
    """The third-party package an import failed on (its install name), or None (our own bugs
    are not that)."""
    name = getattr(error, "name", None)
    own = __package__.rsplit(".", 1)[0]
    if isinstance(error, ModuleNotFoundError) and name and not name.startswith(own):
        return dependencies.install_name(name)
    return None


def _report_failure(operator, error: BaseException) -> set:
    """Report an error that is not the user's input; print the traceback for bug reports."""
    missing = _missing_dependency(error)
    if missing:
        operator.report({'ERROR'}, dependencies.missing_message([missing]))
    elif isinstance(error, MemoryError):
        operator.report({'ERROR'}, "Ran out of memory. Lower the resolution and try again.")
    else:
        traceback.print_exception(type(error), error, error.__traceback__)
        operator.report({'ERROR'}, f"Reconstruction failed ({type(error).__name__}: {error}). "
                                   f"Please report this with the text from the system console "
                                   f"(Window > Toggle System Console on Windows).")
    return {'CANCELLED'}


def _check_dependencies(operator):
    """Report missing packages before any work; None when all are there."""
    missing = dependencies.missing_packages()
    if not missing:
        return None
    operator.report({'ERROR'}, dependencies.missing_message(missing))
    return {'CANCELLED'}


def _log(job: Job, result) -> None:
    """Everything the engine had to say, for the system console (not the Info log)."""
    print(f"UDF Reconstruction of '{job.source_name}': {len(result.mesh.faces):,} faces from "
          f"{len(job.cloud):,} points in {job.seconds:.1f} s")
    for message in result.messages:
        print(f"  note: {message}")
    stats = {k: v for k, v in result.stats.items() if not isinstance(v, dict)}
    print(f"  stats: {stats}")
    print(f"  mesher: {result.stats.get('meshing', {})}")
    print("  seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in result.timings.items()))


def finish_job(operator, context, job: Job) -> set:
    """Report the job's outcome; on success add the mesh object. Returns the operator result."""
    end_job()
    error = job.error
    if isinstance(error, Cancelled):
        operator.report({'INFO'}, "Reconstruction cancelled; nothing was changed.")
        return {'CANCELLED'}
    if isinstance(error, InputError):
        operator.report({'ERROR'}, wording.sentence(str(error)))
        return {'CANCELLED'}
    if error is not None:
        return _report_failure(operator, error)

    result = job.result
    _log(job, result)
    if len(result.mesh.faces) == 0:
        control = wording.radius_control(job.settings.radius_mode, job.settings.custom_range)
        operator.report({'ERROR'}, f"No surface was found. Raise {control} or lower "
                                   f"Resolution, then try again.")
        return {'CANCELLED'}
    for notice in wording.user_notices(result.messages, job.settings.radius_mode,
                                       job.settings.custom_range):
        operator.report({'WARNING'}, notice)
    # Looked up by name: an undo while the job ran invalidates references to bpy data.
    source = bpy.data.objects.get(job.source_name)
    name = f"{job.source_name}_mesh"
    obj = bridge.new_mesh_object(context, result.mesh, name, job.matrix_world, source,
                                 reuse=bridge.previous_result(job.source_name, name))
    if job.hide_source and source is not None and source.name in context.view_layer.objects:
        source.hide_set(True)
    operator.report({'INFO'}, f"Made '{obj.name}': {len(result.mesh.faces):,} faces from "
                              f"{len(job.cloud):,} points in {job.seconds:.1f} s.")
    return {'FINISHED'}


def _redraw_panels(context) -> None:
    """Redraw only the sidebars of the 3D views: redrawing the viewport itself (all the points)
    on every tick takes the interpreter lock from the worker and slows it down severalfold."""
    redraw(context, 'VIEW_3D', 'UI')


class UDFR_OT_reconstruct(WorkerModal, bpy.types.Operator):
    bl_idname = "udf_reconstruction.reconstruct"
    bl_label = "Reconstruct"
    bl_description = ("Build a mesh from the selected point cloud with the settings of the "
                      "Reconstruct panel. Run again, it replaces that cloud's earlier result")
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        if running_job() is not None:
            cls.poll_message_set("A reconstruction is already running; wait for it or cancel it")
            return False
        problem = bridge.reconstruct_target(context).problem
        if problem:
            cls.poll_message_set(problem)
            return False
        return True

    def start_work(self, context):
        """The new job, or the operator's result when it cannot start (reported)."""
        self._shown = None
        refused = _check_dependencies(self)  # before anything is read or computed
        if refused:
            return refused
        try:
            return start_job(context)
        except InputError as error:
            self.report({'ERROR'}, wording.sentence(str(error)))
            return {'CANCELLED'}
        except ImportError as error:
            return _report_failure(self, error)

    def execute(self, context):
        job = self.start_work(context)
        if not isinstance(job, Job):
            return job
        job.run()
        return finish_job(self, context, job)

    def modal(self, context, event):
        job = running_job()
        if event.type == 'ESC' and event.value == 'PRESS':
            job.stop.set()
            return {'RUNNING_MODAL'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        if job.running:
            text = f"Reconstructing '{job.source_name}': {job.status_text}"
            if job.started is not None:  # a stage without progress still shows time passing
                text += f", {time.perf_counter() - job.started:.0f} s"
            text += " - cancelling" if job.stop.is_set() else " - Esc to cancel"
            if text != self._shown:  # redraw only when there is something new to show
                self._shown = text
                context.workspace.status_text_set(text)
                _redraw_panels(context)
            return {'PASS_THROUGH'}
        self.stop_timer(context)
        _redraw_panels(context)
        return finish_job(self, context, job)

    def cancel(self, context):
        # Blender ends the modal operator (file load, window closed): stop the worker too.
        job = running_job()
        if job is not None:
            job.stop.set()
            end_job()
        self.stop_timer(context)
        _redraw_panels(context)


class UDFR_OT_cancel(bpy.types.Operator):
    """Stop the running reconstruction; the scene stays as it was"""

    bl_idname = "udf_reconstruction.cancel"
    bl_label = "Cancel"
    bl_options = {'INTERNAL'}

    @classmethod
    def poll(cls, context):
        if running_job() is None:
            cls.poll_message_set("No reconstruction is running")
            return False
        return True

    def execute(self, context):
        running_job().stop.set()
        return {'FINISHED'}


CLASSES = (UDFR_OT_reconstruct, UDFR_OT_cancel)
