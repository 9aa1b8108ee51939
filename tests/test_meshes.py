"""physdbg.meshes: mesh files and shapes as a user names them, and `physdbg overlap`."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg.cli import app
from physdbg.errors import MeshError
from physdbg.meshes import load_mesh
from physdbg.meshes.shapes import SHAPES

runner = CliRunner()

CUBE_OBJ = """# a unit cube, one quad per side
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vn 0 0 1
g cube
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
f 2/1 3/1 7/1 6/1
f 3//1 4//1 8//1 7//1
f -4 -8 -5 -1
"""


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def _stl_ascii(triangles) -> str:
    out = ["solid t"]
    for tri in triangles:
        out += ["facet normal 0 0 1", "outer loop", *[f"vertex {x} {y} {z}" for x, y, z in tri], "endloop",
                "endfacet"]
    return "\n".join(out + ["endsolid t", ""])


def test_an_obj_with_quads_slashes_and_negative_indices_loads_as_its_triangles(tmp_path):
    mesh = load_mesh(_write(tmp_path, "cube.obj", CUBE_OBJ))
    assert mesh.triangles == 12 and mesh.name == "cube" and not mesh.skipped
    assert np.allclose(mesh.vertices.min(axis=0), 0) and np.allclose(mesh.vertices.max(axis=0), 1)
    assert mesh.hull is not None and len(mesh.hull[2]) == 8


def test_ascii_and_binary_stl_load_the_same_triangles(tmp_path):
    triangles = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], dtype=float)
    ascii_mesh = load_mesh(_write(tmp_path, "two.stl", _stl_ascii(triangles)))
    binary = tmp_path / "two-binary.stl"
    binary.write_bytes(b"\0" * 80 + struct.pack("<I", 2) + b"".join(
        struct.pack("<12fH", 0, 0, 1, *tri.ravel(), 0) for tri in triangles))
    binary_mesh = load_mesh(binary)
    for mesh in (ascii_mesh, binary_mesh):
        assert np.array_equal(mesh.vertices[mesh.faces], triangles)


@pytest.mark.parametrize("text, message", [
    ("v 0 0 0\nv 1 0 zz\n", "line 2: vertex z 'zz' is not a number"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "line 4: face corner 9 names no vertex (3 defined so far)"),
    ("v 0 0 0\nv 1 0 0\nf 1 2\n", "line 3: a face needs at least 3 corners, not 2"),
    ("v 0 0 0\nv 1 0\n", "line 2: a vertex takes x y z (and optionally w or r g b), not 2 numbers"),
    ("v 0 0 0\nbogus 1\n", "line 2: unknown OBJ statement 'bogus'"),
    ("v 0 0 nan\n", "line 1: vertex z 'nan' is not finite"),
    ("# only a comment\n", "holds no triangles"),
])
def test_a_malformed_obj_names_the_file_the_line_and_the_problem(tmp_path, text, message):
    path = _write(tmp_path, "bad.obj", text)
    with pytest.raises(MeshError) as caught:
        load_mesh(path)
    assert str(caught.value).startswith(str(path)) and message in str(caught.value)


@pytest.mark.parametrize("text, message", [
    (_stl_ascii([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]]).replace("vertex 0 1 0", "vertex 0 1 q"),
     "line 6: vertex z 'q' is not a number"),
    (_stl_ascii([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]]).replace("endloop", "endlop"), "line 7: expected 'endloop'"),
    ("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n", "ends inside a facet"),
    ("\x01\x02 not an stl", "neither a binary STL"),
])
def test_a_malformed_stl_names_the_file_the_line_and_the_problem(tmp_path, text, message):
    path = _write(tmp_path, "bad.stl", text)
    with pytest.raises(MeshError) as caught:
        load_mesh(path)
    assert message in str(caught.value)


def test_degenerate_triangles_are_reported_by_line_and_skipped(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 3\n"
    mesh = load_mesh(_write(tmp_path, "flat.obj", text))
    assert mesh.triangles == 1
    assert mesh.skipped == [(6, "zero area"), (7, "a corner repeated")]
    assert "skipped 2 degenerate triangle(s): line 6 (zero area), line 7 (a corner repeated)" in \
        mesh.skipped_words()
    with pytest.raises(MeshError, match="every triangle is degenerate"):
        load_mesh(_write(tmp_path, "none.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"))


def test_a_mesh_too_big_for_the_memory_budget_is_refused_before_it_is_loaded(tmp_path):
    # 30,000 triangles (about 43 MB with their BVH) against a 1 MB budget, then a line the
    # reader would refuse: the budget stops the read long before that line is reached
    faces = "".join(f"f 1 2 {3 + k % 2}\n" for k in range(30_000))
    path = _write(tmp_path, "many.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n" + faces + "what is this\n")
    with pytest.raises(MeshError, match=r"many.obj: [\d,]+ triangles and 4 vertices \(and counting\) need about "
                                        r".* GB with their BVH, over the memory budget"):
        load_mesh(path, max_memory=1e6)
    with pytest.raises(MeshError, match="unknown OBJ statement 'what'"):
        load_mesh(path)  # within the default budget the whole file is read


def test_a_flat_mesh_has_no_hull_and_is_still_searched(tmp_path):
    plate = _write(tmp_path, "plate.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    assert load_mesh(plate).hull is None
    result = runner.invoke(app, ["overlap", str(plate), "paddle", "--pose", "0.5,0.5,0"])
    assert result.exit_code == 1 and "no hull (flat)" in result.output and "hulls: not tested" in result.output
    assert load_mesh("funnel").hull is not None  # open, but not flat


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_every_built_in_shape_is_a_clean_mesh(shape):
    mesh = load_mesh(shape)
    assert mesh.triangles > 0 and not mesh.skipped and mesh.source == f"shape {shape}"


def test_cli_overlap_prints_the_search_tree_and_exits_1_when_meshes_meet():
    result = runner.invoke(app, ["overlap", "icosphere", "paddle", "--pose", "0.5,0,0,0,0,30", "--max-lines", "3"])
    assert result.exit_code == 1, result.output
    lines = result.output.splitlines()
    assert lines[2] == "volume: obb (auto: B turned, so AABBs would be refitted; an OBB only turns)"
    assert lines[5].startswith("MEET: 16 triangle pair(s) meet")
    assert lines[7] == "  A0×B0 volumes meet" and "more node pairs (--max-lines 0 shows all)" in lines[-1]


def test_cli_overlap_exits_0_when_apart_and_the_json_holds_the_whole_tree():
    far = runner.invoke(app, ["overlap", "icosphere", "icosphere", "--pose", "1.02,0,0"])
    assert far.exit_code == 0 and "hulls: apart (tested first): no node visited" in far.output
    result = runner.invoke(app, ["overlap", "icosphere", "paddle", "--pose", "0.92,0.4,0", "--no-hull", "--json",
                                 "--volume", "sphere", "--builder", "lbvh"])
    report = json.loads(result.output)
    assert result.exit_code == 0 and report["meet"] is False and report["hulls"] == "off"
    assert report["volume"] == "sphere" and report["counts"]["visited"] == len(report["tree"]) > 1
    assert report["counts"]["apart"] > 0 and report["pairs"] == []
    # each node pair names the pair whose split led to it and its depth: the tree rebuilds
    tree = report["tree"]
    assert tree[0]["parent"] == -1 and tree[0]["depth"] == 0
    for row in tree[1:]:
        parent = tree[row["parent"]]
        assert parent["outcome"] == "volumes meet" and row["depth"] == parent["depth"] + 1
        assert (row["a"] == parent["a"]) != (row["b"] == parent["b"])  # split on one side


@pytest.mark.parametrize("args, message", [
    (["nope.obj", "paddle"], "error: nope.obj: no such file"),
    (["teapot", "paddle"], "error: teapot: neither a mesh file (.obj, .stl) nor a built-in shape"),
    (["funnel", "paddle", "--pose", "1,2"], "error: --pose '1,2': give 3 or 6 finite numbers"),
    (["funnel", "paddle", "--volume", "kdop"], "error: --volume 'kdop': one of auto, aabb, sphere, obb"),
    (["funnel", "paddle", "--builder", "octree"], "error: --builder 'octree': one of median, mean, sah, lbvh"),
])
def test_cli_overlap_bad_input_is_one_line_and_exit_2(args, message):
    result = runner.invoke(app, ["overlap", *args])
    assert result.exit_code == 2 and result.output.strip().startswith(message), result.output
