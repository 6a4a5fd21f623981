"""Run a reconstruction method over benchmark shapes and score it.

A *method* is any callable ``PointCloud -> Mesh`` (see :mod:`lab.bench.methods`). For each of
the first ``count`` test shapes of a domain, :func:`run_benchmark` builds the ground truth and the
input cloud under a condition (:mod:`lab.bench.dataset`), times the method, measures its peak
memory, and scores the output with :func:`engine.metrics.evaluate` in the ground truth's unit
frame. A method that raises is *failed*: it is scored as the worst result (CD inf, F1 0, NC 0)
and counted, never skipped; an output without faces is scored the same way and counted as
*empty*.

What is measured
----------------
* ``seconds``: wall-clock time of the method call only (not building the shape, not scoring);
  ``cpu_seconds``: process CPU time over the same span. A shape whose field was read from
  disk (``field_from_cache``, ``--fields``) was timed for its meshing alone: the summary's
  time and memory leave it out.
* ``peak_rss_mb``: the process's peak resident set size (``VmHWM``) while the method ran. The
  peak is reset before each call by writing ``5`` to ``/proc/self/clear_refs``, so native
  allocations (Open3D, torch, numpy) count and earlier shapes do not. It includes the
  interpreter and the libraries already loaded; ``peak_delta_mb`` is the peak minus the resident
  size just before the call, i.e. what the call added at its peak. Where the reset is refused
  (not Linux), ``resource.getrusage`` gives a process-lifetime maximum instead and
  ``memory_measure`` says so.

The method gets the input points only (``PointCloud(points)``): the dataset's exact normals are
withheld, so every method estimates what it needs.

Rooms are scanned scenes: faces no scan point saw are not scored. When the dataset provides
``crop_to_input(mesh, points, max_dist, normals)``, the ground truth is cropped to the surface
within ``crop_max_dist`` (default 0.01, the dataset's default) of the *clean* scan of the same room
and facing the way its points do (the scan's normals), so
every condition is scored against the same visible ground truth, and the prediction is cropped to
the faces within the same distance of the same clean scan (without normals: a prediction's
normals are its own), so both are scored over the same region whatever the input. Cropping the
prediction to a sparse input's own points instead would cut it at every gap between the input's
points that the clean scan covers, and the ground truth itself, scored as a prediction, would
keep only 0.67-0.78 of the scored area on the sparse test rooms. Pieces grown around outliers
stay and are scored. The result's ``protocol`` records it; resuming refuses a result made under
another protocol.
"""

import json
import math
import os
import platform
import resource
import sys
import time
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from engine.geometry import Mesh, PointCloud
from engine.metrics import DEFAULT_THRESHOLDS, evaluate, f1_key

METRIC_KEYS = ("cd_l1_x100", "cd_l2") + tuple(f1_key(t) for t in DEFAULT_THRESHOLDS) + ("nc",)
LAYER_KEYS = ("double_layer", "gt_double_layer", "gt_close_sheets", "area_ratio",
              "area_ratio_thin_once", "double_layer_wide", "gt_double_layer_wide")
CROP_DOMAINS = ("rooms",)
DEFAULT_CROP_MAX_DIST = 0.01
_CLEAR_REFS = "/proc/self/clear_refs"
_STATUS = "/proc/self/status"
_RESET_SLACK_KB = 4096


# --------------------------------------------------------------------------------------------
# Memory


def _status_kb(field: str) -> Optional[int]:
    """A ``kB`` field of ``/proc/self/status`` (``VmHWM``, ``VmRSS``), or None off Linux."""
    try:
        with open(_STATUS) as status:
            for line in status:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def _reset_peak() -> bool:
    """Reset the process's peak RSS (``VmHWM``) to its current RSS; False if not possible."""
    try:
        with open(_CLEAR_REFS, "w") as clear:
            clear.write("5")
    except OSError:
        return False
    # Some kernels and sandboxes accept the write and ignore it: trust the reset only when the
    # peak really came down to the current RSS.
    peak, current = _status_kb("VmHWM"), _status_kb("VmRSS")
    return peak is not None and current is not None and peak <= current + _RESET_SLACK_KB


