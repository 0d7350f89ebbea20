"""The engine wrappers under docs/engines/ (Unity, Unreal, Godot 4) cannot drift from the exports.

No engine runs here. What is checked, for both shipped U-Nets:

* the files are what :mod:`neuralao.export.glsl.engines` writes from today's manifests (regenerated and
  compared, byte for byte);
* read back independently of the generator (regular expressions over the C#, C++ and GDScript), every
  pass is there in order with its entry point, and each pass binds exactly the resources of the manifest
  (name, texture, weight range, uniform; Unreal: HLSL type and register too), each name declared in that
  pass's generated HLSL at that register, and dispatches the groups the manifest's ``dispatch`` formulas
  state (texture counted on, texels per group in x and y, groups in z); the Godot table's bindings are
  the Vulkan manifest's (which tests/test_vulkan_target.py checks against the SPIR-V) and its texture
  sizes the manifest's formulas; Unity's texture allocations are the manifest's sizes, layers, formats.

The HLSL the Unity and Unreal wrappers bind runs in tests/test_hlsl_target.py, bound the same way (by
the manifest's names and registers, a weight buffer per pass); the SPIR-V the Godot wrapper loads runs
in tests/test_vulkan_target.py.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import onnx
import pytest
from test_hlsl_target import _hlsl_declarations

from neuralao.export.glsl import generate_compute, write_compute_export
from neuralao.export.glsl.engines import class_name, engine_wrappers
from neuralao.runtime.shipped import shipped_models

DOCS = Path(__file__).resolve().parents[1] / "docs" / "engines"
REGENERATE = "python -m neuralao.export.glsl.engines runtime/models/{0}/model.onnx {0} docs/engines"


@pytest.fixture(scope="module", params=["unet-gtao", "unet-fast"])
def wrapped(request, tmp_path_factory):
    """(model, GLSL manifest (with HLSL entries where spirv-cross is installed), its export folder or None,
    Vulkan manifest, {path: text} in docs, {path: text} generated now)."""
    model = request.param
    onnx_model = onnx.load(shipped_models()[model] / "model.onnx")
    glsl = generate_compute(onnx_model).manifest
    vulkan = generate_compute(onnx_model, dialect="vulkan").manifest
    generated = engine_wrappers(glsl, vulkan, model)
    docs = {rel: (DOCS / model / rel).read_text() for rel in generated}
    out = None
    if shutil.which("spirv-cross") and shutil.which("glslangValidator"):
        out = tmp_path_factory.mktemp(model)
        write_compute_export(generate_compute(onnx_model), out, validate=False, cross=True)
        glsl = json.loads((out / "manifest.json").read_text())
    return model, glsl, out, vulkan, docs, generated


def test_wrappers_are_generated_from_todays_manifests(wrapped):
    model, _, _, _, docs, generated = wrapped
    for rel, text in generated.items():
        assert docs[rel] == text, f"docs/engines/{model}/{rel} is stale: {REGENERATE.format(model)}"


def _groups(manifest: dict, p: dict) -> tuple[str, int, int, int]:
    """(texture, texels x a group, texels y a group, groups z), read from the manifest's formulas
    ("ceil(width(t3) / 64)", "ceil(height(t3) / 32)", "layers(t3) / 1 = 1")."""
    gx, gy, gz = p["dispatch"]["groups"]
    mx = re.fullmatch(r"ceil\(width\((t\d+)\) / (\d+)\)", gx)
    my = re.fullmatch(r"ceil\(height\((t\d+)\) / (\d+)\)", gy)
    mz = re.fullmatch(r"layers\((t\d+)\) / \d+ = (\d+)", gz)
    assert mx and my and mz and mx[1] == my[1] == mz[1], p["dispatch"]
    return mx[1], int(mx[2]), int(my[2]), int(mz[2])


def _blocks(text: str, marker: str, names: list[str]) -> dict[str, str]:
    """{pass name: its block}: the text from each ``<marker><name>:`` comment to the next."""
    starts = [(m.start(), m[1]) for m in re.finditer(rf"{re.escape(marker)}(p\d\d_\w+):", text)]
    assert [n for _, n in starts] == names
    ends = [s for s, _ in starts[1:]] + [len(text)]
    return {n: text[s:e] for (s, n), e in zip(starts, ends, strict=True)}


def _check_hlsl_names(out: Path | None, p: dict, names: dict[str, str]) -> None:
    """Each bound {name: register} is declared in the pass's generated HLSL at that register."""
    if out is None:
        pytest.skip("spirv-cross / glslangValidator not installed: the HLSL is not generated")
    declared = {d["name"]: d["register"] for d in _hlsl_declarations((out / p["hlsl"]["file"]).read_text())}
    for name, register in names.items():
        assert declared.get(name) == register, (p["name"], name, register, declared)


