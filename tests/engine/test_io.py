import os
import re
import time

import numpy as np
import pytest

from engine.errors import InputError
from engine.frame import validate_points
from engine.geometry import Mesh
from engine.io import read_mesh, read_point_cloud, write_mesh
from lab.bench.dataset import shared_dir

REAL = os.path.join(shared_dir(), "data", "real")
needs_real_data = pytest.mark.skipif(not os.path.isdir(REAL), reason="shared real data absent")


def _mesh(rng, colors=None, normals=True):
    """A small mesh: an octahedron-ish cloud of 12 random vertices and 8 triangles."""
    vertices = rng.normal(size=(12, 3)) * 10.0 + 1000.0
    faces = rng.integers(0, 12, size=(8, 3))
    normal = rng.normal(size=(12, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    color = None
    if colors:
        color = (rng.integers(0, 256, size=(12, colors)) / 255.0).astype(np.float32)
    return Mesh(vertices, faces, normal if normals else None, color)


def _fail(path, *fragments):
    """Reading ``path`` raises InputError naming the file and every fragment of the problem."""
    with pytest.raises(InputError) as caught:
        read_mesh(path)
    message = str(caught.value)
    assert message.startswith(os.path.basename(str(path)) + ":"), message
    for fragment in fragments:
        assert fragment in message, message
    assert "\n" not in message
    return message


# ---------------------------------------------------------------- round trips


@pytest.mark.parametrize("extension, channels", [
    ("ply", None), ("ply", 3), ("ply", 4), ("obj", None), ("obj", 3),  # OBJ colours are RGB
    ("off", None), ("off", 3), ("off", 4)])
def test_written_mesh_reads_back_with_normals_and_colours(tmp_path, extension, channels):
    mesh = _mesh(np.random.default_rng(1), colors=channels)
    path = tmp_path / f"shape.{extension}"
    write_mesh(path, mesh)
    back = read_mesh(path)
    np.testing.assert_array_equal(back.vertices, mesh.vertices)  # doubles / 17 digits: exact
    np.testing.assert_array_equal(back.faces, mesh.faces)
    np.testing.assert_allclose(back.normals, mesh.normals, atol=1e-7)
    if channels is None:
        assert back.colors is None
    else:
        assert back.colors.dtype == np.float32 and back.colors.shape == (12, channels)
        np.testing.assert_allclose(back.colors, mesh.colors, atol=0.5 / 255)


@pytest.mark.parametrize("extension, channels", [
    ("glb", None), ("glb", 3), ("glb", 4), ("gltf", 4), ("stl", None)])
def test_trimesh_formats_read_back_with_normals_and_colours(tmp_path, extension, channels):
    """GLB and glTF hold float32 positions and normals and 8-bit colours; STL only triangles."""
    mesh = _mesh(np.random.default_rng(1), colors=channels)
    path = tmp_path / f"shape.{extension}"
    write_mesh(path, mesh)
    back = read_mesh(path)
    if extension == "stl":  # corners merged into shared vertices
        np.testing.assert_allclose(back.vertices[back.faces], mesh.vertices[mesh.faces],
                                   rtol=1e-7)
        assert back.normals is None and back.colors is None
        return
    np.testing.assert_allclose(back.vertices, mesh.vertices, rtol=1e-7)
    np.testing.assert_array_equal(back.faces, mesh.faces)
    np.testing.assert_allclose(back.normals, mesh.normals, atol=1e-6)
    if channels is None:
        assert back.colors is None
    else:
        assert back.colors.shape == (12, channels)
        np.testing.assert_allclose(back.colors, mesh.colors, atol=0.5 / 255)


@pytest.mark.parametrize("extension", ["ply", "obj", "off", "glb"])
def test_points_only_mesh_round_trips_without_faces(tmp_path, extension):
    points = np.random.default_rng(2).uniform(-1, 1, (50, 3))
    write_mesh(tmp_path / f"cloud.{extension}", Mesh(points, np.zeros((0, 3), np.int64)))
    cloud = read_point_cloud(tmp_path / f"cloud.{extension}")
    exact = extension != "glb"  # glTF positions are float32
    np.testing.assert_allclose(cloud.points, points, rtol=0 if exact else 1e-7)
    assert cloud.normals is None and cloud.colors is None
    assert read_mesh(tmp_path / f"cloud.{extension}").faces.shape == (0, 3)


def test_write_refuses_unknown_extension_and_unwritable_path(tmp_path):
    mesh = _mesh(np.random.default_rng(3))
    with pytest.raises(InputError, match=r"^shape\.abc: cannot write this format; use PLY"):
        write_mesh(tmp_path / "shape.abc", mesh)
    with pytest.raises(InputError, match=r"^shape\.ply: cannot be written"):
        write_mesh(tmp_path / "no_such_folder" / "shape.ply", mesh)


# ---------------------------------------------------------------- checked by trimesh


def _closed_sphere():
    """A closed, consistently wound icosphere (642 vertices) far from the origin."""
    trimesh = pytest.importorskip("trimesh")
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    return Mesh(sphere.vertices + [500000.0, 4000000.0, 100.0], sphere.faces,
                sphere.vertex_normals, np.full((len(sphere.vertices), 3), 0.5, np.float32))


@pytest.mark.parametrize("extension", ["ply", "obj", "off", "stl", "glb"])
def test_trimesh_reads_our_files_as_one_closed_consistently_wound_shell(tmp_path, extension):
    trimesh = pytest.importorskip("trimesh")
    mesh = _closed_sphere()
    write_mesh(tmp_path / f"sphere.{extension}", mesh)
    theirs = trimesh.load(tmp_path / f"sphere.{extension}", force="mesh")  # merges corners
    assert len(theirs.vertices) == 642 and len(theirs.faces) == 1280
    assert theirs.is_watertight and theirs.is_winding_consistent
    assert theirs.euler_number == 2
    assert theirs.volume > 0, "faces wound outward"
    exact = extension in ("ply", "obj", "off")
    assert np.abs(np.sort(theirs.vertices, axis=0)
                  - np.sort(mesh.vertices, axis=0)).max() <= (0 if exact else 0.5)


@pytest.mark.parametrize("extension, options", [
    ("ply", {"encoding": "binary"}), ("ply", {"encoding": "ascii"}),
    ("obj", {"include_normals": True, "digits": 12}), ("off", {}), ("stl", {}),
    ("stl_ascii", {}), ("glb", {"include_normals": True})])
def test_files_written_by_trimesh_read_back_as_the_same_mesh(tmp_path, extension, options):
    trimesh = pytest.importorskip("trimesh")
    sphere = trimesh.creation.icosphere(subdivisions=2)
    sphere.visual.vertex_colors = np.tile([[255, 51, 0, 255]], (len(sphere.vertices), 1))
    path = tmp_path / f"sphere.{extension.split('_')[0]}"
    data = sphere.export(file_type=extension, **options)
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    ours = read_mesh(path)
    again = trimesh.Trimesh(ours.vertices, ours.faces, process=False)
    assert again.is_watertight and again.is_winding_consistent and again.euler_number == 2
    assert len(ours.faces) == len(sphere.faces) and len(ours.vertices) == len(sphere.vertices)
    np.testing.assert_allclose(ours.vertices[ours.faces], sphere.vertices[sphere.faces],
                               atol=1e-6)
    if extension in ("ply", "obj", "glb"):
        np.testing.assert_allclose(ours.colors[:, :3], [[1.0, 0.2, 0.0]] * len(ours.vertices))


# ---------------------------------------------------------------- PLY variants


ASCII_PLY = b"""ply
format ascii 1.0
comment a quad, a pentagon and a triangle; extra properties to ignore
element camera 1
property float focal
element vertex 6
property float x
property float y
property float z
property float quality
property uchar red
property uchar green
property uchar blue
element face 3
property list uchar uint vertex_index
property int flags
end_header
2.5
0 0 0 7 255 0 0
1 0 0 7 0 255 0
1 1 0 7 0 0 255
0 1 0 7 255 255 255
0.5 1.5 0 7 0 0 0
0.5 0.5 1 7 51 102 153
4 0 1 2 3 9
5 0 1 2 3 4 9
3 0 1 5 9
"""

QUAD_PENTAGON_TRIANGLE = [[0, 1, 2], [0, 2, 3],
                          [0, 1, 2], [0, 2, 3], [0, 3, 4],
                          [0, 1, 5]]


def test_ascii_ply_with_mixed_polygons_other_elements_and_uchar_colours(tmp_path):
    (tmp_path / "a.ply").write_bytes(ASCII_PLY)
    mesh = read_mesh(tmp_path / "a.ply")
    np.testing.assert_array_equal(mesh.vertices[5], [0.5, 0.5, 1.0])
    np.testing.assert_array_equal(mesh.faces, QUAD_PENTAGON_TRIANGLE)
    np.testing.assert_allclose(mesh.colors[5], [0.2, 0.4, 0.6], rtol=1e-6)
    assert mesh.normals is None


def _binary_ply(order, faces_per_size, float_colours=True):
    """Header and body of a binary PLY in byte order '<' or '>' with polygons of mixed sizes."""
    vertex = np.dtype([("x", order + "f4"), ("y", order + "f4"), ("z", order + "f4"),
                       ("nx", order + "f4"), ("ny", order + "f4"), ("nz", order + "f4"),
                       ("red", order + "f4"), ("green", order + "f4"), ("blue", order + "f4")])
    rng = np.random.default_rng(4)
    table = np.zeros(30, dtype=vertex)
    for field in vertex.names:
        table[field] = rng.uniform(0, 1, 30)
    body, polygons = [table.tobytes()], []
    for size in faces_per_size:
        polygon = rng.integers(0, 30, size)
        polygons.append(polygon.tolist())
        body.append(np.array([size], order + "u2").tobytes())
        body.append(polygon.astype(order + "i4").tobytes())
    name = {"<": "binary_little_endian", ">": "binary_big_endian"}[order]
    header = (f"ply\nformat {name} 1.0\nelement vertex 30\n"
              + "".join(f"property float {f}\n" for f in vertex.names)
              + f"element face {len(faces_per_size)}\n"
              + "property list ushort int vertex_indices\nend_header\n").encode()
    return header, b"".join(body), table, polygons


@pytest.mark.parametrize("order", ["<", ">"])
def test_binary_ply_both_byte_orders_with_runs_of_polygon_sizes(tmp_path, order):
    sizes = [3] * 5 + [4] * 3 + [3] + [5] + [3] * 100 + [4]
    header, body, table, polygons = _binary_ply(order, sizes)
    (tmp_path / "b.ply").write_bytes(header + body)
    mesh = read_mesh(tmp_path / "b.ply")
    np.testing.assert_array_equal(mesh.vertices[:, 1], table["y"].astype(np.float64))
    np.testing.assert_array_equal(mesh.normals[:, 2], table["nz"].astype(np.float64))
    np.testing.assert_allclose(mesh.colors[:, 0], table["red"])
    expected = [[p[0], p[i], p[i + 1]] for p in polygons for i in range(1, len(p) - 1)]
    np.testing.assert_array_equal(mesh.faces, expected)


def test_million_point_binary_ply_loads_in_well_under_a_second(tmp_path):
    points = np.random.default_rng(5).uniform(-1, 1, (1_000_000, 3))
    colors = np.full((1_000_000, 3), 0.5, np.float32)
    write_mesh(tmp_path / "big.ply", Mesh(points, np.zeros((0, 3), np.int64), None, colors))
    start = time.perf_counter()
    cloud = read_point_cloud(tmp_path / "big.ply")
    elapsed = time.perf_counter() - start
    np.testing.assert_array_equal(cloud.points, points)
    assert elapsed < 1.0, f"took {elapsed:.2f} s"


# ---------------------------------------------------------------- OBJ, OFF, text, numpy, LAS


def test_obj_with_slashed_faces_negative_indices_colours_and_normals(tmp_path):
    (tmp_path / "m.obj").write_text(
        "# comment\n"
        "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 0.5 0.5 0.5\n"
        "vt 0 0\nvn 0 0 1\nvn 0 0 -1\n"
        "f 1/1/1 2/1/1 3/1/2 4/1/2\n"          # quad, v/vt/vn
        "f -4//1 -2//1 -1//1\n"                 # negative indices, v//vn
        "g part\nusemtl x\nl 1 2\n")
    mesh = read_mesh(tmp_path / "m.obj")
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 2, 3]])
    np.testing.assert_allclose(mesh.colors[3], [0.5, 0.5, 0.5])
    np.testing.assert_array_equal(mesh.normals[:, 2], [1, 1, 1, 1])  # last face's vn wins


