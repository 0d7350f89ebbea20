"""HLSL and MSL of the compute passes: the names, registers and indices the manifest lists, and the HLSL
executed.

* HLSL: every network pass of both shipped U-Nets, written by SPIRV-Cross from the GLSL (shader model
  5.0, an entry point named after each pass), is compiled back to Vulkan SPIR-V by glslang's HLSL front
  end and run on Mesa lavapipe through wgpu's SPIR-V passthrough (``runtime/wgsl_runner.run_hlsl_all``),
  bound by the manifest's registers with a weight buffer of its own per pass, against onnxruntime at
  three frame sizes (two not multiples of 8) and three radii; the whole frame's HLSL (frame passes and
  network) runs in tests/test_frame_passes.py (``FrameRunner(..., via="hlsl")``);
* every pass, the network's and the frame's (position, GTAO, blur, downsample, depth reduction, input
  assembly, upsample, composite): the HLSL declarations (type, name, register) are exactly the
  manifest's ``hlsl.resources`` (plus one unused SamplerState per input; a frame pass's
  ``cbuffer FrameUniforms`` at ``b0`` with the listed members at their std140 offsets),
  ``[numthreads]`` is the pass's ``local_size`` and the entry point is the pass's name; the SPIR-V
  glslang makes of it names each resource at the binding its register maps to (SPIRV-Cross's
  reflection): what Unity and Unreal bind by name, a D3D host by register;
* MSL (no Metal compiler or runtime here, so this is all that is checked for it), every pass: the
  kernel's signature, parsed, is exactly the manifest's ``msl.arguments`` (type, name,
  ``[[texture(k)]]`` / ``[[buffer(k)]]``) plus the unused samplers and the thread position, the kernel
  is named after the pass, no two arguments of a kind share an index, every listed argument is used in
  the body, the MSL declares ``gl_WorkGroupSize`` as the pass's ``threads_per_threadgroup``, and a frame
  pass's ``struct FrameUniforms`` has the manifest's members in order.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import onnx
import pytest

from neuralao.export.glsl import compile_hlsl, write_compute_export
from neuralao.export.glsl.cross import hlsl_spirv_binding
from neuralao.export.glsl.frame import UNIFORM_MEMBERS, shader_entries
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame_runner import frame_program
from neuralao.runtime.shipped import shipped_models

pytestmark = pytest.mark.skipif(
    shutil.which("spirv-cross") is None or shutil.which("glslangValidator") is None,
    reason="HLSL / MSL need spirv-cross and glslangValidator (Debian: spirv-cross, glslang-tools)",
)
MODELS = ("unet-gtao", "unet-fast")
# (width, height): tiny frames; 37 x 21 and 24 x 16's height pad to the model's multiple of 8 and back
SIZES = ((24, 16), (37, 21), (48, 48))
RADII = (0.05, 0.2, 0.8)  # rho of the radius input: the network's radius channel is clip(rho / depth, 0, 8)


@pytest.fixture(scope="module", params=MODELS)
def cross_export(request, tmp_path_factory):
    """(model name, export folder, manifest) of a shipped U-Net's GLSL passes, the network's and the
    frame's, with their HLSL and MSL. Written unvalidated: the tests below compile every HLSL pass
    themselves."""
    model = request.param
    program = frame_program(onnx.load(shipped_models()[model] / "model.onnx"))
    out = tmp_path_factory.mktemp(model)
    manifest = json.loads(write_compute_export(program, out, validate=False, cross=True).read_text())
    return model, out, manifest


def _gbuffer(channels: int, height: int, width: int, seed: int) -> np.ndarray:
    """(1, C, H, W) float32 network input of the shipped layout: log depth, a unit normal facing the
    camera, and for the hybrid its GTAO channels (one image or two) in [0, 1]."""
    rng = np.random.default_rng(seed)
    x = np.empty((1, channels, height, width), np.float32)
    x[0, 0] = rng.normal(0.0, 0.3, (height, width))
    n = rng.normal(size=(3, height, width)) * 0.4 + np.array([0.0, 0.0, 1.0])[:, None, None]
    x[0, 1:4] = n / np.linalg.norm(n, axis=0)
    x[0, 4:] = rng.uniform(0.0, 1.0, (channels - 4, height, width))
    return x


def _reference(model: str, manifest: dict, x: np.ndarray, rho: float) -> np.ndarray:
    """onnxruntime on x reflect-padded to the manifest's multiple (what the pad pass does), cropped."""
    multiple = manifest["pad"]["multiple"]
    _, _, h, w = x.shape
    padded = np.pad(x, ((0, 0), (0, 0), (0, -h % multiple), (0, -w % multiple)), mode="reflect")
    radius = np.full((1, 1, 1, 1), rho, np.float32)
    path = shipped_models()[model] / "model.onnx"
    return run_onnxruntime(path.read_bytes(), {"gbuffer": padded, "radius": radius})[0][..., :h, :w]


