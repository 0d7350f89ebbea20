"""The hybrid U-Net: GTAO's AO as a fifth input channel, a learned correction as the output.

GTAO stays a GL pass (neuralao.runtime.baselines); the ONNX model takes its output as an input, so parity is
checked on a real GTAO image: torch against onnxruntime, and the generated GLSL against onnxruntime
on the same five-channel input. With the correction zeroed the model is GTAO exactly (closed form),
at the frame's resolution and at an internal resolution (where the correction, not the AO, is
upsampled).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
from neuralao.pipeline.geometry.camera import orbit
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.models.unet import UNet, UNetArgs, predict
from neuralao.runtime.baselines import run_gtao
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.unet_input import HYBRID_CHANNELS, frame_radius_param, preprocess_frame

WIDTHS = [4, 8, 16]


def _hybrid(seed: int = 0, gtao_blur: bool = True) -> UNet:
    torch.manual_seed(seed)
    model = UNet(UNetArgs(in_channels=5, widths=WIDTHS, gtao_input=True, gtao_blur=gtao_blur)).eval()
    with torch.no_grad():  # a correction of visible size, so the comparisons mean something
        model.out.weight.mul_(4.0)
    return model


@pytest.fixture(scope="module")
def frame():
    scene = load_scene("spot")
    f = render_gbuffer(scene, orbit(scene, 3, 96, 64, seed=1)[1])
    radius = 0.125 * scene.diagonal
    f["gtao"] = run_gtao(f, radius)
    return f, radius


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from neuralao.export.unet import export_onnx, write_glsl

    out = tmp_path_factory.mktemp("hybrid")
    model = _hybrid()
    proto = export_onnx(model, out / "model.onnx")
    write_glsl(proto, out / "glsl")
    return model, out


def test_hybrid_needs_five_channels_at_scale_one():
    with pytest.raises(NeuralaoError, match="5 channels"):
        UNet(UNetArgs(in_channels=4, widths=WIDTHS, gtao_input=True))
    with pytest.raises(NeuralaoError, match="scale"):
        UNet(UNetArgs(in_channels=5, widths=WIDTHS, gtao_input=True, scale=2))


def test_metadata_names_the_gtao_channel(exported):
    from neuralao.export.onnx_io import get_metadata, load_onnx
    from neuralao.runtime.predict import is_hybrid

    meta = get_metadata(load_onnx(exported[1] / "model.onnx"))
    assert meta["input_channels"] == ",".join(HYBRID_CHANNELS) and is_hybrid(meta)


def test_zero_correction_is_gtao_exactly(frame):
    f, radius = frame
    model = _hybrid()
    with torch.no_grad():
        model.out.weight.zero_()
        model.out.bias.zero_()
    x = preprocess_frame(f, f["gtao"])
    y = predict(model, x, frame_radius_param(f, radius))
    np.testing.assert_array_equal(y[f["mask"]], f["gtao"][f["mask"]])


def test_onnxruntime_matches_torch_on_real_gtao(exported, frame):
    from neuralao.runtime.predict import ort_runner, run_padded

    model, out = exported
    f, radius = frame
    x = preprocess_frame(f, f["gtao"])
    rho = frame_radius_param(f, radius)
    ref = predict(model, x, rho)
    got = run_padded(ort_runner(out / "model.onnx"), x, model.pad_multiple, rho)
    assert np.ptp(ref[f["mask"]] - f["gtao"][f["mask"]]) > 1e-2  # the correction is not nothing
    assert np.abs(got - ref).max() <= TOL.onnx_vs_torch(1.0, 8)


def test_glsl_matches_onnxruntime_on_real_gtao(exported, frame):
    """Parity of the generated compute passes on the same five-channel input (a real GTAO image)."""
    from neuralao.export.unet import glsl_runner
    from neuralao.runtime.predict import ort_runner, run_padded

    model, out = exported
    f, radius = frame
    x = preprocess_frame(f, f["gtao"])
    rho = frame_radius_param(f, radius)
    want = run_padded(ort_runner(out / "model.onnx"), x, model.pad_multiple, rho)
    got = run_padded(glsl_runner(out / "glsl"), x, model.pad_multiple, rho)
    assert got.shape == want.shape
    assert np.abs(got - want).max() <= TOL.parity_unet_fp32


@pytest.mark.parametrize("internal", [None, 32])
def test_frame_predictor_runs_gtao_and_keeps_it_where_the_correction_is_zero(tmp_path, frame, internal):
    """A zero-correction hybrid through the whole inference path returns the full-resolution GTAO,
    also at an internal resolution (the correction is upsampled, not the AO)."""
    from neuralao.export.unet import export_onnx
    from neuralao.runtime.predict import unet_predictor as frame_predictor

    model = _hybrid()
    with torch.no_grad():
        model.out.weight.zero_()
        model.out.bias.zero_()
    export_onnx(model, tmp_path / "model.onnx")
    (tmp_path / "manifest.json").write_text(json.dumps({"internal_height": internal}))
    f, radius = frame
    plain = {k: v for k, v in f.items() if k != "gtao"}
    ao = frame_predictor(tmp_path / "model.onnx")(plain, radius)
    np.testing.assert_allclose(ao[f["mask"]], f["gtao"][f["mask"]], atol=1e-6)
    assert np.all(ao[~f["mask"]] == 1.0)


# ------------------------------------------------------------------------------------------ training


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset
    from neuralao.pipeline.tracing.labeller import LabelSettings

    out = tmp_path_factory.mktemp("hybrid-ds")
    settings = DatasetSettings(
        name="tiny-hybrid",
        scenes=[
            SceneSpec("spot", "spot", views=3, split="train"),
            SceneSpec("box", "cornell_box", cameras="interior", views=1, split="val"),
        ],
        size=(64, 48),
        labels=LabelSettings(rays=8, radii_rel=[0.125, 0.25]),
        holdout_every=0,
        frames_per_shard=4,
    )
    build_dataset(settings, out, progress=False)
    return out


def test_loader_point_samples_to_the_internal_height_and_adds_gtao(tiny_dataset):
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.models.unet_frames import frames_to_set, network_input
    from neuralao.runtime.internal_resolution import downsample_frame

    frames = list(open_dataset(tiny_dataset).frames(split="train"))
    data = frames_to_set(frames, internal_height=24, gtao=True)
    assert (
        data.x.shape == (3, 4, 24, 32) and data.g.shape == (3, 2, 24, 32) and data.y.shape == (3, 2, 24, 32)
    )
    f = frames[0]
    low = downsample_frame(f, 32, 24)
    np.testing.assert_array_equal(
        data.y[0].float().numpy(), np.moveaxis(low["ao_radii"], -1, 0).astype(np.float16)
    )
    # GTAO runs on the frame as rendered, then is point-sampled with it (as at inference)
    full = run_gtao(f, float(f["radii"][1]))
    np.testing.assert_array_equal(
        data.g[0][1].numpy(),
        downsample_frame({"depth": f["depth"], "a": full}, 32, 24)["a"].astype(np.float16),
    )
    assert network_input(data, 0, 1).shape == (5, 24, 32)
    assert frames_to_set(frames, internal_height=96).x.shape == (3, 4, 96, 128)  # shorter frames go up
    assert frames_to_set(frames).x.shape == (3, 4, 48, 64)  # 0: as rendered
    # input contract 5: the internal height is a most (shorter frames as rendered), rho of the rows kept
    from neuralao.runtime.unet_input import frame_radius_param

    v5 = frames_to_set(frames, internal_height=96, gtao=True, version=5)
    assert v5.x.shape == (3, 4, 48, 64) and v5.g.shape == (3, 2, 48, 64)
    assert v5.rho[0][1] == pytest.approx(frame_radius_param(f, float(f["radii"][1]), 5))
    assert v5.rho[0][1] == pytest.approx(frame_radius_param(f, float(f["radii"][1]), 3) + np.log(48 / 256))
    assert frames_to_set(frames, internal_height=24, version=5).x.shape == (3, 4, 24, 32)


def test_hybrid_trains_exports_and_declares_itself(tiny_dataset, tmp_path):
    from neuralao.export.onnx_io import get_metadata, load_onnx
    from neuralao.export.unet import export_checkpoint
    from neuralao.pipeline.models.unet_frames import load_dataset_frames
    from neuralao.pipeline.models.unet_train import UNetTrainSettings, train
    from neuralao.runtime.predict import is_hybrid

    ts = UNetTrainSettings(
        epochs=2,
        batch_size=2,
        crop=16,
        crops_per_frame=1,
        widths=[4, 8],
        gtao_input=True,
        internal_height=32,
        threads=1,
        seed=0,
    )
    train_set, val_set, info = load_dataset_frames(tiny_dataset, internal_height=32, gtao=True)
    ckpt = train(ts, train_set, val_set, tmp_path / "h.pt", info, progress=False)
    assert ckpt["model_args"]["gtao_input"] and ckpt["model_args"]["in_channels"] == 5
    assert np.isfinite(ckpt["metrics"]["val_ssim"])
    manifest = export_checkpoint(tmp_path / "h.pt", tmp_path / "export")
    meta = get_metadata(load_onnx(tmp_path / "export" / "model.onnx"))
    assert is_hybrid(meta) and str(meta["internal_height"]) == "32" and manifest["internal_height"] == 32


def test_an_export_runs_the_network_at_the_rows_it_is_given(tiny_dataset, tmp_path, capsys):
    """`neuralao export --internal-height`: the export declares the rows it was given (and the rows it
    trained at), and its predictor, its frame passes and the model run at those rows explicitly agree."""
    import onnx
    from helpers import analytic_gbuffer

    from neuralao.export.onnx_io import get_metadata, load_onnx
    from neuralao.pipeline.cli.main import main
    from neuralao.pipeline.models.unet_frames import load_dataset_frames
    from neuralao.pipeline.models.unet_train import UNetTrainSettings, train
    from neuralao.runtime.foundation.manifest import read_json
    from neuralao.runtime.frame_runner import FrameRunner, frame_program
    from neuralao.runtime.predict import unet_predictor

    ts = UNetTrainSettings(
        epochs=1, batch_size=2, crop=16, widths=[4, 8], gtao_input=True, internal_height=32, threads=1, seed=0
    )
    train_set, val_set, info = load_dataset_frames(tiny_dataset, internal_height=32, gtao=True)
    train(ts, train_set, val_set, tmp_path / "h.pt", info, progress=False)
    assert main(["export", str(tmp_path / "h.pt"), "--out", str(tmp_path / "at32")]) == 0
    assert (
        main(["export", str(tmp_path / "h.pt"), "--out", str(tmp_path / "at48"), "--internal-height", "48"])
        == 0
    )
    manifest = read_json(tmp_path / "at48" / "manifest.json", "manifest")
    meta = get_metadata(load_onnx(tmp_path / "at48" / "model.onnx"))
    assert manifest["internal_height"] == 48 and manifest["trained_internal_height"] == 32
    assert str(meta["internal_height"]) == "48" and str(meta["trained_internal_height"]) == "32"
    assert manifest["internal_resolution"]["height"] == 48
    assert "trained_internal_height" not in read_json(tmp_path / "at32" / "manifest.json", "manifest")

    f = analytic_gbuffer(75, 53)
    at48 = unet_predictor(tmp_path / "at48" / "model.onnx", "model")(f, 0.4)
    explicit = unet_predictor(tmp_path / "at32" / "model.onnx", 48)(f, 0.4)
    trained = unet_predictor(tmp_path / "at32" / "model.onnx", "model")(f, 0.4)
    assert np.array_equal(at48, explicit)
    assert float(np.abs(at48 - trained).max()) > 1e-3  # the rows change the AO: the check can fail
    program = frame_program(onnx.load(str(tmp_path / "at48" / "model.onnx")), "glsl430")
    with FrameRunner(program, 75, 53) as runner:
        assert float(np.abs(runner.run(f, 0.4) - at48).max()) <= TOL.frame_passes_vs_reference

    # an export folder (a shipped model's: no checkpoint) written again at other rows: the same model
    assert (
        main(["export", str(tmp_path / "at32"), "--out", str(tmp_path / "re48"), "--internal-height", "48"])
        == 0
    )
    again = read_json(tmp_path / "re48" / "manifest.json", "manifest")
    assert again["internal_height"] == 48 and again["trained_internal_height"] == 32
    assert again["parity"]["glsl_vs_onnxruntime"] <= again["parity"]["tolerance"]
    assert (
        again["exported_from"]["onnx_sha256"]
        == read_json(tmp_path / "at32" / "manifest.json", "m")["onnx_sha256"]
    )
    assert again["internal_resolution"] == json.loads(json.dumps(manifest["internal_resolution"]))
    assert np.array_equal(unet_predictor(tmp_path / "re48" / "model.onnx", "model")(f, 0.4), at48)
    assert (
        main(["export", str(tmp_path / "re48"), "--out", str(tmp_path / "re32"), "--internal-height", "32"])
        == 0
    )
    back = read_json(tmp_path / "re32" / "manifest.json", "manifest")
    assert back["internal_height"] == 32 and "trained_internal_height" not in back
    assert np.array_equal(unet_predictor(tmp_path / "re32" / "model.onnx", "model")(f, 0.4), trained)
    capsys.readouterr()
    assert main(["export", str(tmp_path / "at32"), "--out", str(tmp_path / "bad")]) != 0
    assert "give --internal-height" in capsys.readouterr().err

    # refused in one line, nothing written: rows outside the range
    for bad in ("0", "-5", "100000"):
        capsys.readouterr()
        assert (
            main(["export", str(tmp_path / "h.pt"), "--out", str(tmp_path / "bad"), "--internal-height", bad])
            != 0
        )
        err = capsys.readouterr().err.strip()
        assert "--internal-height" in err and len(err.splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "bad").exists()


def test_export_carries_the_internal_resolution_passes(tiny_dataset, tmp_path):
    """An export trained at an internal height ships the two fragment passes an engine runs around the
    network, and they compile on Mesa."""
    from neuralao.export.unet import export_checkpoint
    from neuralao.pipeline.models.unet_frames import load_dataset_frames
    from neuralao.pipeline.models.unet_train import UNetTrainSettings, train
    from neuralao.runtime import gl

    ts = UNetTrainSettings(
        epochs=1,
        batch_size=2,
        crop=16,
        crops_per_frame=1,
        widths=[2, 4],
        internal_height=32,
        threads=1,
        seed=0,
    )
    train_set, val_set, info = load_dataset_frames(tiny_dataset, internal_height=32)
    train(ts, train_set, val_set, tmp_path / "u.pt", info, progress=False)
    manifest = export_checkpoint(tmp_path / "u.pt", tmp_path / "export")
    passes = manifest["internal_resolution"]
    assert passes["height"] == 32 and len(passes["steps"]) == 3
    folder = tmp_path / "export" / "glsl" / passes["folder"]
    vertex = (folder / passes["sources"]["vertex"]).read_text()
    for key in ("downsample", "upsample"):
        assert gl.compile_program(vertex=vertex, fragment=(folder / passes["sources"][key]).read_text()) > 0


# ------------------------------------------------------------------------------ the export's GTAO pass


def write_internal_export(model: UNet, out, internal_height: int) -> dict:
    """model.onnx + glsl/ + glsl/internal/ + manifest.json of ``model`` at ``internal_height``, as
    :func:`neuralao.export.unet.export_checkpoint` writes them (without a checkpoint). Returns the
    manifest."""
    from neuralao.export.unet import export_onnx, onnx_metadata, write_glsl, write_internal_passes
    from neuralao.runtime.foundation.io import write_json

    meta = onnx_metadata(model) | {"internal_height": str(internal_height)}
    proto = export_onnx(model, out / "model.onnx", meta)
    glsl = write_glsl(proto, out / "glsl")
    internal = write_internal_passes(
        glsl, internal_height, model.args.gtao_input, model.args.gtao_blur, model.args.gtao_raw_input
    )
    manifest = {"kind": "unet", "internal_height": internal_height, "internal_resolution": internal}
    write_json(out / "manifest.json", manifest)
    return manifest


def run_export_gtao(export_dir, frame: dict, radius: float) -> np.ndarray:
    """The GTAO pass of a hybrid export, run from its files and manifest entry alone (as an engine
    would) on the headless GL context: (H, W) float32, 1 on background."""
    from neuralao.runtime import gl
    from neuralao.runtime.baselines import gbuffer_textures, projection_scale
    from neuralao.runtime.gl import GL

    entry = json.loads((export_dir / "manifest.json").read_text())["internal_resolution"]
    folder, g = export_dir / "glsl" / entry["folder"], entry["gtao"]
    src = {k: (folder / v).read_text() for k, v in entry["sources"].items()}
    h, w = frame["depth"].shape
    pos, nrm = gbuffer_textures(frame)
    noise = np.asarray(g["noise"]["texels"], np.float32).reshape(g["noise"]["height"], g["noise"]["width"], 4)
    tex = {
        "u_position": gl.create_texture(w, h, GL.GL_RGBA32F, pos),
        "u_normal": gl.create_texture(w, h, GL.GL_RGBA32F, nrm),
        "u_noise": gl.create_texture(noise.shape[1], noise.shape[0], GL.GL_RGBA32F, noise[::-1]),
        "u_raw": gl.create_texture(w, h, GL.GL_R32F),
    }
    out = gl.create_texture(w, h, GL.GL_R32F)
    p00, p11 = projection_scale(frame["yfov"], w, h)
    formulas = {"u_proj": (p00, p11), "u_radius": (radius,), "u_pixels_per_unit": (0.5 * h * p11,)}
    GL.glViewport(0, 0, w, h)
    GL.glBindVertexArray(gl.context().empty_vao)
    if g["blur"] is None:  # a hybrid on GTAO's pass alone
        passes = [("gtao", g["textures"], out)]
    else:
        passes = [("gtao", g["textures"], tex["u_raw"]), ("gtao_blur", g["blur"]["textures"], out)]
    for key, bindings, target in passes:
        prog = gl.compile_program(vertex=src["vertex"], fragment=src[key])
        fbo = gl.create_framebuffer([target], w, h, depth=False)
        GL.glUseProgram(prog)
        for name, unit in bindings.items():
            GL.glActiveTexture(GL.GL_TEXTURE0 + unit)
            GL.glBindTexture(GL.GL_TEXTURE_2D, tex[name])
        for name, u in g["uniforms"].items() if key == "gtao" else ():
            values = (u["value"],) if "value" in u else formulas[name]
            (GL.glUniform1f if len(values) == 1 else GL.glUniform2f)(
                GL.glGetUniformLocation(prog, name), *values
            )
        GL.glDrawArrays(GL.GL_TRIANGLES, 0, 3)
        GL.glDeleteFramebuffers(1, [fbo])
    GL.glUseProgram(0)
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
    ao = gl.read_texture(out, w, h, GL.GL_R32F)[..., 0].copy()
    GL.glDeleteTextures(5, [*tex.values(), out])
    return np.where(frame["mask"], ao, np.float32(1.0)).astype(np.float32)


def test_hybrid_export_carries_the_gtao_pass_it_refines(tmp_path, frame):
    """gtao.frag + gtao_blur.frag and the manifest's uniforms and noise tile, run from the export alone,
    reproduce neuralao.runtime.baselines' GTAO bit for bit; a pure export carries no GTAO pass."""
    f, radius = frame
    manifest = write_internal_export(_hybrid(), tmp_path / "hybrid", 32)
    entry = manifest["internal_resolution"]
    assert {"gtao", "gtao_blur"} <= set(entry["sources"]) and entry["steps"][0].startswith("gtao.frag")
    got = run_export_gtao(tmp_path / "hybrid", f, radius)
    np.testing.assert_array_equal(got, f["gtao"])
    assert np.abs(run_export_gtao(tmp_path / "hybrid", f, 0.5 * radius) - f["gtao"]).max() > 1e-2

    torch.manual_seed(0)
    pure = UNet(UNetArgs(in_channels=4, widths=WIDTHS)).eval()
    entry = write_internal_export(pure, tmp_path / "pure", 32)["internal_resolution"]
    assert "gtao" not in entry and "gtao" not in entry["sources"]
    assert not (tmp_path / "pure" / "glsl" / "internal" / "gtao.frag").exists()


