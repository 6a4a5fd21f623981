"""Read point clouds and meshes from files; write meshes.

Reading: PLY (ASCII and binary, either byte order), OBJ, OFF (with the C/N/ST variants), STL
(binary and ASCII), GLB and glTF, XYZ, PTS and TXT (columns of numbers), NPY, NPZ, LAS and LAZ.
Writing: PLY (binary little endian), OBJ, OFF, STL (binary), GLB and glTF. The format is
chosen by the file's extension.

Where each format is handled, and why:

- STL, GLB, glTF: trimesh (:mod:`.meshes`).
- PLY, OBJ, OFF: our own readers and writers (:mod:`.ply`, :mod:`.obj`, :mod:`.off`), because
  trimesh loses what these files carry here: it writes PLY positions as float32 (centimetres
  on a georeferenced scan), reads and writes OFF without colours or normals, leaves OBJ's
  relative (negative) face indices unresolved and reads a points-only OBJ as empty. Their
  output is checked against trimesh's readers in the tests.
- XYZ, PTS, TXT (:mod:`.clouds`), NPY and NPZ (:mod:`.npz`): trimesh has no reader for them.
- LAS and LAZ: laspy (:mod:`.las`), after our check of the header against the file size.

Writes are atomic (:mod:`.atomic`): the mesh goes to a temporary file beside the target, which
replaces the target only once it is complete, so a failed or interrupted write leaves the
previous file as it was. :func:`check_output_path` refuses an output that cannot be written
(or that is one of the inputs) before any work is done.

Every problem with a file (missing, unsupported, corrupt, truncated, no points) raises
:class:`InputError` with one message that names the file and says what is wrong.
"""

import os

import numpy as np

from ..errors import InputError
from ..geometry import Mesh, PointCloud
from .atomic import remove_quietly, same_file, temporary_file, write_atomically
from .clouds import read_columns
from .common import BadFile, checked
from .las import read_las
from .meshes import read_gltf, read_stl, write_glb, write_gltf, write_stl
from .npz import read_npy, read_npz, read_npz_arrays
from .obj import read_obj, write_obj
from .off import read_off, write_off
from .ply import read_ply, write_ply

__all__ = ["READ_FORMATS", "WRITE_FORMATS", "read_point_cloud", "read_mesh", "write_mesh",
           "write_ply_in_blocks", "check_output_path", "same_file", "read_npz_arrays"]

_READERS = {"ply": read_ply, "obj": read_obj, "off": read_off, "stl": read_stl,
            "glb": read_gltf, "gltf": read_gltf, "xyz": read_columns, "pts": read_columns,
            "txt": read_columns, "npy": read_npy, "npz": read_npz, "las": read_las,
            "laz": read_las}
_WRITERS = {"ply": write_ply, "obj": write_obj, "off": write_off, "stl": write_stl,
            "glb": write_glb, "gltf": write_gltf}
_FACES_ONLY = ("stl",)

READ_FORMATS = tuple(extension.upper() for extension in _READERS)
WRITE_FORMATS = tuple(extension.upper() for extension in _WRITERS)