def test_obj_negative_indices_count_back_from_the_vertices_read_so_far(tmp_path):
    (tmp_path / "strips.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf -3//-1 -2//-1 -1//-1\n"
        "v 0 0 1\nv 1 0 1\nv 0 1 1\nvn 0 1 0\nf -3//-1 -2//-1 -1//-1\nf 1//1 2//1 6//2\n")
    mesh = read_mesh(tmp_path / "strips.obj")
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [3, 4, 5], [0, 1, 5]])
    np.testing.assert_array_equal(mesh.normals[:, 1], [0, 0, 0, 1, 1, 1])


def test_off_variants_with_comments_colours_normals_and_polygons(tmp_path):
    (tmp_path / "c.off").write_text(
        "COFF # colours as 0..255 with alpha\n# a comment line\n5 2 0\n"
        "0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 0 0 0 255\n"
        "0 0 1 51 102 153 255\n"
        "4 0 1 2 3 200 10 10\n3 0 1 4\n")
    mesh = read_mesh(tmp_path / "c.off")
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])
    np.testing.assert_allclose(mesh.colors[4], [0.2, 0.4, 0.6, 1.0], rtol=1e-6)
    (tmp_path / "n.off").write_text("NOFF 3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n")
    mesh = read_mesh(tmp_path / "n.off")
    np.testing.assert_array_equal(mesh.normals, [[0, 0, 1]] * 3)
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2]])


