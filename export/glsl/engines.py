"""Engine wrappers that run a U-Net export's whole frame, written from its manifests: Unity (C# that
allocates the frame's textures, fills the FrameUniforms buffer from the camera and dispatches each step's
HLSL by name, and the .compute file with one kernel per pass), Unreal (a .usf global shader file, the C++
shader classes with their parameter structs, the RDG textures and passes) and Godot 4 (a GDScript
CompositorEffect that loads the Vulkan export's SPIR-V on RenderingDevice).

    engine_wrappers(glsl_manifest, vulkan_manifest, model) -> {relative path: text}
    write_engine_wrappers(export_dir, out_dir, name) -> [paths]
    python -m neuralao.export.glsl.engines EXPORT_DIR|EXPORT_DIR/model.onnx NAME OUT_DIR   (OUT_DIR/NAME/...)

Everything a wrapper dispatches comes from the manifests' ``frame`` sections: the steps in order (a
``skip`` left out, a ``when`` a condition on the network's size), the frame and network passes, every
texture's size formula, layers and format, the FrameUniforms block's members and offsets; per pass the
names, registers, weight ranges and dispatch divisors of the GLSL manifest's ``hlsl`` entries
(:func:`.cross.hlsl_interface` where an entry has none) and the Vulkan manifest's ``bindings``. The text
comes from :mod:`.engine_templates`. No engine runs here: the HLSL the Unity and Unreal wrappers bind runs
the whole frame on Vulkan (tests/test_frame_passes.py), so does the SPIR-V the Godot wrapper loads.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import textwrap
from pathlib import Path

from neuralao.export.glsl.cross import hlsl_interface
from neuralao.export.glsl.engine_templates import fill_engine
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_bytes

log = logging.getLogger(__name__)

# A manifest's texture format in each engine (R16: 16-bit unsigned normalised, one channel).
_UNITY_FORMATS = {
    "RGBA32F": "ARGBFloat",
    "RGBA16F": "ARGBHalf",
    "R32F": "RFloat",
    "R16F": "RHalf",
    "R16": "R16",
}
_UNREAL_FORMATS = {
    "RGBA32F": "PF_A32B32G32R32F",
    "RGBA16F": "PF_FloatRGBA",
    "R32F": "PF_R32_FLOAT",
    "R16F": "PF_R16F",
    "R16": "PF_G16",
}
_GODOT_FORMATS = {
    "RGBA32F": "DATA_FORMAT_R32G32B32A32_SFLOAT",
    "RGBA16F": "DATA_FORMAT_R16G16B16A16_SFLOAT",
    "R32F": "DATA_FORMAT_R32_SFLOAT",
    "R16F": "DATA_FORMAT_R16_SFLOAT",
    "R16": "DATA_FORMAT_R16_UNORM",
}
_GODOT_KINDS = {"sampled_image": "texture", "storage_image": "image"}
# What each FrameUniforms member holds, lane by lane, as names every wrapper defines: p00, p11 the
# projection's scales (f * H / W, f), radius, pixels_per_unit = 0.5 * H * p11, flip the row order.
_UNIFORM_VALUES = {
    "u_proj": ("p00", "p11"),
    "u_radius": ("radius",),
    "u_pixels_per_unit": ("pixels_per_unit",),
    "u_flip_y": ("flip",),
}
# A step's ``when``: whether it runs when the network's input is the frame's own size.
_WHEN = {"(w, h) == (W, H)": True, "(w, h) != (W, H)": False}
_UNREAL_TYPES = {"float2": "FVector2f", "float": "float", "int": "int32"}


def class_name(model: str) -> str:
    """``unet-gtao`` -> ``NeuralAOUnetGtao``."""
    return "NeuralAO" + "".join(part.capitalize() for part in model.replace("_", "-").split("-") if part)


def godot_file(model: str) -> str:
    """The Godot wrapper's path: ``unet-gtao`` -> ``godot/unet_gtao_frame.gd``."""
    return f"godot/{model.replace('-', '_')}_frame.gd"


def dispatch_divisors(manifest: dict, p: dict) -> tuple[str, int, int, int]:
    """(texture the groups are counted on, texels x a group, texels y a group, groups z) of pass ``p`` (a
    frame pass writes every layer in one group: z = 1): groups = (ceil(width / x), ceil(height / y), z),
    as the manifest's ``dispatch`` states."""
    (lx, ly, _), (bx, by, bl) = p["local_size"], p.get("block", [1, 1, 1])
    size_of = p["dispatch"]["size_of"]
    if "stage" in p:
        return size_of, lx, ly, int(p["dispatch"]["groups"][2])
    return size_of, lx * bx, ly * by, int(manifest["frame"]["textures"][size_of]["layers"]) // bl


