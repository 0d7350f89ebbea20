"""The G-buffer's back layer: the GL pass against rays cast through the pixel centres by a second engine
(trimesh's ray-triangle test), the input contract's thickness channel against its closed form, and the
layer added to a built dataset without touching its shards, labels or hash."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from neuralao.pipeline.geometry.camera import Camera, look_at
from neuralao.pipeline.geometry.scene import scene_from_arrays
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.unet_input import THICKNESS_CAP, preprocess, thickness_channel


def _scene(meshes: list[trimesh.Trimesh]):
    m = trimesh.util.concatenate(meshes)
    return scene_from_arrays(m.vertices, m.faces, "layers", drop_degenerate=False)


def _ray_hits(o: np.ndarray, d: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(rays, faces) distance along each ray to each triangle (Moller-Trumbore, float64), inf for a miss."""
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = np.cross(d[:, None], e2[None])
    det = np.einsum("rfc,fc->rf", p, e1)
    inv = 1.0 / np.where(np.abs(det) > 1e-15, det, np.nan)
    s = o[:, None] - tris[None, :, 0]
    u = np.einsum("rfc,rfc->rf", s, p) * inv
    q = np.cross(s, e1[None])
    v = np.einsum("rc,rfc->rf", d, q) * inv
    t = np.einsum("rfc,fc->rf", q, e2) * inv
    hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return np.where(hit, t, np.inf)


def _next_layer(scene, camera: Camera, front_tri: np.ndarray) -> np.ndarray:
    """The back layer by ray casting (every triangle against every pixel-centre ray, in float64): the first
    hit behind the visible triangle, not that triangle; its depth where it faces the ray the other way
    from the visible one, else 0. NaN where the ray misses the visible triangle (an edge: not compared)."""
    tris = np.asarray(scene.vertices, np.float64)[np.asarray(scene.faces)]
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    origins, dirs = camera.pixel_rays()
    h, w = front_tri.shape
    forward = -np.asarray(camera.pose, np.float64)[:3, 2]
    out = np.zeros(h * w)
    pix = np.flatnonzero(front_tri.reshape(-1) >= 0)
    o, d = origins.reshape(-1, 3)[pix], dirs.reshape(-1, 3)[pix]
    t = _ray_hits(o, d, tris) * (d @ forward)[:, None]  # view depth of each hit
    front = front_tri.reshape(-1)[pix]
    z_front = t[np.arange(len(pix)), front]
    behind = np.isfinite(t) & (t > z_front[:, None] * (1 + 1e-5))
    behind[np.arange(len(pix)), front] = False
    nxt = np.argmin(np.where(behind, t, np.inf), axis=1)
    found = behind[np.arange(len(pix)), nxt]
    away = np.sign(np.einsum("rc,rc->r", normals[nxt], d)) != np.sign(
        np.einsum("rc,rc->r", normals[front], d)
    )
    out[pix] = np.where(found & away, t[np.arange(len(pix)), nxt], 0.0)
    out[pix[~np.isfinite(z_front)]] = np.nan
    return out.reshape(h, w)


def _camera(eye, size=48) -> Camera:
    return Camera(look_at(np.asarray(eye, float), np.zeros(3)), size, size, np.radians(45.0), 0.05, 50.0)


CASES = {
    # a closed box: the ray leaves it through its far faces
    "box": lambda: [trimesh.creation.box(extents=(1.0, 0.6, 0.8))],
    # the same box wound inwards: the visible faces are back faces, the exit faces front faces
    "inward": lambda: [_inverted(trimesh.creation.box(extents=(1.0, 0.6, 0.8)))],
    # a single-sided quad in front of a sphere: thin where the quad is seen, the sphere's far side behind it
    "sheet": lambda: [_quad(0.25, z=0.8), trimesh.creation.icosphere(2, radius=0.5)],
    # two overlapping spheres: a ray entering one may leave through the other's surface
    "spheres": lambda: [
        trimesh.creation.icosphere(2, radius=0.5),
        trimesh.creation.icosphere(2, radius=0.4).apply_translation((0.45, 0.1, 0.0)),
    ],
}


def _inverted(m: trimesh.Trimesh) -> trimesh.Trimesh:
    return trimesh.Trimesh(m.vertices, m.faces[:, ::-1], process=False)


def _quad(half: float, z: float) -> trimesh.Trimesh:
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


@pytest.mark.parametrize("case", sorted(CASES))
def test_back_layer_matches_rays_through_the_pixel_centres(case):
    from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer

    scene = _scene(CASES[case]())
    with GBufferRenderer(scene, back_layer=True) as r:
        for eye in ([0.3, 0.4, 3.0], [2.2, 1.1, 1.6]):
            cam = _camera(eye)
            f = r.render(cam)
            ref = _next_layer(scene, cam, f["tri_id"])
            ok = np.isfinite(ref) & f["mask"]
            assert ok.sum() > 0.9 * f["mask"].sum() > 0
            got = f["depth_back"][ok]
            # the same surface (an exit found by both or by neither), at the G-buffer's depth tolerance
            assert np.array_equal(got > 0, ref[ok] > 0), case
            assert np.allclose(got, ref[ok], rtol=TOL.gbuffer_depth_rel, atol=0), case
            assert (f["depth_back"][~f["mask"]] == 0).all()
            if case in ("box", "inward"):
                assert (got > 0).all()  # a closed solid: every ray leaves it
            if case == "sheet":
                assert (got == 0).any() and (got > 0).any()