XYZ_CASES = {
    "plain.xyz": ("1 2 3\n4 5 6\n7 8 9.5\n", None, None),
    "normals.txt": ("1,2,3,0,0,1\n4,5,6,0,-0.6,0.8\n7,8,9.5,1,0,0\n", [0, -0.6, 0.8], None),
    "rgb.xyz": ("x y z r g b\n1 2 3 255 0 0\n4 5 6 0 51 0\n7 8 9.5 0 0 1\n", None, [0, 0.2, 0]),
    "unit_rgb.xyz": ("1 2 3 0.1 0.2 0.3\n4 5 6 0 0.2 0\n7 8 9.5 0.5 0.5 0.5\n", None,
                     [0, 0.2, 0]),
    "scan.pts": ("3\n1 2 3 -500 255 0 0\n4 5 6 12 0 51 0\n7 8 9.5 3 0 0 1\n", None, [0, 0.2, 0]),
}


@pytest.mark.parametrize("name", sorted(XYZ_CASES))
def test_text_columns_decide_normals_or_colours(tmp_path, name):
    text, normal, color = XYZ_CASES[name]
    (tmp_path / name).write_text("// exported\n" + text)
    cloud = read_point_cloud(tmp_path / name)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6], [7, 8, 9.5]])
    if normal is None:
        assert cloud.normals is None
    else:
        np.testing.assert_allclose(cloud.normals[1], normal)
    if color is None:
        assert cloud.colors is None
    else:
        np.testing.assert_allclose(cloud.colors[1], color, rtol=1e-6)


