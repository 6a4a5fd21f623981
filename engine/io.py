"""Read point clouds and meshes from files; write meshes.

Reading: PLY (ascii and binary, either byte order), OBJ, OFF (with the C/N/ST variants), STL
(binary and ASCII), XYZ, PTS and TXT (columns of numbers), NPY, NPZ, LAS and LAZ. Writing: PLY
(binary little endian), OBJ, OFF and STL (binary). The format is chosen by the file's extension.

Writes are atomic: the mesh goes to a temporary file beside the target, which replaces the
target only once it is complete, so a failed or interrupted write leaves the previous file as it
was. :func:`check_output_path` refuses an output that cannot be written (or that is one of the
inputs) before any work is done.

Every problem with a file (missing, unsupported, corrupt, truncated, no points) raises
:class:`InputError` with one message that names the file and says what is wrong.
Parsing is vectorised: binary PLY bodies are viewed with numpy structured dtypes, text bodies
are split into one token array and converted in one call.
"""

import os
import re
import secrets
import shutil
import struct
import zipfile
import zlib
from typing import List, Optional, Tuple

import numpy as np

from .errors import InputError
from .geometry import Mesh, PointCloud

READ_FORMATS = ("PLY", "OBJ", "OFF", "STL", "XYZ", "PTS", "TXT", "NPY", "NPZ", "LAS", "LAZ")
WRITE_FORMATS = ("PLY", "OBJ", "OFF", "STL")


class _BadFile(Exception):
    """A problem inside a file; :func:`read_mesh` prefixes the file name and raises InputError."""


def read_point_cloud(path) -> PointCloud:
    """Read the points of a file (a mesh file gives its vertices).

    Parameters
    ----------
    path : str or os.PathLike
        A file whose extension is one of ``READ_FORMATS`` (case-insensitive).

    Returns
    -------
    PointCloud
        points (N, 3) float64 in the file's units; normals (N, 3) float64 or None;
        colors (N, 3) or (N, 4) float32 in [0, 1] or None.

    Raises
    ------
    InputError
        The file is missing, unsupported, unreadable, corrupt, truncated or has no points.
    """
    return read_mesh(path).as_point_cloud()


def read_mesh(path) -> Mesh:
    """Read a mesh (or a points-only file, which gives a mesh without faces).

    Parameters
    ----------
    path : str or os.PathLike
        A file whose extension is one of ``READ_FORMATS`` (case-insensitive).

    Returns
    -------
    Mesh
        vertices (V, 3) float64; faces (F, 3) int64, polygons fan-triangulated, (0, 3) when
        the file has none; normals (V, 3) float64 or None; colors (V, 3|4) float32 in [0, 1]
        or None.

    Raises
    ------
    InputError
        The file is missing, unsupported, unreadable, corrupt, truncated or has no points.
    """
    path = os.fspath(path)
    name = os.path.basename(path) or path
    extension = os.path.splitext(path)[1].lower().lstrip(".")
    if not os.path.exists(path):
        raise InputError(f"{name}: file not found (looked for {os.path.abspath(path)})")
    if os.path.isdir(path):
        raise InputError(f"{name}: is a folder, not a file")
    reader = _READERS.get(extension)
    if reader is None:
        raise InputError(f"{name}: unsupported format; use {', '.join(READ_FORMATS[:-1])} "
                         f"or {READ_FORMATS[-1]}")
    try:
        mesh = reader(path)
        return _checked(mesh)
    except _BadFile as error:
        raise InputError(f"{name}: {error}") from None
    except OSError as error:
        raise InputError(f"{name}: cannot be read ({error.strerror or error})") from None
    except (ValueError, IndexError, KeyError, TypeError, OverflowError, EOFError) as error:
        # Anything the format checks above did not foresee still reaches the user as one line.
        raise InputError(f"{name}: not a valid {extension.upper()} file ({error})") from None


def write_mesh(path, mesh: Mesh) -> None:
    """Write a mesh as PLY (binary little endian), OBJ, OFF or STL (binary), by the extension.

    Vertices keep float64 precision (PLY ``double``; 17 significant digits in text formats;
    STL holds float32 triangles only), normals and colours are written when present; PLY stores
    colours as uchar, OBJ and OFF as floats in [0, 1].

    The write is atomic: the mesh goes to a hidden temporary file in the target's folder, which
    replaces the target (``os.replace``) only once it is complete and flushed to disk. When
    anything fails (a full disk, a file-size limit, an exception, Ctrl-C) the temporary file is
    removed and an existing target is left exactly as it was. (A process killed outright may
    leave the hidden ``.NAME.*.tmp`` file behind, never a partial target.)

    Parameters
    ----------
    path : str or os.PathLike
        Destination ending in .ply, .obj, .off or .stl; an existing file is replaced.
    mesh : Mesh
        vertices (V, 3), faces (F, 3) (may be empty, except for STL), optional normals (V, 3)
        and colours (V, 3|4) in [0, 1].

    Raises
    ------
    InputError
        Unsupported extension, or the file cannot be written.
    """
    path = os.fspath(path)
    name = os.path.basename(path) or path
    writer = _WRITERS.get(_extension(path))
    if writer is None:
        raise InputError(f"{name}: cannot write this format; use "
                         f"{', '.join(WRITE_FORMATS[:-1])} or {WRITE_FORMATS[-1]}")
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    normals = None if mesh.normals is None else np.asarray(mesh.normals, np.float64).reshape(-1, 3)
    colors = None
    if mesh.colors is not None:
        colors = np.clip(np.asarray(mesh.colors, dtype=np.float64), 0.0, 1.0)
        colors = colors.reshape(len(colors), -1)
    if writer is _write_stl and len(faces) == 0:
        raise InputError(f"{name}: STL stores triangles only and this mesh has none; "
                         f"use PLY, OBJ or OFF for points")
    folder = os.path.dirname(os.path.abspath(path))
    temporary = None
    try:
        temporary, descriptor = _temporary_file(folder, name)
        try:
            with os.fdopen(descriptor, "wb") as file:
                writer(file, vertices, faces, normals, colors)
                file.flush()
                os.fsync(file.fileno())
            if os.path.exists(path):
                shutil.copymode(path, temporary)  # the replaced file keeps its permissions
            os.replace(temporary, path)
            temporary = None
        finally:
            if temporary is not None:
                _remove_quietly(temporary)
    except OSError as error:
        raise InputError(f"{name}: cannot be written ({error.strerror or error})") from None


