"""The engine wrappers under docs/engines/ (Unity, Unreal, Godot 4) run each shipped export's whole frame
and cannot drift from its manifests.

No engine runs here. What is checked, for both shipped U-Nets, against the export's own manifests
(runtime/models/<model>/{glsl,vulkan}/manifest.json, their ``frame`` sections):

* the files are what :mod:`neuralao.export.glsl.engines` writes from those manifests, byte for byte;
* read back independently of the generator (regular expressions over the C#, C++ and GDScript): every
  step of ``frame.steps`` in order (a skipped step named as skipped, a ``when`` step inside the matching
  size condition), each dispatched pass's kernel / shader class / Godot row with its ``NEURALAO_PASS``
  include of the exported HLSL; per step the resources bound are exactly the pass's ``hlsl.resources``
  (name, texture, weight range, FrameUniforms cbuffer, ``u_flip_y``; Unreal: HLSL type and register
  too), each declared in the exported HLSL at that register, and the dispatch is the manifest's
  ``dispatch`` formula; every texture of ``frame.textures`` is allocated at its size (the C# and C++
  expressions evaluated, the Godot formulas read back, against :func:`frame_sizes`), layers and
  format; the FrameUniforms lanes and members sit at the manifest's offsets with the HLSL's names; the
  Godot table's bindings are the Vulkan manifest's.

The HLSL the Unity and Unreal wrappers bind runs the whole frame in tests/test_frame_passes.py, bound the
same way; the SPIR-V the Godot wrapper loads runs there too.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from test_hlsl_target import _cbuffer_members, _hlsl_declarations

from neuralao.export.glsl.engines import class_name, engine_wrappers, export_manifests, godot_file
from neuralao.export.glsl.frame import frame_sizes
from neuralao.runtime.frame_runner import frame_program
from neuralao.runtime.shipped import shipped_models

DOCS = Path(__file__).resolve().parents[1] / "docs" / "engines"
REGENERATE = "python -m neuralao.export.glsl.engines runtime/models/{0}/model.onnx {0} docs/engines"
SIZES = ((64, 48), (1920, 1080), (333, 256), (256, 256))  # (W, H): scaled, odd, the network's own size
UNITY_FORMATS = {
    "RGBA32F": "ARGBFloat",
    "RGBA16F": "ARGBHalf",
    "R32F": "RFloat",
    "R16F": "RHalf",
    "R16": "R16",
}
UNREAL_FORMATS = {
    "RGBA32F": "PF_A32B32G32R32F",
    "RGBA16F": "PF_FloatRGBA",
    "R32F": "PF_R32_FLOAT",
    "R16F": "PF_R16F",
    "R16": "PF_G16",
}
GODOT_FORMATS = {
    "RGBA32F": "DATA_FORMAT_R32G32B32A32_SFLOAT",
    "RGBA16F": "DATA_FORMAT_R16G16B16A16_SFLOAT",
    "R32F": "DATA_FORMAT_R32_SFLOAT",
    "R16F": "DATA_FORMAT_R16_SFLOAT",
    "R16": "DATA_FORMAT_R16_UNORM",
}


@pytest.fixture(scope="module", params=["unet-gtao", "unet-fast"])
def wrapped(request):
    """(model, export folder, GLSL manifest, Vulkan manifest, {path: text} in docs, {path: text} now)."""
    model = request.param
    root = shipped_models()[model]
    glsl, vulkan = export_manifests(root)
    generated = engine_wrappers(glsl, vulkan, model)
    docs = {rel: (DOCS / model / rel).read_text() for rel in generated}
    return model, root, glsl, vulkan, docs, generated


def test_wrappers_are_generated_from_todays_manifests(wrapped):
    model, _, _, _, docs, generated = wrapped
    for rel, text in generated.items():
        assert docs[rel] == text, f"docs/engines/{model}/{rel} is stale: {REGENERATE.format(model)}"
    on_disk = {str(p.relative_to(DOCS / model)) for p in (DOCS / model).rglob("*") if p.is_file()}
    assert on_disk == set(generated), "docs/engines holds files the generator no longer writes"


# --------------------------------------------------------------------------- the manifest, read here


def _passes(m: dict) -> list[tuple[int, dict, dict | None]]:
    """[(step number, step, pass entry or None when skipped)] of frame.steps."""
    by_name = {p["name"]: p for p in m["frame"]["passes"]}
    return [
        (
            k,
            s,
            None
            if "skip" in s
            else by_name[s["frame_pass"]]
            if "frame_pass" in s
            else m["passes"][s["index"]],
        )
        for k, s in enumerate(m["frame"]["steps"])
    ]


def _dispatched(m: dict) -> list[str]:
    names = [p["name"] for _, _, p in _passes(m) if p is not None]
    return list(dict.fromkeys(names))


def _groups(p: dict) -> tuple[str, int, int, int]:
    """(texture, texels x a group, texels y a group, groups z), read from the manifest's formulas
    ("ceil(width(t3) / 64)", "ceil(height(t3) / 32)", "layers(t3) / 1 = 1" or "1")."""
    gx, gy, gz = p["dispatch"]["groups"]
    mx = re.fullmatch(r"ceil\(width\((\w+)\) / (\d+)\)", gx)
    my = re.fullmatch(r"ceil\(height\((\w+)\) / (\d+)\)", gy)
    mz = re.fullmatch(r"(?:layers\((\w+)\) / \d+ = )?(\d+)", gz)
    assert mx and my and mz and mx[1] == my[1] and mz[1] in (None, mx[1]), p["dispatch"]
    return mx[1], int(mx[2]), int(my[2]), int(mz[2])


def _symbols(m: dict, W: int, H: int) -> dict[str, int]:
    ih, k = m["frame"]["internal_height"], m["pad"]["multiple"]
    w, h = (max(1, round(W * ih / H)), ih) if ih else (W, H)
    return {"W": W, "H": H, "w": w, "h": h, "wp": -(-w // k) * k, "hp": -(-h // k) * k}


def _c_value(expr: str, sym: dict[str, int]) -> int:
    """A C# / C++ integer size expression (symbols, *, /, +) at the symbols' values."""
    return eval(re.sub(r"\b(W|H|w|h|wp|hp)\b", lambda x: str(sym[x[1]]), expr).replace("/", "//"))  # noqa: S307


