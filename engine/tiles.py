"""Large clouds in tiles: each tile's field and mesh on its own, stitched into one mesh.

The field at a grid node depends only on the input points within reach of it (the widest ball,
:data:`engine.field.SPARSE_WIDENING` times the largest radius), so a tile is computed from the
points within its *core* (a cube of ``tile_cells`` cells) widened by a halo of
:data:`HALO_CELLS` cells, where the mesher sees the surface run on, and by that reach. Each tile
is meshed on its own; only the faces whose centroid lies in its core are kept (the cores tile
the space without overlap, so no face is kept twice).

Every tile's grid lies on one lattice shared by all tiles, so two neighbours compute the same
field, cover and, mostly, the same faces along their common border.

Stitching. Boundary vertices of different tiles within :data:`SAME_CELLS` of each other are one
vertex meshed by both and are merged; the others that are each other's nearest across tiles
within :data:`WELD_CELLS` cells are welded (to their mean). The two sides of an open sheet are
equally good layers, and a tile may keep the other side than its neighbours: such a tile is made
again keeping the side they kept (:func:`tiles_to_turn`, which reads a tile and its neighbours
at a time), since the two sides share no vertices along the border; a piece still facing the
other way is turned over. A face both tiles kept is kept once, faces left hanging on a weld are
dropped and the holes left along the seam (up to :data:`SEAM_HOLE_EDGES` edges) are closed.
Each tile's own mesh is already clean, so only the seam (the faces with a vertex within
:data:`SEAM_CELLS` of their tile's core border, and the faces around them) is welded and
tidied; the other faces pass through as they are. The seams are stitched in two rounds
(:func:`stitched_in_blocks`): within blocks of :data:`BLOCK_TILES` tiles per side, then
between the blocks, so that no step holds every tile's seam at once.

Tiles are made one after the other in this process, in worker processes or on a Dask cluster
(:mod:`.tile_runners`), with the same result.

A worker's memory is bounded by the tile size, not the scene. As each tile's mesh reaches the
main process it is split (:func:`split_tile`) and waits in a temporary folder on disk, only its
seam's rim (the weld candidates, which vote on the turn) held; the seams are read back a block
of tiles at a time, and the rest tile by tile into the output (:class:`StitchedMesh`): into
memory, or straight into a file (:mod:`.reconstruct_to_file`), when the main process holds
the blocks' seams and one tile, never the whole mesh. Time grows with the number of tiles
that hold points.
"""

import dataclasses
import os
import tempfile
from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from .errors import InputError
from .progress import CancelFn, ProgressFn, no_progress, sub_progress
from .tile_plan import CloudTiles, Tile

AUTO_TILE_CELLS = 192
"""With ``tile_cells`` 0, tiles of this many cells per side (a worker's memory follows it)."""
AUTO_TILE_ABOVE = 512
"""With ``tile_cells`` 0, a grid of more than this many cells along its longest side is tiled."""
HALO_CELLS = 8
"""Cells beyond a tile's core that it meshes too, so its core's faces see the surface go on."""
SAME_CELLS = 0.1
"""Boundary vertices of different tiles this close (cells) are one vertex meshed by both."""
SEAM_HOLE_EDGES = 16
"""Holes of up to this many edges left along a welded seam are closed."""
NORMAL_RINGS = 3
"""Rings of faces around a welded vertex whose normals vote on the orientation."""
WELD_CELLS = 0.9
"""Other boundary vertices of neighbouring tiles that are each other's nearest within this
many cells are welded too."""
SEAM_CELLS = 4.0
"""Faces with a vertex this close (cells) to their tile's core border are the seam's: the only
ones stitching may change (welds, the rings whose normals vote, ears, holes, bow-ties)."""


def keep_core(vertices: np.ndarray, faces: np.ndarray, tile: Tile):
    """The faces whose centroid lies in the tile's core, with only the vertices they use."""
    if not len(faces):
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    centroids = vertices[faces].mean(axis=1)
    faces = faces[np.all((centroids >= tile.low) & (centroids < tile.high), axis=1)]
    used, faces = np.unique(faces, return_inverse=True)
    return vertices[used], faces.reshape(-1, 3)


SEAM_ARRAYS = ("seam_ids", "seam_points", "seam_tile", "seam_faces", "seam_zone", "seam_piece")
"""The arrays of a :class:`TilePiece` that stitching reads, held or spilled to its file."""


@dataclass
class TilePiece:
    """One tile's kept faces, split for stitching (:func:`split_tile`).

    What stitching reads, the seam's part of the tile (held in memory, or spilled to the
    tile's file until :meth:`held` reads it back: then these are None): ``seam_ids``: the
    tile's vertices on the seam's faces (ascending), ``seam_points`` their positions;
    ``seam_faces``: the seam's faces, over the positions in ``seam_ids``: the zone faces
    (``seam_zone``: a vertex near the border) and the faces sharing a vertex with them, so that
    every edge of a zone face has all of its faces here; ``seam_piece``: their pieces (the
    tile's vertex-connected components). ``seam_tile``: the tile each seam vertex was made in
    (its number among all tiles; a block of tiles stitched together keeps its vertices' tiles,
    -1 for a copy a bow-tie split made): welds join vertices of different tiles only.

    Always held: per piece, ``piece_area`` and ``piece_faces``; the seam's *rim*, its open
    vertices within :data:`SEAM_CELLS` of the core's border (the weld candidates): ``rim``
    (positions in ``seam_ids``), ``rim_points``, ``rim_tile``, ``rim_piece`` and
    ``rim_normal`` (the unit normal of the :data:`NORMAL_RINGS` rings of faces around each,
    which votes on the tile's orientation: :func:`tiles_to_turn` reads the rims alone).

    The rest, read only to assemble the output: ``rest`` (:class:`TileRest`).
    """

    vertex_count: int
    seam_ids: Optional[np.ndarray]
    seam_points: Optional[np.ndarray]
    seam_tile: Optional[np.ndarray]
    seam_faces: Optional[np.ndarray]
    seam_zone: Optional[np.ndarray]
    seam_piece: Optional[np.ndarray]
    piece_area: np.ndarray
    piece_faces: np.ndarray
    rim: np.ndarray
    rim_points: np.ndarray
    rim_tile: np.ndarray
    rim_piece: np.ndarray
    rim_normal: np.ndarray
    rest: "TileRest"

    def held(self) -> "TilePiece":
        """This piece with its seam in memory (read back from its file if it was spilled)."""
        if self.seam_ids is not None:
            return self
        return dataclasses.replace(self, **dict(zip(SEAM_ARRAYS, self.rest.read(*SEAM_ARRAYS))))


