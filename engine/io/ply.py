"""PLY: ASCII and binary (either byte order) read, binary little endian written.

Our own reader and writer rather than trimesh's, for three reasons. The writer keeps vertices
as doubles (trimesh writes float32 positions, which moves a georeferenced scan's vertices by
centimetres); the reader takes a point cloud with any extra properties and colours stored as
uchar, ushort or float; and a header or body that does not match gives one message saying
where the file ends or which count is wrong. Bodies are viewed with numpy structured dtypes,
one block per run of rows with the same layout.
"""

import re
import struct
from typing import List, Optional, Tuple

import numpy as np

from ..geometry import Mesh
from .common import BadFile, fan, numbers, scaled_colors


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_PLY_ORDERS = {"ascii": "<", "binary_little_endian": "<", "binary_big_endian": ">"}


class _PlyElement:
    """One ``element`` of a PLY header: its name, row count and properties.

    properties: list of (name, value type, list-count type or None), types as numpy codes.
    """

    def __init__(self, name: str, count: int):
        self.name, self.count, self.properties = name, count, []

    def plural(self) -> str:
        return {"vertex": "vertices", "face": "faces"}.get(self.name, f"'{self.name}' records")

    def index(self, *names: str) -> Optional[int]:
        for i, prop in enumerate(self.properties):
            if prop[0] in names:
                return i
        return None


def _ply_header(data: bytes) -> Tuple[str, List[_PlyElement], int]:
    """Parse the header -> (format, elements, byte offset of the body)."""
    if not data.startswith(b"ply"):
        if not data:
            raise BadFile("the file is empty")
        raise BadFile("not a PLY file (it does not start with 'ply')")
    end = re.search(rb"end_header[ \t]*\r?\n", data)
    if end is None:
        raise BadFile("the PLY header is incomplete (no 'end_header' line)")
    fmt, elements = None, []
    for line in data[:end.start()].decode("ascii", "replace").splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2:
            fmt = words[1]
            if fmt not in _PLY_ORDERS:
                raise BadFile(f"unknown PLY format {fmt!r} (expected ascii, "
                               f"binary_little_endian or binary_big_endian)")
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append(_PlyElement(words[1], int(words[2])))
        elif words[0] == "property" and elements and len(words) == 3:
            elements[-1].properties.append((words[2], _ply_type(words[1]), None))
        elif (words[0] == "property" and elements and len(words) == 5
              and words[1] == "list"):
            elements[-1].properties.append((words[4], _ply_type(words[3]),
                                            _ply_type(words[2])))
        else:
            raise BadFile(f"the PLY header line {line.strip()!r} is not understood")
    if fmt is None:
        raise BadFile("the PLY header has no 'format' line")
    return fmt, elements, end.end()


def _ply_type(word: str) -> str:
    if word not in _PLY_TYPES:
        raise BadFile(f"unknown PLY property type {word!r}")
    return _PLY_TYPES[word]


_SHORT_RUN = 32
"""Runs of equal-layout rows shorter than this switch a PLY element to the row scan."""


def _ply_element_rows(buffer, offset: int, element: _PlyElement, order: str,
                      as_text: bool) -> Tuple[List[Tuple[np.ndarray, np.ndarray]], int]:
    """View an element's rows as structured numpy blocks.

    A row's byte layout is fixed once its list lengths are known. The layout of the first row
    is assumed for as many following rows as possible and verified in one vectorised compare;
    a new block starts where a list length changes. A mesh of only triangles is one block.
    Where layouts change often (say triangles and quads interleaved) the rest of the element
    is handed to :func:`_scattered_rows`, which walks the row starts in a plain loop.

    In text mode ``buffer`` holds the body's numbers as float64 and every value is one float64.

    Returns
    -------
    blocks : list of (rows, table): rows, the element row numbers (a slice, or (k,) int64
        from the row scan); table (k,)
        structured, field ``p{i}`` holding property i ((k,) scalar or (k, n) list of length n)
    offset : byte offset just after the element
    """
    blocks, done, window = [], 0, element.count
    while done < element.count:
        lengths, _ = _ply_row_lengths(buffer, offset, element, order, as_text, done)
        row = _ply_row_dtype(element, lengths, order, as_text)
        available = (len(buffer) - offset) // row.itemsize if row.itemsize else window
        tried = min(element.count - done, window, available)
        if tried == 0:
            raise BadFile(f"the file ends after {done} of {element.count} {element.plural()}")
        table = np.frombuffer(buffer, row, tried, offset)
        same = np.ones(tried, dtype=bool)
        for i, length in lengths.items():
            same &= table[f"n{i}"] == length
        taken = tried if same.all() else int(np.argmin(same))
        blocks.append((slice(done, done + taken), table[:taken]))
        offset += taken * row.itemsize
        done += taken
        if taken < min(_SHORT_RUN, tried):
            more, offset = _scattered_rows(buffer, offset, element, order, as_text, done)
            return blocks + more, offset
        window = 2 * tried
    return blocks, offset