def test_hybrid_on_gtao_without_its_blur_exports_and_loads_that_gtao(tmp_path, frame, tiny_dataset):
    """A hybrid trained on GTAO's pass alone (``gtao_blur`` False): its training frames hold that GTAO,
    prepared apart from the blurred one's; its export carries the pass and no blur, which run from the
    files reproduce neuralao.runtime.baselines' unblurred GTAO bit for bit; its predictor feeds it the
    same."""
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.models.unet_frames import frames_to_set, prepared_folder
    from neuralao.runtime.baselines import GTAOSettings
    from neuralao.runtime.internal_resolution import downsample_frame
    from neuralao.runtime.predict import unet_predictor

    raw = GTAOSettings(blur=False)
    frames = list(open_dataset(tiny_dataset).frames(split="train"))
    data = frames_to_set(frames, internal_height=24, gtao=True, gtao_blur=False)
    f0 = frames[0]
    want = downsample_frame({"depth": f0["depth"], "a": run_gtao(f0, float(f0["radii"][1]), raw)}, 32, 24)[
        "a"
    ]
    np.testing.assert_array_equal(data.g[0][1].numpy(), want.astype(np.float16))
    blurred = frames_to_set(frames[:1], internal_height=24, gtao=True)
    assert not np.array_equal(blurred.g[0][1].numpy(), data.g[0][1].numpy())
    ds = open_dataset(tiny_dataset)
    keys = {prepared_folder(tiny_dataset, ds, 24, True, 3, blur) for blur in (True, False)}
    assert len(keys) == 2 and prepared_folder(tiny_dataset, ds, 24, True, 3) in keys

    f, radius = frame
    torch.manual_seed(0)
    model = UNet(UNetArgs(in_channels=5, widths=WIDTHS, gtao_input=True, gtao_blur=False)).eval()
    manifest = write_internal_export(model, tmp_path / "raw", 32)
    entry = manifest["internal_resolution"]
    assert (
        "gtao" in entry["sources"] and "gtao_blur" not in entry["sources"] and entry["gtao"]["blur"] is None
    )
    assert not (tmp_path / "raw" / "glsl" / "internal" / "gtao_blur.frag").exists()
    unblurred = run_gtao(f, radius, raw)
    np.testing.assert_array_equal(run_export_gtao(tmp_path / "raw", f, radius), unblurred)
    assert np.abs(unblurred - f["gtao"]).max() > 1e-2  # the blur matters on this frame

    with torch.no_grad():  # no correction: the predictor's AO is the GTAO it feeds the network
        model.out.weight.zero_()
        model.out.bias.zero_()
    write_internal_export(model, tmp_path / "zero", 32)
    got = unet_predictor(tmp_path / "zero" / "model.onnx", internal_height=None)(f, radius)
    np.testing.assert_allclose(got, unblurred, atol=TOL.parity_unet_fp32)


