"""AO texture bakes (pipeline/bakes/texture.py) against the closed form of a floor beside a wall.

The scene is the labeller's wall test (tests/test_labels.py): a floor and a wall meeting at a right
angle. A point at distance s from the other plane has binary AO 1 - segment_fraction(s / R) for s < R
and 1 beyond (disk formula, tests/test_labels.py::wall_binary_reference); by symmetry the same holds
for points on the wall at height s. The floor and the wall are one quad each (two triangles), so a
vertex bake can only interpolate between corners, while a texture follows the curve.
"""

from __future__ import annotations

import io
import json
import math
import struct

import numpy as np
import pytest
import trimesh
from helpers import mc_bound, segment_fraction
from PIL import Image

from neuralao.pipeline import cli
from neuralao.pipeline.bakes.texture import (
    TextureBakeSettings,
    UVMesh,
    bake_texture,
    dilate,
    load_uv_mesh,
    png_path_for,
    point_uvs,
    quantise,
    rasterise,
    read_texture_glb,
    sample_bilinear,
    scene_with_uvs,
    write_texture_glb,
)
from neuralao.pipeline.bakes.vertex import BakeSettings, bake
from neuralao.runtime.foundation.errors import NeuralaoError

R = 1.0  # max distance
UV_SCALE = 0.11  # UV units per scene unit (square texels on both planes)


def corner_mesh() -> UVMesh:
    """Floor x in [-3, 0], y in [-2, 2] (normal +z) and wall x = 0, z in [0, 2] (normal -x), own UVs."""
    floor = np.array([[-3, -2, 0], [0, -2, 0], [0, 2, 0], [-3, 2, 0]], float)
    wall = np.array([[0, -2, 0], [0, -2, 2], [0, 2, 2], [0, 2, 0]], float)
    uv_floor = np.c_[0.02 + (floor[:, 0] + 3) * UV_SCALE, 0.02 + (floor[:, 1] + 2) * UV_SCALE]
    uv_wall = np.c_[0.5 + wall[:, 2] * UV_SCALE, 0.02 + (wall[:, 1] + 2) * UV_SCALE]
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    # wall winding: (0,-2,0) -> (0,-2,2) -> (0,2,2) has normal -x
    return scene_with_uvs(
        np.concatenate([floor, wall]),
        np.concatenate([quad, quad + 4]),
        np.concatenate([uv_floor, uv_wall]),
        "corner",
    )