@dataclass
class TileRest:
    """What of a tile's piece the output reads besides the seam: per piece, its faces away
    from the seam (``piece_rest``), and the arrays ``vertices``, ``faces`` and ``pieces`` (and
    the seam's, :data:`SEAM_ARRAYS`, when it was spilled) in the ``.npz`` file ``stored``
    names, or in ``stored`` (a dict) when split without a file."""

    piece_rest: np.ndarray
    stored: object

    def read(self, *names: str) -> tuple:
        """The named arrays (``vertices``, ``faces``, ``pieces``, a spilled seam's)."""
        if isinstance(self.stored, dict):
            return tuple(self.stored[name] for name in names)
        with np.load(self.stored) as data:
            return tuple(data[name] for name in names)


def split_tile(vertices: np.ndarray, faces: np.ndarray, tile: Tile, spacing: float,
               path: Optional[str] = None, number: int = 0,
               vertex_tile: Optional[np.ndarray] = None, spill: bool = False) -> TilePiece:
    """A tile's kept faces split into its seam (held) and the rest (written to ``path``, an
    ``.npz`` file, when given; else held too). See :class:`TilePiece`. ``number``: the tile's
    among all tiles; ``vertex_tile``, given, each vertex's tile instead (a block's);
    ``spill``: write the seam to ``path`` as well, holding only its rim."""
    from .meshing.mesh_ops import face_normals, vertex_components

    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    count, label = vertex_components(len(v), f) if len(f) else (0, np.zeros(0, np.int64))
    area = np.bincount(label, weights=face_normals(v, f)[1], minlength=count)
    margin = np.minimum(v - tile.low, tile.high - v).min(axis=1)
    close = margin < SEAM_CELLS * spacing
    zone = close[f].any(axis=1)
    touched = np.zeros(len(v), bool)
    touched[f[zone]] = True
    seam = touched[f].any(axis=1)
    on_seam = np.zeros(len(v), bool)
    on_seam[f[seam]] = True
    position = np.cumsum(on_seam) - 1  # of each seam vertex in ``seam_ids``
    held = dict(zip(SEAM_ARRAYS, (
        np.flatnonzero(on_seam), v[on_seam],
        (np.full(int(on_seam.sum()), number, np.int32) if vertex_tile is None
         else np.asarray(vertex_tile, np.int32)[on_seam]),
        position[f[seam]], zone[seam], label[seam])))
    rim = _rim(held["seam_points"], held["seam_faces"], close[on_seam], held["seam_tile"],
               held["seam_piece"])
    rest = {"vertices": v, "faces": f[~seam].astype(np.int32),
            "pieces": label[~seam].astype(np.int32)}
    if path is not None:
        np.savez(path, **rest, **(held if spill else {}))
        rest = path
        if spill:
            held = dict.fromkeys(held)
    return TilePiece(len(v), **held, piece_area=area,
                     piece_faces=np.bincount(label, minlength=count), **rim,
                     rest=TileRest(np.bincount(label[~seam], minlength=count), rest))


def _rim(points, faces, near, tile, face_piece) -> dict:
    """A seam's rim (:class:`TilePiece`): its open vertices near the border, ascending, with
    their positions, tiles, pieces and unit normals."""
    from .meshing.mesh_ops import edge_topology

    rim = np.zeros(0, np.int64)
    if len(faces):
        topo = edge_topology(faces)
        rim = np.unique(topo.edges[topo.counts == 1])
        rim = rim[near[rim]]
    normal = _vertex_normals(points, faces)[rim] if len(rim) else np.zeros((0, 3))
    return {"rim": rim, "rim_points": points[rim], "rim_tile": tile[rim],
            "rim_piece": _vertex_pieces(len(points), faces, face_piece)[rim],
            "rim_normal": normal}


@dataclass
class _Seam:
    """The seams of all the tiles' pieces (:class:`TilePiece`), joined; ``rests``: the rest of
    each (:class:`TileRest`).

    The vertices are numbered across the tiles, tile after tile (tile ``t`` from
    ``offsets[t]``). ``ids``: the joined index of each seam vertex (ascending), ``points``
    their positions; ``faces``: the seam's faces over the seam vertices, ``zone`` and
    ``face_piece`` theirs (the pieces numbered across the tiles: tile ``t``'s from
    ``piece_first[t]``); ``piece_tile``, ``piece_area``, ``piece_faces``: per piece; ``a``,
    ``b``: the seam vertices to weld (:func:`_pairs_across`).
    """

    rests: list
    offsets: np.ndarray
    ids: np.ndarray
    points: np.ndarray
    faces: np.ndarray
    zone: np.ndarray
    face_piece: np.ndarray
    piece_first: np.ndarray
    piece_tile: np.ndarray
    piece_area: np.ndarray
    piece_faces: np.ndarray
    a: np.ndarray
    b: np.ndarray
    held: Optional[np.ndarray] = None  # with a frozen border: its band's seam vertices


SEAM_BLOCK = 1 << 20
"""Most seam faces :meth:`StitchedMesh.face_blocks` yields at once."""


def _split_all(pieces, tiles, spacing: float, hold: bool = False) -> list:
    """The pieces as :class:`TilePiece` (those given as ``(vertices, faces)`` split, held);
    ``hold``: with every seam in memory."""
    split = [piece if isinstance(piece, TilePiece)
             else split_tile(*piece, tile, spacing, number=number)
             for number, (piece, tile) in enumerate(zip(pieces, tiles))]
    return [piece.held() for piece in split] if hold else split