def test_a_hybrid_says_which_gtao_it_reads_or_is_refused():
    from neuralao.runtime.unet_input import hybrid_description, hybrid_gtao_blur

    assert hybrid_gtao_blur({}) and hybrid_gtao_blur(hybrid_description(3))  # the hybrids before the key
    assert not hybrid_gtao_blur(hybrid_description(3, gtao_blur=False))
    assert not hybrid_gtao_blur({"gtao_blur": False}) and hybrid_gtao_blur({"gtao_blur": "True"})
    with pytest.raises(NeuralaoError, match="gtao_blur must be true or false"):
        hybrid_gtao_blur({"gtao_blur": "sometimes"}, "m.onnx")


def test_hybrid_reading_gtao_before_its_blur_too_keeps_the_blurred_gtao_as_its_base(
    tmp_path, frame, tiny_dataset
):
    """``gtao_raw_input``: GTAO before its blur as a channel in front of the blurred GTAO. The training
    frames hold both, the network's input has both in that order, the correction is added to the blurred
    one (a zeroed correction gives it back exactly through the runtime's predictor), and the metadata says
    so."""
    from neuralao.export.unet import export_onnx, onnx_metadata
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.models.unet_frames import frames_to_set, network_input, prepared_folder
    from neuralao.runtime.baselines import GTAOSettings
    from neuralao.runtime.internal_resolution import downsample_frame
    from neuralao.runtime.predict import unet_predictor

    with pytest.raises(NeuralaoError, match="gtao_raw_input"):
        UNet(UNetArgs(in_channels=6, widths=WIDTHS, gtao_input=True, gtao_blur=False, gtao_raw_input=True))
    with pytest.raises(NeuralaoError, match="6 channels"):
        UNet(UNetArgs(in_channels=5, widths=WIDTHS, gtao_input=True, gtao_raw_input=True))

    frames = list(open_dataset(tiny_dataset).frames(split="train"))
    data = frames_to_set(frames, internal_height=24, gtao=True, gtao_raw=True)
    f0, r1 = frames[0], float(frames[0]["radii"][1])
    low = lambda img: downsample_frame({"depth": f0["depth"], "a": img}, 32, 24)["a"].astype(np.float16)  # noqa: E731
    raw = run_gtao(f0, r1, GTAOSettings(blur=False))
    np.testing.assert_array_equal(data.r[0][1].numpy(), low(raw))
    np.testing.assert_array_equal(data.g[0][1].numpy(), low(run_gtao(f0, r1)))
    x = network_input(data, 0, 1)
    assert x.shape == (6, 24, 32)
    np.testing.assert_array_equal(x[4].numpy(), data.r[0][1].float().numpy())
    np.testing.assert_array_equal(x[5].numpy(), data.g[0][1].float().numpy())
    ds = open_dataset(tiny_dataset)
    assert prepared_folder(tiny_dataset, ds, 24, True, 3, gtao_raw=True) != prepared_folder(
        tiny_dataset, ds, 24, True, 3
    )

    f, radius = frame
    torch.manual_seed(0)
    model = UNet(UNetArgs(in_channels=6, widths=WIDTHS, gtao_input=True, gtao_raw_input=True)).eval()
    with torch.no_grad():
        model.out.weight.zero_()
        model.out.bias.zero_()
    meta = onnx_metadata(model)
    assert meta["input_channels"].endswith("gtao_raw,gtao") and "gtao_raw_channel" in meta
    export_onnx(model, tmp_path / "model.onnx", meta)
    got = unet_predictor(tmp_path / "model.onnx", internal_height=None)(f, radius)
    np.testing.assert_allclose(got, f["gtao"], atol=TOL.parity_unet_fp32)
    assert np.abs(f["gtao"] - run_gtao(f, radius, GTAOSettings(blur=False))).max() > 1e-2


