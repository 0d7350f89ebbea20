"""glTF scenes baked as scenes (pipeline/bakes/gltf_scene.py): closed forms, materials, hierarchy, instances.

Closed form: a floor and a ceiling, two large parallel planes h apart, in two nodes under a scaled and
translated root. From a point on either plane, cosine-weighted rays with cos(theta) > h / R hit the
other plane within R (the sine of the polar angle squared is uniform under cosine weighting), so the
binary AO is P(cos(theta) <= h / R) = (h / R)^2 wherever the disk of radius sqrt(R^2 - h^2) around the
point lies inside the other plane. Each plane alone is open (AO 1): a bake that traced the nodes
one by one, or ignored a node's transform, is off by O(1).

The scenes are written here as glTF (neuralao.pipeline.geometry.level_files.GltfWriter), nothing is copied
from shared/.
"""

from __future__ import annotations

import io
import json
import os
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh
from helpers import mc_bound, needs_chromium
from PIL import Image

from neuralao.pipeline import cli
from neuralao.pipeline.bakes.gltf_scene import read_gltf_scene
from neuralao.pipeline.geometry.level_files import GltfWriter, read_gltf_json
from neuralao.runtime.chromium import SWIFTSHADER_WEBGL, headless_chromium, wait_for_page

ARRAY, ELEMENTS = 34962, 34963
R, H = 2.0, 1.0  # max distance and world gap between the planes: binary AO (H / R)^2 = 0.25
QUANT = 0.5 / 255  # 8-bit rounding of a texture map
RED, BLUE = [0.8, 0.1, 0.1, 1.0], [0.1, 0.2, 0.9, 1.0]