class PeakMemory:
    """Peak resident memory of the process over a ``with`` block.

    Attributes (after the block)
    ----------------------------
    peak_mb : float, the process's peak RSS during the block, MiB
    delta_mb : float, ``peak_mb`` minus the RSS at the start of the block
    measure : str, ``"VmHWM reset per call"`` or ``"ru_maxrss (process lifetime)"``
    """

    def __enter__(self) -> "PeakMemory":
        self.exact = _reset_peak()
        if self.exact:
            self._start_kb = _status_kb("VmRSS")
            self.measure = "VmHWM reset per call"
        else:
            self._start_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            self.measure = "ru_maxrss (process lifetime)"
        return self

    def __exit__(self, *exc) -> bool:
        if self.exact:
            peak_kb = _status_kb("VmHWM")
        else:
            peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        self.peak_mb = peak_kb / 1024.0
        self.delta_mb = max(peak_kb - self._start_kb, 0) / 1024.0
        return False


# --------------------------------------------------------------------------------------------
# One benchmark run


def _default_dataset():
    from . import dataset
    return dataset


def _worst_scores() -> Dict[str, float]:
    scores = {"cd_l1_x100": math.inf, "cd_l2": math.inf, "nc": 0.0}
    scores.update({f1_key(t): 0.0 for t in DEFAULT_THRESHOLDS})
    return scores


CROP_CACHE = Path(__file__).resolve().parents[2] / "out" / "bench_cache"


def _cropped_truth(crop: Callable, gt: Mesh, visible: PointCloud, crop_max_dist: float) -> Mesh:
    """``crop(gt, visible.points, crop_max_dist, visible.normals)``, computed once per truth and
    scan: every method and condition of a shape is scored against the same crop (of its clean
    scan). With the benchmark's own dataset the crop is kept in ``CROP_CACHE`` (git-ignored),
    under a digest of the truth, the scan, the distance and the dataset module's source, so a
    change to any of them crops afresh; nothing stays in memory while a method runs."""
    import hashlib
    import tempfile

    from . import dataset

    if crop is not dataset.crop_to_input:
        return crop(gt, visible.points, crop_max_dist, visible.normals)
    digest = hashlib.blake2b(Path(dataset.__file__).read_bytes(), digest_size=20)
    digest.update(repr(float(crop_max_dist)).encode())
    for array in (gt.vertices, gt.faces, visible.points, visible.normals):
        if array is None:
            digest.update(b"none")
            continue
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype}{array.shape}".encode())
        digest.update(array.tobytes())
    path = CROP_CACHE / f"truth_crop_{digest.hexdigest()}.npz"
    try:
        with np.load(path) as saved:
            return Mesh(saved["vertices"], saved["faces"])
    except (OSError, ValueError, KeyError):  # not there yet, or unreadable: crop again
        pass
    cropped = crop(gt, visible.points, crop_max_dist, visible.normals)
    CROP_CACHE.mkdir(parents=True, exist_ok=True)
    handle, partial = tempfile.mkstemp(dir=CROP_CACHE, suffix=".partial")
    with os.fdopen(handle, "wb") as out:  # a name of its own: two runs may crop at once
        np.savez(out, vertices=np.asarray(cropped.vertices, np.float64),
                 faces=np.asarray(cropped.faces, np.int64))
    os.replace(partial, path)
    return cropped


def _score(pred: Mesh, gt: Mesh, samples: int, seed: int, crop: Optional[Callable] = None,
           crop_max_dist: float = DEFAULT_CROP_MAX_DIST, visible: PointCloud = None) -> dict:
    """Metrics of ``pred`` against ``gt`` in the full ground truth's unit frame.

    With ``crop``, the ground truth is cropped to the ``visible`` scan (its points and normals)
    and the prediction to the same scan's points (see the module docstring).
    """
    from engine.frame import UnitFrame

    frame = UnitFrame.from_points(np.asarray(gt.vertices, dtype=np.float64))
    if crop is not None:
        gt = _cropped_truth(crop, gt, visible, crop_max_dist)
        if len(np.asarray(pred.faces).reshape(-1, 3)):
            pred = crop(pred, visible.points, crop_max_dist)
    return evaluate(pred, gt, samples=samples, seed=seed, frame=frame)