def _seam(pieces: list, spacing: float, frozen: Optional[Tile] = None) -> _Seam:
    """The tiles' seams (``pieces``: a :class:`TilePiece` per tile) joined, and the pairs of
    their open vertices to weld. With ``frozen`` (a block of tiles' box), the seam within
    :data:`SEAM_CELLS` of its border is left as it is: no weld there, no face touching it in
    the zone, for the blocks' own stitching (:func:`stitched_in_blocks`)."""
    offsets = np.cumsum([0] + [piece.vertex_count for piece in pieces])
    seam_first = np.cumsum([0] + [len(piece.seam_ids) for piece in pieces])
    piece_first = np.cumsum([0] + [len(piece.piece_area) for piece in pieces])[:-1]
    empty = np.zeros(0, np.int64)
    ids = np.concatenate([piece.seam_ids + offsets[t] for t, piece in enumerate(pieces)]
                         + [empty])
    faces = np.concatenate([piece.seam_faces + seam_first[t] for t, piece in enumerate(pieces)]
                           + [np.zeros((0, 3), np.int64)])
    points = np.concatenate([piece.seam_points for piece in pieces] + [np.zeros((0, 3))])
    zone = np.concatenate([piece.seam_zone for piece in pieces] + [np.zeros(0, bool)])
    held = None
    if frozen is not None:
        margin = np.minimum(points - frozen.low, frozen.high - points).min(axis=1)
        held = margin < SEAM_CELLS * spacing
        zone &= ~held[faces].any(axis=1)
        del margin
    # the zone's open edges are open in the whole mesh too: the weld candidates are the rims
    rim = np.concatenate([piece.rim + seam_first[t] for t, piece in enumerate(pieces)] + [empty])
    tile_of = np.concatenate([piece.rim_tile for piece in pieces] + [np.zeros(0, np.int32)])
    if held is not None:
        tile_of = tile_of[~held[rim]]
        rim = rim[~held[rim]]
    i, j = _pairs_across(points[rim], tile_of, spacing)
    a, b = rim[i], rim[j]
    return _Seam([piece.rest for piece in pieces], offsets, ids, points, faces, zone,
                 np.concatenate([piece.seam_piece + piece_first[t]
                                 for t, piece in enumerate(pieces)] + [empty]),
                 piece_first,
                 np.concatenate([np.full(len(piece.piece_area), t, np.int64)
                                 for t, piece in enumerate(pieces)] + [empty]),
                 np.concatenate([piece.piece_area for piece in pieces] + [np.zeros(0)]),
                 np.concatenate([piece.piece_faces for piece in pieces] + [empty]), a, b,
                 held)


def stitch(pieces, tiles, spacing: float, min_component_faces: int = 0):
    """One mesh from the tiles' kept faces, in memory: :func:`stitched_mesh`'s arrays.

    Returns
    -------
    vertices : (n, 3) float64; faces : (m, 3) int64; stats : dict, as :func:`stitched_mesh`
    """
    stitched, stats = stitched_in_blocks(pieces, tiles, spacing, min_component_faces)
    return stitched.arrays() + (stats,)