def _resources(p: dict) -> list[dict]:
    from neuralao.export.glsl import hlsl_interface

    return hlsl_interface(p)["resources"]


def test_unity_binds_and_dispatches_what_the_manifest_says(wrapped):
    model, glsl, out, _, docs, _ = wrapped
    cls = class_name(model)
    cs, compute = docs[f"unity/{cls}.cs"], docs[f"unity/{cls}.compute"]
    passes = glsl["passes"]
    names = [p["name"] for p in passes]
    kernels = re.findall(r"^#pragma kernel (\w+) NEURALAO_PASS=(\d+)$", compute, re.M)
    assert kernels == [(n, str(k)) for k, n in enumerate(names)]
    includes = re.findall(r"^#(?:el)?if NEURALAO_PASS == (\d+)\n#include \"(\S+)\"$", compute, re.M)
    assert includes == [(str(k), f"{n}.hlsl") for k, n in enumerate(names)]
    weights = {int(k): (int(o), int(b)) for k, o, b in re.findall(r"Weights\((\d+), (\d+), (\d+)\);", cs)}
    assert weights == {
        k: (p["params"]["offset"], p["params"]["bytes"]) for k, p in enumerate(passes) if "params" in p
    }
    allocated = {
        t: (w, h, int(n), f) for t, w, h, n, f in re.findall(
            r'tex\["(t\d+)"\] = Array2D\((.+?), (.+?), (\d+), RenderTextureFormat\.(\w+)\);', cs
        )
    }  # fmt: skip
    formats = {"RGBA32F": "ARGBFloat", "RGBA16F": "ARGBHalf"}
    for ident, t in glsl["textures"].items():
        w, h, layers, fmt = allocated.pop(ident)
        for expr, dim in ((w, t["width"]), (h, t["height"])):
            for base in (8, 24, 1920):  # the C# expression and the manifest's size agree
                got = eval(re.sub(r"\b(Wp|Hp|W|H)\b", str(base), expr).replace("/", "//"))  # noqa: S307
                assert got == base * dim["num"] // dim["den"] + dim["offset"], (ident, expr)
        assert (layers, fmt) == (t["layers"], formats[t["format"]]), ident
    assert not allocated
    for k, (p, block) in enumerate(zip(passes, _blocks(cs, "// ", names).values(), strict=True)):
        assert f'k = shader.FindKernel("{p["name"]}");' in block
        res = _resources(p)
        textures = dict(re.findall(r'shader\.SetTexture\(k, "(\w+)", tex\["(t\d+)"\]\);', block))
        assert textures == {r["name"]: r["texture"] for r in res if "texture" in r}, p["name"]
        buffers = re.findall(r'shader\.SetBuffer\(k, "(\w+)", passWeights\[(\d+)\]\);', block)
        assert buffers == [(r["name"], str(k)) for r in res if "weights" in r], p["name"]
        scalars = re.findall(r'shader\.Set(?:Int|Float)\("(\w+)", ', block)
        assert scalars == [r["name"] for r in res if "cbuffer" in r], p["name"]
        (dispatch,) = re.findall(
            r'shader\.Dispatch\(k, CeilDiv\(tex\["(t\d+)"\]\.width, (\d+)\), '
            r'CeilDiv\(tex\["(t\d+)"\]\.height, (\d+)\), (\d+)\);',
            block,
        )
        size_of, gx, gy, gz = _groups(glsl, p)
        assert dispatch == (size_of, str(gx), size_of, str(gy), str(gz)), p["name"]
        _check_hlsl_names(out, p, {r["name"]: r["register"] for r in res})


_UNREAL_MACROS = {
    "SHADER_PARAMETER_RDG_TEXTURE_SRV": "Texture2DArray<float4>",
    "SHADER_PARAMETER_RDG_TEXTURE_UAV": "RWTexture2DArray<float4>",
    "SHADER_PARAMETER_RDG_BUFFER_SRV": "ByteAddressBuffer",
}


