"""The frame passes (export/glsl/frame.py): a shipped U-Net's whole frame, generated as compute passes and
executed, against the references a user's ``neuralao infer`` computes.

* both shipped models, the whole frame (position from depth, GTAO and its blur, point sampling, the
  mean-depth reduction, the network's input and radius, the network's passes, upsampling with the hybrid's
  correction and combine) in GLSL 4.30 on llvmpipe, Vulkan SPIR-V on lavapipe (wgpu's passthrough),
  WGSL through wgpu and HLSL (SPIRV-Cross's from the GLSL 4.30, compiled to SPIR-V by glslang's HLSL front
  end, bound by the manifest's registers, on lavapipe), at three frame sizes (one not a multiple of 8) and
  three radii, against
  ``neuralao.runtime.predict.unet_predictor`` (GTAO in GL fragment shaders, numpy point sampling and
  upsampling, onnxruntime); GTAO's own texture against ``run_gtao``;
* the screen origin: the same frame stored bottom-up (u_flip_y = 1) and top row first gives the same AO;
* the manifest's frame section: every step in order, the network's uniform pass replaced, sizes and
  dispatch counts; HLSL and MSL written for every frame pass.

The network runs at an internal height of 64 rows here (the shipped 256 makes each frame ~1 s on
llvmpipe): the sources are the same at any height, and 64 rows point-sample the 48- and 53-row frames up
and the 96-row frame down, as 256 does for 1080p frames. ``test_shipped_internal_height`` runs 256 rows.
"""

from __future__ import annotations

import functools
import shutil

import numpy as np
import onnx
import pytest
from helpers import analytic_gbuffer

from neuralao.export.glsl import load_compute_export, load_cross_sources
from neuralao.export.glsl.frame import FORMATS, active_steps, dispatch_counts, frame_sizes, shader_entries
from neuralao.runtime.baselines import run_gtao
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame_runner import FrameRunner, frame_program
from neuralao.runtime.predict import unet_predictor
from neuralao.runtime.shipped import shipped_models

MODELS = ("unet-gtao", "unet-fast")
# (64 x 48, 75 x 53: the network at 64 rows is larger than the frame; 101 x 83: smaller, the upsampling's
# workgroups share their low texels, and the last ones stick out of the frame)
SIZES = ((64, 48), (75, 53), (101, 83))
RADII = (0.15, 0.4, 1.0)
INTERNAL_HEIGHT = 64
# The APIs the whole frame runs in: {name: (the program's dialect, FrameRunner's via)}.
APIS = {
    "glsl430": ("glsl430", None),
    "vulkan": ("vulkan", None),
    "wgsl": ("wgsl", None),
    "hlsl": ("glsl430", "hlsl"),
}
DIALECTS = tuple(APIS)


def _needs(dialect: str) -> None:
    """Skip (with the reason) where a dialect's tools or driver are missing."""
    if dialect == "glsl430":
        return
    wgpu = pytest.importorskip("wgpu", reason="the wgpu package is not installed (pyproject pins it)")
    if dialect == "vulkan" and shutil.which("glslangValidator") is None:
        pytest.skip("glslangValidator not installed (Debian: glslang-tools)")
    if dialect == "hlsl" and not all(shutil.which(t) for t in ("glslangValidator", "spirv-cross")):
        pytest.skip("HLSL needs spirv-cross and glslangValidator (Debian: spirv-cross, glslang-tools)")
    try:
        adapter = wgpu.gpu.request_adapter_sync()
    except RuntimeError:
        adapter = None
    if adapter is None:
        pytest.skip("no WebGPU adapter (Debian: mesa-vulkan-drivers)")
    if dialect in ("vulkan", "hlsl") and "spirv-shader-passthrough" not in adapter.features:
        pytest.skip("the adapter has no SPIR-V passthrough (not a Vulkan adapter)")


@functools.cache
def _program(name: str, height: int | None, dialect: str):
    """A shipped model's program with its frame passes, at internal height ``height`` (None: as shipped);
    ``dialect``: a compute dialect or an API of :data:`APIS`."""
    proto = (
        onnx.load(str(shipped_models()[name] / "model.onnx"))
        if height is None
        else _with_internal_height(name, height)
    )
    return frame_program(proto, APIS.get(dialect, (dialect,))[0])