def _wgpu_passthrough():
    """Skip (with the reason) where wgpu, a Vulkan adapter or SPIR-V passthrough is missing."""
    wgpu = pytest.importorskip("wgpu", reason="the wgpu package is not installed (pyproject pins it)")
    try:
        adapter = wgpu.gpu.request_adapter_sync()
    except RuntimeError:
        adapter = None
    if adapter is None:
        pytest.skip("no WebGPU adapter (Debian: mesa-vulkan-drivers)")
    if "spirv-shader-passthrough" not in adapter.features:
        pytest.skip(f"adapter {adapter.info['device']!r} has no SPIR-V passthrough (not a Vulkan adapter)")


def test_hlsl_runs_on_lavapipe_vs_onnxruntime(cross_export):
    _wgpu_passthrough()
    from neuralao.runtime.wgsl_runner import run_hlsl_all

    model, out, manifest = cross_export
    (onnx_name,) = [o["onnx_name"] for o in manifest["outputs"]]
    for k, (w, h) in enumerate(SIZES):
        x = _gbuffer(manifest["input"]["channels"], h, w, seed=k)
        for rho in RADII:
            ref = _reference(model, manifest, x, rho)
            got = run_hlsl_all(out, x, scalars={"radius": np.float32(rho)})[onnx_name]
            assert got.shape == ref.shape == (1, 1, h, w) and got.dtype == ref.dtype == np.float32
            err = float(np.abs(got - ref).max())
            assert err <= TOL.parity_unet_fp32, f"{model} {w}x{h} rho {rho}: max abs err {err:.3g}"


# HLSL resource declarations as SPIRV-Cross writes them: "TYPE NAME : register(REG);", "uniform T N;" or
# "cbuffer NAME : register(REG)" (its members on the lines after)
_HLSL_DECL = re.compile(
    r"^(?:(?P<type>\S+) (?P<name>\w+) : register\((?P<reg>\w+)\)|uniform (?P<utype>\w+) (?P<uname>\w+))"
    r"(?(type);?|;)$"
)


def _hlsl_declarations(source: str) -> list[dict]:
    decls = []
    for line in source.splitlines():
        m = _HLSL_DECL.match(line)
        if m and m["uname"]:
            decls.append({"name": m["uname"], "type": m["utype"], "register": "b0"})
        elif m:
            decls.append({"name": m["name"], "type": m["type"], "register": m["reg"]})
    return decls


# A cbuffer member as SPIRV-Cross writes it: "    TYPE NAME : packoffset(cN[.xyzw]);"
_HLSL_MEMBER = re.compile(r"^    (\w+) (\w+) : packoffset\(c(\d+)(?:\.([xyzw]))?\);$", re.M)