def test_unreal_shader_classes_and_passes_are_the_manifest(wrapped):
    model, glsl, out, _, docs, _ = wrapped
    cls = class_name(model)
    header, cpp, usf = docs[f"unreal/{cls}.h"], docs[f"unreal/{cls}.cpp"], docs[f"unreal/{cls}.usf"]
    passes = glsl["passes"]
    names = [p["name"] for p in passes]
    includes = re.findall(r"^#(?:el)?if NEURALAO_PASS == (\d+)\n#include \"(\S+)\"$", usf, re.M)
    assert includes == [(str(k), f"{n}.ush") for k, n in enumerate(names)]
    implements = re.findall(
        r'IMPLEMENT_GLOBAL_SHADER\(F(\w+), "/Plugin/NeuralAO/(\S+)", "(\w+)", SF_Compute\);', cpp
    )
    assert implements == [(n, f"{cls}.usf", n) for n in names]
    classes = re.findall(r"^class F(\w+) : public FGlobalShader\n(.*?)^\};", header, re.M | re.S)
    assert [c for c, _ in classes] == names
    for k, (p, (_, body), block) in enumerate(
        zip(passes, classes, _blocks(cpp, "{  // ", names).values(), strict=True)
    ):
        res = _resources(p)
        assert f'SetDefine(TEXT("NEURALAO_PASS"), {k});' in body
        params = re.findall(r"^ +(SHADER_PARAMETER\w*)\((.+?), (\w+)\)  // (\S+)$", body, re.M)
        want = []
        for r in res:
            if "cbuffer" in r:
                want.append(
                    ("SHADER_PARAMETER", "int32" if r["type"] == "int" else "float", r["name"], "$Globals")
                )
            else:
                macro = next(m for m, t in _UNREAL_MACROS.items() if t == r["type"])
                want.append((macro, r["type"], r["name"], r["register"]))
        assert params == want, p["name"]
        binds = re.findall(r"P->(\w+) = (?:Srv|Uav)\(TEXT\(\"(t\d+)\"\)\);", block)
        assert binds == [(r["name"], r["texture"]) for r in res if "texture" in r], p["name"]
        assert re.findall(r"P->(\w+) = Raw\((\d+)\);", block) == [
            (r["name"], str(k)) for r in res if "weights" in r
        ]
        (dispatch,) = re.findall(
            r'DivideAndRoundUp\(Size\(TEXT\("(t\d+)"\)\)\.X, (\d+)\), '
            r'FMath::DivideAndRoundUp\(Size\(TEXT\("(t\d+)"\)\)\.Y, (\d+)\), (\d+)\)\);',
            block,
        )
        size_of, gx, gy, gz = _groups(glsl, p)
        assert dispatch == (size_of, str(gx), size_of, str(gy), str(gz)), p["name"]
        _check_hlsl_names(out, p, {r["name"]: r["register"] for r in res})


def test_godot_table_is_the_vulkan_manifest(wrapped):
    model, _, _, vulkan, docs, _ = wrapped
    gd = docs[f"godot/{model.replace('-', '_')}_network.gd"]
    assert f"class_name {class_name(model)}" in gd and "extends CompositorEffect" in gd
    rows = re.findall(r'^    \["(\w+)", "(\S+)", \["(t\d+)", (\d+), (\d+), (\d+)\], \[(.*)\]\],$', gd, re.M)
    assert [r[0] for r in rows] == [p["name"] for p in vulkan["passes"]]
    for p, (_, spv, size_of, gx, gy, gz, bindings) in zip(vulkan["passes"], rows, strict=True):
        assert spv == p["shader"].removesuffix(".comp") + ".spv"
        assert (size_of, int(gx), int(gy), int(gz)) == _groups(vulkan, p), p["name"]
        got = json.loads(f"[{bindings}]")
        want = []
        for b in p["bindings"]:
            if b["kind"] == "storage_buffer":
                want.append([b["binding"], "weights", [p["params"]["offset"], p["params"]["bytes"]]])
            elif b["kind"] == "uniform_buffer":
                want.append([b["binding"], "uniform", p["uniform_block"]["members"][0]["name"]])
            else:
                want.append(
                    [
                        b["binding"],
                        {"sampled_image": "texture", "storage_image": "image"}[b["kind"]],
                        b["resource"],
                    ]
                )
        assert got == want and all(b["set"] == 0 for b in p["bindings"]), p["name"]
    textures = re.findall(
        r'^    "(t\d+)": \["(\w+)", (\d+), (\d+), (\d+), "(\w+)", (\d+), (\d+), (\d+), (\d+), '
        r"RenderingDevice\.(\w+)\],$",
        gd,
        re.M,
    )
    formats = {"RGBA32F": "DATA_FORMAT_R32G32B32A32_SFLOAT", "RGBA16F": "DATA_FORMAT_R16G16B16A16_SFLOAT"}
    want = [
        (i, t["width"]["of"], *(str(t["width"][k]) for k in ("num", "den", "offset")), t["height"]["of"],
         *(str(t["height"][k]) for k in ("num", "den", "offset")), str(t["layers"]), formats[t["format"]])
        for i, t in vulkan["textures"].items()
    ]  # fmt: skip
    assert textures == want
    for u in vulkan.get("uniforms", []):
        assert f"@export var {u['glsl_name']} := " in gd