def read_point_cloud(path) -> PointCloud:
    """Read the points of a file, as :func:`read_mesh` does (a mesh file gives its vertices).

    Returns
    -------
    PointCloud
        points (N, 3) float64 in the file's units; normals (N, 3) float64 or None;
        colors (N, 3) or (N, 4) float32 in [0, 1] or None.
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
    extension = _extension(path)
    if not os.path.exists(path):
        raise InputError(f"{name}: file not found (looked for {os.path.abspath(path)})")
    if os.path.isdir(path):
        raise InputError(f"{name}: is a folder, not a file")
    reader = _READERS.get(extension)
    if reader is None:
        raise InputError(f"{name}: unsupported format; use {', '.join(READ_FORMATS[:-1])} "
                         f"or {READ_FORMATS[-1]}")
    try:
        return checked(reader(path))
    except BadFile as error:
        raise InputError(f"{name}: {error}") from None
    except OSError as error:
        raise InputError(f"{name}: cannot be read ({error.strerror or error})") from None
    except (ValueError, IndexError, KeyError, TypeError, OverflowError, EOFError) as error:
        # Anything the format checks did not foresee still reaches the user as one line.
        raise InputError(f"{name}: not a valid {extension.upper()} file ({error})") from None


def write_mesh(path, mesh: Mesh, cancel=None) -> None:
    """Write a mesh as PLY, OBJ, OFF, STL, GLB or glTF, chosen by the extension.

    PLY (binary little endian) keeps float64 vertices, float32 normals and uchar colours. OBJ
    and OFF write vertices to 17 significant digits (exact), colours as floats in [0, 1]
    (OBJ: RGB only). STL holds float32 triangles only. GLB and glTF hold float32 positions and
    normals and 8-bit colours; glTF is one JSON file with its buffers embedded.

    The write is atomic: the mesh goes to a hidden temporary file in the target's folder, which
    replaces the target (``os.replace``) only once it is complete and flushed to disk. When
    anything fails (a full disk, a file-size limit, an exception, Ctrl-C) the temporary file is
    removed and an existing target is left exactly as it was.

    Parameters
    ----------
    path : str or os.PathLike
        Destination whose extension is one of ``WRITE_FORMATS``; an existing file is replaced.
    mesh : Mesh
        vertices (V, 3), faces (F, 3) (may be empty, except for STL), optional normals (V, 3)
        and colours (V, 3|4) in [0, 1].
    cancel : callable ``() -> bool``, optional
        Polled before each chunk the writer writes; True stops the write (``Cancelled``).

    Raises
    ------
    InputError
        Unsupported extension, or the file cannot be written.
    Cancelled
        ``cancel()`` returned True; the target is left as it was.
    """
    path = os.fspath(path)
    name = os.path.basename(path) or path
    extension = _extension(path)
    writer = _WRITERS.get(extension)
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
    if extension in _FACES_ONLY and len(faces) == 0:
        raise InputError(f"{name}: {extension.upper()} stores triangles only and this mesh has "
                         f"none; use PLY, OBJ or OFF for points")
    try:
        write_atomically(path, lambda file: writer(_Cancellable(file, cancel), vertices, faces,
                                                   normals, colors))
    except OSError as error:
        raise InputError(f"{name}: cannot be written ({error.strerror or error})") from None


def write_ply_in_blocks(path, vertex_count: int, face_count: int, channels: int,
                        vertex_blocks, face_blocks, cancel=None) -> None:
    """Write a mesh as binary PLY, atomically (as :func:`write_mesh`), from its parts in order:
    ``vertex_blocks`` yields ``(vertices (k, 3), colours (k, channels) in [0, 1] or None)``,
    ``face_blocks`` triangles (k, 3); the counts are the totals. The same bytes as
    :func:`write_mesh` of the whole mesh, without holding it. ``cancel`` is polled between
    blocks. The generators may raise (an :class:`InputError` after the last block, say): the
    target is then left as it was."""
    from ..progress import check_cancel
    from .ply import ply_face_records, ply_header, ply_vertex_records

    path = os.fspath(path)

    def write(file) -> None:
        file.write(ply_header(vertex_count, face_count, False, channels))
        for vertices, colors in vertex_blocks:
            check_cancel(cancel)
            if colors is not None:
                colors = np.clip(np.asarray(colors, dtype=np.float64), 0.0, 1.0)
            file.write(ply_vertex_records(vertices, None, colors))
        for faces in face_blocks:
            check_cancel(cancel)
            file.write(ply_face_records(faces))

    try:
        write_atomically(path, write)
    except OSError as error:
        name = os.path.basename(path) or path
        raise InputError(f"{name}: cannot be written ({error.strerror or error})") from None


class _Cancellable:
    """A file whose writes first poll ``cancel`` (a writer's chunks: a table, a few rows)."""

    def __init__(self, file, cancel):
        self._file, self._cancel = file, cancel

    def write(self, data):
        from ..progress import check_cancel

        check_cancel(self._cancel)
        return self._file.write(data)

    def __getattr__(self, name):
        return getattr(self._file, name)


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
        probe, descriptor = temporary_file(folder, os.path.basename(path))
        os.close(descriptor)
        remove_quietly(probe)
    except OSError as error:
        raise InputError(f"output {path}: cannot create files in {folder} "
                         f"({error.strerror or error})") from None
    return path


def _extension(path: str) -> str:
    return os.path.splitext(path)[1].lower().lstrip(".")