def test_hybrid_on_both_gtao_images_trains_and_exports(tiny_dataset, tmp_path):
    from neuralao.export.unet import export_checkpoint
    from neuralao.pipeline.models.unet_frames import load_dataset_frames
    from neuralao.pipeline.models.unet_train import UNetTrainSettings, train

    ts = UNetTrainSettings(
        epochs=1,
        batch_size=2,
        crop=16,
        widths=[4, 8],
        gtao_input=True,
        gtao_raw_input=True,
        internal_height=32,
        threads=1,
        seed=0,
    )
    sets = load_dataset_frames(tiny_dataset, internal_height=32, gtao=True, gtao_raw=True)
    assert sets[2]["gtao_raw"] is True and sets[0].r is not None
    ckpt = train(ts, sets[0], sets[1], tmp_path / "h.pt", sets[2], progress=False)
    assert ckpt["model_args"]["gtao_raw_input"] and ckpt["model_args"]["in_channels"] == 6
    assert np.isfinite(ckpt["metrics"]["val_rmse"])
    manifest = export_checkpoint(tmp_path / "h.pt", tmp_path / "export")
    assert manifest["internal_resolution"]["gtao_raw"] is True
    assert manifest["metadata"]["input_channels"].endswith("gtao_raw,gtao")
    # `neuralao parity` (and `neuralao ship`, which runs it) gives it both GTAO images
    from neuralao.export.unet import parity
    from neuralao.pipeline.datasets.dataset import open_dataset

    par = parity(tmp_path / "export", frames=[next(iter(open_dataset(tiny_dataset).frames()))])
    assert par["passed"] and par["max_abs_err"] <= TOL.parity_unet_fp32
    # `neuralao ship --shaders-only` regenerates its passes from the ONNX alone: the same passes
    from neuralao.pipeline.release.ship import refresh_shaders
    from neuralao.runtime.foundation.manifest import read_json

    refresh_shaders(tmp_path / "export", 64 << 20)
    again = read_json(tmp_path / "export" / "manifest.json", "manifest")
    assert again["internal_resolution"] == json.loads(json.dumps(manifest["internal_resolution"]))