def check_output_path(path, inputs=()) -> str:
    """Refuse, before any work, an output that could not be written or would destroy an input.

    Checks that ``path`` is none of ``inputs`` (the same file by ``os.path.samefile``, or the
    same resolved path), that its extension is one of ``WRITE_FORMATS``, that it is not a
    folder or a read-only file, and that its folder exists and a file can be created there
    (tried with a hidden probe file, which is removed at once).

    Parameters
    ----------
    path : str or os.PathLike
        The output file.
    inputs : iterable of str or os.PathLike
        Files that must not be overwritten (the inputs of the run).

    Returns
    -------
    str
        ``path`` as a string.

    Raises
    ------
    InputError
        With a message that says what is wrong and names the paths involved.
    """
    path = os.fspath(path)
    for source in inputs:
        if same_file(path, source):
            raise InputError(f"output {path} is the input {os.fspath(source)}: writing it would "
                             f"destroy the input; choose another output name")
    if os.path.isdir(path):
        raise InputError(f"output {path} is a folder; give a file name inside it")
    extension = _extension(path)
    if extension not in _WRITERS:
        what = f"'.{extension}'" if extension else "no extension"
        raise InputError(f"output {path}: cannot write {what}; give a file name ending in "
                         f"{', '.join('.' + f.lower() for f in WRITE_FORMATS)}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(f"output {path}: the folder {folder} does not exist; create it first")
    if os.path.exists(path) and not os.access(path, os.W_OK):
        raise InputError(f"output {path} exists and is read-only; make it writable or choose "
                         f"another name")
    try:
        probe, descriptor = _temporary_file(folder, os.path.basename(path))
        os.close(descriptor)
        _remove_quietly(probe)
    except OSError as error:
        raise InputError(f"output {path}: cannot create files in {folder} "
                         f"({error.strerror or error})") from None
    return path


def same_file(first, second) -> bool:
    """Whether two paths name the same file: the same inode when both exist, else the same
    resolved path (symbolic links followed, case folded where the system folds it)."""
    try:
        return os.path.samefile(first, second)
    except OSError:
        pass
    resolved = [os.path.normcase(os.path.realpath(os.fspath(p))) for p in (first, second)]
    return resolved[0] == resolved[1]


def _extension(path: str) -> str:
    return os.path.splitext(path)[1].lower().lstrip(".")


def _temporary_file(folder: str, name: str) -> Tuple[str, int]:
    """Create a new hidden file ``.NAME.<random>.tmp`` in ``folder`` -> (path, descriptor).

    Created with mode 0o666 less the umask, like ``open``; never replaces an existing file.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    temporary = os.path.join(folder, f".{name}.{secrets.token_hex(6)}.tmp")
    return temporary, os.open(temporary, flags, 0o666)


def _remove_quietly(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass


# --------------------------------------------------------------------------- shared helpers


def _checked(mesh: Mesh) -> Mesh:
    """Common checks and dtypes for every reader's result."""
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    if len(vertices) == 0:
        raise _BadFile("the file contains no points")
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        bad = faces[(faces < 0) | (faces >= len(vertices))][0]
        raise _BadFile(f"a face refers to vertex {bad}, but there are only {len(vertices)} "
                       f"vertices (numbered from 0)")
    normals = mesh.normals
    if normals is not None:
        normals = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    colors = mesh.colors
    if colors is not None:
        colors = np.clip(np.asarray(colors, dtype=np.float32), 0.0, 1.0)
        colors = np.ascontiguousarray(colors.reshape(len(colors), -1))
    return Mesh(vertices, faces, normals, colors)


def _fan(polygons: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons that all have the same vertex count.

    polygons : (P, n) int -> (P * (n - 2), 3) int64; empty for n < 3 (points and edges).
    """
    polygons = np.asarray(polygons, dtype=np.int64)
    count = polygons.shape[1]
    if count < 3:
        return np.zeros((0, 3), np.int64)
    fans = [np.stack([polygons[:, 0], polygons[:, i], polygons[:, i + 1]], axis=1)
            for i in range(1, count - 1)]
    # Keep each polygon's triangles together, in order.
    return np.stack(fans, axis=1).reshape(-1, 3)


def _fan_lists(polygons: List[List[int]]) -> np.ndarray:
    """Fan-triangulate polygons of mixed sizes (given as Python lists) -> (T, 3) int64."""
    triangles = [(p[0], p[i], p[i + 1]) for p in polygons for i in range(1, len(p) - 1)]
    return np.array(triangles, dtype=np.int64).reshape(-1, 3)


def _scaled_colors(values: np.ndarray, integer_max: Optional[int]) -> np.ndarray:
    """Colour channels -> float32 in [0, 1]; integer storage is divided by its full scale."""
    values = np.asarray(values, dtype=np.float64)
    if integer_max:
        values = values / integer_max
    return np.clip(values, 0.0, 1.0).astype(np.float32)


def _text_colors(values: np.ndarray) -> np.ndarray:
    """Colours written as text: 0..255 when any channel exceeds 1, otherwise floats in [0, 1]."""
    return _scaled_colors(values, 255 if values.size and values.max() > 1.0 else None)


def _numbers(tokens: List[bytes], what: str) -> np.ndarray:
    """Convert text tokens to float64 in one call; name the first bad token on failure."""
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        for token in tokens:
            try:
                float(token)
            except ValueError:
                text = token.decode("utf-8", "replace")[:40]
                raise _BadFile(f"{what}: {text!r} is not a number") from None
        raise


def _table(rows: List[bytes], what: str) -> np.ndarray:
    """Rows of whitespace-separated numbers -> (R, C) float64 (C = the shortest row's length).

    One token split and one conversion when every row has the same length; rows of mixed
    length (e.g. OBJ vertices with and without colour) are cut to the shortest.
    """
    if not rows:
        return np.zeros((0, 0))
    width = len(rows[0].split())
    tokens = b" ".join(rows).split()
    if len(tokens) == width * len(rows):
        return _numbers(tokens, what).reshape(len(rows), width)
    split = [row.split() for row in rows]
    width = min(len(row) for row in split)
    return _numbers([t for row in split for t in row[:width]], what).reshape(len(rows), width)


def _text_lines(data: bytes) -> List[bytes]:
    """Non-empty, stripped lines with ``#`` comments removed."""
    if b"#" in data:
        data = re.sub(rb"#[^\r\n]*", b"", data)
    return [line for line in (raw.strip() for raw in data.splitlines()) if line]


# --------------------------------------------------------------------------- PLY

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
            raise _BadFile("the file is empty")
        raise _BadFile("not a PLY file (it does not start with 'ply')")
    end = re.search(rb"end_header[ \t]*\r?\n", data)
    if end is None:
        raise _BadFile("the PLY header is incomplete (no 'end_header' line)")
    fmt, elements = None, []
    for line in data[:end.start()].decode("ascii", "replace").splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2:
            fmt = words[1]
            if fmt not in _PLY_ORDERS:
                raise _BadFile(f"unknown PLY format {fmt!r} (expected ascii, "
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
            raise _BadFile(f"the PLY header line {line.strip()!r} is not understood")
    if fmt is None:
        raise _BadFile("the PLY header has no 'format' line")
    return fmt, elements, end.end()


def _ply_type(word: str) -> str:
    if word not in _PLY_TYPES:
        raise _BadFile(f"unknown PLY property type {word!r}")
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
            raise _BadFile(f"the file ends after {done} of {element.count} {element.plural()}")
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
                raise _BadFile(f"the file ends after {row_number} of {element.count} "
                               f"{element.plural()}")
            length = int(np.frombuffer(buffer, count, 1, at)[0])
            if length < 0:
                raise _BadFile(f"a list in {element.plural()} has negative length {length}")
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
        raise _BadFile(f"the file ends after {first + r} of {element.count} "
                       f"{element.plural()}") from None
    if lengths.size and lengths.min() < 0:
        raise _BadFile(f"a list in {element.plural()} has a negative length")
    list_indices = [i for i, (f, _) in enumerate(steps) if f is not None]
    raw = np.frombuffer(buffer, np.uint8)
    blocks = []
    for layout in np.unique(lengths, axis=0):
        selected = np.flatnonzero(np.all(lengths == layout, axis=1))
        row = _ply_row_dtype(element, dict(zip(list_indices, layout.tolist())), order, as_text)
        table = raw[starts[selected, None] + np.arange(row.itemsize)].view(row).reshape(-1)
        blocks.append((first + selected, table))
    return blocks, offset


def _read_ply(path: str) -> Mesh:
    with open(path, "rb") as file:
        data = file.read()
    fmt, elements, body_start = _ply_header(data)
    order = _PLY_ORDERS[fmt]
    as_text = fmt == "ascii"
    if as_text:
        buffer = _numbers(data[body_start:].split(), "PLY data").tobytes()
    else:
        buffer = memoryview(data)[body_start:]
    blocks, offset = {}, 0
    for element in elements:
        blocks[element.name], offset = _ply_element_rows(buffer, offset, element, order,
                                                         as_text)
    if as_text and offset < len(buffer):
        counts = ", ".join(f"{e.count} {e.plural()}" for e in elements)
        raise _BadFile(f"the header declares {counts}, but {(len(buffer) - offset) // 8} more "
                       f"values follow them: the counts in the header are probably wrong")
    vertex = next((e for e in elements if e.name == "vertex"), None)
    if vertex is None:
        raise _BadFile("the PLY file has no 'vertex' element")
    if vertex.count == 0:
        raise _BadFile("the file contains no points (0 vertices)")

    def column(i):
        values = np.empty(vertex.count, np.float64)
        for rows, table in blocks["vertex"]:
            values[rows] = table[f"p{i}"]
        return values

    xyz = [vertex.index(axis) for axis in ("x", "y", "z")]
    if None in xyz:
        raise _BadFile("the PLY vertices have no x, y, z properties")
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
        colors = _scaled_colors(np.stack([column(i) for i in channels], axis=1),
                                np.iinfo(kind).max if kind.kind in "iu" else None)
    faces = np.zeros((0, 3), np.int64)
    face = next((e for e in elements if e.name == "face"), None)
    if face is not None and face.count:
        index = face.index("vertex_indices", "vertex_index")
        if index is None or face.properties[index][2] is None:
            raise _BadFile("the PLY faces have no 'vertex_indices' list")
        polygons = [(rows, table[f"p{index}"].reshape(len(table), -1))
                    for rows, table in blocks["face"]]
        faces = np.concatenate([_fan(corners) for _, corners in polygons])
        if len(polygons) > 1:
            # Blocks of the row scan come grouped by polygon size; restore the file's order.
            row_numbers = np.arange(face.count)
            origins = np.concatenate([np.repeat(row_numbers[rows], max(corners.shape[1] - 2, 0))
                                      for rows, corners in polygons])
            faces = faces[np.argsort(origins, kind="stable")]
    return Mesh(vertices, faces, normals, colors)


def _write_ply(file, vertices, faces, normals, colors) -> None:
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    header = ["ply", "format binary_little_endian 1.0", "comment UDF Reconstruction",
              f"element vertex {len(vertices)}",
              "property double x", "property double y", "property double z"]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
        header += ["property float nx", "property float ny", "property float nz"]
    channels = ("red", "green", "blue", "alpha")[:0 if colors is None else colors.shape[1]]
    fields += [(c, "u1") for c in channels]
    header += [f"property uchar {c}" for c in channels]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices",
               "end_header"]
    table = np.empty(len(vertices), dtype=fields)
    table["x"], table["y"], table["z"] = vertices.T
    if normals is not None:
        table["nx"], table["ny"], table["nz"] = normals.T
    for i, channel in enumerate(channels):
        table[channel] = np.round(colors[:, i] * 255.0)
    face_table = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face_table["n"], face_table["v"] = 3, faces
    file.write(("\n".join(header) + "\n").encode("ascii"))
    file.write(table.tobytes())
    file.write(face_table.tobytes())


# --------------------------------------------------------------------------- OBJ


def _obj_buckets(lines: List[bytes]) -> dict:
    """The rest of each ``v``, ``vn`` and ``f`` line, keyed by the keyword, in one pass."""
    buckets = {b"v": [], b"vn": [], b"f": []}
    keys = {b"v ": b"v", b"v\t": b"v", b"vn": b"vn", b"f ": b"f", b"f\t": b"f"}
    for line in lines:
        key = keys.get(line[:2])
        if key is not None:
            buckets[key].append(line)
    return {key: [line[len(key):] for line in rows] for key, rows in buckets.items()}


def _read_obj(path: str) -> Mesh:
    with open(path, "rb") as file:
        data = file.read()
    if b"#" in data:
        data = re.sub(rb"#[^\r\n]*", b"", data)
    lines = [line.strip() for line in data.splitlines()]
    rows = _obj_buckets(lines)
    table = _table(rows[b"v"], "a vertex ('v' line)")
    if len(table) == 0:
        raise _BadFile("the file contains no points (no 'v' lines)")
    if table.shape[1] < 3:
        raise _BadFile("a vertex ('v' line) has fewer than 3 coordinates")
    vertices = table[:, :3]
    colors = _text_colors(table[:, 3:6]) if table.shape[1] >= 6 else None
    normal_table = _table(rows[b"vn"], "a normal ('vn' line)")
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
        faces = _fan(vertex_refs)
    else:
        faces, vertex_refs, normal_refs = _obj_mixed_faces(data)
    normals = None
    if len(normal_table):
        normal_table = normal_table[:, :3]
        has_refs = normal_refs is not None and normal_refs.size
        if has_refs and (normal_refs.min() < 0 or normal_refs.max() >= len(normal_table)):
            raise _BadFile(f"a face refers to normal {normal_refs.max() + 1}, but there are "
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
        raise _BadFile("a face has index 0 (OBJ indices start at 1)")
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
    return _fan_lists(polygons), np.array(vertex_refs, np.int64), normals


def _obj_index(token: bytes, count_so_far: int, what: str) -> int:
    """A 1-based (or negative, relative) OBJ index -> 0-based index."""
    try:
        index = int(token)
    except ValueError:
        raise _BadFile(f"a face has {what} index {token.decode('utf-8', 'replace')!r}, "
                       f"which is not a whole number") from None
    if index == 0:
        raise _BadFile(f"a face has {what} index 0 (OBJ indices start at 1)")
    return index - 1 if index > 0 else count_so_far + index


def _write_obj(file, vertices, faces, normals, colors) -> None:
    file.write(b"# UDF Reconstruction\n")
    if colors is not None:
        rows = np.concatenate([vertices, colors[:, :3]], axis=1)
        _write_rows(file, "v" + " %.17g" * 3 + " %.6g" * 3 + "\n", rows)
    else:
        _write_rows(file, "v %.17g %.17g %.17g\n", vertices)
    if normals is not None:
        _write_rows(file, "vn %.9g %.9g %.9g\n", normals)
        _write_rows(file, "f %d//%d %d//%d %d//%d\n", np.repeat(faces + 1, 2, axis=1))
    else:
        _write_rows(file, "f %d %d %d\n", faces + 1)


def _write_rows(file, row_format: str, rows: np.ndarray) -> None:
    file.write("".join(row_format % tuple(row) for row in rows.tolist()).encode("ascii"))


# --------------------------------------------------------------------------- OFF

_OFF_KEYWORD = re.compile(rb"^(ST)?(C)?(N)?(4)?(n)?OFF$")


def _read_off(path: str) -> Mesh:
    with open(path, "rb") as file:
        data = file.read()
    lines = _text_lines(data)
    if not lines:
        raise _BadFile("the file is empty")
    words = lines[0].split()
    keyword = _OFF_KEYWORD.match(words[0])
    if keyword is None:
        raise _BadFile("not an OFF file (the first line is not 'OFF', 'COFF', 'NOFF', ...)")
    has_st, has_color, has_normal, four_d, n_dim = keyword.groups()
    if four_d or n_dim:
        raise _BadFile("4-D and n-D OFF files are not supported; use 3-D vertices")
    counts, body = words[1:], lines[1:]
    if not counts:
        if not body:
            raise _BadFile("the file ends before the vertex and face counts")
        counts, body = body[0].split(), body[1:]
    try:
        vertex_count, face_count = int(counts[0]), int(counts[1])
    except (ValueError, IndexError):
        raise _BadFile("the line after 'OFF' must give the vertex and face counts") from None
    if vertex_count < 0 or face_count < 0:
        raise _BadFile(f"the header gives {vertex_count} vertices and {face_count} faces; "
                       f"counts cannot be negative")
    if len(body) < vertex_count:
        raise _BadFile(f"the file ends after {len(body)} of {vertex_count} vertices")
    if len(body) < vertex_count + face_count:
        raise _BadFile(f"the file ends after {len(body) - vertex_count} of {face_count} faces")
    if len(body) > vertex_count + face_count:
        extra = len(body) - vertex_count - face_count
        raise _BadFile(f"the header gives {vertex_count} vertices and {face_count} faces, but "
                       f"the file has {extra} more line{'s' if extra > 1 else ''}: the counts "
                       f"in the header are probably wrong")
    table = _table(body[:vertex_count], "a vertex")
    if vertex_count and table.shape[1] < 3:
        raise _BadFile("a vertex has fewer than 3 coordinates")
    vertices, at = table[:, :3], 3
    normals = None
    if has_normal and table.shape[1] >= at + 3:
        normals, at = table[:, at:at + 3], at + 3
    colors = None
    channels = table.shape[1] - at - (2 if has_st else 0)
    if has_color and channels in (3, 4):
        colors = _text_colors(table[:, at:at + channels])
    return Mesh(vertices, _off_faces(body[vertex_count:vertex_count + face_count]),
                normals, colors)


def _off_faces(rows: List[bytes]) -> np.ndarray:
    """OFF face lines ``n i1 .. in [colour]`` -> fan-triangulated (F, 3) int64."""
    if not rows:
        return np.zeros((0, 3), np.int64)
    table = _table(rows, "a face")
    sizes = table[:, 0]
    if len(table) and table.shape[1] > sizes[0] and np.all(sizes == sizes[0]):
        corners = table[:, :1 + int(sizes[0])]
        if np.all(corners == np.round(corners)):  # else the loop names the bad line
            return _fan(corners[:, 1:])
    polygons = []
    for number, row in enumerate(rows, 1):
        values = row.split()
        try:
            size = int(values[0])
            corners = [int(v) for v in values[1:size + 1]]
        except ValueError:
            raise _BadFile(f"face line {number} ({row[:40].decode('utf-8', 'replace')!r}) is "
                           f"not 'n i1 .. in' with whole numbers; if it is a vertex, the "
                           f"vertex count in the header is too small") from None
        if size < 0:
            raise _BadFile(f"face line {number} has a negative vertex count {size}")
        if len(values) < size + 1:
            raise _BadFile(f"a face lists {size} vertices but gives only {len(values) - 1}")
        polygons.append(corners)
    return _fan_lists(polygons)


def _write_off(file, vertices, faces, normals, colors) -> None:
    keyword = ("C" if colors is not None else "") + ("N" if normals is not None else "") + "OFF"
    file.write(f"{keyword}\n{len(vertices)} {len(faces)} 0\n".encode("ascii"))
    columns, row_format = [vertices], "%.17g %.17g %.17g"
    if normals is not None:
        columns.append(normals)
        row_format += " %.9g %.9g %.9g"
    if colors is not None:
        columns.append(colors)
        row_format += " %.6g" * colors.shape[1]
    _write_rows(file, row_format + "\n", np.concatenate(columns, axis=1))
    _write_rows(file, "3 %d %d %d\n", faces)


# --------------------------------------------------------------------------- XYZ / PTS / TXT / NPY


def _read_columns(path: str) -> Mesh:
    """Text columns: x y z, then optional intensity, normals and colours (see _split_columns).

    Separators are whitespace, commas or semicolons; ``#`` and ``//`` start comments; a line
    holding one whole number (a PTS point count) is skipped; a first line with no numbers
    (column names) is skipped.
    """
    with open(path, "rb") as file:
        data = file.read()
    rows = []
    for line in data.replace(b",", b" ").replace(b";", b" ").splitlines():
        line = line.split(b"#", 1)[0].split(b"//", 1)[0].strip()
        if line and not line.isdigit():
            rows.append(line)
    if rows and not any(_is_number(word) for word in rows[0].split()):
        rows = rows[1:]
    if not rows:
        raise _BadFile("the file contains no points")
    width = len(rows[0].split())
    tokens = b" ".join(rows).split()
    if len(tokens) != width * len(rows):
        bad = next(i for i, row in enumerate(rows) if len(row.split()) != width)
        raise _BadFile(f"data line {bad + 1} has {len(rows[bad].split())} values, but the "
                       f"first data line has {width}; every line needs the same columns")
    table = _numbers(tokens, "the point data").reshape(len(rows), width)
    return _split_columns(table)


def _is_number(word: bytes) -> bool:
    try:
        float(word)
        return True
    except ValueError:
        return False


def _split_columns(table: np.ndarray) -> Mesh:
    """Columns of numbers -> points with optional normals and colours.

    3: x y z; 4: x y z intensity; 6: x y z + triple; 7: x y z intensity + triple (PTS);
    9: x y z + triple + triple; 10: x y z intensity + two triples; other widths >= 3: x y z
    and the rest ignored. Intensity is ignored; each triple is classified by
    :func:`_triple_kind`.
    """
    if table.ndim != 2 or table.shape[1] < 3:
        raise _BadFile(f"needs at least 3 columns (x y z), found "
                       f"{table.shape[1] if table.ndim == 2 else table.ndim}")
    starts = {6: [3], 7: [4], 9: [3, 6], 10: [4, 7]}.get(table.shape[1], [])
    normals = colors = None
    for start in starts:
        triple = table[:, start:start + 3]
        kind = _triple_kind(triple)
        if kind == "normals" and normals is None:
            normals = triple
        elif kind == "colors255" and colors is None:
            colors = _scaled_colors(triple, 255)
        elif kind == "colors" and colors is None:
            colors = _scaled_colors(triple, None)
    return Mesh(table[:, :3], np.zeros((0, 3), np.int64), normals, colors)


def _triple_kind(triple: np.ndarray) -> Optional[str]:
    """Decide whether three columns are normals or colours; the first rule that fits wins.

    1. every value a whole number in 0..255 and some value above 1 -> ``colors255`` (/255);
    2. some value negative, or every row of unit length (within 0.01) -> ``normals``;
    3. every value in [0, 1] -> ``colors``;
    4. otherwise ``None``: the columns are ignored.
    """
    if triple.size == 0 or not np.isfinite(triple).all():
        return None
    low, high = triple.min(), triple.max()
    if low >= 0 and high <= 255 and high > 1 and np.all(triple == np.round(triple)):
        return "colors255"
    if low < 0 or np.all(np.abs(np.linalg.norm(triple, axis=1) - 1.0) < 0.01):
        return "normals"
    if low >= 0 and high <= 1:
        return "colors"
    return None


def _read_npy(path: str) -> Mesh:
    with open(path, "rb") as file:
        array = _npy_array(file, os.fstat(file.fileno()).st_size, "the file")
    if array.dtype.kind not in "iuf":
        raise _BadFile("the NPY file must hold a numeric (N, 3) or (N, 6) array")
    if array.ndim != 2 or array.shape[1] not in (3, 6):
        raise _BadFile(f"the array has shape {array.shape}; expected (N, 3) points or "
                       f"(N, 6) points with normals or colours")
    return _split_columns(array.astype(np.float64))


def _npy_array(stream, size: int, what: str) -> np.ndarray:
    """One NPY array from ``stream`` holding ``size`` bytes; the header is checked first.

    The header's shape and dtype must describe exactly the bytes that follow, so a corrupt
    header (bad syntax, an absurd shape such as a claimed 2 TiB array, object arrays) is
    refused in one message before anything is allocated.
    """
    from numpy.lib import format as npy_format

    try:
        version = npy_format.read_magic(stream)
        if version == (1, 0):
            shape, fortran, dtype = npy_format.read_array_header_1_0(stream)
        elif version == (2, 0):
            shape, fortran, dtype = npy_format.read_array_header_2_0(stream)
        else:
            shape, fortran, dtype = npy_format._read_array_header(stream, version)
    except Exception as error:  # the header parser raises ValueError, SyntaxError, TokenError...
        detail = str(error.args[0] if error.args else "") or type(error).__name__
        raise _BadFile(f"{what} has a corrupt NPY header "
                       f"({detail.splitlines()[0][:120]})") from None
    dtype = np.dtype(dtype)
    if dtype.hasobject or dtype.itemsize == 0:
        raise _BadFile(f"{what} holds {dtype} values; expected numbers")
    if any(not isinstance(n, int) or n < 0 for n in shape):
        raise _BadFile(f"{what} claims the impossible shape {shape}")
    needed = dtype.itemsize * int(np.prod(shape, dtype=object))
    available = size - stream.tell()
    if needed > available:
        raise _BadFile(f"{what} claims a {shape} array of {dtype} ({_bytes(needed)}), but "
                       f"only {_bytes(available)} follow its header: the file is truncated "
                       f"or its header is corrupt")
    data = stream.read(needed)
    if len(data) != needed:
        raise _BadFile(f"{what} ends after {_bytes(len(data))} of {_bytes(needed)}")
    return np.frombuffer(data, dtype).reshape(shape, order="F" if fortran else "C")


def _bytes(count: int) -> str:
    """A byte count for people: '912 bytes', '3.1 MiB', '2.18 TiB'."""
    if count < 1024:
        return f"{count} bytes"
    for unit in ("KiB", "MiB", "GiB", "TiB", "PiB"):
        count /= 1024.0
        if count < 1024 or unit == "PiB":
            return f"{count:.3g} {unit}"


_NPZ_KEYS = ("points", "vertices", "normals", "colors", "faces")


def read_npz_arrays(path, keys) -> Tuple[dict, List[str]]:
    """The arrays ``keys`` of an NPZ archive, each header checked before anything is read.

    Returns ``(arrays, names)``: the arrays found among ``keys`` and the names of every array
    in the archive. Members not in ``keys`` are never read, however big they claim to be.

    Raises
    ------
    InputError
        The file is missing, not an NPZ archive, truncated, or has a corrupt member, with one
        message naming the file.
    """
    path = os.fspath(path)
    name = os.path.basename(path) or path
    try:
        return _npz_members(path, keys)
    except _BadFile as error:
        raise InputError(f"{name}: {error}") from None
    except OSError as error:
        raise InputError(f"{name}: cannot be read ({error.strerror or error})") from None


def _npz_members(path: str, keys) -> Tuple[dict, List[str]]:
    try:
        with zipfile.ZipFile(path) as archive:
            members = {info.filename[:-4]: info for info in archive.infolist()
                       if info.filename.endswith(".npy")}
            arrays = {}
            for key in keys:  # only what is asked for: a huge extra member is never read
                info = members.get(key)
                if info is None:
                    continue
                if info.file_size > 1100 * info.compress_size + (1 << 20):  # deflate gives < 1032:1
                    raise _BadFile(f"'{key}' claims {_bytes(info.file_size)} uncompressed from "
                                   f"{_bytes(info.compress_size)}: the archive is corrupt")
                with archive.open(info) as stream:
                    arrays[key] = _npy_array(stream, info.file_size, f"'{key}'")
    except zipfile.BadZipFile as error:
        with open(path, "rb") as file:
            single = file.read(6) == b"\x93NUMPY"
        if single:
            raise _BadFile("not an NPZ archive (it holds a single NPY array)") from None
        raise _BadFile(f"not a readable NPZ archive ({error})") from None
    except (zlib.error, EOFError, NotImplementedError, RuntimeError) as error:
        raise _BadFile(f"not a readable NPZ archive ({error})") from None
    return arrays, sorted(members)


def _read_npz(path: str) -> Mesh:
    arrays, members = _npz_members(path, _NPZ_KEYS)
    key = "points" if "points" in arrays else "vertices" if "vertices" in arrays else None
    if key is None:
        raise _BadFile(f"has no 'points' or 'vertices' array (it has: "
                       f"{', '.join(sorted(members)) or 'nothing'})")
    vertices = _npz_array(arrays, key, (3,))
    normals = _npz_array(arrays, "normals", (3,)) if "normals" in arrays else None
    colors = None
    if "colors" in arrays:
        raw = _npz_array(arrays, "colors", (3, 4))
        colors = _scaled_colors(raw, np.iinfo(raw.dtype).max if raw.dtype.kind in "iu" else None)
    faces = np.zeros((0, 3), np.int64)
    if "faces" in arrays:
        raw = arrays["faces"]
        if raw.ndim != 2 or raw.dtype.kind not in "iu":
            raise _BadFile(f"'faces' must be an (F, 3) integer array, not {raw.dtype} "
                           f"with shape {raw.shape}")
        faces = _fan(raw)
    for name, values in (("normals", normals), ("colors", colors)):
        if values is not None and len(values) != len(vertices):
            raise _BadFile(f"'{name}' has {len(values)} rows but '{key}' has {len(vertices)}")
    return Mesh(vertices, faces, normals, colors)


def _npz_array(arrays: dict, key: str, widths: Tuple[int, ...]) -> np.ndarray:
    array = arrays[key]
    if array.ndim != 2 or array.shape[1] not in widths or array.dtype.kind not in "iuf":
        raise _BadFile(f"'{key}' must be a numeric (N, {' or '.join(map(str, widths))}) "
                       f"array, not {array.dtype} with shape {array.shape}")
    return array


# --------------------------------------------------------------------------- STL

_STL_TRIANGLE = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)),
                          ("attribute", "<u2")])  # 50 bytes per triangle