def grid(half: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Square [-half, half]^2 at z = 0 facing +z as n x n quads: vertices ((n+1)^2, 3) float64,
    faces (2 n^2, 3) int64, glTF UVs ((n+1)^2, 2) float64 (v down) inside [0.05, 0.95]."""
    t = np.linspace(-half, half, n + 1)
    xx, yy = np.meshgrid(t, t, indexing="ij")
    v = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    uv = 0.05 + 0.9 * np.c_[(xx.ravel() + half) / (2 * half), 1 - (yy.ravel() + half) / (2 * half)]
    return v, faces, uv


def cube(half: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed box [-half, half]^3 with split corners (24 vertices, 12 faces, outward) and one UV
    island per side in a 3 x 2 grid of cells: vertices, faces, glTF UVs."""
    box = trimesh.creation.box(extents=[2 * half] * 3)
    verts, faces, uvs = [], [], []
    sides = np.unique(np.round(box.face_normals).astype(int), axis=0)
    for side, normal in enumerate(sides):
        f = box.faces[(np.round(box.face_normals).astype(int) == normal).all(axis=1)]
        corners = np.unique(f)
        remap = {c: i + 4 * side for i, c in enumerate(corners)}
        p = box.vertices[corners]
        axes = [k for k in range(3) if abs(normal[k]) < 0.5]
        local = (p[:, axes] + half) / (2 * half)  # [0, 1]^2 on the side
        cell = np.array([side % 3, side // 3], float)
        verts.append(p)
        uvs.append((cell + 0.1 + 0.8 * local) / np.array([3.0, 2.0]))
        faces.append(np.vectorize(remap.get)(f))
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(uvs)


def write_gltf(path, meshes: list[dict], nodes: list[dict], roots: list[int], materials=(), images=()):
    """A glTF from parts. meshes: [{"name", "primitives": [{"v", "f", "uv"?, "colour"?, "material"?}]}];
    nodes: glTF node dicts as they are; images: PNG bytes, one texture each (embedded in .glb, files beside a
    .gltf). Returns the path."""
    w = GltfWriter("neuralao tests")
    for m in meshes:
        prims = []
        for p in m["primitives"]:
            attrs = {"POSITION": w.accessor(np.asarray(p["v"], np.float32), target=ARRAY)}
            if "uv" in p:
                attrs["TEXCOORD_0"] = w.accessor(np.asarray(p["uv"], np.float32), target=ARRAY)
            if "colour" in p:
                attrs["COLOR_0"] = w.accessor(np.asarray(p["colour"], np.float32), target=ARRAY)
            prim = {
                "attributes": attrs,
                "mode": 4,
                "indices": w.accessor(np.asarray(p["f"], np.uint32).reshape(-1), target=ELEMENTS),
            }
            if "material" in p:
                prim["material"] = p["material"]
            prims.append(prim)
        w.doc["meshes"].append({"name": m["name"], "primitives": prims})
    w.doc["nodes"] = nodes
    w.doc["scenes"] = [{"name": "test scene", "nodes": roots}]
    if materials:
        w.doc["materials"] = list(materials)
    for k, png in enumerate(images):
        if path.suffix == ".gltf":
            (path.parent / f"image{k}.png").write_bytes(png)
            image = {"uri": f"image{k}.png"}
        else:
            image = {"bufferView": w.buffer_view(png), "mimeType": "image/png"}
        w.doc.setdefault("images", []).append(image)
        w.doc.setdefault("textures", []).append({"source": k})
    return w.write(path)


def png(rgb: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(np.asarray(rgb, np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def glb_parts(path) -> tuple[dict, bytes]:
    """The JSON and binary chunks of a .glb, parsed here (not through a glTF library)."""
    data = path.read_bytes()
    magic, version, total = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and total == len(data)
    jlen, _ = struct.unpack_from("<II", data, 12)
    blen, _ = struct.unpack_from("<II", data, 20 + jlen)
    return json.loads(data[20 : 20 + jlen]), data[28 + jlen : 28 + jlen + blen]


def image_of(doc: dict, binary: bytes, texture: int) -> np.ndarray:
    view = doc["bufferViews"][doc["images"][doc["textures"][texture]["source"]]["bufferView"]]
    start = view.get("byteOffset", 0)
    return np.asarray(Image.open(io.BytesIO(binary[start : start + view["byteLength"]])).convert("RGB"))


# --------------------------------------------------------------------------- closed form


def planes_gltf(path, ceiling: str = "rotated", colour: np.ndarray | None = None):
    """Floor and ceiling (one grid mesh each, authored at z = 0 facing +z) under a root node that
    scales by 0.5 and translates: world floor at z = 1, ceiling H above it facing down, half-size 4.
    ``ceiling``: "rotated" (180 degrees about x) or "mirrored" (scale z by -1: glTF flips the winding);
    ``colour``: an RGBA COLOR_0 for every floor vertex."""
    v, f, uv = grid(8.0, 8)
    turn = {"rotation": [1.0, 0.0, 0.0, 0.0]} if ceiling == "rotated" else {"scale": [1.0, 1.0, -1.0]}
    nodes = [
        {"name": "rig", "children": [1, 2], "scale": [0.5, 0.5, 0.5], "translation": [3.0, -2.0, 1.0]},
        {"name": "floor", "mesh": 0},
        {"name": "ceiling", "mesh": 1, "translation": [0.0, 0.0, 2 * H], **turn},
    ]
    floor = {"v": v, "f": f, "uv": uv} | ({} if colour is None else {"colour": np.tile(colour, (len(v), 1))})
    meshes = [
        {"name": "floor", "primitives": [floor]},
        {"name": "ceiling", "primitives": [{"v": v, "f": f, "uv": uv}]},
    ]
    return write_gltf(path, meshes, nodes, [0])


def interior(v_local: np.ndarray) -> np.ndarray:
    """(n,) bool: grid vertices (local units, world = local / 2) whose sqrt(R^2 - H^2) disk stays on
    the other plane (world half-size 4)."""
    reach = np.sqrt(R * R - H * H) + 1e-9
    return (np.abs(v_local[:, :2]) / 2 <= 4.0 - reach).all(axis=1)


@pytest.mark.parametrize("ceiling", ["rotated", "mirrored"])
def test_vertex_bake_matches_the_parallel_planes_closed_form(tmp_path, ceiling):
    src = planes_gltf(tmp_path / "planes.glb", ceiling)
    out = tmp_path / "baked.glb"
    rays = 512
    args = ["bake", str(src), "--method", "vertex", "--rays", str(rays), "--max-distance", str(R)]
    assert cli.main([*args, "--out", str(out)]) == 0
    doc, get = read_gltf_json(out)
    expected = (H / R) ** 2
    v_local = grid(8.0, 8)[0]
    inside = interior(v_local)
    measured = {}
    for node in doc["nodes"][1:]:
        prim = doc["meshes"][node["mesh"]]["primitives"][0]
        ao = get(prim["attributes"]["_AO"])
        colour = get(prim["attributes"]["COLOR_0"])  # normalised uint8 -> float
        np.testing.assert_allclose(colour[:, 0], np.rint(ao * 255) / 255, atol=1e-6)
        assert np.all(np.abs(ao[inside] - expected) <= mc_bound(expected, rays)), (node["name"], ao[inside])
        assert ao[~inside].max() > expected + 0.1  # the edges are more open: the value is not a constant
        measured[node["name"]] = float(ao[inside].mean())
    print(f"\nparallel planes ({ceiling}), vertex: mean interior AO {measured}, closed form {expected}")
    # the transforms are kept: the output's nodes are the input's
    assert [n["name"] for n in doc["nodes"]] == ["rig", "floor", "ceiling"]
    assert doc["nodes"][0]["scale"] == [0.5, 0.5, 0.5] and doc["nodes"][0]["children"] == [1, 2]


def texel_points(get, prim: dict, texcoord: int, n: int) -> np.ndarray:
    """(n, n, 3) object-space points of the texel centres of an n x n map on UV set ``texcoord`` of a
    baked primitive (NaN where no UV triangle holds the centre), read back from the file."""
    from neuralao.pipeline.bakes.texture import rasterise

    st = get(prim["attributes"][f"TEXCOORD_{texcoord}"])
    faces = get(prim["indices"]).astype(np.int64).reshape(-1, 3)
    positions = get(prim["attributes"]["POSITION"]).astype(np.float64)
    texels = rasterise(np.c_[st[:, 0], 1.0 - st[:, 1]], faces, n)  # glTF v down -> trimesh v up
    out = np.full((n * n, 3), np.nan)
    out[texels.pixel] = np.einsum("kc,kcd->kd", texels.bary, positions[faces[texels.face]])
    return out.reshape(n, n, 3)


@pytest.mark.parametrize("uv", ["mesh", "xatlas"])
def test_texture_bake_matches_the_parallel_planes_closed_form(tmp_path, uv):
    """On the planes' own UVs, and on an xatlas lightmap set added beside them (TEXCOORD_1)."""
    src = planes_gltf(tmp_path / "planes.glb")
    out = tmp_path / "baked.glb"
    rays, n = 256, 64
    args = [
        "bake",
        str(src),
        "--to",
        "texture",
        "--resolution",
        str(n),
        "--rays",
        str(rays),
        "--max-distance",
        str(R),
        "--uv",
        uv,
        "--out",
        str(out),
    ]
    assert cli.main(args) == 0
    doc, binary = glb_parts(out)
    _, get = read_gltf_json(out)
    expected = (H / R) ** 2
    measured = {}
    for node in doc["nodes"][1:]:
        prim = doc["meshes"][node["mesh"]]["primitives"][0]
        material = doc["materials"][prim["material"]]
        texcoord = material["occlusionTexture"].get("texCoord", 0)
        assert texcoord == (0 if uv == "mesh" else 1)  # a lightmap set goes beside the mesh's own
        assert "TEXCOORD_0" in prim["attributes"]
        points = texel_points(get, prim, texcoord, n)
        inside = interior(np.nan_to_num(points, nan=1e9).reshape(-1, 3)).reshape(n, n)
        assert inside.sum() > 200
        red = image_of(doc, binary, material["occlusionTexture"]["index"])[:, :, 0] / 255.0
        assert red.shape == (n, n)
        assert np.all(np.abs(red[inside] - expected) <= mc_bound(expected, rays) + QUANT), node["name"]
        # the mean of all interior texels: Monte-Carlo noise averages out, a bias would not
        assert abs(red[inside].mean() - expected) <= mc_bound(expected, rays * inside.sum()) + QUANT
        measured[node["name"]] = round(float(red[inside].mean()), 4)
    print(
        f"\nparallel planes, texture {n}x{n} on {uv} UVs: mean interior AO {measured}, closed form {expected}"
    )


def test_each_plane_alone_is_open(tmp_path):
    """The control: without the other node the closed form would be 1 (what a per-object bake gives)."""
    v, f, uv = grid(8.0, 8)
    src = write_gltf(
        tmp_path / "floor.glb",
        [{"name": "floor", "primitives": [{"v": v, "f": f}]}],
        [{"name": "floor", "mesh": 0, "scale": [0.5, 0.5, 0.5]}],
        [0],
    )
    out = tmp_path / "baked.glb"
    assert (
        cli.main(
            [
                "bake",
                str(src),
                "--method",
                "vertex",
                "--rays",
                "64",
                "--max-distance",
                str(R),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    doc, get = read_gltf_json(out)
    assert np.all(get(doc["meshes"][0]["primitives"][0]["attributes"]["_AO"]) == 1.0)


def test_obscurance_matches_its_closed_form_through_the_transforms(tmp_path):
    """Obscurance weighs each hit by its distance d = H / cos(theta), so the world gap (0.5 x the
    authored one) enters the value, not only the hit / miss boundary. With t = cos^2(theta) uniform:
    ao = c^2 + integral_{c^2}^1 (1 - 0.5^(H / (half sqrt(t)))) dt, c = H / R."""
    from scipy.integrate import quad

    half = 0.5
    src = planes_gltf(tmp_path / "planes.glb")
    out = tmp_path / "baked.glb"
    rays = 512
    args = [
        "bake",
        str(src),
        "--method",
        "vertex",
        "--rays",
        str(rays),
        "--max-distance",
        str(R),
        "--kernel",
        "obscurance",
        "--half-distance",
        str(half),
        "--out",
        str(out),
    ]
    assert cli.main(args) == 0
    c2 = (H / R) ** 2
    expected = c2 + quad(lambda t: 1.0 - 0.5 ** (H / (half * np.sqrt(t))), c2, 1.0)[0]
    doc, get = read_gltf_json(out)
    inside = interior(grid(8.0, 8)[0])
    for node in doc["nodes"][1:]:
        ao = get(doc["meshes"][node["mesh"]]["primitives"][0]["attributes"]["_AO"])[inside]
        assert np.all(np.abs(ao - expected) <= mc_bound(expected, rays)), (node["name"], ao, expected)
        print(
            f"\nobscurance {node['name']}: mean {ao.mean():.4f} max |err| {np.abs(ao - expected).max():.4f}, "
            f"closed form {expected:.4f}"
        )


def test_authored_vertex_colours_are_kept_and_darkened(tmp_path):
    """glTF multiplies the base colour by COLOR_0, so a primitive's own vertex colour times AO is what
    renders the bake; _AO keeps the AO alone."""
    colour = np.array([1.0, 0.5, 0.25, 0.75])
    src = planes_gltf(tmp_path / "planes.glb", colour=colour)
    out = tmp_path / "baked.glb"
    assert (
        cli.main(
            [
                "bake",
                str(src),
                "--method",
                "vertex",
                "--rays",
                "64",
                "--max-distance",
                str(R),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    doc, get = read_gltf_json(out)
    attrs = doc["meshes"][doc["nodes"][1]["mesh"]]["primitives"][0]["attributes"]
    ao, got = get(attrs["_AO"]), get(attrs["COLOR_0"])
    assert ao.min() < 0.3
    np.testing.assert_allclose(got[:, :3], colour[:3] * ao[:, None], atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(got[:, 3], colour[3], atol=0.5 / 255 + 1e-6)


# --------------------------------------------------------------------------- materials, hierarchy, instances


ROOT_TO_Y_UP = [-0.7071067811865476, 0.0, 0.0, 0.7071067811865476]  # -90 degrees about x: +z -> +y


def checker(n: int = 8) -> np.ndarray:
    """(n, n, 3) uint8 white / light-grey checker (a base colour texture the blue factor tints)."""
    ij = np.add.outer(np.arange(n), np.arange(n)) % 2
    return np.where(ij[..., None] == 1, 255, 170).repeat(3, axis=2).astype(np.uint8)


def room_gltf(path):
    """Three nodes with meshes, two materials, a shared mesh, a hierarchy (Y up):
    room -> floor (red_paint, a grid rotated from z-up), crate_a (blue_checker: blue factor x checker
    texture + a flat normal map) -> crate_b (crate_a's mesh, floating 0.25 above it, off-centre)."""
    fv, ff, fuv = grid(2.0, 8)
    cv, cf, cuv = cube(0.5)
    materials = [
        {
            "name": "red_paint",
            "pbrMetallicRoughness": {"baseColorFactor": RED, "metallicFactor": 0.0, "roughnessFactor": 0.7},
        },
        {
            "name": "blue_checker",
            "pbrMetallicRoughness": {
                "baseColorFactor": BLUE,
                "baseColorTexture": {"index": 0},
                "metallicFactor": 0.0,
                "roughnessFactor": 0.5,
            },
            "normalTexture": {"index": 1, "scale": 0.8},
        },
    ]
    nodes = [
        {"name": "room", "children": [1, 2]},
        {"name": "floor", "mesh": 0, "rotation": ROOT_TO_Y_UP},
        {"name": "crate_a", "mesh": 1, "translation": [0.0, 0.5, 0.0], "children": [3]},
        {"name": "crate_b", "mesh": 1, "translation": [0.3, 1.25, 0.1]},
    ]
    meshes = [
        {"name": "floor_mesh", "primitives": [{"v": fv, "f": ff, "uv": fuv, "material": 0}]},
        {"name": "crate_mesh", "primitives": [{"v": cv, "f": cf, "uv": cuv, "material": 1}]},
    ]
    flat_normal = np.full((4, 4, 3), (128, 128, 255), np.uint8)
    return write_gltf(path, meshes, nodes, [0], materials, [png(checker()), png(flat_normal)])


def bake_room(tmp_path, to: str, suffix: str = ".glb", rays: int = 32, resolution: int = 32, more=()):
    src = room_gltf(tmp_path / f"room{suffix}")
    out = tmp_path / f"room_{to}.glb"
    extra = ["--method", "vertex"] if to == "vertex" else ["--to", "texture", "--resolution", str(resolution)]
    assert cli.main(["bake", str(src), "--rays", str(rays), *extra, *more, "--out", str(out)]) == 0
    return src, out


@pytest.mark.parametrize("to, suffix", [("vertex", ".glb"), ("texture", ".glb"), ("texture", ".gltf")])
def test_materials_names_and_hierarchy_survive(tmp_path, to, suffix):
    _, out = bake_room(tmp_path, to, suffix)
    doc, binary = glb_parts(out)
    assert [n["name"] for n in doc["nodes"]] == ["room", "floor", "crate_a", "crate_b"]
    assert doc["nodes"][0]["children"] == [1, 2] and doc["nodes"][2]["children"] == [3]
    assert doc["nodes"][1]["rotation"] == ROOT_TO_Y_UP and doc["nodes"][3]["translation"] == [0.3, 1.25, 0.1]
    assert doc["scenes"][doc.get("scene", 0)]["name"] == "test scene"
    assert doc["asset"]["extras"]["neuralao"]["to"] == to
    by_node = {n["name"]: doc["meshes"][n["mesh"]]["primitives"][0] for n in doc["nodes"][1:]}
    for name, prim in by_node.items():
        material = doc["materials"][prim["material"]]
        pbr = material["pbrMetallicRoughness"]
        assert pbr["baseColorFactor"] == (RED if name == "floor" else BLUE)
        assert material["name"] == ("red_paint" if name == "floor" else "blue_checker")
        if name != "floor":
            assert pbr["roughnessFactor"] == 0.5 and material["normalTexture"]["scale"] == 0.8
            np.testing.assert_array_equal(image_of(doc, binary, pbr["baseColorTexture"]["index"]), checker())
            assert image_of(doc, binary, material["normalTexture"]["index"])[0, 0].tolist() == [128, 128, 255]
        if to == "vertex":
            assert {"COLOR_0", "_AO"} <= set(prim["attributes"]) and "occlusionTexture" not in material
        else:
            ao = image_of(doc, binary, material["occlusionTexture"]["index"])[:, :, 0]
            assert ao.shape == (32, 32) and ao.min() < 200  # contact shadows
            assert "COLOR_0" not in prim["attributes"]
    # trimesh reads the same scene: names, placement and materials
    scene = trimesh.load(str(out))
    assert {"floor", "crate_a", "crate_b"} <= set(scene.graph.nodes_geometry)
    np.testing.assert_allclose(scene.graph["crate_b"][0][:3, 3], [0.3, 1.75, 0.1], atol=1e-6)
    for name in ("floor", "crate_a", "crate_b"):
        geometry = scene.geometry[scene.graph[name][1]]
        material = geometry.visual.material
        colour = RED if name == "floor" else BLUE
        np.testing.assert_allclose(np.asarray(material.baseColorFactor) / 255.0, colour, atol=1 / 255)
        if name != "floor":
            assert material.baseColorTexture is not None and material.normalTexture is not None
        if to == "texture":
            assert material.occlusionTexture is not None


def test_a_shared_mesh_gets_its_own_ao_per_instance(tmp_path):
    src, out = bake_room(tmp_path, "vertex", rays=64, more=["--max-distance", "1.0"])
    doc, get = read_gltf_json(out)
    source, _ = read_gltf_json(src)
    assert source["nodes"][2]["mesh"] == source["nodes"][3]["mesh"] == 1
    a, b = doc["nodes"][2]["mesh"], doc["nodes"][3]["mesh"]
    assert a != b and len(doc["meshes"]) == 3  # the crate mesh copied once; the floor's stays single
    assert doc["nodes"][1]["mesh"] == 0 and doc["meshes"][b]["name"] == "crate_mesh"
    pa, pb = doc["meshes"][a]["primitives"][0], doc["meshes"][b]["primitives"][0]
    assert pa["attributes"]["POSITION"] == pb["attributes"]["POSITION"]  # geometry still shared
    ao_a, ao_b = get(pa["attributes"]["_AO"]), get(pb["attributes"]["_AO"])
    # crate_b floats 0.25 above crate_a: crate_a's top face is under it, crate_b's top is open
    faces = get(pa["indices"]).reshape(-1, 3)
    top = np.unique(faces[(get(pa["attributes"]["POSITION"])[faces][..., 1] > 0.49).all(axis=1)])
    print(f"\ncrate_a top-face AO {ao_a[top].round(2)}, crate_b top-face AO {ao_b[top].round(2)}")
    assert ao_a[top].mean() < ao_b[top].mean() - 0.3 and ao_b[top].min() > 0.95


def test_scene_bake_reads_the_same_world_as_the_flattened_loader(tmp_path):
    """The world scene built from the document matches trimesh's own flattening (transforms, hierarchy)."""
    from neuralao.pipeline.geometry.scene import load_scene

    src = room_gltf(tmp_path / "room.glb")
    world = read_gltf_scene(src).world
    flat = load_scene(src)
    np.testing.assert_allclose(np.sort(world.vertices, axis=0), np.sort(flat.vertices, axis=0), atol=1e-6)
    assert len(world.faces) == len(flat.faces)


@pytest.mark.parametrize("to", ["vertex", "texture"])
def test_a_zero_scale_keeps_the_node_and_drops_the_faces_it_collapses(tmp_path, caplog, to):
    """glTF hides a node by scaling it to zero: the scene bake keeps it, as the flattened reader does, and
    drops the faces a zero scale collapses as degenerate (a box flattened along y keeps its top and
    bottom)."""
    v, f, uv = cube(0.5)
    nodes = [
        {"name": "hidden", "mesh": 0, "scale": [0.0, 0.0, 0.0]},
        {"name": "flat", "mesh": 0, "scale": [1.0, 0.0, 1.0], "translation": [3.0, 0.0, 0.0]},
        {"name": "shown", "mesh": 0, "translation": [0.0, 0.0, 3.0]},
    ]
    src = write_gltf(
        tmp_path / "hide.gltf",
        [{"name": "box", "primitives": [{"v": v, "f": f, "uv": uv}]}],
        nodes,
        [0, 1, 2],
    )
    with caplog.at_level("WARNING"):
        world = read_gltf_scene(src).world
    assert "node 0 'hidden': a zero scale collapses it" in caplog.text and "node 1 'flat'" in caplog.text
    assert len(world.faces) == 12 + 4 and np.isfinite(world.face_normals).all()
    out = tmp_path / "baked.glb"
    extra = ["--method", "vertex"] if to == "vertex" else ["--to", "texture", "--resolution", "16"]
    assert cli.main(["bake", str(src), "--rays", "8", *extra, "--out", str(out)]) == 0
    doc, get = read_gltf_json(out)
    assert [n["name"] for n in doc["nodes"]] == ["hidden", "flat", "shown"]
    assert doc["nodes"][0]["scale"] == [0.0, 0.0, 0.0]
    _, binary = glb_parts(out)
    for mesh in doc["meshes"]:
        prim = mesh["primitives"][0]
        if to == "vertex":
            ao = get(prim["attributes"]["_AO"])
            assert np.isfinite(ao).all() and 0 <= ao.min() and ao.max() <= 1
        else:  # a map of texels no face covers in the world is open (1), never NaN's 0
            texture = doc["materials"][prim["material"]]["occlusionTexture"]["index"]
            assert image_of(doc, binary, texture).max() == 255


# --------------------------------------------------------------------------- in the viewer


def srgb_to_linear(c: float) -> float:
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


@needs_chromium
def test_viewer_shows_both_bakes_with_their_materials(tmp_path):
    """The three-node, two-material room baked both ways, drawn by `neuralao view` in headless Chromium:
    the read-back base colour has the red floor and the blue checker crates, the AO has the contact
    shadows, and a screenshot of each bake goes to gltf-scene-bake.png (NEURALAO_ARTIFACTS or tmp)."""
    from PIL import ImageDraw
    from selenium.webdriver.common.by import By

    bakes = [bake_room(tmp_path, to, rays=64, resolution=64)[1] for to in ("vertex", "texture")]
    page = tmp_path / "page"
    assert cli.main(["view", *map(str, bakes), "--out", str(page), "--size", "320", "240"]) == 0
    shots = []
    with headless_chromium(*SWIFTSHADER_WEBGL, "--window-size=700,600") as driver:
        driver.get((page / "index.html").as_uri())
        state = wait_for_page(driver)
        assert state and state[0] and not state[1], state
        methods = driver.execute_script("return window.neuralao.methods")
        assert [m["kind"] for m in methods] == ["scene", "scene"]
        blue = np.asarray(BLUE[:3])
        for i, m in enumerate(methods):
            driver.execute_script(f"window.neuralao.setMethod({i}); window.neuralao.setPose(35, 15, 1.0);")
            c = driver.execute_script("return window.neuralao.capture()")
            h, w = c["height"], c["width"]
            img = {
                k: np.frombuffer(__import__("base64").b64decode(c[k]), np.float32).reshape(h, w, 4)[::-1]
                for k in ("position", "ao", "albedo")
            }
            mask = img["position"][..., 3] > 0.5
            albedo = img["albedo"][..., :3][mask]
            red = np.abs(albedo - np.asarray(RED[:3])).max(axis=1) < 1e-3
            light = np.abs(albedo - blue).max(axis=1) < 1e-2  # checker 255: the factor alone
            dark = np.abs(albedo - blue * srgb_to_linear(170 / 255)).max(axis=1) < 1e-2  # checker 170, linear
            assert red.mean() > 0.2 and light.sum() > 200 and dark.sum() > 200, (
                m["name"],
                red.mean(),
                light.sum(),
                dark.sum(),
            )
            ao = img["ao"][..., 0][mask]
            assert ao.max() > 0.95 and ao.min() < 0.85  # open floor and contact shadows
            path = tmp_path / f"scene-{i}.png"
            path.write_bytes(driver.find_element(By.ID, "view").screenshot_as_png)
            shot = Image.open(path).convert("RGB")
            assert shot.size == (320, 240)
            ImageDraw.Draw(shot).text((6, 4), m["name"].split(",")[0], fill=(230, 230, 230))
            shots.append(shot)
    out = Path(os.environ.get("NEURALAO_ARTIFACTS", tmp_path))
    out.mkdir(parents=True, exist_ok=True)
    sheet = Image.new("RGB", (640, 240))
    for k, shot in enumerate(shots):
        sheet.paste(shot, (320 * k, 0))
    sheet.save(out / "gltf-scene-bake.png")


def test_images_outside_the_gltf_folder_are_not_embedded(tmp_path):
    """An image uri that leaves the file's folder is kept as it is, never read into the output."""
    (tmp_path / "secret.png").write_bytes(png(np.zeros((2, 2, 3))))
    folder = tmp_path / "scene"
    folder.mkdir()
    src = room_gltf(folder / "room.gltf")
    doc = json.loads(src.read_text())
    doc["images"][1]["uri"] = "../secret.png"
    src.write_text(json.dumps(doc))
    out = tmp_path / "baked.glb"
    assert cli.main(["bake", str(src), "--method", "vertex", "--rays", "8", "--out", str(out)]) == 0
    baked, _ = glb_parts(out)
    assert baked["images"][1] == {"uri": "../secret.png"} and "bufferView" in baked["images"][0]


def test_compressed_geometry_is_a_one_line_error(tmp_path, capsys):
    src = planes_gltf(tmp_path / "planes.glb")
    doc, binary = glb_parts(src)
    doc["extensionsRequired"] = doc["extensionsUsed"] = ["KHR_draco_mesh_compression"]
    w = GltfWriter.from_document(doc, binary)
    w.write(tmp_path / "draco.glb")
    out = tmp_path / "baked.glb"
    assert cli.main(["bake", str(tmp_path / "draco.glb"), "--rays", "8", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "KHR_draco_mesh_compression" in err and "\n" not in err and not out.exists()