def _cbuffer_members(source: str, name: str) -> list[dict]:
    """The members of ``cbuffer <name>``: [{"name", "type", "offset" (bytes)}] in order."""
    body = source[source.index(f"cbuffer {name} :") :].split("};", 1)[0]
    return [
        {"name": m[2], "type": m[1], "offset": 16 * int(m[3]) + 4 * "xyzw".index(m[4] or "x")}
        for m in _HLSL_MEMBER.finditer(body)
    ]


def test_hlsl_declares_the_manifest_resources_and_entry(cross_export):
    _, out, manifest = cross_export
    assert {p["name"] for p in manifest["frame"]["passes"]} <= {p["name"] for p in shader_entries(manifest)}
    for p in shader_entries(manifest):
        hlsl = p["hlsl"]
        source = (out / hlsl["file"]).read_text()
        want = [{k: r[k] for k in ("name", "type", "register")} for r in hlsl["resources"]]
        samplers = [
            {"name": f"_{r['name']}_sampler", "type": "SamplerState", "register": "s" + r["register"][1:]}
            for r in hlsl["resources"]
            if r["type"] == "Texture2DArray<float4>"
        ]
        key = lambda d: d["name"]  # noqa: E731
        assert sorted(_hlsl_declarations(source), key=key) == sorted(want + samplers, key=key), p["name"]
        assert hlsl["entry"] == p["name"] and hlsl["numthreads"] == p["local_size"]
        lx, ly, lz = p["local_size"]
        assert f"[numthreads({lx}, {ly}, {lz})]\nvoid {p['name']}(SPIRV_Cross_Input stage_input)" in source
        assert not re.search(r"\b_\d+_\w+ :", source)  # no generated resource or member names
        assert manifest["files"][hlsl["file"]]
        if "uniform_block" in p:  # a frame pass: FrameUniforms at b0, the members at their std140 offsets
            (cb,) = [r for r in hlsl["resources"] if r["type"] == "cbuffer"]
            assert cb["name"] == "FrameUniforms" and cb["register"] == "b0" and cb["bytes"] == 32
            assert _cbuffer_members(source, "FrameUniforms") == cb["members"], p["name"]
            assert [(m["name"], m["offset"]) for m in cb["members"]] == [
                (f"frame_{name}", offset) for name, _, offset, _ in UNIFORM_MEMBERS
            ]
            (dst,) = [r for r in hlsl["resources"] if r["name"] == "dst"]
            assert dst["register"] == "u0"
        if "params" in p:  # the pass's own buffer: its weights.bin range, read from byte 0
            (prm,) = [r for r in hlsl["resources"] if r["type"] == "ByteAddressBuffer"]
            assert prm["weights"] == {
                "file": "weights.bin",
                "offset": p["params"]["offset"],
                "bytes": p["params"]["bytes"],
            }
            assert prm["name"] == "params" and prm["register"] == "t16"


_REFLECT_KINDS = {
    "separate_images": "Texture2DArray",
    "images": "RWTexture2DArray",
    "ssbos": "ByteAddressBuffer",
}


