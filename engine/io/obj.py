"""Wavefront OBJ: ``v`` (with optional r g b), ``vn`` and ``f`` lines read; written with
vertices to 17 significant digits, colours and per-vertex normals.

Our own reader and writer rather than trimesh's: trimesh's reader leaves negative (relative)
face indices unresolved and returns nothing for a points-only file, and its writer prints a
fixed number of decimals, which rounds small coordinates.
"""

from typing import List, Optional, Tuple

import numpy as np

from ..geometry import Mesh
from .common import BadFile, fan, fan_lists, number_table, strip_comments, text_colors, write_rows


def _obj_buckets(lines: List[bytes]) -> dict:
    """The rest of each ``v``, ``vn`` and ``f`` line, keyed by the keyword, in one pass."""
    buckets = {b"v": [], b"vn": [], b"f": []}
    keys = {b"v ": b"v", b"v\t": b"v", b"vn": b"vn", b"f ": b"f", b"f\t": b"f"}
    for line in lines:
        key = keys.get(line[:2])
        if key is not None:
            buckets[key].append(line)
    return {key: [line[len(key):] for line in rows] for key, rows in buckets.items()}


def read_obj(path: str) -> Mesh:
    with open(path, "rb") as file:
        data = file.read()
    data = strip_comments(data)
    lines = [line.strip() for line in data.splitlines()]
    rows = _obj_buckets(lines)
    table = number_table(rows[b"v"], "a vertex ('v' line)")
    if len(table) == 0:
        raise BadFile("the file contains no points (no 'v' lines)")
    if table.shape[1] < 3:
        raise BadFile("a vertex ('v' line) has fewer than 3 coordinates")
    vertices = table[:, :3]
    colors = text_colors(table[:, 3:6]) if table.shape[1] >= 6 else None
    normal_table = number_table(rows[b"vn"], "a normal ('vn' line)")
    corners = _obj_corners(rows[b"f"])
    if corners is not None:
        vertex_refs, normal_refs = corners
        if (vertex_refs < 0).any() or (normal_refs is not None and (normal_refs < 0).any()):
            # Negative indices count back from the vertices (normals) read so far.
            numbered = list(enumerate(lines))
            face_lines = [i for i, line in numbered if line.startswith((b"f ", b"f\t"))]
            seen = {key: np.searchsorted([i for i, line in numbered if line.startswith(key)],
                                         face_lines)[:, None]
                    for key in ((b"v ", b"v\t"), (b"vn ", b"vn\t"))}
            vertex_refs = _obj_resolve(vertex_refs, seen[b"v ", b"v\t"])
            if normal_refs is not None:
                normal_refs = _obj_resolve(normal_refs, seen[b"vn ", b"vn\t"])
        else:
            vertex_refs = _obj_resolve(vertex_refs, 0)
            normal_refs = None if normal_refs is None else _obj_resolve(normal_refs, 0)
        faces = fan(vertex_refs)
    else:
        faces, vertex_refs, normal_refs = _obj_mixed_faces(data)
    normals = None
    if len(normal_table):
        normal_table = normal_table[:, :3]
        has_refs = normal_refs is not None and normal_refs.size
        if has_refs and (normal_refs.min() < 0 or normal_refs.max() >= len(normal_table)):
            raise BadFile(f"a face refers to normal {normal_refs.max() + 1}, but there are "
                           f"only {len(normal_table)}")
        if len(normal_table) == len(vertices) and (
                not has_refs or np.array_equal(normal_refs, vertex_refs)):
            normals = normal_table  # one normal per vertex, in vertex order
        elif has_refs:
            # Faces say which normal belongs to which vertex; use that when it covers them all.
            covered = np.zeros(len(vertices), bool)
            covered[vertex_refs] = True
            if covered.all():
                normals = np.zeros((len(vertices), 3))
                normals[vertex_refs] = normal_table[normal_refs]
    return Mesh(vertices, faces, normals, colors)


def _obj_corners(rows: List[bytes]) -> Optional[Tuple[np.ndarray, Optional[np.ndarray]]]:
    """Face rows that all have the same corner count and form (``v``, ``v/vt``, ``v//vn``,
    ``v/vt/vn``) -> raw vertex refs (F, n) and normal refs (F, n) or None; None when mixed."""
    if not rows:
        return np.zeros((0, 3), np.int64), None
    first = rows[0].split()
    if not first:
        return None
    slashes, doubled = first[0].count(b"/"), b"//" in first[0]
    joined = b" ".join(rows)
    corners = len(rows) * len(first)
    if (len(joined.split()) != corners or joined.count(b"/") != corners * slashes
            or joined.count(b"//") != (corners if doubled else 0)):
        return None
    fields = slashes + 1 - doubled
    try:
        refs = np.array(joined.replace(b"//", b"/").replace(b"/", b" ").split(), np.int64)
    except ValueError:
        return None  # let the row-by-row reader name the bad index
    refs = refs.reshape(len(rows), len(first), fields)
    return refs[..., 0], refs[..., -1] if slashes == 2 else None


def _obj_resolve(refs: np.ndarray, seen) -> np.ndarray:
    """1-based or negative (relative to ``seen`` items read so far) OBJ refs -> 0-based."""
    if refs.size and (refs == 0).any():
        raise BadFile("a face has index 0 (OBJ indices start at 1)")
    return np.where(refs > 0, refs - 1, refs + seen)


def _obj_mixed_faces(data: bytes) -> Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
    """Faces of mixed sizes or corner forms, one line at a time.

    Returns fan triangles (T, 3), and every corner's vertex and normal refs (0-based,
    flattened); the normal refs are None when some corner has none.
    """
    vertex_count = normal_count = 0
    polygons, vertex_refs, normal_refs = [], [], []
    for line in data.splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == b"v":
            vertex_count += 1
        elif parts[0] == b"vn":
            normal_count += 1
        elif parts[0] == b"f":
            polygon = []
            for corner in parts[1:]:
                refs = corner.split(b"/")
                polygon.append(_obj_index(refs[0], vertex_count, "vertex"))
                if len(refs) > 2 and refs[2]:
                    normal_refs.append(_obj_index(refs[2], normal_count, "normal"))
            vertex_refs.extend(polygon)
            polygons.append(polygon)
    normals = np.array(normal_refs, np.int64) if len(normal_refs) == len(vertex_refs) else None
    return fan_lists(polygons), np.array(vertex_refs, np.int64), normals


def _obj_index(token: bytes, count_so_far: int, what: str) -> int:
    """A 1-based (or negative, relative) OBJ index -> 0-based index."""
    try:
        index = int(token)
    except ValueError:
        raise BadFile(f"a face has {what} index {token.decode('utf-8', 'replace')!r}, "
                       f"which is not a whole number") from None
    if index == 0:
        raise BadFile(f"a face has {what} index 0 (OBJ indices start at 1)")
    return index - 1 if index > 0 else count_so_far + index


def write_obj(file, vertices, faces, normals, colors) -> None:
    file.write(b"# UDF Reconstruction\n")
    if colors is not None:
        rows = np.concatenate([vertices, colors[:, :3]], axis=1)
        write_rows(file, "v" + " %.17g" * 3 + " %.6g" * 3 + "\n", rows)
    else:
        write_rows(file, "v %.17g %.17g %.17g\n", vertices)
    if normals is not None:
        write_rows(file, "vn %.9g %.9g %.9g\n", normals)
        write_rows(file, "f %d//%d %d//%d %d//%d\n", np.repeat(faces + 1, 2, axis=1))
    else:
        write_rows(file, "f %d %d %d\n", faces + 1)