def _step_blocks(text: str, marker: str) -> list[tuple[int, str, str, str]]:
    """[(step number, pass, skipped-or-summary line, the text up to the next step)] of the wrapper."""
    found = list(re.finditer(rf"{re.escape(marker)}step (\d+): (\w+)(:| skipped:)", text))
    ends = [f.start() for f in found[1:]] + [len(text)]
    return [(int(f[1]), f[2], f[3], text[f.start() : e]) for f, e in zip(found, ends, strict=True)]


def _check_steps(m: dict, blocks: list, guard: str) -> None:
    """Every step of frame.steps, in order; skipped ones named so; a ``when`` step inside the condition."""
    want = _passes(m)
    assert [(k, n) for k, n, _, _ in blocks] == [
        (k, s["skip"] if p is None else p["name"]) for k, s, p in want
    ]
    for (k, s, p), (_, _, kind, _) in zip(want, blocks, strict=True):
        assert (kind == " skipped:") == (p is None), k
        if "when" in s:
            cond = guard if s["when"] == "(w, h) == (W, H)" else f"!{guard}"
            before = blocks[[b[0] for b in blocks].index(k) - 1][3]
            assert re.search(rf"if \({re.escape(cond)}\)  // {re.escape(s['when'])}\n\s*\{{\s*$", before), k