def _runner(program, size: tuple[int, int], api: str, flip_y: bool = False) -> FrameRunner:
    return FrameRunner(program, *size, flip_y=flip_y, via=APIS[api][1])


def _with_internal_height(name: str, height: int) -> onnx.ModelProto:
    proto = onnx.load(str(shipped_models()[name] / "model.onnx"))
    for p in proto.metadata_props:
        if p.key == "internal_height":
            p.value = str(height)
    return proto


@pytest.fixture(scope="module")
def frames() -> dict:
    return {size: analytic_gbuffer(*size) for size in SIZES}


@pytest.fixture(scope="module", params=MODELS)
def model(request, tmp_path_factory, frames):
    """(name, ONNX proto at INTERNAL_HEIGHT, {(size, radius): reference AO}) of a shipped U-Net."""
    proto = _with_internal_height(request.param, INTERNAL_HEIGHT)
    path = tmp_path_factory.mktemp(request.param) / "model.onnx"
    onnx.save(proto, str(path))
    predict = unet_predictor(path)
    refs = {(size, r): predict(frames[size], r) for size in SIZES for r in RADII}
    return request.param, proto, refs


@pytest.mark.parametrize("dialect", DIALECTS)
def test_whole_frame_matches_the_references(model, dialect, frames):
    _needs(dialect)
    name, _, refs = model
    program = _program(name, INTERNAL_HEIGHT, dialect)
    errors = []
    for size in SIZES:
        with _runner(program, size, dialect) as runner:
            for r in RADII:
                f = frames[size]
                ao = runner.run(f, r)
                assert ao.shape == refs[size, r].shape == size[::-1] and ao.dtype == np.float32
                errors.append(float(np.abs(ao - refs[size, r]).max()))
                assert np.all(ao[~f["mask"]] == 1.0)
                if name == "unet-gtao":  # GTAO itself, against the GL fragment shaders
                    gtao = runner.read("gtao")[..., 0]
                    assert float(np.abs(gtao - run_gtao(f, r)).max()) <= TOL.frame_passes_vs_reference
    print(f"{name} {dialect}: whole frame max abs error {max(errors):.3g} vs the reference")
    assert max(errors) <= TOL.frame_passes_vs_reference, (name, dialect, errors)
    # the frames are not trivial: occlusion somewhere, and it grows with the radius
    assert min(float(refs[SIZES[1], r].min()) for r in RADII) < 0.8


@pytest.mark.parametrize("dialect", DIALECTS)
def test_origin_uniform_both_ways_gives_the_same_ao(dialect, frames):
    """The same frame stored bottom-up (GL, u_flip_y = 1) and top row first (u_flip_y = 0): the AO read
    back top row first is the same, bit for bit (flipped input -> flipped output)."""
    _needs(dialect)
    program = _program("unet-gtao", INTERNAL_HEIGHT, dialect)
    for size in SIZES[1:]:
        with _runner(program, size, dialect) as top, _runner(program, size, dialect, flip_y=True) as bottom:
            a, b = top.run(frames[size], RADII[1]), bottom.run(frames[size], RADII[1])
            assert np.array_equal(a, b)
            assert np.array_equal(top.read("gtao"), bottom.read("gtao"))
        assert float(a.min()) < 0.9