def run_benchmark(method: Callable[[PointCloud], Mesh], domain: str, condition: str, count: int,
                  seed: int = 0, samples: int = 100_000, progress=None, *, name: str = None,
                  dataset=None, crop_max_dist: float = DEFAULT_CROP_MAX_DIST,
                  pass_ground_truth: bool = False, jobs: int = 1,
                  method_factory: Optional[Callable[[], Callable]] = None,
                  earlier: Optional[dict] = None, meshes: Optional[str] = None) -> dict:
    """Run ``method`` on the first ``count`` test shapes of ``domain`` under ``condition``.

    Parameters
    ----------
    method : callable ``PointCloud -> Mesh``
        The reconstruction. Any exception it raises (except ``KeyboardInterrupt``) marks the
        shape failed.
    domain : ``cars``, ``garments`` or ``rooms`` (a name of ``dataset.DOMAINS``)
    condition : a name of ``dataset.CONDITIONS`` (``clean``, ``sparse``, ``noisy``, ``outliers``)
    count : number of test shapes, the first ``count`` of ``dataset.test_seeds(domain, count)``
    seed : seed of the metric's surface sampling (the shapes and inputs are fixed by their own
        seeds)
    samples : area-weighted samples per mesh for the metrics
    progress : callable ``(fraction, message)`` or None
    name : the method's name in the result; default ``method.__name__``
    dataset : module-like object with ``test_seeds``, ``make_shape``, ``make_input`` and optional
        ``crop_to_input``; default :mod:`lab.bench.dataset` (tests pass a small stand-in).
        The method is given ``PointCloud(points)`` only (no normals, no colours).
    crop_max_dist : distance of the rooms crop (unit frame)
    pass_ground_truth : call ``method(cloud, gt)`` instead: for :func:`ground_truth`, the
        sampling floor (a perfect reconstruction's scores), and ``truth-udf``, the mesher's
    jobs : shapes run at once, each in its own process (default 1: in this process). Every
        shape's input, method and scoring are seeded alone, so the scores do not depend on
        ``jobs``; the seconds and memory are each process's own. Needs ``method_factory`` and the
        default dataset; each process limits numpy, BLAS and torch to one thread.
    method_factory : picklable callable that builds ``method`` (in each worker process), e.g.
        ``functools.partial(methods.make_method, "ours", resolution=256)``
    earlier : a result of an earlier run of the same method, domain, condition, samples and
        seed (:func:`read_json`): its shapes are kept as they are (also those past ``count``, after
        the others) and only the missing ones among the first ``count`` run, so a long benchmark
        can be extended or finished in several sittings. A result of another method or protocol
        raises ``ValueError``.
    meshes : a folder where each predicted mesh is saved (:func:`mesh_file`), so that
        :func:`rescore` can score it again under another protocol without running the method

    Returns
    -------
    dict
        ``method``, ``domain``, ``condition``, ``count``, ``seed``, ``samples``, ``protocol``
        (str), ``memory_measure``, ``environment`` (versions), ``shapes`` (one dict per shape:
        ``shape_seed``, ``points``, ``seconds``, ``cpu_seconds``, ``peak_rss_mb``,
        ``peak_delta_mb``, ``failed``, ``error``, ``empty``, ``pred_faces`` and the metric keys)
        and ``summary`` (see :func:`summarize`).
    """
    if jobs > 1 and (method_factory is None or dataset is not None):
        raise ValueError("jobs > 1 needs a method_factory and the default dataset")
    dataset = dataset or _default_dataset()
    name = name or getattr(method, "__name__", "method")
    crop = getattr(dataset, "crop_to_input", None) if domain in CROP_DOMAINS else None
    shape_seeds = [int(shape_seed) for shape_seed in dataset.test_seeds(domain, count)][:count]
    protocol = _protocol(samples, seed, domain, crop is not None, crop_max_dist)
    kept = _rows_to_keep(earlier, name, domain, condition, samples, seed, protocol)
    tasks = [(shape_seed, domain, condition, samples, seed, crop is not None,
              crop_max_dist, pass_ground_truth,
              None if meshes is None else mesh_file(meshes, name, domain, condition, shape_seed))
             for shape_seed in shape_seeds if shape_seed not in kept]
    label = f"{name} {domain}/{condition}"
    new_rows: List[dict] = []
    measure = earlier.get("memory_measure") if earlier else None
    if jobs > 1 and tasks:
        for row, measure in _run_parallel(method_factory, tasks, jobs, progress, label):
            new_rows.append(row)
    else:
        for index, task in enumerate(tasks):
            if progress is not None:
                progress(index / max(len(tasks), 1), f"{label} shape {index + 1}/{len(tasks)}")
            row, measure = _run_shape(method, dataset, *task)
            new_rows.append(row)
    by_seed = {**kept, **{row["shape_seed"]: row for row in new_rows}}
    rows = [by_seed[shape_seed] for shape_seed in shape_seeds]
    rows += [row for shape_seed, row in kept.items() if shape_seed not in shape_seeds]
    if progress is not None:
        progress(1.0, f"{name} {domain}/{condition} done")

    return {
        "method": name, "domain": domain, "condition": condition, "count": len(rows),
        "seed": seed, "samples": samples, "protocol": protocol, "memory_measure": measure,
        "environment": environment(), "shapes": rows, "summary": summarize(rows),
    }


