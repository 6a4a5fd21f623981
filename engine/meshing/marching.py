"""The double cover: marching cubes at a small iso-value r of the unsigned distance field.

For small r > 0 the level set {d = r} bounds the r-offset of the surface S: a closed, oriented
2-manifold whatever S's topology, whose two sides both map onto S (an open sheet becomes a thin
pancake). The grid is padded with one layer of far nodes so the cover stays closed where it
meets the box, and processed in slabs along x so only a slab is ever dense.

Index → world is exact: node (i, j, k) is at ``origin + (i, j, k) * spacing``.
"""

from dataclasses import dataclass
from typing import List, Optional

import numpy as np

from ..errors import InputError
from ..progress import CancelFn, ProgressFn, check_cancel, no_progress
from . import mesh_ops

SLAB = 64  # nodes per slab along x
SMALL_COMPONENT = 32  # faces; smaller closed pieces of the cover count as fragments
FRAGMENT_SHARE = 0.02  # a cover whose fragments hold more of its faces than this is shredded
MAX_ISO = 2.0  # voxels; the automatic iso never goes above this


@dataclass
class CoverReport:
    """What the r-surface looks like.

    components: closed pieces; small: pieces with fewer than ``SMALL_COMPONENT`` faces (the
    crumbs a noisy field leaves, which the clean-up drops); handles: total genus of the pieces
    (tunnels through a pancake: holes in the surface, or two sheets whose covers touch);
    fragmented: the small pieces hold more than ``FRAGMENT_SHARE`` of the cover's faces, so r is
    too small for the field's noise. Handles do not count: close sheets, a garment's bands and a
    car's touching parts give a cover real ones at every r.
    """

    components: int
    small: int
    handles: int
    fragmented: bool


def marching_cover(field, iso: float, slab: int = SLAB,
                   cancel: Optional[CancelFn] = None):
    """Marching cubes of ``field`` at ``iso`` (world units).

    Parameters
    ----------
    field : UDFGrid
    iso : float
        Level, world units.
    slab : int
        Nodes per slab along x (memory: slab * ny * nz * 4 bytes).

    Returns
    -------
    vertices : (n, 3) float64 world positions; faces : (m, 3) int64, oriented so that the
    normals point towards larger distances (out of the offset volume).
    """
    from skimage.measure import marching_cubes

    nx, ny, nz = field.shape
    far = np.float32(max(field.far_value, 2.0 * iso, iso + field.spacing))
    # padded node p = global node + 1; slabs share their last/first padded x layer
    starts = list(range(0, nx + 1, slab))
    all_verts, all_faces, planes = [], [], []
    count = 0
    for a in starts:
        check_cancel(cancel)
        b = min(a + slab, nx + 1)
        if b <= a:
            continue
        vol = np.full((b - a + 1, ny + 2, nz + 2), far, dtype=np.float32)
        g0, g1 = max(a - 1, 0), min(b - 1, nx - 1)  # global x nodes inside this slab
        if g1 >= g0:
            vol[g0 - (a - 1):g1 - (a - 1) + 1, 1:-1, 1:-1] = field.slab(g0, g1 + 1)
        if b < nx + 1:
            planes.append(b)
        if vol.min() >= iso:
            continue
        verts, faces, _, _ = marching_cubes(vol, level=iso, method="lewiner",
                                            allow_degenerate=False,
                                            gradient_direction="descent")
        verts = verts.astype(np.float64)
        verts[:, 0] += a
        all_verts.append(verts)
        all_faces.append(faces.astype(np.int64) + count)
        count += len(verts)
    if not all_verts:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    verts = np.concatenate(all_verts)
    faces = np.concatenate(all_faces)
    # weld the vertices the slabs share on their common planes (computed from the same values)
    remap = np.arange(len(verts))
    on_plane = np.nonzero(np.isin(verts[:, 0], np.asarray(planes, dtype=np.float64)))[0]
    if on_plane.size:
        _, first, inverse = np.unique(verts[on_plane], axis=0, return_index=True,
                                      return_inverse=True)
        remap[on_plane] = on_plane[first][inverse.reshape(-1)]
    faces = remap[faces]
    verts, faces, _ = mesh_ops.remove_unreferenced(verts, faces)
    return field.index_to_world(verts - 1.0), faces