def test_frame_section_lists_the_whole_frame_in_order():
    for name in MODELS:
        program = _program(name, None, "glsl430")
        m = program.manifest
        frame = m["frame"]
        steps = frame["steps"]
        frame_names = [s.get("frame_pass") for s in steps if "frame_pass" in s]
        hybrid = name == "unet-gtao"
        assert frame["hybrid"] is hybrid and frame["preprocess_version"] == 3
        assert frame_names[0] == ("f_gtao" if hybrid else "f_downsample")
        assert frame_names[-2:] == ["f_upsample", "f_composite"]
        # no full-resolution copy of the G-buffer: the passes read the engine's depth and normal
        assert "f_position" not in frame_names and "gbuffer" not in frame["textures"]
        full = [k for k, t in frame["textures"].items() if (t["width"], t["height"]) == ("W", "H")]
        assert sorted(full) == sorted(["depth", "normal", "ao", *(["gtao_raw", "gtao"] if hybrid else [])])
        assert ("f_gtao" in frame_names) is hybrid and "f_network_input" in frame_names
        # frame-local input: no reduction over the frame (nothing an engine would read back)
        assert (
            not {"f_depth_columns", "f_depth_mean"} & set(frame_names)
            and "depth_mean" not in frame["textures"]
        )
        network = [s["network_pass"] for s in steps if "network_pass" in s]
        skipped = [s["skip"] for s in steps if "skip" in s]
        assert network + skipped == [p["name"] for p in m["passes"] if p["name"] not in skipped] + skipped
        assert [
            m["passes"][i]["kind"] for i in range(len(m["passes"])) if m["passes"][i]["name"] in skipped
        ] == ["uniform"]
        # the network's input and radius textures are written by frame passes, its output read by one
        written = {p["output"]["texture"] for p in frame["passes"]}
        assert {m["input"]["texture"], m["outputs"][0]["texture"]} <= set(frame["textures"])
        assert m["input"]["texture"] in written
        for entry in shader_entries(m):
            assert entry["shader"] in program.sources
        sizes = frame_sizes(m, 1920, 1080)
        assert sizes["low_gbuffer"][:2] == (455, 256) and sizes["ao"][:2] == (1920, 1080)
        counts = dispatch_counts(m, 1920, 1080)
        assert counts["passes"] == len(frame["passes"]) - 1 + len(network)  # upsample or composite


def test_frame_passes_compile_to_spirv_hlsl_and_msl():
    """Every frame pass of both models: Vulkan GLSL -> SPIR-V that spirv-val accepts; GLSL 4.30 -> HLSL
    (compiled back by glslang's HLSL front end) and MSL through SPIRV-Cross."""
    from neuralao.export.glsl import compile_spirv, cross_compile, spirv_cross_available, validate_hlsl

    if not spirv_cross_available():
        pytest.skip("spirv-cross / glslangValidator not installed (make system-deps)")
    seen = set()
    for name in MODELS:
        gl, vk = _program(name, None, "glsl430"), _program(name, None, "vulkan")
        for entry, vk_entry in zip(
            gl.manifest["frame"]["passes"], vk.manifest["frame"]["passes"], strict=True
        ):
            assert compile_spirv(vk.sources[vk_entry["shader"]])[:4] == b"\x03\x02\x23\x07"
            source = gl.sources[entry["shader"]]
            if source in seen:
                continue
            seen.add(source)
            out = cross_compile(source)
            validate_hlsl(out["hlsl"])
            assert "[numthreads(" in out["hlsl"] and "FrameUniforms" in out["hlsl"]
            assert "kernel void" in out["msl"]


def test_network_at_the_frame_size_is_composited_not_upsampled(tmp_path):
    """A frame exactly the network's size (64 x 64 at 64 rows) runs f_composite instead of f_upsample,
    as the reference skips resampling then."""
    name = "unet-fast"
    program = _program(name, INTERNAL_HEIGHT, "glsl430")
    f = analytic_gbuffer(64, 64)
    with FrameRunner(program, 64, 64) as runner:
        ao = runner.run(f, 0.4)
    onnx.save(_with_internal_height(name, INTERNAL_HEIGHT), str(tmp_path / "model.onnx"))
    want = unet_predictor(tmp_path / "model.onnx")(f, 0.4)
    assert float(np.abs(ao - want).max()) <= TOL.frame_passes_vs_reference
    names = [s.get("frame_pass") for s in active_steps(program.manifest, 64, 64)]
    assert "f_composite" in names and "f_upsample" not in names