def test_the_first_pass_is_unchanged_by_the_back_layer():
    from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer

    scene = _scene(CASES["spheres"]())
    cam = _camera([1.0, 0.5, 2.5])
    one, two = render_gbuffer(scene, cam), render_gbuffer(scene, cam, back_layer=True)
    assert set(two) - set(one) == {"depth_back"}
    for k in one:
        assert np.array_equal(np.asarray(one[k]), np.asarray(two[k])), k


def test_thickness_channel_closed_form():
    depth = np.array([[2.0, 2.0, 2.0, 0.0, 3.0]], np.float32)
    back = np.array([[3.0, 0.0, 1.0, 0.0, 3.0 * np.exp(9.0)]], np.float32)
    mask = depth > 0
    t = thickness_channel(depth, back, mask)
    assert np.allclose(t, [[np.log(1.5), 0.0, 0.0, 0.0, THICKNESS_CAP]], atol=1e-6)
    normal = np.zeros((1, 5, 3), np.float32)
    normal[..., 2] = 1.0
    x = preprocess(depth, normal, mask, version=4, depth_back=back)
    assert x.shape == (5, 1, 5) and np.array_equal(x[4], t)
    assert preprocess(depth, normal, mask, version=3).shape == (4, 1, 5)
    with pytest.raises(NeuralaoError, match="back layer"):
        preprocess(depth, normal, mask, version=4)
    # scale-free: the whole scene scaled leaves the channel as it was
    assert np.allclose(thickness_channel(depth * 1e4, back * 1e4, mask), t, atol=1e-6)


TINY = {
    "name": "tiny-layers",
    "seed": 3,
    "size": [24, 16],
    "frames_per_shard": 2,
    "labels": {"rays": 8, "radii_rel": [0.1, 0.25]},
    "scenes": [
        {"name": "suzanne", "mesh": "suzanne", "cameras": "orbit", "views": 3, "split": "train"},
        {"name": "box", "mesh": "cornell_box", "cameras": "interior", "views": 2, "split": "val"},
    ],
}


def build_and_read(settings, out):
    from neuralao.pipeline.datasets.dataset import build_dataset, open_dataset

    build_dataset(settings, out, progress=False)
    return list(open_dataset(out).frames())


def test_back_layer_added_to_a_built_dataset_renders_only_the_layer(tmp_path):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, build_dataset, open_dataset
    from neuralao.runtime.foundation.settings import from_dict

    plain = from_dict(DatasetSettings, TINY)
    layered = replace(plain, back_layer=True)
    fresh = build_dataset(layered, tmp_path / "fresh", progress=False)
    built = build_dataset(plain, tmp_path / "added", progress=False)
    shard_bytes = {e["file"]: (tmp_path / "added" / e["file"]).read_bytes() for e in built["shards"]}
    added = build_dataset(layered, tmp_path / "added", progress=False)
    # the shards, their labels and the dataset hash as they were; the layers as a fresh build makes them
    assert added["dataset_hash"] == built["dataset_hash"] == fresh["dataset_hash"]
    assert added["config"] == built["config"]
    for e in added["shards"]:
        assert (tmp_path / "added" / e["file"]).read_bytes() == shard_bytes[e["file"]]
    assert added["back_layer"] == fresh["back_layer"]
    assert [e["layer_sha256"] for e in added["shards"]] == [e["layer_sha256"] for e in fresh["shards"]]
    frames = list(open_dataset(tmp_path / "added").frames())
    assert all("depth_back" in f for f in frames) and len(frames) == 5
    assert any((f["depth_back"] > f["depth"]).any() for f in frames)
    # rerun: nothing to do, the same manifest
    again = build_dataset(layered, tmp_path / "added", progress=False)
    assert again == added
    # a layer file that went missing is rendered again, the same bytes
    (tmp_path / "added" / added["shards"][0]["layer_file"]).unlink()
    assert build_dataset(layered, tmp_path / "added", progress=False) == added
    # a dataset without the layer gives frames without it
    assert all("depth_back" not in f for f in build_and_read(plain, tmp_path / "plain"))
    manifest = json.loads((tmp_path / "fresh" / "manifest.json").read_text())
    assert manifest["back_layer"]["keys"] == ["depth_back"]


@pytest.fixture(scope="module")
def layered(tmp_path_factory):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, build_dataset
    from neuralao.runtime.foundation.settings import from_dict

    out = tmp_path_factory.mktemp("layered") / "data"
    build_dataset(replace(from_dict(DatasetSettings, TINY), back_layer=True), out, progress=False)
    return out