def test_a_hybrid_trains_on_input_contract_5_and_its_onnx_runs_at_any_height(tiny_dataset, tmp_path):
    """Contract 5 (the radius input states the rows the network sees): trained on frames as rendered up
    to its internal height, its ONNX runs through the predictor; the generated frame passes do not know it
    yet and say so in one line."""
    from neuralao.export.unet import export_checkpoint, export_onnx, load_model, onnx_metadata
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.models.unet_frames import load_dataset_frames
    from neuralao.pipeline.models.unet_train import UNetTrainSettings, train
    from neuralao.runtime.predict import unet_predictor

    ts = UNetTrainSettings(
        epochs=1, batch_size=2, crop=16, widths=[4, 8], gtao_input=True, internal_height=96,
        preprocess_version=5, threads=1, seed=0,
    )  # fmt: skip
    sets = load_dataset_frames(tiny_dataset, internal_height=96, gtao=True, version=5)
    assert sets[0].x.shape[-2:] == (48, 64)  # as rendered: shorter than 96 rows
    ckpt = train(ts, sets[0], sets[1], tmp_path / "v5.pt", sets[2], progress=False)
    assert np.isfinite(ckpt["metrics"]["val_rmse"])
    model, ck = load_model(tmp_path / "v5.pt")
    meta = onnx_metadata(model, ck)
    assert meta["preprocess_version"] == "5" and meta["internal_height"] == "96"
    export_onnx(model, tmp_path / "v5.onnx", meta)
    frame = next(iter(open_dataset(tiny_dataset).frames()))
    ao = unet_predictor(tmp_path / "v5.onnx")(frame)
    assert ao.shape == frame["depth"].shape and np.isfinite(ao).all()
    with pytest.raises(NeuralaoError, match="preprocess versions 2, 3 and 4, the model has 5") as e:
        export_checkpoint(tmp_path / "v5.pt", tmp_path / "export")
    assert "\n" not in str(e.value)