def test_npy_and_npz_clouds_and_meshes(tmp_path):
    rng = np.random.default_rng(6)
    points = rng.uniform(-1, 1, (20, 3))
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    np.save(tmp_path / "p.npy", points)
    np.testing.assert_array_equal(read_point_cloud(tmp_path / "p.npy").points, points)
    np.save(tmp_path / "pn.npy", np.concatenate([points, normals], axis=1))
    np.testing.assert_allclose(read_point_cloud(tmp_path / "pn.npy").normals, normals)
    colors = rng.integers(0, 256, (20, 3)).astype(np.uint8)
    faces = np.array([[0, 1, 2, 3]])
    np.savez(tmp_path / "m.npz", vertices=points, normals=normals, colors=colors, faces=faces)
    mesh = read_mesh(tmp_path / "m.npz")
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_allclose(mesh.colors, colors / 255.0, rtol=1e-6)
    np.testing.assert_array_equal(mesh.normals, normals)


@pytest.mark.parametrize("extension", ["las", "laz"])
def test_las_and_laz_give_scaled_coordinates_and_16_bit_colours(tmp_path, extension):
    laspy = pytest.importorskip("laspy")
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([500000.0, 4000000.0, 100.0])
    las = laspy.LasData(header)
    rng = np.random.default_rng(7)
    xyz = np.round(rng.uniform(0, 50, (100, 3)), 3) + header.offsets
    las.x, las.y, las.z = xyz.T
    rgb = rng.integers(0, 65536, (100, 3))
    las.red, las.green, las.blue = rgb.T
    las.write(str(tmp_path / f"scan.{extension}"))
    cloud = read_point_cloud(tmp_path / f"scan.{extension}")
    np.testing.assert_allclose(cloud.points, xyz, atol=1e-6)
    np.testing.assert_allclose(cloud.colors, rgb / 65535.0, rtol=1e-6)