def _protocol(samples: int, seed: int, domain: str, cropped: bool, crop_max_dist: float) -> str:
    """How a result is scored, in words (the result's ``protocol``)."""
    protocol = (f"metrics in the GT unit frame, {samples} area-weighted samples per mesh, "
                f"sampling seed {seed}")
    if cropped:
        protocol += (f"; GT and prediction cropped to faces within {crop_max_dist} of the clean "
                     f"scan (GT: facing as the scan's normals and in the plane of its points; "
                     f"dataset.crop_to_input)")
    elif domain in CROP_DOMAINS:
        protocol += "; no crop (dataset has no crop_to_input): unseen GT faces count as missed"
    return protocol


def _rows_to_keep(earlier: Optional[dict], name: str, domain: str, condition: str,
                  samples: int, seed: int, protocol: str) -> Dict[int, dict]:
    """The rows of an earlier result, by shape seed, after checking it is the same benchmark."""
    if earlier is None:
        return {}
    wanted = {"method": name, "domain": domain, "condition": condition, "samples": samples,
              "seed": seed, "protocol": protocol}
    differs = {key: (earlier.get(key), value) for key, value in wanted.items()
               if earlier.get(key) != value}
    if differs:
        detail = ", ".join(f"{key} {old!r} (now {new!r})" for key, (old, new) in differs.items())
        raise ValueError(f"the earlier result is another benchmark: {detail}")
    return {int(row["shape_seed"]): row for row in earlier["shapes"]}