def size_formula(text: str) -> tuple[str, int, int, int]:
    """A frame size formula (``W``, ``wp*1/4``, ``hp*1/2+1``, ``1``) as (symbol or "", num, den, offset)."""
    m = re.fullmatch(r"(?:([A-Za-z]\w*)(?:\*(\d+)/(\d+))?)?([+-]?\d+)?", str(text))
    if m is None or not (m[1] or m[4]):
        raise NeuralaoError(f"size formula {text!r} is not symbol[*num/den][+-offset]")
    if not m[1]:
        return "", 0, 1, int(m[4])
    return m[1], int(m[2] or 1), int(m[3] or 1), int(m[4] or 0)


def _expr(text: str) -> str:
    """A size formula as an integer expression (C#, C++)."""
    of, num, den, offset = size_formula(text)
    if not of:
        return str(offset)
    expr = of if num == den == 1 else f"{of} * {num} / {den}"
    return expr if offset == 0 else f"{expr} {'+' if offset > 0 else '-'} {abs(offset)}"


def _frame(m: dict) -> dict:
    if "frame" not in m:
        raise NeuralaoError("engine wrappers run the whole frame: export the model with its frame passes")
    return m["frame"]


def _steps(m: dict) -> list[tuple[int, dict, dict | None]]:
    """[(step number, step, its pass entry or None for a skipped step)] of the manifest's frame.steps."""
    frame = _frame(m)
    by_name = {p["name"]: p for p in frame["passes"]}
    out = []
    for k, step in enumerate(frame["steps"]):
        if "skip" in step:
            out.append((k, step, None))
            continue
        if "when" in step and step["when"] not in _WHEN:
            raise NeuralaoError(f"frame step {k}: unknown condition {step['when']!r}")
        out.append(
            (k, step, by_name[step["frame_pass"]] if "frame_pass" in step else m["passes"][step["index"]])
        )
    return out


def _dispatched(m: dict) -> list[dict]:
    """Each pass the frame dispatches, once, in order of its first step."""
    seen: dict[str, dict] = {}
    for _, _, p in _steps(m):
        if p is not None:
            seen.setdefault(p["name"], p)
    return list(seen.values())


def _resources(p: dict) -> list[dict]:
    """Pass ``p``'s HLSL resources, as its manifest entry states them."""
    return (p.get("hlsl") or hlsl_interface(p))["resources"]


def _summary(p: dict) -> str:
    return p["summary"] if "stage" in p else " + ".join(p["ops"])


def _lanes(m: dict) -> list[tuple[str, int, str, tuple[str, ...]]]:
    """[(manifest member name, byte offset, type, lane values)] of the frame's uniform block."""
    out = []
    for u in _frame(m)["uniform_block"]["members"]:
        if u["name"] not in _UNIFORM_VALUES:
            raise NeuralaoError(f"the frame uniform {u['name']!r} has no value in the engine wrappers")
        out.append((u["name"], int(u["offset"]), u["type"], _UNIFORM_VALUES[u["name"]]))
    return out


def _hlsl_block(m: dict) -> dict:
    """The FrameUniforms cbuffer of the HLSL (every frame pass binds the same one)."""
    blocks = [r for p in _frame(m)["passes"] for r in _resources(p) if "uniform_block" in r]
    if not blocks or any(b != blocks[0] for b in blocks):
        raise NeuralaoError("the frame passes do not bind one FrameUniforms cbuffer")
    return blocks[0]


def _hlsl_member(block: dict, offset: int) -> str:
    """The HLSL name of the cbuffer member at byte ``offset``."""
    (name,) = [u["name"] for u in block["members"] if u["offset"] == offset]
    return name


def _guard(text: str, step: dict, condition: str, template: str, indent: str) -> str:
    """A step's block, inside ``if (condition)`` when the step has a ``when``."""
    if "when" not in step:
        return text
    cond = condition if _WHEN[step["when"]] else f"!{condition}"
    return fill_engine(template, condition=cond, when=step["when"], block=textwrap.indent(text, indent))


def _includes(passes: list[dict], template: str, ext: str) -> str:
    """The ``#if NEURALAO_PASS == k`` chain that includes each pass's HLSL (its file, as ``ext``)."""
    lines = [
        fill_engine(
            template,
            keyword="#if" if k == 0 else "#elif",
            index=k,
            file=Path(p["hlsl"]["file"]).stem + ext,
        )
        for k, p in enumerate(passes)
    ]
    return "\n".join(lines) + "\n#endif"