def test_hlsl_spirv_binds_each_name_at_its_register(cross_export, tmp_path):
    """glslang's SPIR-V of each HLSL pass (what the run above executes) has exactly the manifest's
    resources, by name and type, each at the binding its register maps to; a network pass's uniform is
    the one member of $Globals, at offset 0; a frame pass's FrameUniforms has the listed members."""
    _, out, manifest = cross_export
    spv = tmp_path / "pass.spv"
    for p in shader_entries(manifest):
        hlsl = p["hlsl"]
        spv.write_bytes(compile_hlsl((out / hlsl["file"]).read_text(), hlsl["entry"]))
        r = subprocess.run(["spirv-cross", str(spv), "--reflect"], capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        refl = json.loads(r.stdout)
        assert [e["name"] for e in refl["entryPoints"]] == [p["name"]]
        got = sorted(
            (res["name"], kind, res["set"], res["binding"])
            for key, kind in _REFLECT_KINDS.items()
            for res in refl.get(key, [])
        )
        want = sorted(
            (res["name"], res["type"].split("<")[0], 0, hlsl_spirv_binding(res["register"]))
            for res in hlsl["resources"]
            if "cbuffer" not in res and "uniform_block" not in res
        )
        assert got == want, p["name"]
        uniforms = [res for res in hlsl["resources"] if "cbuffer" in res or "uniform_block" in res]
        ubos = refl.get("ubos", [])
        assert len(ubos) == len(uniforms) <= 1, p["name"]
        for ubo, res in zip(ubos, uniforms, strict=True):
            assert ubo["binding"] == hlsl_spirv_binding(res["register"]), p["name"]
            members = [(m["name"], m["offset"]) for m in refl["types"][ubo["type"]]["members"]]
            if "uniform_block" in res:
                assert ubo["name"] == "FrameUniforms"
                assert members == [(m["name"], m["offset"]) for m in res["members"]]
            else:
                assert ubo["name"] == "$Global" and members == [(res["name"], res["offset"])]


def _msl_signature(source: str, kernel: str) -> list[dict]:
    """The arguments of ``kernel void <kernel>(...)``: [{"type", "name", "attr"}] in order."""
    m = re.search(rf"^kernel void {kernel}\((.*)\)$", source, re.M)
    assert m, f"no kernel {kernel}"
    args = []
    for piece in m[1].split("]], "):
        a = re.fullmatch(r"(.+) (\w+) \[\[(\w+(?:\(\d+\))?)(?:\]\])?", piece.strip())
        assert a, piece
        args.append({"type": a[1], "name": a[2], "attr": a[3]})
    return args


def test_msl_kernel_is_the_manifest_arguments(cross_export):
    _, out, manifest = cross_export
    for p in shader_entries(manifest):
        msl = p["msl"]
        source = (out / msl["file"]).read_text()
        assert msl["kernel"] == p["name"] and msl["threads_per_threadgroup"] == p["local_size"]
        args = _msl_signature(source, msl["kernel"])
        want = [{"type": a["type"], "name": a["name"], "attr": a["index"]} for a in msl["arguments"]]
        samplers = [
            {"type": "sampler", "name": f"{a['name']}Smplr", "attr": a["index"].replace("texture", "sampler")}
            for a in msl["arguments"]
            if a["type"] == "texture2d_array<float>"
        ]
        position = {"type": "uint3", "name": "gl_GlobalInvocationID", "attr": "thread_position_in_grid"}
        # Metal fills its builtins itself: a pass sharing workgroup memory (the upsampling) also takes its
        # thread's index in the threadgroup and the threadgroup's position; nothing else is unbound
        builtins = {"thread_position_in_grid", "thread_index_in_threadgroup", "threadgroup_position_in_grid"}
        key = lambda d: d["name"]  # noqa: E731
        bound = [a for a in args if a["attr"] not in builtins]
        assert position in args and len(args) - len(bound) <= len(builtins), p["name"]
        assert sorted(bound, key=key) == sorted(want + samplers, key=key), p["name"]
        attrs = [a["attr"] for a in args]
        assert len(set(attrs)) == len(attrs), p["name"]  # no index shared within a kind
        body = source[source.index(f"kernel void {msl['kernel']}(") :].split("\n", 1)[1]
        for a in msl["arguments"]:
            assert re.search(rf"\b{a['name']}\b", body), (p["name"], a["name"])
        lx, ly, lz = p["local_size"]
        if (lx, ly, lz) != (1, 1, 1):  # SPIRV-Cross leaves the constant out of a one-thread group
            assert f"gl_WorkGroupSize [[maybe_unused]] = uint3({lx}u, {ly}u, {lz}u);" in source
        assert "main0" not in source and "v_60" not in source
        if "uniform_block" in p:  # the struct an engine fills: the GLSL block's members, in order
            struct = source[source.index("struct FrameUniforms\n{") :].split("};", 1)[0]
            assert re.findall(r"^    \w+ (\w+);$", struct, re.M) == [m[0] for m in UNIFORM_MEMBERS]