def _run_shape(method: Callable, dataset, shape_seed: int, domain: str, condition: str,
               samples: int, seed: int, cropped: bool, crop_max_dist: float,
               pass_ground_truth: bool, mesh_path: Optional[Path] = None):
    """Build one shape's ground truth and input, run ``method`` on it, score it (and save the
    mesh to ``mesh_path``).

    Returns ``(row, memory_measure)``: the row of :func:`run_benchmark`'s ``shapes``.
    """
    gt = dataset.make_shape(domain, shape_seed)
    cloud = PointCloud(np.asarray(dataset.make_input(gt, domain, condition, shape_seed).points))
    crop, visible = _scored_region(dataset, gt, domain, shape_seed, cropped)
    row = {"shape_seed": int(shape_seed), "points": len(cloud), "failed": False, "error": None,
           "run_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    pred = None
    cpu_start = time.process_time()
    with PeakMemory() as memory:
        start = time.perf_counter()
        try:
            pred = method(cloud, gt) if pass_ground_truth else method(cloud)
        except Exception as error:  # the benchmark counts every failure, whatever it is
            row.update(failed=True, error=f"{type(error).__name__}: {error}")
        seconds = time.perf_counter() - start
    row.update(seconds=seconds, cpu_seconds=time.process_time() - cpu_start,
               peak_rss_mb=memory.peak_mb, peak_delta_mb=memory.delta_mb)
    if pred is not None and getattr(method, "field_from_cache", False):
        row["field_from_cache"] = True  # its time and memory are the mesher's alone
    if pred is None:
        row.update(_worst_scores(), empty=True, pred_faces=0)
    else:
        if mesh_path is not None:
            save_mesh(pred, mesh_path)
        row.update(_scores(pred, gt, samples, seed, crop, crop_max_dist, visible))
    return row, memory.measure


def _scored_region(dataset, gt: Mesh, domain: str, shape_seed: int, cropped: bool):
    """The crop and the clean scan it crops to (``(None, None)`` for an uncropped domain)."""
    if not cropped:
        return None, None
    return dataset.crop_to_input, dataset.make_input(gt, domain, "clean", shape_seed)


def _scores(pred: Mesh, gt: Mesh, samples: int, seed: int, crop, crop_max_dist: float,
            visible) -> dict:
    """The metric and layer keys of a row, ``empty`` and ``pred_faces``."""
    scores = _score(pred, gt, samples, seed, crop, crop_max_dist, visible)
    row = {key: scores[key] for key in METRIC_KEYS + LAYER_KEYS}
    row.update(empty=bool(scores["empty"]), pred_faces=int(scores["pred_faces"]))
    return row


# --------------------------------------------------------------------------------------------
# Saved meshes: score a run again under another protocol without running the method


def mesh_file(folder, name: str, domain: str, condition: str, shape_seed: int) -> Path:
    """Where the mesh of one shape of a run is saved."""
    return Path(folder) / f"{name}_{domain}_{condition}_{int(shape_seed)}.npz"


def save_mesh(mesh: Mesh, path: Path) -> None:
    """Write ``mesh`` (float64 vertices, int64 faces, compressed) through a temporary file, so
    that an interrupted run leaves no half-written mesh."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    with open(partial, "wb") as handle:
        np.savez_compressed(handle, vertices=np.asarray(mesh.vertices, np.float64),
                            faces=np.asarray(mesh.faces, np.int64).reshape(-1, 3))
    os.replace(partial, path)


def rescore(earlier: dict, meshes, crop_max_dist: float = DEFAULT_CROP_MAX_DIST,
            dataset=None, progress=None) -> dict:
    """``earlier`` (a result of :func:`run_benchmark`) scored again under today's protocol from
    the meshes its run saved in ``meshes``; times, memory and failures are kept as they were.

    Raises ``FileNotFoundError`` naming a shape whose mesh was not saved.
    """
    dataset = dataset or _default_dataset()
    name, domain, condition = earlier["method"], earlier["domain"], earlier["condition"]
    samples, seed = earlier["samples"], earlier["seed"]
    cropped = domain in CROP_DOMAINS and hasattr(dataset, "crop_to_input")
    rows = []
    for index, old in enumerate(earlier["shapes"]):
        if progress is not None:
            progress(index / len(earlier["shapes"]), f"rescoring {name} {domain}/{condition}")
        row = dict(old)
        if not (old["failed"] or old["empty"]):
            path = mesh_file(meshes, name, domain, condition, old["shape_seed"])
            if not path.exists():
                raise FileNotFoundError(f"no saved mesh for shape {old['shape_seed']} of "
                                        f"{name} {domain}/{condition}: {path}")
            with np.load(path) as saved:
                pred = Mesh(saved["vertices"], saved["faces"])
            gt = dataset.make_shape(domain, old["shape_seed"])
            crop, visible = _scored_region(dataset, gt, domain, old["shape_seed"], cropped)
            row.update(_scores(pred, gt, samples, seed, crop, crop_max_dist, visible))
        rows.append(row)
    protocol = _protocol(samples, seed, domain, cropped, crop_max_dist)
    return {**earlier, "protocol": protocol, "shapes": rows, "summary": summarize(rows)}


# One thread per worker process (numpy's BLAS and torch both read these at start): a pool of
# N processes should use N cores, not N x cores.
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_worker_method = None


def _start_worker(method_factory) -> None:
    global _worker_method
    _worker_method = method_factory()


def _worker_shape(task):
    return _run_shape(_worker_method, _default_dataset(), *task)


def _run_parallel(method_factory, tasks, jobs: int, progress, label: str):
    """The rows of ``tasks`` (in task order), run in ``jobs`` spawned worker processes."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    saved = {key: os.environ.get(key) for key in _THREAD_VARIABLES}
    os.environ.update({key: "1" for key in _THREAD_VARIABLES})  # inherited by the workers
    try:
        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_start_worker,
                                 initargs=(method_factory,)) as pool:
            for done, result in enumerate(pool.map(_worker_shape, tasks)):
                if progress is not None:
                    progress((done + 1) / len(tasks), f"{label} shape {done + 1}/{len(tasks)}")
                yield result
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def first_shapes(result: dict, count: int) -> Optional[dict]:
    """``result`` cut to its first ``count`` shapes, summary recomputed; None if it has fewer.

    Rows of a table must be scored on the same shapes: a run over 20 shapes and one over 5 are
    compared on the first 5 (the test seeds are taken in order, so these are the same shapes).
    """
    if len(result["shapes"]) < count:
        return None
    shapes = result["shapes"][:count]
    return {**result, "count": len(shapes), "shapes": shapes, "summary": summarize(shapes)}