# ---------------------------------------------------------------- real files


def _readme_table():
    """{file: (V, F)} from the shared data README (V counts distinct used positions)."""
    text = open(os.path.join(REAL, "..", "README.md")).read()
    rows = re.findall(r"^\| (\S+\.(?:off|ply)) \| (\d+) \| (\d+) \|", text, re.MULTILINE)
    return {name: (int(v), int(f)) for name, v, f in rows}


@needs_real_data
def test_real_meshes_match_the_data_readme():
    table = _readme_table()
    assert len(table) == 12
    for folder in ("cgal", "scans", "rangemap", "misc"):
        for name in sorted(os.listdir(os.path.join(REAL, folder))):
            if name not in table:
                continue
            mesh = read_mesh(os.path.join(REAL, folder, name))
            vertices, faces = table.pop(name)
            assert len(mesh.faces) == faces, name
            # The README counts distinct positions that faces use; some files repeat vertices.
            used = np.unique(mesh.vertices[np.unique(mesh.faces)], axis=0)
            assert len(used) == vertices, name
    assert not table


@needs_real_data
def test_real_files_exact_counts_and_lidar_colours():
    bunny = read_mesh(os.path.join(REAL, "cgal", "bunny00.off"))
    assert bunny.vertices.shape == (37706, 3) and bunny.faces.shape == (75408, 3)
    owl = read_mesh(os.path.join(REAL, "scans", "owl.ply"))
    assert owl.vertices.shape == (12442, 3) and owl.faces.shape == (24407, 3)
    lidar = read_point_cloud(os.path.join(REAL, "cgal", "b9_training.ply"))
    assert lidar.points.shape == (22300, 3) and lidar.colors.shape == (22300, 3)
    assert lidar.normals is None
    # An independent read of the body (x, y, z double; r, g, b uchar; label int).
    data = open(os.path.join(REAL, "cgal", "b9_training.ply"), "rb").read()
    body = data[data.index(b"end_header\n") + len(b"end_header\n"):]
    raw = np.frombuffer(body, [("xyz", "<f8", (3,)), ("rgb", "u1", (3,)), ("label", "<i4")])
    np.testing.assert_array_equal(lidar.points, raw["xyz"])  # georeferenced doubles, exact
    np.testing.assert_allclose(lidar.colors, raw["rgb"] / 255.0, rtol=1e-6)
    assert len(np.unique(raw["rgb"], axis=0)) == 4  # the file colours points by class