def _check_hlsl(root: Path, p: dict) -> None:
    """Each resource of the pass is declared in the exported HLSL at its register (and the cbuffer's
    members at the manifest's offsets)."""
    source = (root / "glsl" / p["hlsl"]["file"]).read_text()
    declared = {d["name"]: d["register"] for d in _hlsl_declarations(source)}
    for r in p["hlsl"]["resources"]:
        assert declared.get(r["name"]) == r["register"], (p["name"], r["name"], declared)
        if "uniform_block" in r:
            got = [(u["name"], u["offset"]) for u in _cbuffer_members(source, r["name"])]
            assert got == [(u["name"], u["offset"]) for u in r["members"]], p["name"]


def _frame_block(m: dict) -> dict:
    (block,) = {
        json.dumps(r, sort_keys=True)
        for p in m["frame"]["passes"]
        for r in p["hlsl"]["resources"]
        if "uniform_block" in r
    }
    return json.loads(block)


# --------------------------------------------------------------------------- Unity


def test_unity_runs_the_frame_steps_as_the_manifest_says(wrapped):
    model, root, m, _, docs, _ = wrapped
    cls = class_name(model)
    cs, compute = docs[f"unity/{cls}.cs"], docs[f"unity/{cls}.compute"]
    names = _dispatched(m)
    entries = {p["name"]: p for _, _, p in _passes(m) if p is not None}
    kernels = re.findall(r"^#pragma kernel (\w+) NEURALAO_PASS=(\d+)$", compute, re.M)
    assert kernels == [(n, str(k)) for k, n in enumerate(names)]
    includes = re.findall(r"^#(?:el)?if NEURALAO_PASS == (\d+)\n#include \"(\S+)\"$", compute, re.M)
    assert includes == [(str(k), entries[n]["hlsl"]["file"]) for k, n in enumerate(names)]
    assert f"PadMultiple = {m['pad']['multiple']};" in cs
    assert f"InternalHeight = {m['frame']['internal_height'] or 0};" in cs
    index = {p["name"]: k for k, p in enumerate(m["passes"])}
    weights = {int(k): (int(o), int(b)) for k, o, b in re.findall(r"Weights\((\d+), (\d+), (\d+)\);", cs)}
    assert weights == {
        index[n]: (r["weights"]["offset"], r["weights"]["bytes"])
        for n in names
        for r in entries[n]["hlsl"]["resources"]
        if "weights" in r
    }
    allocated = {
        t: (w, h, int(n), f)
        for t, w, h, n, f in re.findall(
            r'tex\["(\w+)"\] = Array2D\((.+?), (.+?), (\d+), RenderTextureFormat\.(\w+)\);', cs
        )
    }
    assert set(allocated) == set(m["frame"]["textures"])
    for W, H in SIZES:
        sizes, sym = frame_sizes(m, W, H), _symbols(m, W, H)
        for ident, (w, h, layers, fmt) in allocated.items():
            want = sizes[ident]
            assert (_c_value(w, sym), _c_value(h, sym), layers, fmt) == (*want[:3], UNITY_FORMATS[want[3]])
    block = _frame_block(m)
    lanes = re.findall(r"^        u\[(\d+)\] = (.+?);  // (\w+)$", cs, re.M)
    want_lanes = []
    for u in block["members"]:
        n = {"float2": 2, "float": 1, "int": 1}[u["type"]]
        want_lanes += [(str(u["offset"] // 4 + i), u["name"]) for i in range(n)]
    assert [(k, name) for k, _, name in lanes] == want_lanes
    assert f"new GraphicsBuffer(GraphicsBuffer.Target.Constant, {block['bytes'] // 4}, 4)" in cs
    blocks = _step_blocks(cs, "// ")
    _check_steps(m, blocks, "sameSize")
    for (_, _, p), (_, _, _, text) in zip(_passes(m), blocks, strict=True):
        if p is None:
            continue
        res = p["hlsl"]["resources"]
        assert f'k = shader.FindKernel("{p["name"]}");' in text
        textures = re.findall(r'shader\.SetTexture\(k, "(\w+)", tex\["(\w+)"\]\);', text)
        assert textures == [(r["name"], r["texture"]) for r in res if "texture" in r], p["name"]
        buffers = re.findall(r'shader\.SetBuffer\(k, "(\w+)", passWeights\[(\d+)\]\);', text)
        assert buffers == [(r["name"], str(index[p["name"]])) for r in res if "weights" in r], p["name"]
        cbuffers = re.findall(r'shader\.SetConstantBuffer\("(\w+)", frameUniforms, 0, (\d+)\);', text)
        assert cbuffers == [(r["name"], str(r["bytes"])) for r in res if "uniform_block" in r], p["name"]
        scalars = re.findall(r'shader\.SetInt\("(\w+)", flip\);', text)
        assert (
            scalars
            == [r["name"] for r in res if "cbuffer" in r]
            == (["u_flip_y"] if p.get("uniforms") else [])
        )
        (dispatch,) = re.findall(
            r'shader\.Dispatch\(k, CeilDiv\(tex\["(\w+)"\]\.width, (\d+)\), '
            r'CeilDiv\(tex\["(\w+)"\]\.height, (\d+)\), (\d+)\);',
            text,
        )
        size_of, gx, gy, gz = _groups(p)
        assert dispatch == (size_of, str(gx), size_of, str(gy), str(gz)), p["name"]
        _check_hlsl(root, p)


# --------------------------------------------------------------------------- Unreal

_UNREAL_MACROS = {
    "SHADER_PARAMETER_RDG_TEXTURE_SRV": "Texture2DArray<",
    "SHADER_PARAMETER_RDG_TEXTURE_UAV": "RWTexture2DArray<",
    "SHADER_PARAMETER_RDG_BUFFER_SRV": "ByteAddressBuffer",
}


def test_unreal_shader_classes_and_passes_are_the_manifest(wrapped):
    model, root, m, _, docs, _ = wrapped
    cls = class_name(model)
    header, cpp, usf = docs[f"unreal/{cls}.h"], docs[f"unreal/{cls}.cpp"], docs[f"unreal/{cls}.usf"]
    names = _dispatched(m)
    entries = {p["name"]: p for _, _, p in _passes(m) if p is not None}
    includes = re.findall(r"^#(?:el)?if NEURALAO_PASS == (\d+)\n#include \"(\S+)\"$", usf, re.M)
    assert includes == [
        (str(k), entries[n]["hlsl"]["file"].replace(".hlsl", ".ush")) for k, n in enumerate(names)
    ]
    implements = re.findall(
        r'IMPLEMENT_GLOBAL_SHADER\(F(\w+), "/Plugin/NeuralAO/(\S+)", "(\w+)", SF_Compute\);', cpp
    )
    assert implements == [(n, f"{cls}.usf", n) for n in names]
    block = _frame_block(m)
    assert f'IMPLEMENT_GLOBAL_SHADER_PARAMETER_STRUCT(F{block["name"]}, "{block["name"]}");' in cpp
    members = re.findall(r"^    SHADER_PARAMETER\((\w+), (\w+)\)  // offset (\d+)$", header, re.M)
    types = {"float2": "FVector2f", "float": "float", "int": "int32"}
    assert members == [(types[u["type"]], u["name"], str(u["offset"])) for u in block["members"]]
    for u in block["members"]:
        assert re.search(rf"^    U->{u['name']} = .+;$", cpp, re.M), u["name"]
    made = {
        t: (w, h, int(n), f)
        for t, w, h, n, f in re.findall(r'Make\(TEXT\("(\w+)"\), (.+?), (.+?), (\d+), (\w+)\);', cpp)
    }
    assert set(made) == set(m["frame"]["textures"])
    for W, H in SIZES:
        sizes, sym = frame_sizes(m, W, H), _symbols(m, W, H)
        for ident, (w, h, layers, fmt) in made.items():
            want = sizes[ident]
            assert (_c_value(w, sym), _c_value(h, sym), layers, fmt) == (*want[:3], UNREAL_FORMATS[want[3]])
    classes = dict(re.findall(r"^class F(\w+) : public FGlobalShader\n(.*?)^\};", header, re.M | re.S))
    assert list(classes) == names
    index = {p["name"]: k for k, p in enumerate(m["passes"])}
    blocks = _step_blocks(cpp, "// ")
    _check_steps(m, blocks, "bSameSize")
    for (_, _, p), (_, _, _, text) in zip(_passes(m), blocks, strict=True):
        if p is None:
            continue
        res, body = p["hlsl"]["resources"], classes[p["name"]]
        assert f'SetDefine(TEXT("NEURALAO_PASS"), {names.index(p["name"])});' in body
        params = re.findall(r"^ +(SHADER_PARAMETER\w*)\((.+?), (\w+)\)  // (\S+)$", body, re.M)
        want = []
        for r in res:
            if "cbuffer" in r:
                want.append(
                    ("SHADER_PARAMETER", "int32" if r["type"] == "int" else "float", r["name"], "$Globals")
                )
            elif "uniform_block" in r:
                want.append(
                    (
                        "SHADER_PARAMETER_RDG_UNIFORM_BUFFER",
                        f"F{r['uniform_block']}",
                        r["name"],
                        r["register"],
                    )
                )
            else:
                macro = next(k for k, t in _UNREAL_MACROS.items() if r["type"].startswith(t))
                want.append((macro, r["type"], r["name"], r["register"]))
        assert params == want, p["name"]
        binds = re.findall(r"P->(\w+) = (?:Srv|Uav)\(TEXT\(\"(\w+)\"\)\);", text)
        assert binds == [(r["name"], r["texture"]) for r in res if "texture" in r], p["name"]
        assert re.findall(r"P->(\w+) = Raw\((\d+)\);", text) == [
            (r["name"], str(index[p["name"]])) for r in res if "weights" in r
        ]
        assert re.findall(r"P->(\w+) = FrameUniformBuffer;", text) == [
            r["name"] for r in res if "uniform_block" in r
        ]
        assert re.findall(r"P->(\w+) = flip;", text) == [r["name"] for r in res if "cbuffer" in r]
        (dispatch,) = re.findall(
            r'DivideAndRoundUp\(Size\(TEXT\("(\w+)"\)\)\.X, (\d+)\), '
            r'FMath::DivideAndRoundUp\(Size\(TEXT\("(\w+)"\)\)\.Y, (\d+)\), (\d+)\)\);',
            text,
        )
        size_of, gx, gy, gz = _groups(p)
        assert dispatch == (size_of, str(gx), size_of, str(gy), str(gz)), p["name"]
        _check_hlsl(root, p)


# --------------------------------------------------------------------------- Godot


def test_godot_tables_are_the_vulkan_manifest(wrapped):
    model, _, _, vk, docs, _ = wrapped
    gd = docs[godot_file(model)]
    assert f"class_name {class_name(model)}" in gd and "extends CompositorEffect" in gd
    assert f"PAD_MULTIPLE := {vk['pad']['multiple']}" in gd
    assert f"INTERNAL_HEIGHT := {vk['frame']['internal_height'] or 0}" in gd
    steps = re.findall(r'^    \["(\w+)", "(.*)"\],$', gd, re.M)
    assert steps == [(p["name"], s.get("when", "")) for _, s, p in _passes(vk) if p is not None]
    rows = re.findall(r'^    "(\w+)": \["(\S+)", \["(\w+)", (\d+), (\d+), (\d+)\], \[(.*)\]\],$', gd, re.M)
    entries = {p["name"]: p for _, _, p in _passes(vk) if p is not None}
    assert [r[0] for r in rows] == _dispatched(vk)
    for name, spv, size_of, gx, gy, gz, bindings in rows:
        p = entries[name]
        assert spv == p["shader"].removesuffix(".comp") + ".spv"
        assert (size_of, int(gx), int(gy), int(gz)) == _groups(p), name
        want = []
        for b in p["bindings"]:
            if b["kind"] == "storage_buffer":
                want.append([b["binding"], "weights", [p["params"]["offset"], p["params"]["bytes"]]])
            elif b["kind"] == "uniform_buffer" and b["resource"] == vk["frame"]["uniform_block"]["name"]:
                want.append([b["binding"], "frame", b["resource"]])
            elif b["kind"] == "uniform_buffer":
                want.append([b["binding"], "uniform", p["uniform_block"]["members"][0]["name"]])
            else:
                kind = {"sampled_image": "texture", "storage_image": "image"}[b["kind"]]
                want.append([b["binding"], kind, b["resource"]])
        assert json.loads(f"[{bindings}]") == want and all(b["set"] == 0 for b in p["bindings"]), name
    textures = re.findall(
        r'^    "(\w+)": \["(\w*)", (\d+), (\d+), (-?\d+), "(\w*)", (\d+), (\d+), (-?\d+), (\d+), '
        r"RenderingDevice\.(\w+)\],$",
        gd,
        re.M,
    )
    assert {t[0] for t in textures} == set(vk["frame"]["textures"])
    for W, H in SIZES:
        sizes, sym = frame_sizes(vk, W, H), _symbols(vk, W, H)
        for ident, wof, wn, wd, wo, hof, hn, hd, ho, layers, fmt in textures:
            dims = [
                (sym[of] * int(n) // int(d) if of else 0) + int(o)
                for of, n, d, o in ((wof, wn, wd, wo), (hof, hn, hd, ho))
            ]
            want = sizes[ident]
            assert (*dims, int(layers), fmt) == (*want[:3], GODOT_FORMATS[want[3]]), ident
    block = vk["frame"]["uniform_block"]
    members = re.findall(r'^    \["(\w+)", (\d+), \[(.*)\]\],$', gd, re.M)
    lanes = {"vec2": 2, "float": 1, "int": 1}
    assert [(n, int(o), len(json.loads(f"[{v}]"))) for n, o, v in members] == [
        (u["name"], u["offset"], lanes[u["type"]]) for u in block["members"]
    ]
    assert f"uniform_buffer_create({block['bytes']}, _frame_uniforms(" in gd


def test_fp16_wrappers_allocate_the_formats_the_fp16_passes_write():
    """The wrappers of an export written with --precision fp16 allocate each frame texture as its fp16
    passes write it: the hybrid's GTAO R16, 16-bit unsigned normalised (Unity R16, Unreal PF_G16, Godot
    DATA_FORMAT_R16_UNORM), the AO R16F; the Unreal GTAO passes' UAV is the HLSL's unorm float."""
    model = "unet-gtao"
    onnx_path = shipped_models()[model] / "model.onnx"
    glsl, vulkan = (frame_program(onnx_path, d, precision="fp16").manifest for d in ("glsl430", "vulkan"))
    docs = engine_wrappers(glsl, vulkan, model)
    cls = class_name(model)
    cs, cpp, gd = docs[f"unity/{cls}.cs"], docs[f"unreal/{cls}.cpp"], docs[godot_file(model)]
    for ident, fmt in (("gtao_raw", "R16"), ("gtao", "R16"), ("ao", "R16F")):
        assert (
            glsl["frame"]["textures"][ident]["format"] == vulkan["frame"]["textures"][ident]["format"] == fmt
        )
        assert re.search(rf'tex\["{ident}"\] = Array2D\(.+, RenderTextureFormat\.{UNITY_FORMATS[fmt]}\);', cs)
        assert re.search(rf'Make\(TEXT\("{ident}"\), .+, {UNREAL_FORMATS[fmt]}\);', cpp)
        assert re.search(rf'^    "{ident}": \[.+, RenderingDevice\.{GODOT_FORMATS[fmt]}\],$', gd, re.M)
    header = docs[f"unreal/{cls}.h"]
    for name in ("f_gtao", "f_gtao_blur"):
        (body,) = re.findall(rf"^class F{name} : public FGlobalShader\n(.*?)^\}};", header, re.M | re.S)
        assert "SHADER_PARAMETER_RDG_TEXTURE_UAV(RWTexture2DArray<unorm float>, dst)" in body, name