def test_fp16_stores_the_ao_target_as_half_floats_and_the_networks_inputs_as_floats():
    """At fp16 the AO target is R16F (GL, Vulkan) and the hybrid's GTAO targets, the network's input, R16
    (16-bit unsigned normalised: the GLSL's r16); both stay r32float in WGSL (no r16float or r16unorm
    storage texture in core WebGPU). The network's textures are RGBA16F but its input and what the passes
    compute from it pixel by pixel (log depth, the radius channel: every pass before the first 3x3 conv),
    which stay RGBA32F with the depth-derived ones."""
    for preset in ("gpu", "cpu"):
        for dialect, half, gtao in (
            ("glsl430", "R16F", "R16"),
            ("vulkan", "R16F", "R16"),
            ("wgsl", "R32F", "R32F"),
        ):
            proto = _with_internal_height("unet-gtao", INTERNAL_HEIGHT)
            program = frame_program(proto, dialect, precision="fp16", preset=preset)
            frame = program.manifest
            textures = frame["frame"]["textures"]
            assert textures["ao"]["format"] == half
            assert textures["gtao_raw"]["format"] == textures["gtao"]["format"] == gtao
            assert textures["low_gbuffer"]["format"] == "RGBA32F"
            ext = ".wgsl" if dialect == "wgsl" else ".comp"
            for name, target in (("f_gtao", "gtao_raw"), ("f_gtao_blur", "gtao")):
                (entry,) = [p for p in frame["frame"]["passes"] if p["name"] == name]
                assert entry["output"] == {"texture": target, "binding": 2, "format": FORMATS[gtao]}
                declared = "<r32float, write>" if dialect == "wgsl" else f"binding = 2, {FORMATS[gtao]})"
                assert declared in program.sources[name + ext], (dialect, name)
            assert frame["frame"]["gtao_formats"]["this_program"] == gtao
            formats = [frame["textures"][p["output"]["texture"]]["format"] for p in frame["passes"]]
            spatial = [i for i, p in enumerate(frame["passes"]) if "LeakyRelu" in p["ops"]]
            assert set(formats[: spatial[0]]) == {"RGBA32F"}
            assert set(formats[spatial[0] : -1]) == {"RGBA16F"}  # the last pass writes the output
            assert all(
                p["output"]["fp16_format"] == f.lower() for p, f in zip(frame["passes"], formats, strict=True)
            )


@pytest.mark.parametrize("api", DIALECTS)
def test_fp16_frame_runs_within_the_fp16_bound_in_every_api(api, frames):
    """The whole frame at fp16 in each API (GL on llvmpipe; Vulkan SPIR-V, WGSL and the HLSL through wgpu
    on lavapipe: 16-bit textures, 16-bit arithmetic where the device has it) against the fp32 frame in
    GL: within the fp16 bound the model's manifest states, and not equal to it (the half-float textures
    were written)."""
    _needs(api)
    errors, bounds = {}, {}
    size = SIZES[1]
    for name in MODELS:
        bounds[name] = read_json(shipped_models()[name] / "manifest.json", "manifest")["fp16"]["bound"]
        proto = _with_internal_height(name, INTERNAL_HEIGHT)
        fp32 = frame_program(proto, "glsl430")
        fp16 = frame_program(proto, APIS[api][0], precision="fp16")
        with FrameRunner(fp32, *size) as a, _runner(fp16, size, api) as b:
            for r in RADII:
                errors[name, r] = float(np.abs(b.run(frames[size], r) - a.run(frames[size], r)).max())
    print(f"{api} fp16 frame vs fp32 frame: max abs AO difference {max(errors.values()):.3g}")
    assert all(0 < e <= bounds[name] for (name, _), e in errors.items()), (errors, bounds)


@pytest.mark.slow
@pytest.mark.parametrize("dialect", DIALECTS)
def test_shipped_internal_height(dialect, frames):
    """The shipped models as they ship (256 rows), one size and radius: the 53-row frame point-sampled up.
    HLSL: the shipped export's files (runtime/models/<name>/glsl/*.hlsl), as an engine loads them."""
    _needs(dialect)
    size, r = SIZES[1], RADII[1]
    for name in MODELS:
        onnx_path = shipped_models()[name] / "model.onnx"
        want = unet_predictor(onnx_path)(frames[size], r)
        if dialect == "hlsl":
            export = shipped_models()[name] / "glsl"
            program, hlsl = load_compute_export(export), load_cross_sources(export, "hlsl")
            runner = FrameRunner(program, *size, via="hlsl", hlsl=hlsl)
        else:
            runner = _runner(_program(name, None, dialect), size, dialect)
        with runner:
            got = runner.run(frames[size], r)
        err = float(np.abs(got - want).max())
        print(f"{name} {dialect} (shipped internal height): max abs error {err:.3g}")
        assert err <= TOL.frame_passes_vs_reference, name