def _with_hlsl(passes: list[dict]) -> list[dict]:
    return [
        p if "hlsl" in p else dict(p, hlsl=hlsl_interface(p) | {"file": p["name"] + ".hlsl"}) for p in passes
    ]


def _inputs(m: dict, prefix: str) -> str:
    return "\n".join(f"{prefix}  {t}: {meaning}" for t, meaning in _frame(m)["inputs"].items())


# ----------------------------------------------------------------------------------------------- Unity


def _unity_binds(p: dict, index: dict[str, int], block_bytes: int) -> list[str]:
    binds = []
    for r in _resources(p):
        if "texture" in r:
            binds.append(fill_engine("unity_set_texture", name=r["name"], texture=r["texture"]))
        elif "weights" in r:
            binds.append(fill_engine("unity_set_buffer", name=r["name"], index=index[p["name"]]))
        elif "uniform_block" in r:
            binds.append(fill_engine("unity_set_cbuffer", name=r["name"], bytes=block_bytes))
        elif r["name"] == "u_flip_y":
            binds.append(fill_engine("unity_set_int", name=r["name"]))
        else:
            raise NeuralaoError(f"pass {p['name']}: the frame sets no uniform {r['name']!r}")
    return binds


def _unity(m: dict, model: str, cls: str) -> dict[str, str]:
    generated = fill_engine("generated", model=model)
    frame = _frame(m)
    passes = _with_hlsl(_dispatched(m))
    index = {p["name"]: k for k, p in enumerate(m["passes"])}
    block = _hlsl_block(m)
    weights = [
        fill_engine(
            "unity_weights",
            index=index[p["name"]],
            offset=r["weights"]["offset"],
            bytes=r["weights"]["bytes"],
        )
        for p in passes
        for r in _resources(p)
        if "weights" in r
    ]
    steps = []
    for k, step, p in _steps(m):
        if p is None:
            steps.append(fill_engine("unity_skip", step=k, entry=step["skip"], why=step.get("why", "")))
            continue
        size_of, gx, gy, gz = dispatch_divisors(m, p)
        text = fill_engine(
            "unity_step",
            step=k,
            entry=p["name"],
            summary=_summary(p),
            binds="\n".join(_unity_binds(p, index, block["bytes"])),
            size_of=size_of,
            gx=gx,
            gy=gy,
            gz=gz,
        )
        steps.append(_guard(text, step, "sameSize", "unity_when", "    "))
    lanes = []
    for _, offset, kind, values in _lanes(m):
        for i, value in enumerate(values):
            lanes.append(
                fill_engine(
                    "unity_lane_int" if kind == "int" else "unity_lane_float",
                    lane=offset // 4 + i,
                    value=value,
                    member=_hlsl_member(block, offset),
                )
            )
    textures = [
        fill_engine(
            "unity_texture",
            texture=ident,
            width=_expr(t["width"]),
            height=_expr(t["height"]),
            layers=t["layers"],
            format=_UNITY_FORMATS[t["format"]],
        )
        for ident, t in frame["textures"].items()
    ]
    cs = fill_engine(
        "unity_cs",
        generated=generated,
        model=model,
        cls=cls,
        dispatches=sum(p is not None for _, _, p in _steps(m)),
        inputs=_inputs(m, "///"),
        output=frame["output"],
        multiple=m["pad"]["multiple"],
        internal_height=frame["internal_height"] or 0,
        uniform_floats=block["bytes"] // 4,
        uniform_bytes=block["bytes"],
        uniform_lanes="\n".join(lanes),
        weight_buffers="\n".join(weights),
        textures="\n".join(textures),
        net_input=m["input"]["texture"],
        steps="\n".join(steps),
    )
    kernels = [fill_engine("unity_kernel", entry=p["name"], index=k) for k, p in enumerate(passes)]
    compute = fill_engine(
        "unity_compute",
        generated=generated,
        kernels="\n".join(kernels),
        includes=_includes(passes, "unity_include", ".hlsl"),
    )
    return {f"unity/{cls}.cs": cs, f"unity/{cls}.compute": compute}


# ---------------------------------------------------------------------------------------------- Unreal


def _unreal_param(r: dict) -> str:
    if "texture" in r:
        kind = "unreal_param_uav" if r["type"].startswith("RW") else "unreal_param_srv"
        return fill_engine(kind, type=r["type"], name=r["name"], register=r["register"])
    if "weights" in r:
        return fill_engine("unreal_param_buffer", type=r["type"], name=r["name"], register=r["register"])
    if "uniform_block" in r:
        return fill_engine(
            "unreal_param_block", type=r["uniform_block"], name=r["name"], register=r["register"]
        )
    return fill_engine("unreal_param_scalar", type="int32" if r["type"] == "int" else "float", name=r["name"])