def ground_truth(cloud: PointCloud, gt: Mesh) -> Mesh:
    """The 'method' that returns the ground truth: its scores are the sampling floor.

    Run it with ``run_benchmark(ground_truth, ..., pass_ground_truth=True)``.
    """
    return gt


def _mean(values: Sequence[float]) -> Optional[float]:
    return float(np.mean(values)) if len(values) else None


def summarize(rows: Sequence[dict]) -> dict:
    """Aggregates of per-shape rows.

    Returns
    -------
    dict
        ``n``, ``failed`` (the method raised), ``empty`` (no surface, including failed),
        ``scored`` (shapes with a surface); ``cd_l1_x100`` and ``cd_l2``: means over the scored
        shapes (None when none), ``cd_l1_x100_all``: mean over all shapes (inf when any shape has
        no surface); F-scores and ``nc``: means over all shapes, a shape without surface counting
        0; ``seconds``: mean wall seconds per shape; ``peak_rss_mb``: the largest per-shape peak;
        ``peak_delta_mb``: the largest per-shape increase. The last three leave out the shapes
        whose field was read from disk (``field_from_cache``: :mod:`.field_cache`).
    """
    scored = [row for row in rows if not row["empty"]]
    summary = {
        "n": len(rows),
        "failed": sum(bool(row["failed"]) for row in rows),
        "empty": sum(bool(row["empty"]) for row in rows),
        "scored": len(scored),
        "cd_l1_x100": _mean([row["cd_l1_x100"] for row in scored]),
        "cd_l2": _mean([row["cd_l2"] for row in scored]),
        "cd_l1_x100_all": _mean([row["cd_l1_x100"] for row in rows]),
    }
    for key in METRIC_KEYS[2:]:
        summary[key] = _mean([row[key] for row in rows])
    for key in LAYER_KEYS:  # rows scored before these metrics existed have none
        values = [row[key] for row in scored if row.get(key) is not None]
        summary[key] = _mean(values) if len(values) == len(scored) else None
    timed = [row for row in rows if not row.get("field_from_cache")]
    summary["seconds"] = _mean([row["seconds"] for row in timed])
    summary["peak_rss_mb"] = max((row["peak_rss_mb"] for row in timed), default=None)
    summary["peak_delta_mb"] = max((row["peak_delta_mb"] for row in timed), default=None)
    return summary