def _with_back_layer(frame: dict) -> dict:
    """The analytic frame with a back layer: the sphere and the box 0.5 deep (depth under 5.5), the floor
    and the wall thin (0)."""
    depth = frame["depth"]
    return dict(frame) | {
        "depth_back": np.where((depth > 0) & (depth < 5.5), depth + 0.5, 0.0).astype(np.float32)
    }


@pytest.mark.parametrize("hybrid", [True, False])
@pytest.mark.parametrize("dialect", DIALECTS)
def test_input_version_4_frame_reads_the_back_layer_like_the_reference(tmp_path, frames, dialect, hybrid):
    """A seeded U-Net of input version 4 (the back layer's thickness as a fifth channel): the generated
    frame (the engine's depth_back point-sampled beside depth, the thickness in the network's input)
    against onnxruntime on numpy's preprocessing; the layer moves the AO, so ignoring it would fail."""
    import torch

    from neuralao.export.unet import export_onnx, onnx_metadata
    from neuralao.pipeline.models.unet import UNet, UNetArgs

    _needs(dialect)
    torch.manual_seed(5)
    args = UNetArgs(in_channels=6 if hybrid else 5, widths=[4, 8], gtao_input=hybrid, preprocess_version=4)
    model = UNet(args).eval()
    with torch.no_grad():
        model.out.weight.mul_(4.0)
    meta = onnx_metadata(model) | {"internal_height": str(INTERNAL_HEIGHT)}
    proto = export_onnx(model, tmp_path / "model.onnx", meta)
    predict = unet_predictor(tmp_path / "model.onnx")
    program = frame_program(proto, APIS[dialect][0])
    assert "depth_back" in program.manifest["frame"]["inputs"]
    errors, moved = [], []
    for size in SIZES[1:]:
        f = _with_back_layer(frames[size])
        with _runner(program, size, dialect) as runner:
            for r in RADII[:2]:
                want = predict(f, r)
                errors.append(float(np.abs(runner.run(f, r) - want).max()))
                thin = dict(f) | {"depth_back": np.zeros_like(f["depth_back"])}
                moved.append(float(np.abs(predict(thin, r) - want).max()))
    assert max(errors) <= TOL.frame_passes_vs_reference, errors
    assert max(moved) > 20 * TOL.frame_passes_vs_reference, moved


@pytest.mark.parametrize("dialect", DIALECTS)
def test_hybrid_on_gtao_without_its_blur_runs_like_the_reference(tmp_path, frames, dialect):
    """A seeded hybrid trained on GTAO's pass without its blur (metadata gtao_blur "false"): its frame has
    no blur step and feeds the raw GTAO to the network, as onnxruntime on the unblurred GTAO does; the same
    weights read as a blurred hybrid give another AO, so a frame that kept the blur would fail."""
    import torch

    from neuralao.export.unet import export_onnx, onnx_metadata
    from neuralao.pipeline.models.unet import UNet, UNetArgs

    _needs(dialect)
    torch.manual_seed(6)
    args = UNetArgs(in_channels=5, widths=[4, 8], gtao_input=True, gtao_blur=False)
    model = UNet(args).eval()
    with torch.no_grad():
        model.out.weight.mul_(4.0)
    meta = onnx_metadata(model) | {"internal_height": str(INTERNAL_HEIGHT)}
    assert meta["gtao_blur"] == "false"
    proto = export_onnx(model, tmp_path / "model.onnx", meta)
    blurred = export_onnx(
        model, tmp_path / "blurred.onnx", {k: v for k, v in meta.items() if k != "gtao_blur"}
    )
    predict, predict_blurred = (
        unet_predictor(tmp_path / "model.onnx"),
        unet_predictor(tmp_path / "blurred.onnx"),
    )
    program = frame_program(proto, APIS[dialect][0])

    def frame_passes(p) -> list[str]:
        return [s["frame_pass"] for s in p.manifest["frame"]["steps"] if "frame_pass" in s]

    assert "f_gtao" in frame_passes(program) and "f_gtao_blur" not in frame_passes(program)
    assert "gtao_raw" not in program.manifest["frame"]["textures"]
    assert "f_gtao_blur" in frame_passes(frame_program(blurred, APIS[dialect][0]))
    errors, moved = [], []
    for size in SIZES[1:]:
        f = frames[size]
        with _runner(program, size, dialect) as runner:
            for r in RADII[:2]:
                want = predict(f, r)
                errors.append(float(np.abs(runner.run(f, r) - want).max()))
                moved.append(float(np.abs(predict_blurred(f, r) - want).max()))
    assert max(errors) <= TOL.frame_passes_vs_reference, errors
    assert max(moved) > 20 * TOL.frame_passes_vs_reference, moved