def test_training_frames_of_version_4_carry_the_thickness(layered, tmp_path):
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.models.unet_frames import load_dataset_frames

    train, val, info = load_dataset_frames(layered, version=4, gtao=True)
    frames = {f"{f['scene']}/{f['view']}": f for f in open_dataset(layered).frames()}
    for k, name in enumerate(train.names):
        f = frames[name]
        x = train.x[k].numpy() if hasattr(train.x[k], "numpy") else np.asarray(train.x[k])
        assert x.shape[0] == 5
        np.testing.assert_array_equal(x[4], thickness_channel(f["depth"], f["depth_back"], f["mask"]))
    assert info["preprocess_version"] == 4
    # the same dataset without its layer is refused by name for version 4, kept for version 3
    manifest = json.loads((layered / "manifest.json").read_text())
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "shards").symlink_to(layered / "shards")
    (plain / "manifest.json").write_text(json.dumps({k: v for k, v in manifest.items() if k != "back_layer"}))
    with pytest.raises(NeuralaoError, match="no back layer"):
        load_dataset_frames(plain, version=4)
    assert load_dataset_frames(plain, version=3)[0].x[0].shape[0] == 4


def test_a_version_4_hybrid_with_no_correction_is_gtao_through_the_runtime(tmp_path):
    import torch

    from neuralao.export.onnx_io import get_metadata, load_onnx
    from neuralao.export.unet import export_onnx, onnx_metadata
    from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
    from neuralao.pipeline.geometry.camera import orbit
    from neuralao.pipeline.geometry.scene import load_scene
    from neuralao.pipeline.models.unet import UNet, UNetArgs
    from neuralao.runtime.baselines import run_gtao
    from neuralao.runtime.frame import Frame
    from neuralao.runtime.predict import unet_predictor

    model = UNet(UNetArgs(in_channels=6, widths=[4, 8], gtao_input=True, preprocess_version=4)).eval()
    with torch.no_grad():
        model.out.weight.zero_()
        model.out.bias.zero_()
    export_onnx(model, tmp_path / "model.onnx", onnx_metadata(model))
    meta = get_metadata(load_onnx(tmp_path / "model.onnx"))
    assert meta["input_channels"].split(",") == ["depth", "normal_cam_x", "normal_cam_y", "normal_cam_z"] + [
        "thickness",
        "gtao",
    ]
    scene = load_scene("spot")
    f = Frame.from_arrays(render_gbuffer(scene, orbit(scene, 2, 64, 48, seed=2)[0], back_layer=True))
    radius = 0.125 * scene.diagonal
    predict = unet_predictor(tmp_path / "model.onnx", internal_height=None)
    got = predict(f, radius)
    want = run_gtao(f, radius)
    np.testing.assert_array_equal(got[f.mask], want[f.mask])
    with pytest.raises(NeuralaoError, match="back layer"):
        predict(f.replace(depth_back=None), radius)


def test_a_negative_back_layer_is_refused_where_the_frame_is_read():
    from neuralao.runtime.frame import Frame

    depth = np.full((4, 5), 2.0, np.float32)
    normal = np.zeros((4, 5, 3), np.float32)
    normal[..., 2] = 1.0
    back = depth + 1.0
    Frame.from_arrays({"depth": depth, "normal_cam": normal, "depth_back": back})
    back[1, 2] = -3.0  # z_cam instead of -z_cam
    with pytest.raises(NeuralaoError, match="'depth_back' has 1 negative value"):
        Frame.from_arrays({"depth": depth, "normal_cam": normal, "depth_back": back}, "f.npz")


@pytest.mark.parametrize("version", [3, 4])
def test_prepared_frames_are_counted_before_they_are_written(layered, tmp_path, monkeypatch, version):
    """The disk the prepared frames take is known before any is written (within 10% of what is written),
    and a disk without room for them is refused in one line naming the other prepared sets."""
    import shutil

    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.models.unet_frames import load_dataset_frames, prepared_bytes, prepared_folder
    from neuralao.runtime.foundation import limits

    data = tmp_path / "data"
    shutil.copytree(layered, data)
    ds = open_dataset(data)
    entries = [e for e in ds.manifest["shards"] if e["split"] in ("train", "val")]
    want = prepared_bytes(ds, entries, 32, True, version)
    load_dataset_frames(data, internal_height=32, gtao=True, version=version)
    folder = prepared_folder(data, ds, 32, True, version)
    written = sum(p.stat().st_size for p in folder.glob("*.bin"))
    assert 0.9 * written <= want <= 1.1 * written, (want, written)
    (folder.parent / "an-older-set").mkdir()
    monkeypatch.setattr(limits, "free_disk", lambda folder: want // 2)
    with pytest.raises(NeuralaoError, match="the prepared frames .* an-older-set"):
        load_dataset_frames(data, internal_height=24, gtao=True, version=version)
    assert not list(prepared_folder(data, ds, 24, True, version).glob("*.bin"))