def test_the_predictor_refines_gtao_images_it_is_given(frame):
    """The shipped default on GTAO images made elsewhere (an engine's): the runtime's own images give its AO
    bit for bit, other images another AO, and images it does not read, or of another size, are refused."""
    from neuralao.runtime.baselines import hybrid_gtao
    from neuralao.runtime.predict import unet_predictor
    from neuralao.runtime.shipped import default_export

    f, radius = frame
    f = {k: v for k, v in f.items() if k != "gtao"}
    onnx_path = default_export("unet") / "model.onnx"
    predict = unet_predictor(onnx_path)
    raw = "gtao_raw" in json.dumps(json.loads((onnx_path.parent / "manifest.json").read_text())["metadata"])
    images = hybrid_gtao(f, radius, raw=raw)
    np.testing.assert_array_equal(predict(f, radius, gtao=images), predict(f, radius))
    darker = {k: np.clip(v - 0.2, 0.0, 1.0) for k, v in images.items()}
    assert np.abs(predict(f, radius, gtao=darker) - predict(f, radius))[f["mask"]].max() > 0.05
    for wrong in (
        {"gtao": images["gtao"]} if raw else {**images, "gtao_raw": images["gtao"]},
        {k: v[:-1] for k, v in images.items()},
    ):
        with pytest.raises(NeuralaoError, match="reads GTAO images"):
            predict(f, radius, gtao=wrong)