# ---------------------------------------------------------------- bad files


def test_missing_file_folder_and_unsupported_format(tmp_path):
    _fail(tmp_path / "bunny.ply", "file not found", str(tmp_path))
    (tmp_path / "folder.ply").mkdir()
    _fail(tmp_path / "folder.ply", "is a folder")
    (tmp_path / "scan.e57").write_bytes(b"ASTM-E57")
    _fail(tmp_path / "scan.e57",
          "unsupported format; use PLY, OBJ, OFF, STL, GLB, GLTF, XYZ, PTS, TXT, NPY, NPZ, "
          "LAS or LAZ")


@pytest.mark.parametrize("name", ["e.ply", "e.obj", "e.off", "e.xyz", "e.pts", "e.txt"])
def test_empty_files_are_refused(tmp_path, name):
    (tmp_path / name).write_bytes(b"")
    message = _fail(tmp_path / name)
    assert "empty" in message or "no points" in message


@pytest.mark.parametrize("content, problem", [
    (b"solid cube\nfacet normal 0 0 1\n", "not a PLY file"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", "no 'end_header'"),
    (b"ply\nformat binary_middle_endian 1.0\nend_header\n", "unknown PLY format"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
     "unknown PLY property type 'float128'"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n1\n",
     "no x, y, z properties"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
     b"property float z\nend_header\n0 0 0\n1 1 zero\n", "'zero' is not a number"),
    (b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
     b"property float z\nend_header\n", "contains no points"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
     b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
     b"end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "refers to vertex 7, but there are only 3"),
])
def test_corrupt_ply_headers_and_bodies(tmp_path, content, problem):
    (tmp_path / "bad.ply").write_bytes(content)
    _fail(tmp_path / "bad.ply", problem)


def test_truncated_binary_ply_says_how_far_it_got(tmp_path):
    header, body, _, _ = _binary_ply("<", [3] * 10)
    vertex_bytes = 30 * 9 * 4
    (tmp_path / "bunny.ply").write_bytes(header + body[:12 * 9 * 4 + 5])
    _fail(tmp_path / "bunny.ply", "the file ends after 12 of 30 vertices")
    (tmp_path / "faces.ply").write_bytes(header + body[:vertex_bytes + 4 * 14 + 3])
    _fail(tmp_path / "faces.ply", "the file ends after 4 of 10 faces")
    (tmp_path / "text.ply").write_bytes(ASCII_PLY[:ASCII_PLY.index(b"1 1 0 7")])
    _fail(tmp_path / "text.ply", "the file ends after 2 of 6 vertices")


@pytest.mark.parametrize("name, content, problem", [
    ("a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 5\n", "refers to vertex 4, but there are only 3"),
    ("b.obj", "v 0 0 zero\n", "'zero' is not a number"),
    ("c.obj", "v 0 0 0\nf 0 1 1\n", "index 0 (OBJ indices start at 1)"),
    ("d.obj", "# nothing\nvt 0 0\n", "no points"),
    ("a.off", "PLY\n3 1 0\n", "not an OFF file"),
    ("b.off", "OFF\n5 1 0\n0 0 0\n1 0 0\n", "the file ends after 2 of 5 vertices"),
    ("c.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "the file ends after 1 of 2 faces"),
    ("d.off", "OFF\nthree 1 0\n", "vertex and face counts"),
    ("e.off", "4OFF\n1 0 0\n0 0 0 0\n", "4-D and n-D OFF files are not supported"),
    ("a.xyz", "0 0 0\n1 0 0 5\n", "data line 2 has 4 values, but the first data line has 3"),
    ("b.xyz", "0 0\n1 0\n", "at least 3 columns"),
    ("c.xyz", "1 2 3\n4 5 six\n", "'six' is not a number"),
    ("d.pts", "# only comments\n// and more\n", "no points"),
])
def test_corrupt_text_files(tmp_path, name, content, problem):
    (tmp_path / name).write_text(content)
    _fail(tmp_path / name, problem)


def test_corrupt_numpy_and_las_files(tmp_path):
    np.save(tmp_path / "flat.npy", np.zeros((4, 2)))
    _fail(tmp_path / "flat.npy", "shape (4, 2)")
    (tmp_path / "junk.npy").write_bytes(b"\x93NUMPY garbage")
    _fail(tmp_path / "junk.npy")
    np.savez(tmp_path / "keys.npz", xyz=np.zeros((4, 3)))
    _fail(tmp_path / "keys.npz", "no 'points' or 'vertices' array (it has: xyz)")
    np.savez(tmp_path / "rows.npz", points=np.zeros((4, 3)), normals=np.zeros((3, 3)))
    _fail(tmp_path / "rows.npz", "'normals' has 3 rows but 'points' has 4")
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not a zip")
    _fail(tmp_path / "junk.npz", "not a readable NPZ archive")
    os.rename(tmp_path / "flat.npy", tmp_path / "renamed.npz")
    _fail(tmp_path / "renamed.npz", "not an NPZ archive")
    (tmp_path / "junk.las").write_bytes(b"LASF" + bytes(50))
    _fail(tmp_path / "junk.las")


def test_binary_stl_whose_header_starts_with_solid_reads_as_binary(tmp_path):
    mesh = _closed_sphere()
    write_mesh(tmp_path / "sphere.stl", mesh)
    data = (tmp_path / "sphere.stl").read_bytes()
    (tmp_path / "solid.stl").write_bytes(b"solid exported by a CAD program".ljust(80) + data[80:])
    back = read_mesh(tmp_path / "solid.stl")
    assert back.faces.shape == (1280, 3) and back.vertices.shape == (642, 3)


def test_corrupt_glb_and_gltf_files(tmp_path):
    (tmp_path / "junk.glb").write_bytes(b"glTF" + bytes(40))
    _fail(tmp_path / "junk.glb", "not a readable file of this format")
    (tmp_path / "junk.gltf").write_text('{"asset": {"version": "2.0"}, "meshes": [{"primitives"')
    _fail(tmp_path / "junk.gltf", "not a readable file of this format")
    (tmp_path / "empty.gltf").write_text('{"asset": {"version": "2.0"}}')
    _fail(tmp_path / "empty.gltf", "contains no meshes or points")
    write_mesh(tmp_path / "cut.glb", _mesh(np.random.default_rng(8)))
    data = (tmp_path / "cut.glb").read_bytes()
    (tmp_path / "cut.glb").write_bytes(data[:len(data) // 2])
    _fail(tmp_path / "cut.glb", "not a readable file of this format")


def test_nan_coordinates_load_and_are_then_refused_by_the_frame(tmp_path):
    (tmp_path / "holes.xyz").write_text("".join(f"{i} {i * i % 7} {i % 3}\n" for i in range(20))
                                        + "nan 0 0\n1 inf 2\n")
    cloud = read_point_cloud(tmp_path / "holes.xyz")
    assert len(cloud) == 22 and np.isnan(cloud.points[20, 0])
    with pytest.raises(InputError, match="2 of 22 points have NaN or infinite coordinates"):
        validate_points(cloud.points)