def _unreal_bind(p: dict, r: dict, index: dict[str, int]) -> str:
    if "texture" in r:
        kind = "unreal_bind_uav" if r["type"].startswith("RW") else "unreal_bind_srv"
        return fill_engine(kind, name=r["name"], texture=r["texture"])
    if "weights" in r:
        return fill_engine("unreal_bind_buffer", name=r["name"], index=index[p["name"]])
    if "uniform_block" in r:
        return fill_engine("unreal_bind_block", name=r["name"])
    if r["name"] == "u_flip_y":
        return fill_engine("unreal_bind_flip", name=r["name"])
    raise NeuralaoError(f"pass {p['name']}: the frame sets no uniform {r['name']!r}")


def _unreal(m: dict, model: str, cls: str) -> dict[str, str]:
    generated = fill_engine("generated", model=model)
    frame = _frame(m)
    passes = _with_hlsl(_dispatched(m))
    index = {p["name"]: k for k, p in enumerate(m["passes"])}
    block = _hlsl_block(m)
    classes = [
        fill_engine(
            "unreal_class",
            entry=p["name"],
            parameters="\n".join(_unreal_param(r) for r in _resources(p)),
            index=k,
        )
        for k, p in enumerate(passes)
    ]
    steps = []
    for k, step, p in _steps(m):
        if p is None:
            steps.append(fill_engine("unreal_skip", step=k, entry=step["skip"], why=step.get("why", "")))
            continue
        size_of, gx, gy, gz = dispatch_divisors(m, p)
        text = fill_engine(
            "unreal_step",
            step=k,
            entry=p["name"],
            summary=_summary(p),
            binds="\n".join(_unreal_bind(p, r, index) for r in _resources(p)),
            size_of=size_of,
            gx=gx,
            gy=gy,
            gz=gz,
        )
        steps.append(_guard(text, step, "bSameSize", "unreal_when", ""))
    members, lanes = [], []
    for _, offset, _, values in _lanes(m):
        (u,) = [u for u in block["members"] if u["offset"] == offset]
        members.append(
            fill_engine("unreal_member", type=_UNREAL_TYPES[u["type"]], name=u["name"], offset=offset)
        )
        value = f"FVector2f({', '.join(values)})" if len(values) == 2 else values[0]
        lanes.append(fill_engine("unreal_lane", member=u["name"], value=value))
    textures = [
        fill_engine(
            "unreal_texture",
            texture=ident,
            width=_expr(t["width"]),
            height=_expr(t["height"]),
            layers=t["layers"],
            format=_UNREAL_FORMATS[t["format"]],
        )
        for ident, t in frame["textures"].items()
    ]
    header = fill_engine(
        "unreal_h",
        generated=generated,
        namespace=cls,
        multiple=m["pad"]["multiple"],
        internal_height=frame["internal_height"] or 0,
        block=block["name"],
        uniform_bytes=block["bytes"],
        members="\n".join(members),
        classes="\n\n".join(classes),
        inputs=_inputs(m, " *"),
        output=frame["output"],
    )
    cpp = fill_engine(
        "unreal_cpp",
        generated=generated,
        cls=cls,
        namespace=cls,
        block=block["name"],
        implements="\n".join(
            fill_engine("unreal_implement", entry=p["name"], usf=f"{cls}.usf") for p in passes
        ),
        textures="\n".join(textures),
        net_input=m["input"]["texture"],
        uniform_lanes="\n".join(lanes),
        steps="\n".join(steps),
        output=frame["output"],
    )
    usf = fill_engine(
        "unreal_usf", generated=generated, cls=cls, includes=_includes(passes, "unreal_include", ".ush")
    )
    return {f"unreal/{cls}.h": header, f"unreal/{cls}.cpp": cpp, f"unreal/{cls}.usf": usf}


# ----------------------------------------------------------------------------------------------- Godot


def _godot_binding(p: dict, b: dict) -> str:
    if b["kind"] == "storage_buffer":
        return f'[{b["binding"]}, "weights", [{p["params"]["offset"]}, {p["params"]["bytes"]}]]'
    if b["kind"] == "uniform_buffer" and "stage" in p:
        return f'[{b["binding"]}, "frame", "{b["resource"]}"]'
    if b["kind"] == "uniform_buffer":
        (member,) = p["uniform_block"]["members"]
        return f'[{b["binding"]}, "uniform", "{member["name"]}"]'
    return f'[{b["binding"]}, "{_GODOT_KINDS[b["kind"]]}", "{b["resource"]}"]'