def _write_stl(file, vertices, faces, normals, colors) -> None:
    """Binary STL: an 80-byte header, the triangle count, then 50 bytes per triangle (the
    facet normal from the corners' order, zero for a degenerate triangle; float32)."""
    corners = vertices[faces]
    facet = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(facet, axis=1, keepdims=True)
    facet = np.divide(facet, length, out=np.zeros_like(facet), where=length > 0)
    table = np.zeros(len(faces), _STL_TRIANGLE)
    table["normal"], table["corners"] = facet, corners
    file.write(b"UDF Reconstruction binary STL".ljust(80, b" "))
    file.write(struct.pack("<I", len(faces)))
    file.write(table.tobytes())


def _read_stl(path: str) -> Mesh:
    """Binary or ASCII STL -> a mesh whose equal corners are merged into shared vertices."""
    with open(path, "rb") as file:
        data = file.read()
    if len(data) >= 84:
        count = struct.unpack_from("<I", data, 80)[0]
        if 84 + count * _STL_TRIANGLE.itemsize == len(data):
            corners = np.frombuffer(data, _STL_TRIANGLE, count, 84)["corners"]
            return _stl_mesh(corners.astype(np.float64))
    if not data.lstrip().startswith(b"solid"):
        if not data:
            raise _BadFile("the file is empty")
        if len(data) >= 84:
            raise _BadFile(f"a binary STL of {count:,} triangles needs "
                           f"{84 + count * 50:,} bytes, but the file has {len(data):,}")
        raise _BadFile("not an STL file (too short for binary STL, no 'solid' line)")
    rows = [line.split()[1:] for line in data.splitlines() if line.strip().startswith(b"vertex")]
    if len(rows) % 3 or any(len(row) != 3 for row in rows):
        raise _BadFile("an ASCII STL facet needs three 'vertex x y z' lines")
    corners = _numbers([t for row in rows for t in row], "a vertex").reshape(-1, 3, 3)
    return _stl_mesh(corners)