@pytest.mark.parametrize("version", [3, 4])
@pytest.mark.parametrize("dialect", DIALECTS)
def test_hybrid_on_both_gtao_images_runs_like_the_reference(tmp_path, frames, dialect, version):
    """A seeded hybrid that reads GTAO before its blur beside the blurred GTAO (input channels ...,
    gtao_raw, gtao; with the back layer's thickness in front at version 4): the frame point-samples both
    images and packs them where onnxruntime's input has them, as numpy's preprocessing does; swapping the
    two images moves the AO, so a frame that mixed them up would fail."""
    import torch

    from neuralao.export.unet import export_onnx, onnx_metadata
    from neuralao.pipeline.models.unet import UNet, UNetArgs
    from neuralao.runtime.predict import reads_gtao_raw

    _needs(dialect)
    torch.manual_seed(7)
    channels = 7 if version == 4 else 6
    args = UNetArgs(
        in_channels=channels, widths=[4, 8], gtao_input=True, gtao_raw_input=True, preprocess_version=version
    )
    model = UNet(args).eval()
    with torch.no_grad():
        model.out.weight.mul_(4.0)
    meta = onnx_metadata(model) | {"internal_height": str(INTERNAL_HEIGHT)}
    proto = export_onnx(model, tmp_path / "model.onnx", meta)
    assert reads_gtao_raw(meta)
    predict = unet_predictor(tmp_path / "model.onnx")
    program = frame_program(proto, APIS[dialect][0])
    errors, moved = [], []
    for size in SIZES[1:]:
        f = _with_back_layer(frames[size]) if version == 4 else frames[size]
        with _runner(program, size, dialect) as runner:
            for r in RADII[:2]:
                want = predict(f, r)
                errors.append(float(np.abs(runner.run(f, r) - want).max()))
    # the test can fail: onnxruntime on the same frame with the blurred GTAO in both channels gives
    # another AO, so the unblurred image the frame packs in front of GTAO matters to these weights
    from neuralao.runtime.baselines import GTAOSettings, run_gtao
    from neuralao.runtime.predict import ort_runner, run_padded
    from neuralao.runtime.unet_input import frame_radius_param, preprocess_frame

    run = ort_runner(str(tmp_path / "model.onnx"))
    f = _with_back_layer(frames[SIZES[1]]) if version == 4 else frames[SIZES[1]]
    for r in RADII[:2]:
        blurred, raw = run_gtao(f, r), run_gtao(f, r, GTAOSettings(blur=False))
        rho = frame_radius_param(f, r, version)
        ao = [
            run_padded(run, preprocess_frame(f, blurred, version, image), model.pad_multiple, rho)
            for image in (raw, blurred)
        ]
        moved.append(float(np.abs(ao[0] - ao[1])[np.asarray(f["mask"], bool)].max()))
    assert max(errors) <= TOL.frame_passes_vs_reference, errors
    assert max(moved) > 20 * TOL.frame_passes_vs_reference, moved
