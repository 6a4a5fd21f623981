"""The Reconstruct and Cancel operators.

One :class:`Job` runs the engine on numpy copies of the object's points. From the N-panel
(``invoke``) it runs on a worker thread that never touches bpy, while a 0.25 s modal timer shows
its progress and Esc or the Cancel button sets its stop flag; from scripts and ``blender -b``
(``execute``) it runs to the end before returning. Either way the new object is made on the main
thread only once the engine has finished, so a cancel or an error leaves the scene untouched.
"""

import threading
import time
import traceback

import bpy

from ..engine.errors import Cancelled, InputError
from ..engine.settings import ReconstructSettings
from . import bridge, dependencies, wording

# How often the modal operator looks at the worker's progress (seconds).
TIMER_SECONDS = 0.25

_job = None  # the running Job, if any: one reconstruction at a time


class Job:
    """One reconstruction of a copied point cloud; ``run`` never touches bpy."""

    def __init__(self, source, cloud, settings):
        self.source_name = source.name
        self.matrix_world = source.matrix_world.copy()
        self.hide_source = True
        self.cloud = cloud
        self.settings = settings
        self.stop = threading.Event()
        self.fraction = 0.0
        self.message = "Starting"
        self.stage = "Preparing"
        self.result = None
        self.error = None
        self.seconds = 0.0
        self.started = None
        self.thread = None
        # Imported here, on the main thread, so a missing dependency shows up at once and
        # enabling the extension never pays for the engine's imports.
        from ..engine.reconstruct import reconstruct
        self._reconstruct = reconstruct

    def _progress(self, fraction: float, message: str) -> None:
        self.stage = wording.stage_name(message, self.stage)
        self.fraction, self.message = float(fraction), message

    @property
    def status_text(self) -> str:
        """The progress in a few words, short enough for the sidebar: "Distances 58 %"."""
        return wording.progress_text(self.message, self.fraction, self.stage)

    def run(self) -> None:
        self.started = start = time.perf_counter()
        try:
            self.result = self._reconstruct(self.cloud, self.settings,
                                            progress=self._progress, cancel=self.stop.is_set)
        except BaseException as error:  # handed to the main thread, which reports it
            self.error = error
        self.seconds = time.perf_counter() - start

    def start_thread(self) -> None:
        self.thread = threading.Thread(target=self.run, name="udf_reconstruction", daemon=True)
        self.thread.start()

    @property
    def running(self) -> bool:
        return self.thread is not None and self.thread.is_alive()


def running_job():
    """The reconstruction in progress (for the panel), or None."""
    return _job


def _check_device(settings) -> None:
    """Refuse CUDA at once when there is no GPU, instead of after the first stage's work."""
    if settings.device == "cuda" and not dependencies.gpu_available(wait=True):
        raise InputError("No GPU was found, so Device cannot be CUDA. Set Device to Auto or CPU "
                         "and try again.")


def start_job(context) -> Job:
    """Copy the target cloud's points and settings into a new Job (raises InputError).

    The target is the selected cloud, or the cloud of a selected earlier result
    (:func:`bridge.reconstruct_target`).
    """
    global _job
    target = bridge.reconstruct_target(context)
    if target.source is None:
        raise InputError(wording.sentence(target.problem))
    props = context.scene.udf_reconstruction  # the panel's properties (ui/properties.py)
    settings = ReconstructSettings.from_attributes(props, single_precision=True)
    _check_device(settings)
    cloud = bridge.read_point_cloud(context, target.source)
    _job = Job(target.source, cloud, settings)
    _job.hide_source = props.hide_source
    return _job


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
    global _job
    _job = None
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
        operator.report({'ERROR'}, "No surface was found. Raise the radius or lower the "
                                   "resolution, then try again.")
        return {'CANCELLED'}
    for notice in wording.user_notices(result.messages, job.settings.radius_mode):
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
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                for region in area.regions:
                    if region.type == 'UI':
                        region.tag_redraw()


class UDFR_OT_reconstruct(bpy.types.Operator):
    bl_idname = "udf_reconstruction.reconstruct"
    bl_label = "Reconstruct"
    bl_description = ("Build a mesh from the selected point cloud with the settings of the "
                      "Reconstruct panel. Run again, it replaces that cloud's earlier result")
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        if _job is not None:
            cls.poll_message_set("A reconstruction is already running; wait for it or cancel it")
            return False
        problem = bridge.reconstruct_target(context).problem
        if problem:
            cls.poll_message_set(problem)
            return False
        return True

    def _start(self, context):
        """The new job, or the operator's result when it cannot start (reported)."""
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
        job = self._start(context)
        if not isinstance(job, Job):
            return job
        job.run()
        return finish_job(self, context, job)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        job = self._start(context)
        if not isinstance(job, Job):
            return job
        job.start_thread()
        self._timer = context.window_manager.event_timer_add(TIMER_SECONDS,
                                                             window=context.window)
        self._shown = None
        context.window_manager.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        job = _job
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
        self._stop_timer(context)
        return finish_job(self, context, job)

    def cancel(self, context):
        # Blender ends the modal operator (file load, window closed): stop the worker too.
        global _job
        if _job is not None:
            _job.stop.set()
            _job = None
        self._stop_timer(context)

    def _stop_timer(self, context):
        context.window_manager.event_timer_remove(self._timer)
        context.workspace.status_text_set(None)
        _redraw_panels(context)


class UDFR_OT_cancel(bpy.types.Operator):
    """Stop the running reconstruction; the scene stays as it was"""

    bl_idname = "udf_reconstruction.cancel"
    bl_label = "Cancel"
    bl_options = {'INTERNAL'}

    @classmethod
    def poll(cls, context):
        if _job is None:
            cls.poll_message_set("No reconstruction is running")
            return False
        return True

    def execute(self, context):
        _job.stop.set()
        return {'FINISHED'}


CLASSES = (UDFR_OT_reconstruct, UDFR_OT_cancel)
