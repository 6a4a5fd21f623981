"""Entry point of the mesher: a UDF grid in, a one-layer triangle mesh out (DCUDF).

Stages: marching cubes at a small iso-value r (the double cover) → covering-map optimisation
onto the zero set → one layer chosen over the whole cover, rims moved out (:mod:`.layers`) →
clean-up. See the modules of this package for each stage.
"""

import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np

from ..devices import resolve_device
from ..errors import InputError
from ..geometry import Mesh
from ..progress import CancelFn, ProgressFn, check_cancel, no_progress, sub_progress
from ..settings import DEVICES
from .cleanup import clean_mesh
from ..udf_grid import UDFGrid
from .layers import (choose_layer, close_pinholes, drop_facing_pairs, drop_flaps,
                     extend_rims, peel_lips)
from .marching import double_cover
from .optimize import ITERATIONS, LAPLACIAN_WEIGHT, LR, NORMAL_START, optimize_cover


@dataclass
class MeshingSettings:
    """How to mesh a UDF grid. Lengths in voxels unless said otherwise.

    iso: the marching-cubes level r in world units; None picks ``max(1 voxel, min(d) + 0.5
        voxel)`` and raises it (up to 2 voxels) while the cover fragments.
    iterations: optimisation iterations (both stages).
    laplacian_weight: smoothing weight of stage 1, voxel units (DCUDF's weight times the voxel
        size; DCUDF's 2000 at 256^3 over [-1, 1] is about 16: lower keeps more detail of a clean
        field, higher resists noise).
    lr: peak step of VectorAdam, voxels per iteration.
    normal_start: fraction of the iterations after which stage 2 (normal-constrained) starts.
    cut: keep one layer of the double cover (False keeps both layers).
    other_side: keep the other layer of each piece (the one with the smaller area): a tile's
        choice made to agree with its neighbours' (:mod:`engine.tiles`).
    min_component_faces: drop output pieces with fewer faces (0: no limit; specks, the crumbs
        a noisy cover leaves, go either way: see :func:`.cleanup.find_specks`).
    seed: kept for reproducible settings; the layer choice itself draws no random numbers.
    device: ``auto``, ``cpu`` or ``cuda``: where the optimisation runs. ``cuda`` (and ``auto``
        when PyTorch sees a GPU) runs it in torch on the GPU; ``cpu`` in numpy (faster on a CPU
        than torch: 6.4 s vs 14.7 s for the sphere at 128 on 2 cores). The other stages run on
        the CPU.
    """

    iso: Optional[float] = None
    iterations: int = ITERATIONS
    laplacian_weight: float = LAPLACIAN_WEIGHT
    lr: float = LR
    normal_start: float = NORMAL_START
    cut: bool = True
    other_side: bool = False
    min_component_faces: int = 0
    seed: int = 0
    device: str = "auto"

    def validate(self) -> "MeshingSettings":
        """Raise :class:`InputError` when a setting is out of range."""
        if self.iso is not None and not (np.isfinite(self.iso) and self.iso > 0):
            raise InputError(f"iso must be a positive number, got {self.iso}")
        if not 0 <= int(self.iterations) <= 10000:
            raise InputError(f"iterations must be in [0, 10000], got {self.iterations}")
        if not self.laplacian_weight >= 0:
            raise InputError("laplacian_weight must be >= 0")
        if not 0 < self.lr <= 1:
            raise InputError(f"lr must be in (0, 1] voxels per iteration, got {self.lr}")
        if not 0 <= self.normal_start <= 1:
            raise InputError("normal_start must be in [0, 1]")
        if self.min_component_faces < 0:
            raise InputError("min_component_faces must be >= 0")
        if self.device not in DEVICES:
            raise InputError(f"device must be one of {', '.join(DEVICES)}, not {self.device!r}")
        return self


@dataclass
class MeshingResult:
    """The mesh and what happened on the way.

    mesh: the one-layer mesh (world units); iso: the level used (world units); timings: seconds
    per stage; messages: what a user can act on, in plain words; details: the mesher's own notes
    for logs (iso-value raised, a fragmented cover); stats: numbers for logs (cover pieces,
    twins, trees, seam vertices, pairs left double).
    """

    mesh: Mesh
    iso: float
    timings: Dict[str, float] = field(default_factory=dict)
    messages: List[str] = field(default_factory=list)
    stats: Dict[str, float] = field(default_factory=dict)
    details: List[str] = field(default_factory=list)