def _stl_mesh(corners: np.ndarray) -> Mesh:
    if len(corners) == 0:
        raise _BadFile("the file contains no triangles")
    vertices, faces = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    return Mesh(vertices, faces.reshape(-1, 3).astype(np.int64), None, None)


# --------------------------------------------------------------------------- LAS / LAZ


def _read_las(path: str) -> Mesh:
    _check_las_header(path)  # before laspy: a bad LAZ can make lazrs abort the process
    import laspy  # only LAS/LAZ users need it

    try:
        las = laspy.read(path)
    except laspy.errors.LaspyException as error:
        if "backend" in str(error).lower():
            raise _BadFile("cannot decompress LAZ; install the 'lazrs' package "
                           "(pip install 'laspy[lazrs]')") from None
        raise _BadFile(f"not a readable LAS/LAZ file ({error})") from None
    except MemoryError:
        raise _BadFile("not a readable LAS/LAZ file (its point count does not fit in "
                       "memory)") from None
    except Exception as error:  # lazrs.LazrsError and the like: a corrupt compressed body
        raise _BadFile(f"the LAS/LAZ point data is corrupt or truncated "
                       f"({type(error).__name__}: {str(error)[:120]})") from None
    # las.x etc. apply the file's scale and offset.
    vertices = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    colors = None
    if "red" in las.point_format.dimension_names:
        rgb = np.stack([np.asarray(las.red), np.asarray(las.green), np.asarray(las.blue)], 1)
        colors = _scaled_colors(rgb, 65535)
    return Mesh(vertices.astype(np.float64), np.zeros((0, 3), np.int64), None, colors)