def stitched_mesh(pieces, tiles, spacing: float, min_component_faces: int = 0,
                  frozen: Optional[Tile] = None):
    """One mesh from the tiles' kept faces: ``pieces`` is a list with, per tile of ``tiles``,
    its :class:`TilePiece` or its ``(vertices, faces)``. The list is emptied as it is read.
    ``frozen``: a block's box whose border band is left for a later stitch (see :func:`_seam`).

    Only the seam (:class:`TilePiece`) is welded and tidied: each tile's own mesh is already
    clean, so the faces away from its core's border pass through unchanged, read tile by tile
    (from disk, for pieces split with a file) into the output: memory beyond the output
    follows the seam, not the scene. ``min_component_faces``: drop pieces (joined across the
    tiles) with fewer faces.

    Returns
    -------
    stitched : :class:`StitchedMesh`, to be read while the pieces' files exist
    stats : dict with ``welded`` vertices, ``flipped`` pieces, ``ears_dropped`` faces,
        ``holes_closed``, and the clean-up's ``cleanup_degenerate``, ``cleanup_split_vertices``,
        ``cleanup_specks`` and ``cleanup_small_pieces``
    """
    from .meshing.cleanup import find_specks
    from .meshing.layers import close_pinholes
    from .meshing.mesh_ops import face_normals, split_nonmanifold_vertices, vertex_components

    given = _split_all(pieces, tiles, spacing, hold=True)
    pieces.clear()
    seam = _seam(given, spacing, frozen)
    del given
    stats = {"welded": 0, "flipped": 0, "ears_dropped": 0, "holes_closed": 0,
             "cleanup_degenerate": 0, "cleanup_split_vertices": 0, "cleanup_specks": 0,
             "cleanup_small_pieces": 0}
    faces, zone, piece, local, a, b = (seam.faces, seam.zone, seam.face_piece, seam.points,
                                       seam.a, seam.b)
    # from here on the seam's arrays change hands: the seam keeps what the output reads
    seam.faces = seam.zone = seam.face_piece = seam.points = seam.a = seam.b = None
    flip = np.zeros(len(seam.piece_tile), bool)
    if not len(faces):  # no surface near a border: nothing to stitch
        return StitchedMesh(seam, local, faces, flip, flip), stats
    if len(a):
        flip = _piece_flips(local, faces, piece, len(flip), a, b)
        stats["flipped"] = int(flip.sum())
        local, merged = _weld(local, a, b)
        del a, b
        stats["welded"] = int(len(local) - len(np.unique(merged)))
        faces = merged[faces]
    turn = flip[piece]
    faces[turn] = faces[turn][:, ::-1]
    del turn
    keep = ((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
            & (faces[:, 0] != faces[:, 2]))
    faces, zone, piece = faces[keep], zone[keep], piece[keep]
    # a face both tiles kept once its corners are welded: keep it once
    keep = np.sort(np.unique(np.sort(faces, axis=1), axis=0, return_index=True)[1])
    faces, zone, piece = faces[keep], zone[keep], piece[keep]
    keep, stats["ears_dropped"] = _ears_kept(faces, zone)
    faces, zone, piece = faces[keep], zone[keep], piece[keep]
    # the seam's context faces may border faces that are not here: no hole through them
    in_zone = np.zeros(len(local), bool)
    in_zone[faces[zone]] = True
    before = len(faces)
    faces, stats["holes_closed"] = close_pinholes(faces, SEAM_HOLE_EDGES, keep_open=~in_zone)
    added = len(faces) - before
    zone = np.concatenate([zone, np.ones(added, bool)])
    vertex_piece = np.zeros(len(local), np.int64)
    vertex_piece[faces[:before].reshape(-1)] = np.repeat(piece, 3)
    piece = np.concatenate([piece, vertex_piece[faces[before:, 0]]])  # a patch joins its rim
    area = face_normals(local, faces)[1]
    degenerate = zone & (area < 1e-8 * spacing ** 2)
    stats["cleanup_degenerate"] = int(degenerate.sum())
    faces, zone, piece = faces[~degenerate], zone[~degenerate], piece[~degenerate]
    in_zone[:] = False
    in_zone[faces[zone]] = True
    if seam.held is not None:  # a bow-tie beside the held band may be one once it is welded
        held = np.zeros(len(local), bool)
        held[:len(seam.held)] = seam.held
        in_zone[faces[held[faces].any(axis=1)]] = False
        del held
    before = len(local)
    local, faces = split_nonmanifold_vertices(local, faces, only=in_zone, compact=False)
    stats["cleanup_split_vertices"] = int(len(np.unique(faces[faces >= before])))
    # specks the stitching left (a sliver that found nothing to weld to): only pieces with no
    # context face lie wholly in the seam, so only they can be judged here
    count, label = vertex_components(len(local), faces)
    whole = np.bincount(label, weights=~zone, minlength=count) == 0
    speck = find_specks(local, faces, spacing) & whole[label]
    stats["cleanup_specks"] = int(len(np.unique(label[speck])))
    faces, zone, piece = faces[~speck], zone[~speck], piece[~speck]
    small = np.zeros(len(flip), bool)
    if min_component_faces > 0:
        small = _small_pieces(seam, faces, piece, min_component_faces)
        stats["cleanup_small_pieces"] = int(small.sum())
    return StitchedMesh(seam, local, faces[~small[piece]], flip, small), stats


BLOCK_TILES = 2
"""Tiles per side of a block: a block's tiles are stitched together first, the band along the
block's border left for the blocks' own stitch (:func:`stitched_in_blocks`)."""


def plan_blocks(tiles) -> list:
    """The tiles grouped in blocks of :data:`BLOCK_TILES` per side: per block, its box (a
    :class:`Tile`) and its tiles' numbers, ascending."""
    groups = {}
    for number, tile in enumerate(tiles):
        groups.setdefault(tuple(i // BLOCK_TILES for i in tile.index), []).append(number)
    return [(Tile(key, np.min([tiles[m].low for m in members], axis=0),
                  np.max([tiles[m].high for m in members], axis=0)), members)
            for key, members in sorted(groups.items())]


def stitched_in_blocks(pieces, tiles, spacing: float, min_component_faces: int = 0,
                       folder: Optional[str] = None):
    """:func:`stitched_mesh` in two rounds, so that no step holds the seams of all tiles at
    once: the tiles of each block (:func:`plan_blocks`) stitched together, their seam within
    :data:`SEAM_CELLS` of the block's border left as it is; each block's mesh split again
    against the block's box (its rest written to ``folder``, when given); then the blocks
    stitched as tiles, each seam vertex welding only to another tile's. Tiles that make one
    block are stitched in one round. ``pieces`` (as for :func:`stitched_mesh`) is emptied as it
    is read.

    Returns ``(stitched, stats)`` as :func:`stitched_mesh`, the stats of both rounds summed.
    """
    plan = plan_blocks(tiles)
    if len(plan) == 1:  # one block: one round
        return stitched_mesh(pieces, tiles, spacing, min_component_faces)
    given = _split_all(pieces, tiles, spacing)
    pieces.clear()
    blocks, boxes, totals = [], [], {}
    for number, (box, members) in enumerate(plan):
        if len(members) == 1:
            blocks.append(given[members[0]])
        else:
            stitched, stats = stitched_mesh([given[m] for m in members],
                                             [tiles[m] for m in members], spacing, 0, box)
            vertices, faces = stitched.arrays()
            vertex_tile = stitched.vertex_tiles(members)
            del stitched
            path = None if folder is None else os.path.join(folder, f"block{number}.npz")
            blocks.append(split_tile(vertices, faces, box, spacing, path,
                                     vertex_tile=vertex_tile, spill=path is not None))
            del vertices, faces, vertex_tile
            for key, value in stats.items():
                totals[key] = totals.get(key, 0) + value
        for member in members:
            given[member] = None
        boxes.append(box)
    stitched, stats = stitched_mesh(blocks, boxes, spacing, min_component_faces)
    return stitched, {key: value + totals.get(key, 0) for key, value in stats.items()}


def _ears_kept(faces: np.ndarray, may_drop: np.ndarray, passes: int = 3):
    """The faces left when those hanging on a weld are dropped (``may_drop`` only): a face
    with a third face on one of its edges and nothing on the other two (one tile's face over
    the other tile's, sharing an edge); where there is none, a flap: a face with a third face
    on one edge and nothing on one other, one per such edge. Returns the kept mask and how
    many were dropped."""
    from .meshing.mesh_ops import edge_topology

    keep = np.ones(len(faces), bool)
    for _ in range(passes):
        index = np.flatnonzero(keep)
        if not len(index):
            break
        topo = edge_topology(faces[index])
        uses = topo.counts[topo.face_edges]
        crowded = (uses > 2).sum(axis=1) == 1
        ear = ((uses == 1).sum(axis=1) == 2) & crowded & may_drop[index]
        if not ear.any():
            # a flap: one open edge, on an edge it crowds; one per crowded edge, the last
            edge = np.where(uses > 2, topo.face_edges, -1).max(axis=1)
            flap = np.flatnonzero(((uses == 1).sum(axis=1) == 1) & crowded & may_drop[index])
            flap = flap[::-1][np.unique(edge[flap[::-1]], return_index=True)[1]]
            ear = np.zeros(len(index), bool)
            ear[flap] = True
        if not ear.any():
            break
        keep[index[ear]] = False
    return keep, int((~keep).sum())


def _small_pieces(seam: _Seam, faces: np.ndarray, piece: np.ndarray, min_faces: int):
    """Per piece: True where the pieces it joins across the seams (by a shared seam vertex)
    have fewer than ``min_faces`` faces in all."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    count = len(seam.piece_tile)
    nodes = count + int(faces.max()) + 1 if len(faces) else count
    rows = np.repeat(piece, 3)
    cols = count + faces.reshape(-1)
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nodes, nodes))
    _, label = connected_components(graph, directed=False)
    size = np.bincount(label[:count], weights=seam.piece_faces, minlength=nodes)
    return size[label[:count]] < min_faces


class StitchedMesh:
    """The whole stitched mesh, read tile by tile (working frame): every tile's faces away from
    the seam (turned over where their piece was, left out where it was ``dropped``) and the
    stitched seam ``faces`` over its vertices ``local`` (the seam's vertices, welded, then any
    copies); unused vertices left out.

    ``vertex_count`` and ``face_count`` are known at once; :meth:`vertex_blocks` and
    :meth:`face_blocks` yield the output in order, a tile at a time, each tile's rest read from
    where :func:`split_tile` put it, so a writer holds the seam and one tile, never the whole
    mesh: what is kept across the tiles follows the seam (each seam vertex's number in the
    output) and the number of tiles (each tile's count of used vertices). :meth:`arrays`
    gathers it into memory. Read it while the tiles' files exist.
    """

    def __init__(self, seam: _Seam, local: np.ndarray, faces: np.ndarray, flip: np.ndarray,
                 dropped: np.ndarray):
        self.seam, self.local, self.flip, self.dropped = seam, local, flip, dropped
        s = len(seam.ids)
        self._on_seam = np.zeros(len(local), bool)  # local vertices the seam's faces use
        self._on_seam[faces.reshape(-1)] = True
        output = np.full(len(local), -1, np.int64)  # each local vertex's number in the output
        self.counts = []  # per tile, its vertices in the output
        self.face_count = len(faces)
        first = 0
        for number, rest, _ in self._rests():
            used = self._used(number, rest)
            where = self._seam_range(number)
            on = np.flatnonzero(self._on_seam[where]) + where.start
            output[on] = first + (np.cumsum(used) - 1)[seam.ids[on] - seam.offsets[number]]
            self.counts.append(int(used.sum()))
            self.face_count += len(rest)
            first += self.counts[-1]
        copies = np.flatnonzero(self._on_seam[s:]) + s
        output[copies] = first + np.arange(len(copies))
        self.firsts = np.cumsum([0] + self.counts)
        self.vertex_count = int(first + len(copies))
        self._faces, self._output = faces, output

    def _rests(self):
        """Per tile: its number, and its kept rest faces (tile numbering) and their pieces."""
        for number, first in enumerate(self.seam.piece_first):
            rest, label = self.seam.rests[number].read("faces", "pieces")
            kept = ~self.dropped[first + label]
            yield number, rest[kept], label[kept] + first

    def _seam_range(self, number: int) -> slice:
        """The local vertices that are tile ``number``'s seam vertices."""
        return slice(*np.searchsorted(self.seam.ids, self.seam.offsets[number:number + 2]))

    def _used(self, number: int, rest: np.ndarray) -> np.ndarray:
        """Which of tile ``number``'s vertices the output has: those of its kept ``rest`` faces
        and of the seam's faces."""
        seam = self.seam
        used = np.zeros(seam.offsets[number + 1] - seam.offsets[number], bool)
        used[rest.reshape(-1)] = True
        where = self._seam_range(number)
        used[seam.ids[where][self._on_seam[where]] - seam.offsets[number]] = True
        return used

    def vertex_blocks(self):
        """The output's vertices (float64, working frame), a tile's at a time."""
        seam, local = self.seam, self.local
        for number, rest, _ in self._rests():
            used = self._used(number, rest)
            del rest
            vertices, = seam.rests[number].read("vertices")
            block = vertices[used]
            del vertices
            where = self._seam_range(number)
            on = np.flatnonzero(self._on_seam[where]) + where.start  # moved by the stitching
            block[self._output[on] - self.firsts[number]] = local[on]
            yield block
        yield local[len(seam.ids):][self._on_seam[len(seam.ids):]]

    def vertex_tiles(self, numbers) -> np.ndarray:
        """The tile of each output vertex, in :meth:`vertex_blocks`' order: ``numbers[k]`` for
        the ``k``-th piece's (a welded vertex: its group's first), -1 for the copies."""
        return np.concatenate([np.repeat(np.asarray(numbers, np.int32), self.counts),
                               np.full(self.vertex_count - int(self.firsts[-1]), -1, np.int32)])

    def face_blocks(self):
        """The output's faces (int64, over the output's vertices), a tile's at a time, then
        the seam's."""
        for number, rest, label in self._rests():
            remap = np.cumsum(self._used(number, rest), dtype=np.int64)
            remap += self.firsts[number] - 1
            block = remap[rest]
            turn = np.flatnonzero(self.flip[label])
            block[turn] = block[turn][:, ::-1]
            yield block
        for start in range(0, len(self._faces), SEAM_BLOCK):  # the seam's may be many
            yield self._output[self._faces[start:start + SEAM_BLOCK]]

    def piece_sizes(self):
        """``(pieces, largest)``: the number of connected pieces (faces sharing a vertex) and
        the faces of the largest, (0, 0) without faces. Counted tile by tile: each tile's rest
        faces in their own pieces, joined through the seam's vertices they share with the
        seam's faces (no rest face has a vertex a weld moved), so what is held follows the
        seam and the pieces, not the mesh."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        from .meshing.mesh_ops import vertex_components

        if self.face_count == 0:
            return 0, 0
        seam = self.seam
        # the seam's own pieces, then those joined by the tiles' rest pieces they touch
        count, label = (vertex_components(len(self.local), self._faces) if len(self._faces)
                        else (0, np.zeros(0, np.int64)))
        sizes = [np.bincount(label, minlength=count)]
        on_piece = np.full(len(self.local), -1, np.int64)  # each seam vertex's seam piece
        for corner in range(3):
            on_piece[self._faces[:, corner]] = label
        del label
        links = []
        for number, rest, _ in self._rests():
            if not len(rest):
                continue
            size = seam.offsets[number + 1] - seam.offsets[number]
            pieces, label = vertex_components(size, rest)  # per face
            rest_piece = np.full(size, -1, np.int64)
            for corner in range(3):
                rest_piece[rest[:, corner]] = label
            where = self._seam_range(number)
            both = np.column_stack([on_piece[where],
                                    rest_piece[seam.ids[where] - seam.offsets[number]]])
            both = both[(both >= 0).all(axis=1)]
            links.append(both + [0, count])
            sizes.append(np.bincount(label, minlength=pieces))
            count += pieces
        links = np.concatenate(links + [np.zeros((0, 2), np.int64)])
        graph = coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(count, count))
        _, joined = connected_components(graph, directed=False)
        faces = np.bincount(joined, weights=np.concatenate(sizes))
        faces = faces[faces > 0]
        return (int(len(faces)), int(faces.max())) if len(faces) else (0, 0)

    def arrays(self):
        """``(vertices (n, 3) float64, faces (m, 3) int64)``: the whole mesh in memory."""
        vertices = np.empty((self.vertex_count, 3))
        at = 0
        for block in self.vertex_blocks():
            vertices[at:at + len(block)] = block
            at += len(block)
        faces = np.empty((self.face_count, 3), np.int64)
        at = 0
        for block in self.face_blocks():
            faces[at:at + len(block)] = block
            at += len(block)
        return vertices, faces


def tiles_to_turn(pieces, tiles, spacing: float) -> np.ndarray:
    """Indices of the tiles whose kept layer faces against their neighbours' across the
    borders (by the votes of :func:`_pair_agreement`): the smaller side, by area. ``pieces``:
    per tile, its :class:`TilePiece` or its ``(vertices, faces)``.

    The votes are gathered tile by tile, each from the seams of the tile and its neighbours
    alone (:func:`_tile_votes`), so memory follows a few tiles' seams, not the scene's; they
    are the votes all the seams at once would give (before any weld no face spans two tiles,
    and every vertex a weld candidate can reach lies in a neighbouring tile).
    """
    pieces = _split_all(pieces, tiles, spacing)
    piece_first = np.cumsum([0] + [len(piece.piece_area) for piece in pieces])
    count = int(piece_first[-1])
    number_of = {tile.index: number for number, tile in enumerate(tiles)}
    votes = []
    for number, tile in enumerate(tiles):
        window = sorted({number_of[neighbour] for neighbour in _around(tile.index)
                         if neighbour in number_of})
        votes.append(_tile_votes(pieces, piece_first, window, number, spacing))
    pa, pb, agree = (np.concatenate(column) for column in zip(*votes)) if votes else (
        np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    if not len(pa):
        return np.zeros(0, np.int64)
    flip = _flips_from_votes(pa, pb, agree, count)
    area = np.concatenate([piece.piece_area for piece in pieces])
    if area[flip].sum() > area[~flip].sum():
        flip = ~flip  # an open sheet's orientation is free: turn the smaller side
    piece_tile = np.repeat(np.arange(len(pieces)), np.diff(piece_first))
    share = np.bincount(piece_tile, weights=area * flip, minlength=len(pieces))
    total = np.bincount(piece_tile, weights=area, minlength=len(pieces))
    return np.flatnonzero(share > 0.5 * np.maximum(total, 1e-300))


def _around(index: Tuple[int, int, int]):
    """The tile indices of ``index`` and its 26 neighbours."""
    i, j, k = index
    return [(i + di, j + dj, k + dk) for di in (-1, 0, 1) for dj in (-1, 0, 1)
            for dk in (-1, 0, 1)]


def _tile_votes(pieces: list, piece_first: np.ndarray, window: list, number: int,
                spacing: float):
    """The votes of the weld pairs between tile ``number`` and the higher-numbered tiles of
    ``window`` (tile numbers, ascending, ``number`` among them), from their rims
    (:class:`TilePiece`): the two pieces of each pair (numbered across all tiles) and whether
    their normals agree (their dot product)."""
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    if len(window) < 2:
        return empty
    rims = [pieces[member] for member in window]
    points = np.concatenate([rim.rim_points for rim in rims])
    tile_of = np.concatenate([rim.rim_tile for rim in rims])
    i, j = _pairs_across(points, tile_of, spacing)
    ti, tj = tile_of[i], tile_of[j]
    mine = ((ti == number) & (tj > number)) | ((tj == number) & (ti > number))
    i, j = i[mine], j[mine]
    if not len(i):
        return empty
    normal = np.concatenate([rim.rim_normal for rim in rims])
    piece = np.concatenate([rim.rim_piece + piece_first[member]
                            for rim, member in zip(rims, window)])
    return piece[i], piece[j], np.einsum("ij,ij->i", normal[i], normal[j])


def _pairs_across(points: np.ndarray, tile_of: np.ndarray, spacing: float):
    """Pairs ``(i, j)`` of boundary vertices of different tiles to weld: every pair closer
    than :data:`SAME_CELLS` cells (the same vertex, meshed by both tiles), then, among the
    vertices left, each other's nearest of another tile within :data:`WELD_CELLS` cells."""
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    same = cKDTree(points).query_pairs(SAME_CELLS * spacing, output_type="ndarray")
    same = same[tile_of[same[:, 0]] != tile_of[same[:, 1]]]
    left = np.setdiff1d(np.arange(len(points)), same.reshape(-1))
    i, j = _mutual_nearest_across(points[left], tile_of[left], WELD_CELLS * spacing)
    return (np.concatenate([same[:, 0], left[i]]).astype(np.int64),
            np.concatenate([same[:, 1], left[j]]).astype(np.int64))


def _weld(vertices: np.ndarray, a: np.ndarray, b: np.ndarray):
    """Merge the vertices joined by pairs ``(a, b)``, each group at its mean position.

    Returns the new vertices and, per old vertex, the index of the vertex it became (the
    group's smallest index; unused vertices are left in place).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(vertices)
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    first = np.full(group.max() + 1, n, dtype=np.int64)
    np.minimum.at(first, group, np.arange(n))
    merged = first[group]
    sums = np.zeros_like(vertices)
    np.add.at(sums, merged, vertices)
    size = np.bincount(merged, minlength=n)
    welded = vertices.copy()
    grouped = size > 1
    welded[grouped] = sums[grouped] / size[grouped, None]
    return welded, merged


def _mutual_nearest_across(points: np.ndarray, tile_of: np.ndarray, reach: float):
    """Pairs ``(i, j)``, ``i < j``, of points of different tiles that are each other's nearest
    point of another tile, closer than ``reach``."""
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    tree = cKDTree(points)
    k = min(8, len(points))
    distance, near = tree.query(points, k=k, distance_upper_bound=reach)
    distance = np.atleast_2d(distance)
    near = np.atleast_2d(near)
    valid = np.isfinite(distance)
    other = valid & (tile_of[np.minimum(near, len(points) - 1)] != tile_of[:, None])
    first = np.where(other.any(axis=1), np.argmax(other, axis=1), -1)
    has = first >= 0
    best = np.full(len(points), -1)
    best[has] = near[np.flatnonzero(has), first[has]]
    i = np.flatnonzero(has)
    j = best[i]
    mutual = best[j] == i
    i, j = i[mutual], j[mutual]
    keep = i < j
    return i[keep], j[keep]


def _piece_flips(vertices, faces, face_piece, count, a, b) -> np.ndarray:
    """Which pieces to turn over so that their faces at welded pairs face as their
    neighbours' do: (count,) bool. ``face_piece`` (m,) numbers the pieces (``count`` of them)
    per face; ``a``, ``b``: the welded pairs (see :func:`_flips_from_votes`)."""
    agree = _pair_agreement(vertices, faces, a, b)
    piece = _vertex_pieces(len(vertices), faces, face_piece)
    return _flips_from_votes(piece[a], piece[b], agree, count)


def _vertex_pieces(count: int, faces: np.ndarray, face_piece: np.ndarray) -> np.ndarray:
    """The piece of each vertex (of its faces')."""
    piece = np.zeros(count, np.int64)
    for k in range(3):
        piece[faces[:, k]] = face_piece
    return piece


def _pair_agreement(vertices, faces, a, b) -> np.ndarray:
    """Per pair ``(a, b)`` of vertices, the dot product of their normals
    (:func:`_vertex_normals`)."""
    normal = _vertex_normals(vertices, faces)
    return np.einsum("ij,ij->i", normal[a], normal[b])


def _vertex_normals(vertices, faces) -> np.ndarray:
    """Each vertex's unit normal: the area-weighted normal of the :data:`NORMAL_RINGS` rings of
    faces around it (the faces at a tile's cut are slivers)."""
    from .meshing.mesh_ops import face_normals, incidence_matrix

    normals, areas = face_normals(vertices, faces)
    incidence = incidence_matrix(len(vertices), faces)  # vertices x faces
    vertex_normal = incidence @ (normals * areas[:, None])
    for _ in range(NORMAL_RINGS):
        vertex_normal = incidence @ (incidence.T @ vertex_normal)
    vertex_normal /= np.maximum(np.linalg.norm(vertex_normal, axis=1), 1e-300)[:, None]
    return vertex_normal


def _flips_from_votes(pa, pb, agree, count: int) -> np.ndarray:
    """Which of ``count`` pieces to turn over: each pair of pieces ``(pa, pb)`` votes with the
    sign of ``agree`` (its normals' dot product); a spanning forest over the pieces, strongest
    votes first, fixes each piece's parity. (count,) bool."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import minimum_spanning_tree

    between = pa != pb
    pa, pb, agree = pa[between], pb[between], agree[between]
    if not len(pa):
        return np.zeros(count, bool)
    lo, hi = np.minimum(pa, pb), np.maximum(pa, pb)
    key = lo * count + hi
    keys, inverse = np.unique(key, return_inverse=True)
    vote = np.bincount(inverse, weights=np.sign(agree), minlength=len(keys))
    strength = np.bincount(inverse, weights=np.abs(agree), minlength=len(keys))
    u, v = keys // count, keys % count
    # strongest evidence first: a minimum spanning forest over negative strengths
    graph = coo_matrix((-(strength + 1e-12), (u, v)), shape=(count, count)).tocsr()
    forest = minimum_spanning_tree(graph).tocoo()
    sign = dict(zip(zip(u.tolist(), v.tolist()), np.sign(vote).tolist()))
    adjacency = {}
    for x, y in zip(forest.row.tolist(), forest.col.tolist()):
        s = sign.get((min(x, y), max(x, y)), 1.0)
        adjacency.setdefault(x, []).append((y, s))
        adjacency.setdefault(y, []).append((x, s))
    flip = np.zeros(count, bool)
    seen = np.zeros(count, bool)
    for root in sorted(adjacency):
        if seen[root]:
            continue
        seen[root] = True
        stack = [root]
        while stack:
            node = stack.pop()
            for other, s in adjacency[node]:
                if not seen[other]:
                    seen[other] = True
                    flip[other] = flip[node] ^ (s < 0)
                    stack.append(other)
    return flip


def tile_size(detail, settings) -> int:
    """Cells per tile side for a reconstruction, 0 for one grid without tiles."""
    if settings.tile_cells:
        return int(settings.tile_cells)
    return AUTO_TILE_CELLS if detail.cells > AUTO_TILE_ABOVE else 0


def tile_reach(settings, spacing: float) -> float:
    """How far beyond a tile's core its points must reach: the mesher's halo plus the widest
    ball any node of the halo may read (a sparse ball widened to its last factor), or, when
    gaps are filled, the farthest point a filled node's tests read (:mod:`.gap_fill`)."""
    from .field import MIN_BAND_NODES, SPARSE_WIDENING
    from .gap_fill import EDGE_NODES, GAP_NODES, THIN_NODES
    from .radius import max_radius

    ball = max(max_radius(settings), MIN_BAND_NODES * spacing)
    reach = SPARSE_WIDENING[-1] * ball
    if settings.fill_gaps:  # an edge point, its own neighbours, a thinned cube across
        reach = max(reach, (2.0 * GAP_NODES + EDGE_NODES + 2.0 * THIN_NODES) * spacing)
    return HALO_CELLS * spacing + reach + spacing


def mesh_tile(points: np.ndarray, tile: Tile, anchor: np.ndarray, settings, meshing,
              udf_source: str, progress: Optional[ProgressFn] = None,
              cancel: Optional[CancelFn] = None):
    """The field and mesh of one tile from its points (working frame); the faces of its core.

    Returns ``(vertices, faces, stats)``: the kept faces and the field's and mesher's numbers,
    with ``peak_bytes``, the peak memory of the process that ran the tile, up to its end.
    """
    from .field import compute_udf_band
    from .meshing import extract_surface
    from .tile_runners import process_peak_bytes

    progress = progress or no_progress
    halo = HALO_CELLS / settings.resolution
    band = compute_udf_band(points, settings, sub_progress(progress, 0.0, 0.6), cancel,
                            udf_source=udf_source, anchor=anchor,
                            bounds=(tile.low - halo, tile.high + halo))
    meshed = extract_surface(band.grid, meshing, sub_progress(progress, 0.6, 1.0), cancel)
    vertices, faces = keep_core(np.asarray(meshed.mesh.vertices, np.float64),
                                np.asarray(meshed.mesh.faces, np.int64), tile)
    return vertices, faces, {**band.stats, "iso": float(meshed.iso),
                             "peak_bytes": process_peak_bytes(), "process": os.getpid()}


def mesh_in_tiles(points: np.ndarray, settings, meshing, tile_cells: int,
                  udf_source: str = "network", progress: Optional[ProgressFn] = None,
                  cancel: Optional[CancelFn] = None, consume=None, to_unit=None):
    """One mesh of a cloud (working frame) made tile by tile (see the module docstring).

    ``consume(stitched, progress)``, given, reads the :class:`StitchedMesh` (to write it to a
    file block by block, say) while the tiles' files exist; its return value is the output.
    ``to_unit``, given, maps ``points`` (then in the input's units) to the working frame, a
    tile's points at a time (:class:`.tile_plan.CloudTiles`).

    Returns
    -------
    output : ``(vertices (n, 3) float64, faces (m, 3) int64)``, or what ``consume`` returned
    field_stats : dict, the tiles' field numbers summed (``band_nodes``, ``network_queries``,
        ``sparse_balls``, ``widened_balls``, ``open_gap_nodes``), ``mean_patch_points`` over
        all, ``tiles``,
        ``tile_peak_bytes`` (the largest peak memory of a process that ran tiles: a worker's,
        or this process's when the tiles ran here), ``worker_processes`` (the other processes
        that made tiles; 0 when they were made here)
    mesh_stats : dict, the stitching's numbers (``welded``, ``flipped``, ``ears_dropped``,
        ``holes_closed``), the clean-up's and ``iso`` (the tiles' median iso-level)
    """
    from .field import grid_layout
    from .tile_runners import available_cores, run_tiles

    progress = progress or no_progress
    spacing = 1.0 / settings.resolution
    cloud = CloudTiles(points, spacing, tile_cells, tile_reach(settings, spacing), to_unit)
    tiles = cloud.tiles
    # the tiles' nodes are the nodes one grid over the whole cloud would have, so tiling
    # changes where the field is read nowhere (anchored on the lowest point instead, a floor
    # and the walls a whole number of cells from it lie on node planes, where the cover's
    # iso-value of one cell meets the next nodes and marching cubes cuts slivers)
    anchor = grid_layout(np.stack([cloud.low, cloud.high]), settings.resolution, 0.0)[1]

    def job(number: int) -> tuple:
        return (cloud.points_of(number), tiles[number], anchor, settings, meshing, udf_source)

    # a tile's work follows the points it reads: workers take the largest tiles first
    costs = [cloud.cost_of(number) for number in range(len(tiles))]
    with tempfile.TemporaryDirectory(prefix="udf-tiles-") as folder:

        def keep(number: int, result: tuple, side: str = "") -> tuple:
            """A tile's mesh on disk, its rim here (:class:`TilePiece`); and its numbers."""
            vertices, faces, band = result
            path = os.path.join(folder, f"tile{number}{side}.npz")
            try:
                return (split_tile(vertices, faces, tiles[number], spacing, path, number,
                                   spill=True), band)
            except OSError as error:
                raise InputError(f"could not write a tile's mesh to the temporary folder "
                                 f"{folder}: {error}; free some disk space there or set TMPDIR "
                                 f"to a folder with room") from None

        results = run_tiles(mesh_tile, len(tiles), job, settings.workers, settings.scheduler,
                            sub_progress(progress, 0.0, 0.85), cancel, costs, keep)
        # where a tile kept the other side of an open sheet than its neighbours, make it again
        # keeping the side they kept: the two sides share no vertices along the border
        turn = tiles_to_turn([piece for piece, _ in results], tiles, spacing)
        tile_peak = max(band["peak_bytes"] for _, band in results)
        if len(turn):
            other = dataclasses.replace(meshing, other_side=not meshing.other_side)

            def again(number: int) -> tuple:
                return job(int(turn[number]))[:4] + (other, udf_source)

            redone = run_tiles(mesh_tile, len(turn), again, settings.workers,
                               settings.scheduler, sub_progress(progress, 0.85, 0.95), cancel,
                               [costs[int(number)] for number in turn],
                               lambda number, result: keep(int(turn[number]), result, "-again"))
            for number, result in zip(turn, redone):
                results[number] = result
                tile_peak = max(tile_peak, result[1]["peak_bytes"])
        processes = {band["process"] for _, band in results} - {os.getpid()}
        sums = {"band_nodes": 0, "network_queries": 0, "sparse_balls": 0, "widened_balls": 0,
                "open_gap_nodes": 0}
        patch_points = 0.0
        device = "none"
        isos = []
        for _, band in results:
            isos.append(band["iso"])
            for key in sums:
                sums[key] += int(band.get(key, 0))
            seen = band.get("network_queries", 0) - band["sparse_balls"]
            patch_points += band["mean_patch_points"] * seen
            device = band["device"]
        progress(0.95, f"stitching {len(tiles)} tiles")
        pieces = [piece for piece, _ in results]
        del results  # the stitcher frees each tile's seam once joined
        mesh, stitched = stitched_in_blocks(pieces, tiles, spacing,
                                            meshing.min_component_faces, folder)
        output = (consume(mesh, sub_progress(progress, 0.97, 1.0)) if consume is not None
                  else mesh.arrays())
        del mesh
    seen = sums["network_queries"] - sums["sparse_balls"]
    field_stats = {**sums, "tiles": len(tiles), "tile_cells": tile_cells, "spacing": spacing,
                   "workers": settings.workers or available_cores(),
                   "mean_patch_points": patch_points / max(seen, 1), "device": device,
                   "tile_peak_bytes": tile_peak, "worker_processes": len(processes),
                   "udf_source": udf_source}
    mesh_stats = {**stitched, "tiles_turned": int(len(turn)),
                  "iso": float(np.median(isos)) if isos else 0.0}
    progress(1.0, "tiles stitched")
    return output, field_stats, mesh_stats