def extract_surface(field: UDFGrid, settings: Optional[MeshingSettings] = None,
                    progress: Optional[ProgressFn] = None,
                    cancel: Optional[CancelFn] = None) -> MeshingResult:
    """Mesh the zero level set of an unsigned distance grid.

    Parameters
    ----------
    field : UDFGrid
        Dense or band grid, world units (optionally with an exact closest-point callable).
    settings : MeshingSettings, optional
    progress : callable ``(fraction, message)``, optional
    cancel : callable ``() -> bool``, optional; checked at least every few iterations.

    Returns
    -------
    MeshingResult
    """
    settings = (settings or MeshingSettings()).validate()
    progress = progress or no_progress
    if not isinstance(field, UDFGrid):
        raise InputError("extract_surface needs a UDFGrid")
    h = field.spacing
    timings: Dict[str, float] = {}
    messages: List[str] = []
    device = resolve_device(settings.device)
    if device == "cuda" and field.exact is not None:
        device = "cpu"
        messages.append("an exact (analytic) field is optimised on the CPU")

    start = time.perf_counter()
    verts, faces, iso, report, notes = double_cover(
        field, settings.iso, sub_progress(progress, 0.0, 0.05), cancel)
    timings["marching_cubes"] = time.perf_counter() - start
    stats = {"iso_voxels": iso / h, "cover_vertices": len(verts), "cover_faces": len(faces),
             "cover_pieces": report.components}
    if len(faces) == 0:
        return MeshingResult(Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64)), iso,
                             timings, messages + ["no surface found"], stats, notes)

    start = time.perf_counter()
    check_cancel(cancel)
    cover_start = verts.copy()
    if field.exact is None:
        bricks = field.prepare(iso + 3.0 * h)
        stats["field_bricks"] = bricks
    timings["field"] = time.perf_counter() - start

    start = time.perf_counter()
    if device == "cuda":
        from .optimize_torch import optimize_cover_torch

        verts, opt = optimize_cover_torch(verts, faces, field, settings.iterations,
                                          settings.laplacian_weight, settings.lr,
                                          settings.normal_start,
                                          sub_progress(progress, 0.05, 0.9), cancel,
                                          device=device)
    else:
        verts, opt = optimize_cover(verts, faces, field, settings.iterations,
                                    settings.laplacian_weight, settings.lr, settings.normal_start,
                                    sub_progress(progress, 0.05, 0.9), cancel)
    timings["optimize"] = time.perf_counter() - start
    stats["optimize_device"] = device
    stats["optimize_kernels"] = opt.kernels
    stats.update({"mean_distance_voxels": opt.mean_distance,
                  "max_distance_voxels": opt.max_distance, "iterations": opt.iterations})

    start = time.perf_counter()
    progress(0.9, "choosing one layer")
    if settings.cut:
        keep, verts, layer = choose_layer(cover_start, verts, faces, h, field, iso / h, cancel,
                                          settings.other_side)
        kept, lips = peel_lips(verts, faces[keep])
        kept, flaps = drop_flaps(kept)
        kept, facing = drop_facing_pairs(verts, kept, field, h)
        kept, closed = close_pinholes(kept)
        verts, kept, seams = extend_rims(verts, kept, field, h)
        kept, reclosed = close_pinholes(kept)  # where a face turned over by a rim step went
        stats.update({"twinned_faces": layer.twins, "layer_trees": layer.trees,
                      "double_pairs": layer.double_pairs, "centred_vertices": layer.centred,
                      "seam_vertices": len(seams),
                      "lip_faces_dropped": lips, "flaps_dropped": flaps,
                      "facing_faces_dropped": facing,
                      "pinholes_closed": closed + reclosed})
    else:
        kept = faces
    timings["layers"] = time.perf_counter() - start

    start = time.perf_counter()
    check_cancel(cancel)
    out_v, out_f, counts = clean_mesh(verts, kept, h, settings.min_component_faces)
    timings["cleanup"] = time.perf_counter() - start
    stats.update({f"cleanup_{k}": v for k, v in counts.items()})
    if counts["small_pieces"]:
        messages.append(f"{counts['small_pieces']} pieces with fewer than "
                        f"{settings.min_component_faces} faces were removed")
    progress(1.0, "meshing done")
    return MeshingResult(Mesh(out_v, out_f.astype(np.int64)), iso, timings, messages, stats,
                         notes)