def _ply_row_lengths(buffer, offset: int, element: _PlyElement, order: str, as_text: bool,
                     row_number: int) -> Tuple[dict, int]:
    """The list lengths of the row at ``offset`` -> ({property index: length}, row end)."""
    lengths, at = {}, offset
    for i, (_, kind, count_kind) in enumerate(element.properties):
        value = np.dtype("<f8" if as_text else order + kind)
        if count_kind is not None:
            count = np.dtype("<f8" if as_text else order + count_kind)
            if at + count.itemsize > len(buffer):
                raise BadFile(f"the file ends after {row_number} of {element.count} "
                               f"{element.plural()}")
            length = int(np.frombuffer(buffer, count, 1, at)[0])
            if length < 0:
                raise BadFile(f"a list in {element.plural()} has negative length {length}")
            lengths[i] = length
            at += count.itemsize + length * value.itemsize
        else:
            at += value.itemsize
    return lengths, at


def _ply_row_dtype(element: _PlyElement, lengths: dict, order: str,
                   as_text: bool) -> np.dtype:
    """Structured dtype of one row: fields ``n{i}`` (list lengths) and ``p{i}`` (values)."""
    names, formats, offsets, at = [], [], [], 0
    for i, (_, kind, count_kind) in enumerate(element.properties):
        value = np.dtype("<f8" if as_text else order + kind)
        if count_kind is not None:
            count = np.dtype("<f8" if as_text else order + count_kind)
            names.append(f"n{i}"), formats.append(count), offsets.append(at)
            at += count.itemsize
            value = np.dtype((value, (lengths[i],)))
        names.append(f"p{i}"), formats.append(value), offsets.append(at)
        at += value.itemsize
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": at})


def _scattered_rows(buffer, offset: int, element: _PlyElement, order: str, as_text: bool,
                    first: int) -> Tuple[List[Tuple[np.ndarray, np.ndarray]], int]:
    """Rows ``first`` .. end of an element whose row layouts keep changing.

    One loop finds each row's start and list lengths (a few struct reads per row); then the
    rows of each distinct layout are gathered into one structured block.
    """
    steps = []  # per property: (struct format of the count or None, value size)
    for _, kind, count_kind in element.properties:
        value_size = 8 if as_text else np.dtype(kind).itemsize
        count_format = None
        if count_kind is not None:
            count_format = "<d" if as_text else order + np.dtype(count_kind).char
        steps.append((count_format, value_size))
    rows = element.count - first
    starts = np.empty(rows, np.int64)
    lengths = np.empty((rows, sum(f is not None for f, _ in steps)), np.int64)
    end = len(buffer)
    try:
        for r in range(rows):
            starts[r], j = offset, 0
            for count_format, value_size in steps:
                if count_format is None:
                    offset += value_size
                    continue
                length = int(struct.unpack_from(count_format, buffer, offset)[0])
                lengths[r, j], j = length, j + 1
                offset += struct.calcsize(count_format) + length * value_size
            if offset > end:
                raise struct.error
    except struct.error:
        raise BadFile(f"the file ends after {first + r} of {element.count} "
                       f"{element.plural()}") from None
    if lengths.size and lengths.min() < 0:
        raise BadFile(f"a list in {element.plural()} has a negative length")
    list_indices = [i for i, (f, _) in enumerate(steps) if f is not None]
    raw = np.frombuffer(buffer, np.uint8)
    blocks = []
    for layout in np.unique(lengths, axis=0):
        selected = np.flatnonzero(np.all(lengths == layout, axis=1))
        row = _ply_row_dtype(element, dict(zip(list_indices, layout.tolist())), order, as_text)
        table = raw[starts[selected, None] + np.arange(row.itemsize)].view(row).reshape(-1)
        blocks.append((first + selected, table))
    return blocks, offset


