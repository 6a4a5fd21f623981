"""The reconstruction job: one at a time, started by the Reconstruct operator, shown by the panel.

A :class:`Job` runs the engine on numpy copies of the object's points. ``run`` never touches bpy,
so the operator can run it on a worker thread (from the N-panel) or to the end at once (from
scripts and ``blender -b``).
"""

import threading
import time

from ..engine.errors import InputError
from ..engine.settings import ReconstructSettings
from . import bridge, dependencies, wording

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
    """The reconstruction in progress (for the panel and the operators), or None."""
    return _job


def end_job() -> None:
    """Forget the running job (finished, failed or cancelled): a new one may start."""
    global _job
    _job = None


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