def _godot(vk: dict, model: str, cls: str) -> dict[str, str]:
    frame = _frame(vk)
    passes = []
    for p in _dispatched(vk):
        size_of, gx, gy, gz = dispatch_divisors(vk, p)
        passes.append(
            fill_engine(
                "godot_pass",
                entry=p["name"],
                spirv=p["shader"].removesuffix(".comp") + ".spv",
                size_of=size_of,
                gx=gx,
                gy=gy,
                gz=gz,
                bindings=", ".join(_godot_binding(p, b) for b in p["bindings"]),
            )
        )
    steps = [
        fill_engine("godot_step", entry=p["name"], when=step.get("when", ""))
        for _, step, p in _steps(vk)
        if p is not None
    ]
    textures = []
    for ident, t in frame["textures"].items():
        (wof, wnum, wden, woff), (hof, hnum, hden, hoff) = size_formula(t["width"]), size_formula(t["height"])
        textures.append(
            fill_engine(
                "godot_texture",
                texture=ident,
                wof=wof,
                wnum=wnum,
                wden=wden,
                woff=woff,
                hof=hof,
                hnum=hnum,
                hden=hden,
                hoff=hoff,
                layers=t["layers"],
                format=_GODOT_FORMATS[t["format"]],
            )
        )
    members = [
        fill_engine("godot_uniform", member=name, offset=offset, lanes=", ".join(f'"{v}"' for v in values))
        for name, offset, _, values in _lanes(vk)
    ]
    gd = fill_engine(
        "godot_gd",
        generated=fill_engine("generated", model=model),
        cls=cls,
        model=model,
        inputs=_inputs(vk, "##"),
        multiple=vk["pad"]["multiple"],
        internal_height=frame["internal_height"] or 0,
        uniform_bytes=frame["uniform_block"]["bytes"],
        uniform_members="\n".join(members),
        textures="\n".join(textures),
        passes="\n".join(passes),
        steps="\n".join(steps),
        net_input=vk["input"]["texture"],
        output=frame["output"],
    )
    return {godot_file(model): gd}


def engine_wrappers(glsl_manifest: dict, vulkan_manifest: dict, model: str) -> dict[str, str]:
    """{relative path: text} of the Unity, Unreal and Godot wrappers of one export: ``glsl_manifest``
    (format neuralao-glsl-compute, with its frame: the HLSL's passes) and ``vulkan_manifest``
    (neuralao-vulkan-compute, the same frame: the SPIR-V's) of the same model and settings; ``model``
    names it."""
    if glsl_manifest.get("format") != "neuralao-glsl-compute":
        raise NeuralaoError("engine wrappers need the GLSL 4.30 program's manifest (its HLSL)")
    if vulkan_manifest.get("format") != "neuralao-vulkan-compute":
        raise NeuralaoError("engine wrappers need the Vulkan program's manifest (its SPIR-V)")
    if _frame(glsl_manifest)["steps"] != _frame(vulkan_manifest)["steps"]:
        raise NeuralaoError("the GLSL and Vulkan manifests are not of the same frame")
    cls = class_name(model)
    return (
        _unity(glsl_manifest, model, cls)
        | _unreal(glsl_manifest, model, cls)
        | _godot(vulkan_manifest, model, cls)
    )


def export_manifests(export_dir: str | Path) -> tuple[dict, dict]:
    """(GLSL manifest, Vulkan manifest) of an export folder (``glsl/`` and ``vulkan/`` inside it; a path to
    a file in the folder, such as its model.onnx, names the folder)."""
    root = Path(export_dir)
    root = root.parent if root.is_file() else root
    return tuple(json.loads((root / sub / "manifest.json").read_text()) for sub in ("glsl", "vulkan"))


def write_engine_wrappers(export_dir: str | Path, out_dir: str | Path, name: str) -> list[Path]:
    """Write the wrappers of the export in ``export_dir`` (its glsl/ and vulkan/ manifests) under
    ``out_dir``/``name``; returns the paths written."""
    written = []
    for rel, text in engine_wrappers(*export_manifests(export_dir), name).items():
        path = Path(out_dir) / name / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes(path, text.encode())
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write the Unity, Unreal and Godot wrappers of an export.")
    parser.add_argument("export", help="the export folder (glsl/ and vulkan/ inside), or its model.onnx")
    parser.add_argument("name", help="the model's name (folder and class names)")
    parser.add_argument("out", help="folder: the wrappers go to OUT/NAME/{unity,unreal,godot}")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for path in write_engine_wrappers(args.export, args.out, args.name):
        log.info("wrote %s", path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