def read_ply(path: str) -> Mesh:
    with open(path, "rb") as file:
        data = file.read()
    fmt, elements, body_start = _ply_header(data)
    order = _PLY_ORDERS[fmt]
    as_text = fmt == "ascii"
    if as_text:
        buffer = numbers(data[body_start:].split(), "PLY data").tobytes()
    else:
        buffer = memoryview(data)[body_start:]
    blocks, offset = {}, 0
    for element in elements:
        blocks[element.name], offset = _ply_element_rows(buffer, offset, element, order,
                                                         as_text)
    if as_text and offset < len(buffer):
        counts = ", ".join(f"{e.count} {e.plural()}" for e in elements)
        raise BadFile(f"the header declares {counts}, but {(len(buffer) - offset) // 8} more "
                       f"values follow them: the counts in the header are probably wrong")
    vertex = next((e for e in elements if e.name == "vertex"), None)
    if vertex is None:
        raise BadFile("the PLY file has no 'vertex' element")
    if vertex.count == 0:
        raise BadFile("the file contains no points (0 vertices)")

    def column(i):
        values = np.empty(vertex.count, np.float64)
        for rows, table in blocks["vertex"]:
            values[rows] = table[f"p{i}"]
        return values

    xyz = [vertex.index(axis) for axis in ("x", "y", "z")]
    if None in xyz:
        raise BadFile("the PLY vertices have no x, y, z properties")
    vertices = np.stack([column(i) for i in xyz], axis=1)
    normal_index = [vertex.index(axis) for axis in ("nx", "ny", "nz")]
    normals = None
    if None not in normal_index:
        normals = np.stack([column(i) for i in normal_index], axis=1)
    colors = None
    channels = [vertex.index(c, "diffuse_" + c) for c in ("red", "green", "blue", "alpha")]
    if None not in channels[:3]:
        channels = [c for c in channels if c is not None]
        kind = np.dtype(vertex.properties[channels[0]][1])
        colors = scaled_colors(np.stack([column(i) for i in channels], axis=1),
                                np.iinfo(kind).max if kind.kind in "iu" else None)
    faces = np.zeros((0, 3), np.int64)
    face = next((e for e in elements if e.name == "face"), None)
    if face is not None and face.count:
        index = face.index("vertex_indices", "vertex_index")
        if index is None or face.properties[index][2] is None:
            raise BadFile("the PLY faces have no 'vertex_indices' list")
        polygons = [(rows, table[f"p{index}"].reshape(len(table), -1))
                    for rows, table in blocks["face"]]
        faces = np.concatenate([fan(corners) for _, corners in polygons])
        if len(polygons) > 1:
            # Blocks of the row scan come grouped by polygon size; restore the file's order.
            row_numbers = np.arange(face.count)
            origins = np.concatenate([np.repeat(row_numbers[rows], max(corners.shape[1] - 2, 0))
                                      for rows, corners in polygons])
            faces = faces[np.argsort(origins, kind="stable")]
    return Mesh(vertices, faces, normals, colors)


def write_ply(file, vertices, faces, normals, colors) -> None:
    file.write(ply_header(len(vertices), len(faces), normals is not None,
                          0 if colors is None else colors.shape[1]))
    file.write(ply_vertex_records(vertices, normals, colors))
    file.write(ply_face_records(faces))


def ply_header(vertex_count: int, face_count: int, normals: bool, channels: int) -> bytes:
    """The header :func:`write_ply` writes: float64 positions, float32 normals when
    ``normals``, ``channels`` (0, 3 or 4) uchar colour channels, int vertex indices. With
    :func:`ply_vertex_records` and :func:`ply_face_records` a mesh can be written in blocks."""
    header = ["ply", "format binary_little_endian 1.0", "comment UDF Reconstruction",
              f"element vertex {vertex_count}",
              "property double x", "property double y", "property double z"]
    if normals:
        header += ["property float nx", "property float ny", "property float nz"]
    header += [f"property uchar {c}" for c in _CHANNELS[:channels]]
    header += [f"element face {face_count}", "property list uchar int vertex_indices",
               "end_header"]
    return ("\n".join(header) + "\n").encode("ascii")


def ply_vertex_records(vertices, normals, colors) -> bytes:
    """Vertices (k, 3) float64 with their normals and colours (in [0, 1]) or None, as the
    records of :func:`ply_header`'s vertex element."""
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    channels = _CHANNELS[:0 if colors is None else colors.shape[1]]
    fields += [(c, "u1") for c in channels]
    table = np.empty(len(vertices), dtype=fields)
    table["x"], table["y"], table["z"] = vertices.T
    if normals is not None:
        table["nx"], table["ny"], table["nz"] = normals.T
    for i, channel in enumerate(channels):
        table[channel] = np.round(colors[:, i] * 255.0)
    return table.tobytes()


def ply_face_records(faces) -> bytes:
    """Triangles (k, 3) as the records of :func:`ply_header`'s face element."""
    table = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    table["n"], table["v"] = 3, faces
    return table.tobytes()


_CHANNELS = ("red", "green", "blue", "alpha")