def closed_form(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Binary AO (k,) at points of corner_mesh, and where the infinite-plane form holds (|y| <= 1)."""
    on_wall = np.isclose(points[:, 0], 0.0) & (points[:, 2] > 1e-9)
    s = np.where(on_wall, points[:, 2], -points[:, 0])  # distance to the other plane
    ao = np.array([1.0 - segment_fraction(min(x / R, 1.0)) for x in s])
    return ao, np.abs(points[:, 1]) <= 1.0


def random_surface_points(mesh: UVMesh, k: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    face = rng.integers(0, len(mesh.faces), k)
    r1, r2 = np.sqrt(rng.random(k)), rng.random(k)
    bary = np.c_[1 - r1, r1 * (1 - r2), r1 * r2]
    points = np.einsum("kc,kcd->kd", bary, mesh.vertices[mesh.faces[face]])
    return face, bary, points


SETTINGS = TextureBakeSettings(resolution=64, margin=2, rays=1024, max_distance=R, seed=0)


@pytest.fixture(scope="module")
def corner_bake():
    mesh = corner_mesh()
    return mesh, bake_texture(mesh, SETTINGS)


def test_texel_centres_match_the_closed_form(corner_bake):
    mesh, result = corner_bake
    n = SETTINGS.resolution
    texels = rasterise(mesh.uv, mesh.faces, n)
    points = np.einsum("kc,kcd->kd", texels.bary, mesh.vertices[mesh.faces[texels.face]])
    expected, ok = closed_form(points)
    got = result.ao.reshape(-1)[texels.pixel].astype(np.float64)
    assert ok.sum() > 300 and result.info["invalid_texels"] == 0
    err = np.abs(got - expected)[ok]
    assert np.all(err <= mc_bound(expected[ok], SETTINGS.rays)), err.max()
    assert abs(np.mean(got[ok] - expected[ok])) <= mc_bound(0.5, SETTINGS.rays * ok.sum())  # no bias
    assert expected[ok].min() < 0.55 and (expected[ok] == 1).any()  # the curve is really sampled


def test_texture_beats_the_vertex_bake_at_random_points(corner_bake, tmp_path):
    """What a viewer shows: bilinear lookups of the 8-bit map in the .glb, against the closed form."""
    mesh, result = corner_bake
    out = write_texture_glb(tmp_path / "corner.glb", mesh, result.ao)
    read_mesh, red = read_texture_glb(out)
    np.testing.assert_array_equal(red, quantise(result.ao) / np.float32(255.0))
    face, bary, points = random_surface_points(mesh, 4000, seed=7)
    expected, ok = closed_form(points)
    tex = sample_bilinear(red, point_uvs(read_mesh, face, bary))
    rmse_texture = math.sqrt(np.mean((tex - expected)[ok] ** 2))
    scene = mesh.scene()
    vertex = bake(scene, BakeSettings(rays=1024, max_distance=R, method="vertex"))
    lsq = bake(
        scene, BakeSettings(rays=1024, max_distance=R, samples_per_vertex=512, samples_per_face_cap=2048)
    )
    corners = {
        name: np.einsum("kc,kc->k", bary, r.ao[mesh.faces[face]].astype(np.float64))
        for name, r in (("vertex", vertex), ("least-squares", lsq))
    }
    rmse = {k: math.sqrt(np.mean((v - expected)[ok] ** 2)) for k, v in corners.items()}
    # 1024 rays: per-texel noise sd <= 0.016; bilinear weights average it down; 8 bits add 0.001
    assert rmse_texture < 0.015, rmse_texture
    assert min(rmse.values()) > 5 * rmse_texture, (rmse, rmse_texture)


def test_rasterise_maps_texel_centres_into_their_triangles():
    # one triangle covering the lower-left half of the square (u + v <= 1), and the other half
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    n = 16
    t = rasterise(uv, faces, n)
    assert len(t.pixel) == n * n and len(np.unique(t.pixel)) == n * n and t.overlap == 0.0
    r, c = np.divmod(t.pixel, n)
    centre = np.c_[(c + 0.5) / n, 1.0 - (r + 0.5) / n]
    mesh = UVMesh(np.c_[uv, np.zeros(4)], faces, uv)
    np.testing.assert_allclose(point_uvs(mesh, t.face, t.bary), centre, atol=1e-12)
    below = centre.sum(axis=1) < 1 - 1e-9
    assert np.all(t.face[below] == 0) and np.all(t.face[centre.sum(axis=1) > 1 + 1e-9] == 1)
    # the same triangle twice: every texel it holds is held by two faces
    twice = rasterise(uv, np.array([[0, 1, 2], [0, 1, 2]]), n)
    assert twice.overlap > 0.8  # all but the texels on the diagonal edge


def test_a_map_too_small_for_the_mesh_says_so(caplog):
    # a 32 x 32 grid of quads (2,048 faces) on the unit square: an 8 x 8 map centres a texel in 64 of them
    g = np.linspace(0.0, 1.0, 33)
    uv = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    k = (np.arange(32)[:, None] * 33 + np.arange(32)).ravel()
    faces = np.r_[np.c_[k, k + 1, k + 33], np.c_[k + 1, k + 34, k + 33]]
    mesh = UVMesh(np.c_[uv, np.zeros(len(uv))], faces, uv)
    with caplog.at_level("WARNING"):
        bake_texture(mesh, TextureBakeSettings(resolution=8, margin=1, rays=2))
    assert "only 64 of the 2048 faces hold a texel centre" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING"):
        bake_texture(mesh, TextureBakeSettings(resolution=64, rays=2))
    assert "hold a texel centre" not in caplog.text


def test_dilation_fills_gutters_and_holes_from_valid_texels():
    n = 12
    values = np.zeros((n, n))
    known = np.zeros((n, n), bool)
    values[4:8, 4:8], known[4:8, 4:8] = 0.3, True
    known[5, 5] = False  # an invalid texel inside the chart
    target = np.zeros((n, n), bool)
    target[2:10, 2:10] = True  # the chart grown by a margin of 2
    out = dilate(values, known, target, fill=1.0)
    np.testing.assert_allclose(out[target], 0.3, atol=1e-6)
    assert np.all(out[~target] == 1.0)


def test_glb_holds_the_map_as_occlusion_texture_and_keeps_the_material(tmp_path, corner_bake):
    """Parsed from the GLB's own JSON and binary chunks (not through trimesh's loader)."""
    mesh, result = corner_bake
    from trimesh.visual.material import PBRMaterial

    mesh = UVMesh(
        mesh.vertices,
        mesh.faces,
        mesh.uv,
        PBRMaterial(baseColorFactor=[200, 10, 10, 255], roughnessFactor=0.3),
        "mesh",
    )
    path = write_texture_glb(tmp_path / "m.glb", mesh, result.ao)
    data = path.read_bytes()
    magic, version, _ = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2
    jlen, _ = struct.unpack_from("<II", data, 12)
    gltf = json.loads(data[20 : 20 + jlen])
    blen, _ = struct.unpack_from("<II", data, 20 + jlen)
    binary = data[28 + jlen : 28 + jlen + blen]
    material = gltf["materials"][gltf["meshes"][0]["primitives"][0]["material"]]
    assert "TEXCOORD_0" in gltf["meshes"][0]["primitives"][0]["attributes"]
    assert material["pbrMetallicRoughness"]["roughnessFactor"] == pytest.approx(0.3)
    assert material["pbrMetallicRoughness"]["baseColorFactor"][0] == pytest.approx(200 / 255, abs=1e-6)
    image = gltf["images"][gltf["textures"][material["occlusionTexture"]["index"]]["source"]]
    view = gltf["bufferViews"][image["bufferView"]]
    png = binary[view.get("byteOffset", 0) : view.get("byteOffset", 0) + view["byteLength"]]
    red = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))[:, :, 0]
    np.testing.assert_array_equal(red, quantise(result.ao))


def test_mesh_uvs_are_used_when_usable_else_xatlas(tmp_path):
    mesh = corner_mesh()
    tm = trimesh.Trimesh(
        mesh.vertices, mesh.faces, visual=trimesh.visual.TextureVisuals(uv=mesh.uv), process=False
    )
    good = tmp_path / "good.glb"
    good.write_bytes(tm.export(file_type="glb"))
    loaded = load_uv_mesh(good, TextureBakeSettings(resolution=64))
    assert loaded.uv_source == "mesh"
    np.testing.assert_allclose(loaded.uv, mesh.uv, atol=1e-6)
    # mirrored UVs (the wall reuses the floor's island): auto falls back to xatlas, mesh refuses
    uv = mesh.uv.copy()
    uv[4:] = uv[:4]
    tm.visual = trimesh.visual.TextureVisuals(uv=uv)
    bad = tmp_path / "mirrored.glb"
    bad.write_bytes(tm.export(file_type="glb"))
    auto = load_uv_mesh(bad, TextureBakeSettings(resolution=64))
    assert auto.uv_source == "xatlas"
    assert rasterise(auto.uv, auto.faces, 64).overlap == 0.0
    with pytest.raises(NeuralaoError, match="overlap"):
        load_uv_mesh(bad, TextureBakeSettings(resolution=64, uv="mesh"))


def test_cli_texture_bake_end_to_end_and_deterministic(tmp_path):
    out = tmp_path / "cb.glb"
    args = ["bake", "cornell_box", "--to", "texture", "--resolution", "32", "--rays", "16", "--out", str(out)]
    assert cli.main(args) == 0
    first = out.read_bytes()
    png = png_path_for(out)
    mesh, red = read_texture_glb(out)
    np.testing.assert_array_equal(np.asarray(Image.open(png)), np.rint(red * 255).astype(np.uint8))
    assert red.shape == (32, 32) and 0 <= red.min() < 1
    assert cli.main(args) == 0 and out.read_bytes() == first  # seeded: same bytes


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--resolution", "2"], "--resolution"),
        (["--margin", "-1"], "--margin"),
        (["--method", "vertex"], "does not apply"),
        (["--uv", "mesh"], "--uv mesh"),
        (["--engine", "ray"], "locally"),
    ],
)
def test_cli_bad_input_is_a_one_line_error(tmp_path, capsys, extra, message):
    out = tmp_path / "x.glb"
    assert cli.main(["bake", "cornell_box", "--to", "texture", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert not out.exists() and not png_path_for(out).exists()
    assert list(tmp_path.iterdir()) == []


def test_cli_texture_needs_a_glb(tmp_path, capsys):
    assert cli.main(["bake", "cornell_box", "--to", "texture", "--out", str(tmp_path / "x.ply")]) == 2
    assert ".glb" in capsys.readouterr().err


def _glb_json(path):
    data = path.read_bytes()
    jlen, _ = struct.unpack_from("<II", data, 12)
    gltf = json.loads(data[20 : 20 + jlen])
    blen, _ = struct.unpack_from("<II", data, 20 + jlen)
    binary = data[28 + jlen : 28 + jlen + blen]

    def image(texture_index):
        view = gltf["bufferViews"][gltf["images"][gltf["textures"][texture_index]["source"]]["bufferView"]]
        start = view.get("byteOffset", 0)
        return np.asarray(Image.open(io.BytesIO(binary[start : start + view["byteLength"]])).convert("RGB"))

    return gltf, image


def test_cli_keeps_the_source_base_colour_texture_with_mesh_uvs(tmp_path):
    from trimesh.visual.material import PBRMaterial

    mesh = corner_mesh()
    colour = np.zeros((8, 8, 3), np.uint8)
    colour[:, :4] = (200, 30, 30)
    material = PBRMaterial(baseColorTexture=Image.fromarray(colour), roughnessFactor=0.4)
    tm = trimesh.Trimesh(
        mesh.vertices,
        mesh.faces,
        process=False,
        visual=trimesh.visual.TextureVisuals(uv=mesh.uv, material=material),
    )
    src = tmp_path / "textured.glb"
    src.write_bytes(tm.export(file_type="glb"))
    out = tmp_path / "baked.glb"
    args = ["bake", str(src), "--to", "texture", "--resolution", "32", "--rays", "16", "--max-distance", "1"]
    assert cli.main([*args, "--out", str(out)]) == 0
    gltf, image = _glb_json(out)
    (mat,) = gltf["materials"]
    pbr = mat["pbrMetallicRoughness"]
    assert pbr["roughnessFactor"] == pytest.approx(0.4)
    np.testing.assert_array_equal(image(pbr["baseColorTexture"]["index"]), colour)
    ao = image(mat["occlusionTexture"]["index"])[:, :, 0]
    assert ao.shape == (32, 32) and ao.min() < 200  # the contact shadow is in the red channel
    uv_accessor = gltf["accessors"][gltf["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"]]
    assert uv_accessor["count"] == 8  # the mesh's own UVs (8 vertices), not an atlas
