"""The per-mesh AO field: samples, determinism, the single-sided case, export bytes and parity, the CLI.

Real Embree labels, real OSMesa G-buffers, onnxruntime and the generated GLSL on Mesa; small meshes,
few rays and short training so the file runs in seconds.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from helpers import box, floor_quad, merge, onnx_vs_torch_tol

from neuralao.export.field import export_checkpoint, parity, random_inputs
from neuralao.export.onnx_io import load_onnx, run_onnxruntime
from neuralao.pipeline import cli
from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.models.field import (
    FieldNet,
    FieldSettings,
    bounding_box,
    collect_samples,
    count_parameters,
    frequency_matrix,
    load_checkpoint,
    model_from_checkpoint,
    parameter_bytes,
    predict,
    smooth_normals_at,
    train,
    train_model,
)
from neuralao.pipeline.tracing.labeller import LabelSettings
from neuralao.runtime.foundation.tolerances import TOL

FAST = FieldSettings(
    hidden=[16, 8],
    octaves=3,
    samples=4096,
    steps=300,
    check_every=100,
    holdout_views=1,
    holdout_size=(48, 48),
    labels=LabelSettings(rays=32),
)


@pytest.fixture(scope="module")
def spot_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("field")
    ckpt = train(FAST, root / "spot.pt", mesh="spot")
    export_checkpoint(root / "spot.pt", root / "export")
    return root, ckpt


def test_encoding_is_axis_aligned_octaves():
    m = frequency_matrix(3)
    assert m.shape == (3, 9) and np.count_nonzero(m) == 9
    assert m[2, 3 * 2 + 2] == np.float32(np.pi * 4) and m[0, 1] == 0
    net = FieldNet([4], 3, [0, 0, 0], [1, 1, 1])
    q = torch.tensor([[0.25, -0.5, 1.0]])
    feats = net.encode(q, torch.tensor([[0.0, 0.0, 1.0]]))[0].numpy()
    z = np.array([0.25, -0.5, 1.0])[None, :] * (np.pi * 2.0 ** np.arange(3))[:, None]  # (octave, axis)
    np.testing.assert_allclose(feats[6:15], np.sin(z).reshape(-1), atol=1e-6)
    np.testing.assert_allclose(feats[15:], np.cos(z).reshape(-1), atol=1e-6)


def test_bounding_box_maps_to_unit_cube_and_survives_flat_axes():
    v = np.array([[0.0, 2.0, 5.0], [4.0, 6.0, 5.0]])
    c, inv = bounding_box(v)
    np.testing.assert_allclose((v - c) * inv, [[-1, -1, 0], [1, 1, 0]], atol=1e-6)
    assert np.all(np.isfinite(inv))


def test_smooth_normals_match_the_gbuffer():
    """The training inputs use the normals the G-buffer shows: at a pixel's exact surface point the
    interpolated normal of :func:`smooth_normals_at` equals the rendered normal_obj."""
    from neuralao.pipeline.geometry.camera import orbit
    from neuralao.pipeline.tracing.labeller import Labeller

    scene = load_scene("spot")
    cam = orbit(scene, 1, 64, 64, seed=3)[0]
    with GBufferRenderer(scene) as r:
        frame = r.render(cam)
    points, _, pix, exact = Labeller(scene).visible_points(frame)
    face = frame["tri_id"].reshape(-1)[pix]
    tri = scene.triangles[face]
    # barycentrics of each point in its triangle
    e0, e1, d = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], points - tri[:, 0]
    d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
    d20, d21 = (d * e0).sum(1), (d * e1).sum(1)
    den = d00 * d11 - d01 * d01
    b1, b2 = (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den
    bary = np.stack([1 - b1 - b2, b1, b2], axis=1)
    n = smooth_normals_at(scene, face, bary)
    rendered = frame["normal_obj"].reshape(-1, 3)[pix]
    facing = np.sign(np.einsum("kd,kd->k", rendered, scene.face_normals[face]))[:, None]  # back faces flip
    cos = np.einsum("kd,kd->k", n * facing, rendered)
    assert np.quantile(cos[exact], 0.01) > TOL.gbuffer_normal_cos


def test_same_seed_same_weights_and_samples(spot_run):
    scene = load_scene("spot")
    s = FieldSettings(**{**FAST.__dict__, "steps": 60, "holdout_views": 0})
    a, b = collect_samples(scene, s), collect_samples(scene, s)
    assert (
        np.array_equal(a.position, b.position)
        and np.array_equal(a.ao, b.ao)
        and np.array_equal(a.split, b.split)
    )
    m1, _ = train_model(a, scene, s)
    m2, _ = train_model(b, scene, s)
    for (k, v1), v2 in zip(m1.state_dict().items(), m2.state_dict().values(), strict=True):
        assert torch.equal(v1, v2), k
    m3, _ = train_model(a, scene, FieldSettings(**{**s.__dict__, "seed": 1}))
    assert not torch.equal(m1.net[0].weight, m3.net[0].weight)


def test_field_beats_a_constant_on_held_back_views(spot_run):
    _, ckpt = spot_run
    m = ckpt["metrics"]
    assert m["holdout_frames"] == 1
    assert m["holdout_rmse"] < 0.75 * m["holdout_constant_rmse"], m
    assert m["val_rmse"] < 0.75 * m["constant_val_rmse"], m


def test_export_bytes_metadata_and_parity(spot_run):
    root, ckpt = spot_run
    manifest = json.loads((root / "export" / "manifest.json").read_text())
    model = model_from_checkpoint(load_checkpoint(root / "spot.pt"))
    feats = 6 + 6 * 3
    params = feats * 16 + 16 + 16 * 8 + 8 + 8 + 1
    assert count_parameters(model) == params
    assert manifest["parameter_bytes"] == parameter_bytes(model) == 4 * (params + 6 + 9)
    proto = load_onnx(root / "export" / "model.onnx")
    meta = {p.key: p.value for p in proto.metadata_props}
    assert (
        meta["neuralao_kind"] == "field"
        and meta["octaves"] == "3"
        and meta["parameter_bytes"] == str(4 * (params + 15))
    )
    assert json.loads(meta["bounding_box_centre"]) == pytest.approx(model.centre.reshape(-1).tolist())
    assert {n.op_type for n in proto.graph.node} <= {
        "Sub",
        "Mul",
        "MatMul",
        "Sin",
        "Cos",
        "Concat",
        "Gemm",
        "Tanh",
    }
    # onnxruntime vs torch on random inputs
    p, n = random_inputs(model, 257, seed=4)
    y = run_onnxruntime(proto.SerializeToString(), {"position": p, "normal": n})[0]
    assert y.shape == (257, 1) and y.dtype == np.float32
    ref = predict(model, p, n)
    assert float(np.abs(y[:, 0] - ref).max()) <= onnx_vs_torch_tol(ref, proto)
    # generated GLSL (3.30 and ES 3.00) vs onnxruntime on rendered G-buffers of the mesh
    r = parity(root / "export")
    assert r["passed"] and r["max_abs_err"] <= TOL.parity_mlp_fp32 and r["background_max_abs_err"] == 0.0
    assert {c["dialect"] for c in r["checks"]} == {"glsl330", "es300"}
    glsl = json.loads((root / "export" / "glsl" / "manifest.json").read_text())
    assert glsl["kind"] == "field" and [t["texture"] for t in glsl["passes"][0]["inputs"]] == [
        "position",
        "normal",
    ]


def test_single_sided_plane_with_a_box_on_one_side():
    """An open plane (z = 0, facing +z) with a box standing on its +z side. Seen from above, the floor
    by the box is dark; seen from below (the G-buffer then shows the normal -z) the same points are
    fully open. A vertex bake holds one value per vertex and cannot show both; the field, whose normal
    input tells the sides apart, must."""
    floor = floor_quad(1.0)
    v, f = box(0.2, inward=False)
    scene = merge(floor, (v + [0.0, 0.0, 0.2], f), name="plane_box")
    s = FieldSettings(
        hidden=[32, 16],
        octaves=4,
        samples=8192,
        steps=1500,
        check_every=250,
        holdout_views=0,
        labels=LabelSettings(rays=64),
    )
    samples = collect_samples(scene, s)
    # both sides of the floor were labelled and kept; the box's inside (back faces) was dropped
    assert samples.info["valid_back"] > 0.3 * samples.info["surface_points"] * (4.0 / (4.0 + 20 * 0.04))
    model, _ = train_model(samples, scene, s)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.35, 0.35, size=(400, 2))
    xy = xy[np.abs(xy).max(axis=1) > 0.24]  # on the floor next to the box, not under it
    p = np.concatenate([xy, np.zeros((len(xy), 1))], axis=1).astype(np.float32)
    up = np.tile([0.0, 0.0, 1.0], (len(p), 1)).astype(np.float32)
    top, bottom = predict(model, p, up), predict(model, p, -up)
    assert np.mean(bottom) > 0.95 and np.mean(top) < np.mean(bottom) - 0.15, (np.mean(top), np.mean(bottom))
    # the field agrees with the labeller on both sides
    from neuralao.pipeline.tracing.labeller import Labeller

    ref_top, _ = Labeller(scene, LabelSettings(rays=256)).ao_at_points(
        p.astype(np.float64), up.astype(np.float64)
    )
    assert float(np.sqrt(np.mean((np.clip(top, 0, 1) - ref_top) ** 2))) < 0.08


def test_cli_train_export_parity_and_bad_input(tmp_path, capsys):
    out = tmp_path / "f.pt"
    args = [
        "train",
        "field",
        "--mesh",
        "spot",
        "--size",
        "8x4",
        "--octaves",
        "2",
        "--rays",
        "16",
        "--set",
        "samples=2048",
        "--set",
        "steps=50",
        "--set",
        "holdout_views=0",
        "--out",
        str(out),
        "--no-progress",
    ]
    assert cli.main(args) == 0 and out.is_file()
    assert cli.main(["export", str(out), "--out", str(tmp_path / "e")]) == 0
    assert cli.main(["parity", str(tmp_path / "e")]) == 0
    assert (
        cli.main(["train", "field", "--mesh", str(tmp_path / "missing.obj"), "--out", str(tmp_path / "x.pt")])
        == 2
    )
    assert (
        cli.main(
            ["train", "field", "--mesh", "spot", "--data", str(tmp_path), "--out", str(tmp_path / "x.pt")]
        )
        == 2
    )
    assert (
        cli.main(["train", "field", "--mesh", "spot", "--set", "octaves=-1", "--out", str(tmp_path / "x.pt")])
        == 2
    )
    assert not (tmp_path / "x.pt").exists()
    errors = [ln for ln in capsys.readouterr().err.splitlines() if "error:" in ln]
    assert len(errors) == 3 and all(ln.startswith("neuralao ") for ln in errors)


def test_infer_frame_matches_torch_and_cli(spot_run, tmp_path):
    """`neuralao infer` on a field ONNX: onnxruntime on a rendered G-buffer equals the torch network."""
    from PIL import Image

    from neuralao.pipeline.geometry.camera import orbit
    from neuralao.pipeline.models.field import predict_frame
    from neuralao.runtime.foundation.io import write_npz
    from neuralao.runtime.predict import field_infer_frame as infer_frame

    root, _ = spot_run
    scene = load_scene("spot")
    with GBufferRenderer(scene) as r:
        frame = r.render(orbit(scene, 1, 40, 30, seed=5)[0])
    ao = infer_frame(root / "export" / "model.onnx", frame)
    want = predict_frame(model_from_checkpoint(load_checkpoint(root / "spot.pt")), frame)
    assert ao.shape == want.shape == (30, 40) and ao.dtype == np.float32
    tol = onnx_vs_torch_tol(want, root / "export" / "model.onnx")
    assert float(np.abs(ao - want).max()) <= tol and (ao[~frame["mask"]] == 1).all()
    write_npz(tmp_path / "f.npz", **{k: np.asarray(v) for k, v in frame.items()})
    assert (
        cli.main(
            [
                "infer",
                str(root / "export" / "model.onnx"),
                str(tmp_path / "f.npz"),
                "--out",
                str(tmp_path / "ao.png"),
            ]
        )
        == 0
    )
    png = np.asarray(Image.open(tmp_path / "ao.png")).astype(float)
    assert np.abs(png - (ao * 255 + 0.5).astype(np.uint8)).max() <= 1