def cover_report(faces: np.ndarray) -> CoverReport:
    """Count the pieces, fragments and handles of a closed cover."""
    if len(faces) == 0:
        return CoverReport(0, 0, 0, True)
    topo = mesh_ops.edge_topology(faces)
    pairs, _ = mesh_ops.dual_edges(faces, topo)
    count, labels = mesh_ops.face_components(len(faces), pairs)
    nf = np.bincount(labels, minlength=count)
    first_side = np.unique(topo.face_edges.reshape(-1), return_index=True)[1]
    ne = np.bincount(labels[first_side // 3], minlength=count)
    vert_label = np.zeros(int(faces.max()) + 1, dtype=np.int64)
    vert_label[faces.reshape(-1)] = np.repeat(labels, 3)
    used = np.unique(faces.reshape(-1))
    nv = np.bincount(vert_label[used], minlength=count)
    chi = nv - ne + nf
    handles = int(np.maximum((2 - chi) // 2, 0).sum())
    small = nf < SMALL_COMPONENT
    shredded = nf[small].sum() > FRAGMENT_SHARE * len(faces)
    return CoverReport(int(count), int(small.sum()), handles, bool(shredded))


def double_cover(field, iso: Optional[float] = None, progress: Optional[ProgressFn] = None,
                 cancel: Optional[CancelFn] = None):
    """Extract the double cover, choosing (or checking) the iso-value.

    Parameters
    ----------
    field : UDFGrid
    iso : float or None
        World units. ``None``: start at ``max(1.0 h, min(d) + 0.5 h)`` and raise it (x1.25, up
        to 2 h) while the cover is shredded (:class:`CoverReport`: its crumbs hold more than
        ``FRAGMENT_SHARE`` of its faces). Handles do not raise it: a larger r merges the covers of
        sheets up to 2 r apart and closes holes narrower than r. A given value is used as is (a
        warning when the cover is shredded).

    Returns
    -------
    vertices (n, 3) world, faces (m, 3), iso (world units), report, messages (list of str).
    """
    progress = progress or no_progress
    h = field.spacing
    messages: List[str] = []
    if iso is not None:
        iso = float(iso)
        if not iso > 0:
            raise InputError(f"the iso-value must be positive, got {iso}")
        if iso <= field.min_value:
            raise InputError(
                f"the iso-value {iso:.4g} is below the smallest distance in the grid "
                f"({field.min_value:.4g}): there is no surface; raise --iso")
        verts, faces = marching_cover(field, iso, cancel=cancel)
        report = cover_report(faces)
        if report.fragmented:
            messages.append(
                f"the iso-value {iso / h:.2f} voxels gives a fragmented cover ({report.components} "
                f"pieces, {report.handles} handles); a larger iso-value (about 1 voxel) is safer")
        return verts, faces, iso, report, messages
    iso = max(1.0 * h, field.min_value + 0.5 * h)
    while True:
        progress(0.0, f"marching cubes at iso {iso / h:.2f} voxels")
        verts, faces = marching_cover(field, iso, cancel=cancel)
        report = cover_report(faces)
        if not report.fragmented:
            return verts, faces, iso, report, messages
        if iso * 1.25 > MAX_ISO * h + 1e-12:
            if len(faces) == 0:
                raise InputError("the distance field has no surface (nothing below "
                                 f"{iso:.4g}); is the grid a distance field?")
            messages.append(
                f"the cover is fragmented even at iso {iso / h:.2f} voxels ({report.components} "
                f"pieces, {report.handles} handles): the distance field is noisy")
            return verts, faces, iso, report, messages
        messages.append(f"iso raised from {iso / h:.2f} to {1.25 * iso / h:.2f} voxels: "
                        f"the cover was fragmented ({report.components} pieces)")
        iso *= 1.25