_LASZIP_USER = b"laszip encoded"
_LASZIP_RECORD = 22204


def _check_las_header(path: str) -> None:
    """Check a LAS/LAZ header against the file's size before any point is decompressed.

    The header's sizes and offsets must lie inside the file, the VLRs must end before the
    point data, an uncompressed body must hold every point it claims, and a LAZ file's chunk
    table must lie inside the file and list no more chunks than its point count allows. A
    corrupt or truncated LAZ passing these is still caught when lazrs decodes it; these
    checks refuse the files that would make lazrs allocate absurd amounts (and abort).
    """
    size = os.path.getsize(path)
    with open(path, "rb") as file:
        header = file.read(375)
        if len(header) < 4 or header[:4] != b"LASF":
            raise _BadFile("not a LAS/LAZ file (it does not start with 'LASF')")
        if len(header) < 227:
            raise _BadFile(f"the LAS header is truncated: the file has {size} bytes, a header "
                           f"needs at least 227")
        minor = header[25]
        header_size, point_offset, vlr_count = struct.unpack_from("<HII", header, 94)
        format_id, record_length, legacy_count = struct.unpack_from("<BHI", header, 104)
        count = legacy_count
        if minor >= 4 and header_size >= 375 and len(header) >= 255:
            count = struct.unpack_from("<Q", header, 247)[0] or legacy_count
        if not 227 <= header_size <= point_offset <= size:
            raise _BadFile(f"the LAS header is corrupt: header size {header_size} and point "
                           f"data offset {point_offset} do not fit a file of {size:,} bytes")
        if record_length == 0:
            raise _BadFile("the LAS header is corrupt: a point record length of 0")
        chunk_size = None
        at = header_size
        for _ in range(vlr_count):
            if at + 54 > point_offset:
                raise _BadFile(f"the LAS header lists {vlr_count} VLRs, but they run past "
                               f"the start of the point data at byte {point_offset}")
            file.seek(at)
            vlr = file.read(54)
            length = struct.unpack_from("<H", vlr, 20)[0]
            if vlr[2:18].rstrip(b"\0") == _LASZIP_USER and struct.unpack_from(
                    "<H", vlr, 18)[0] == _LASZIP_RECORD and length >= 16:
                chunk_size = struct.unpack_from("<I", file.read(16), 12)[0]
            at += 54 + length
        if at > point_offset:
            raise _BadFile(f"the LAS VLRs run past the start of the point data at byte "
                           f"{point_offset}")
        compressed = bool(format_id & 0xC0)
        body = size - point_offset
        if not compressed:
            if count * record_length > body:
                raise _BadFile(f"the file claims {count:,} points of {record_length} bytes "
                               f"({count * record_length:,} bytes) but holds {body:,} bytes "
                               f"of point data: it is truncated or corrupt")
            return
        if chunk_size is None:
            raise _BadFile("a compressed LAZ file without its 'laszip encoded' VLR")
        if count and body < 8 + record_length:
            raise _BadFile(f"the LAZ point data is truncated ({_bytes(body)} for "
                           f"{count:,} points)")
        if count == 0:
            return
        file.seek(point_offset)
        table_offset = struct.unpack("<q", file.read(8))[0]
        if table_offset == -1:
            return  # written without a chunk table (streamed); lazrs reads chunk by chunk
        if not point_offset + 8 <= table_offset <= size - 8:
            raise _BadFile(f"the LAZ chunk table offset {table_offset:,} lies outside the "
                           f"file ({size:,} bytes): it is truncated or corrupt")
        file.seek(table_offset)
        table_version, chunks = struct.unpack("<II", file.read(8))
        most = count if chunk_size in (0, 0xFFFFFFFF) else -(-count // chunk_size)
        if table_version != 0 or not 1 <= chunks <= min(most, table_offset - point_offset):
            raise _BadFile(f"the LAZ chunk table is corrupt (version {table_version}, "
                           f"{chunks:,} chunks for {count:,} points): the file is truncated "
                           f"or has been altered")


_READERS = {"ply": _read_ply, "obj": _read_obj, "off": _read_off, "stl": _read_stl,
            "xyz": _read_columns,
            "pts": _read_columns, "txt": _read_columns, "npy": _read_npy, "npz": _read_npz,
            "las": _read_las, "laz": _read_las}
_WRITERS = {"ply": _write_ply, "obj": _write_obj, "off": _write_off, "stl": _write_stl}
