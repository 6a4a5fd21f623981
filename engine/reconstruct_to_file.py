"""Reconstruct straight into a mesh file: what the CLI and the batch use.

A cloud made in tiles (:mod:`.tiles`) and written as PLY goes to the file as it is stitched,
a tile at a time (:class:`.tiles.StitchedMesh`): its vertices mapped to the input's
coordinates and coloured block by block, its pieces counted by a union-find over the face
blocks. The process then never holds the whole mesh, only the tiles' seams and one tile, so
its memory does not grow with the output (docs/scale.md). Any other output (one grid, or
another format) is made in memory by :func:`.reconstruct.reconstruct` and written whole. The
bytes are the same either way.

Either way the write is atomic and an empty result (no faces, or only specks) is refused
without touching the target (:func:`.commands.preflight.check_pieces`).
"""

import os
from typing import Optional, Union

import numpy as np

from .cpu_threads import core_budget
from .geometry import PointCloud
from .progress import CancelFn, ProgressFn, check_cancel
from .reconstruct import ReconstructResult, _reconstruct, nearest_colors
from .settings import ReconstructSettings


def reconstruct_to_file(cloud: Union[PointCloud, np.ndarray], path,
                        settings: Optional[ReconstructSettings] = None,
                        progress: Optional[ProgressFn] = None,
                        cancel: Optional[CancelFn] = None,
                        udf_source: Optional[str] = None) -> ReconstructResult:
    """Reconstruct a mesh from a point cloud and write it to ``path`` (the format by its
    extension, as :func:`.io.write_mesh`).

    Parameters and errors as :func:`.reconstruct.reconstruct`; also :class:`InputError` when
    the result is empty or only specks, or the file cannot be written, and
    :class:`Cancelled` when ``cancel()`` turns True before the file is complete. In every
    such case the target is left as it was.

    Returns
    -------
    ReconstructResult
        Its ``mesh`` is None when the mesh went to the file tile by tile; ``stats`` give its
        ``vertices``, ``faces`` and ``components`` either way.
    """
    from .commands.preflight import check_result
    from .io import write_mesh

    settings = ReconstructSettings.coerce(settings)
    path = os.fspath(path)
    def write_ply(stitched, frame, colors, tree, write_progress):
        return _write_stitched(path, stitched, frame, colors, tree, write_progress, cancel,
                               settings.radius_mode)
    write_tiled = write_ply if os.path.splitext(path)[1].lower() == ".ply" else None

    with core_budget(settings.workers):
        result = _reconstruct(cloud, settings, progress, cancel, udf_source, write_tiled)
    if result.mesh is not None:
        check_result(result.mesh, radius_mode=settings.radius_mode)
        check_cancel(cancel)
        write_mesh(path, result.mesh, cancel)
    return result


def _write_stitched(path: str, stitched, frame, colors, tree, progress, cancel,
                    radius_mode: str):
    """Write a :class:`.tiles.StitchedMesh` (working frame) to a PLY file at ``path`` block by
    block, in the input's coordinates with the nearest input point's colour; refuse it, with
    nothing written, when it is empty or only specks. Returns ``(pieces, faces of the largest
    piece)``."""
    from .commands.preflight import check_pieces
    from .io import write_ply_in_blocks

    pieces = stitched.piece_sizes()
    check_pieces(stitched.vertex_count, stitched.face_count, *pieces,  # nothing written yet
                 radius_mode=radius_mode)
    total = stitched.vertex_count + stitched.face_count
    done = [0]

    def advance(count: int) -> None:
        done[0] += count
        progress(done[0] / max(total, 1), f"writing {os.path.basename(path)}")

    def vertex_blocks():
        for block in stitched.vertex_blocks():
            block_colors = None if colors is None or not len(block) else nearest_colors(
                block, colors, tree)
            yield frame.from_unit(block, in_place=True), block_colors
            advance(len(block))

    def face_blocks():
        for block in stitched.face_blocks():
            yield block
            advance(len(block))

    channels = 0 if colors is None else np.asarray(colors).reshape(len(colors), -1).shape[1]
    write_ply_in_blocks(path, stitched.vertex_count, stitched.face_count, channels,
                        vertex_blocks(), face_blocks(), cancel)
    return pieces