def environment() -> dict:
    """Versions and machine facts that bear on the numbers."""
    info = {"python": platform.python_version(), "numpy": np.__version__,
            "machine": platform.machine(), "cpus": os.cpu_count(),
            "omp_num_threads": os.environ.get("OMP_NUM_THREADS")}
    open3d = sys.modules.get("open3d")
    if open3d is not None:
        info["open3d"] = open3d.__version__
    return info


# --------------------------------------------------------------------------------------------
# Output


def _fmt(value, digits: int) -> str:
    if value is None:
        return "–"
    if isinstance(value, float) and not math.isfinite(value):
        return "inf"
    return f"{value:.{digits}f}"


TABLE_HEADER = ("| method | domain | condition | N | failed | CD-L1 ×10² | F1@0.005 | F1@0.01 "
                "| NC | double % (GT %); within 4 spacings | area ratio (thin parts once) "
                "| s/shape | peak MB |\n"
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def _layers(summary: dict) -> str:
    """``double % (GT %)`` of a summary, then the same within 4 spacings where it was scored;
    ``–`` for rows scored without the layer metrics."""
    if summary.get("double_layer") is None:
        return "–"
    text = f"{100 * summary['double_layer']:.1f} ({100 * summary['gt_double_layer']:.1f})"
    if summary.get("double_layer_wide") is None:
        return text
    return (f"{text}; {100 * summary['double_layer_wide']:.1f} "
            f"({100 * summary['gt_double_layer_wide']:.1f})")


def _area(summary: dict) -> str:
    """``area ratio (thin parts once)``, the second left out for rows scored without it."""
    ratio = _fmt(summary.get("area_ratio"), 3)
    if summary.get("area_ratio_thin_once") is None:
        return ratio
    return f"{ratio} ({_fmt(summary['area_ratio_thin_once'], 3)})"


def table_row(result: dict) -> str:
    """One markdown row of a :func:`run_benchmark` result."""
    s = result["summary"]
    failed = str(s["failed"])
    if s["empty"] > s["failed"]:
        failed += f" (+{s['empty'] - s['failed']} empty)"
    return (f"| {result['method']} | {result['domain']} | {result['condition']} | {s['n']} "
            f"| {failed} | {_fmt(s['cd_l1_x100'], 3)} | {_fmt(s[f1_key(0.005)], 3)} "
            f"| {_fmt(s[f1_key(0.01)], 3)} | {_fmt(s['nc'], 3)} | {_layers(s)} "
            f"| {_area(s)} | {_fmt(s['seconds'], 1)} "
            f"| {_fmt(s['peak_rss_mb'], 0)} |")


def format_table(results: Sequence[dict]) -> str:
    """A markdown table, one row per result (method × domain × condition).

    CD is the mean over shapes that produced a surface; F-scores and NC are means over all shapes
    (a failed or empty shape counts 0); ``failed`` counts shapes where the method raised (and,
    in brackets, those where it returned no surface).
    """
    return "\n".join([TABLE_HEADER] + [table_row(result) for result in results])


def _strict(value):
    """``value`` with non-finite floats replaced by None, so the JSON stays strict."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {key: _strict(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(item) for item in value]
    return value


def result_filename(result: dict) -> str:
    """``<method>_<domain>_<condition>.json``."""
    return f"{result['method']}_{result['domain']}_{result['condition']}.json"


def read_json(path: str) -> dict:
    """A result written by :func:`write_json`; the CD of shapes without a surface is inf again."""
    with open(path) as handle:
        result = json.load(handle)
    for row in result["shapes"]:
        for key in ("cd_l1_x100", "cd_l2"):
            if row.get(key) is None:
                row[key] = math.inf
    return result


def write_json(result: dict, out_dir: str) -> str:
    """Write ``result`` as strict JSON (inf → null) into ``out_dir``; return the file path.

    The file is written beside its final name and moved over it, so an interrupted run leaves
    the previous result (which ``--resume`` extends) whole."""
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, result_filename(result))
    partial = path + ".partial"
    with open(partial, "w") as handle:
        json.dump(_strict(result), handle, indent=1, allow_nan=False)
        handle.write("\n")
    os.replace(partial, path)
    return path
