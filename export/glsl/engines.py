"""Engine wrappers of a compute program's network passes, written from its manifests: Unity (C# that
binds each pass's HLSL by name and dispatches it, and the .compute file with one kernel per pass),
Unreal (a .usf global shader file, the C++ shader classes with their parameter structs, the RDG passes)
and Godot 4 (a GDScript CompositorEffect that loads the Vulkan export's SPIR-V on RenderingDevice).

    engine_wrappers(glsl_manifest, vulkan_manifest, model) -> {relative path: text}
    write_engine_wrappers(model_path, out_dir, name) -> [paths]
    python -m neuralao.export.glsl.engines MODEL.onnx NAME OUT_DIR     (writes OUT_DIR/NAME/...)

Every name, register, binding, weight range, dispatch divisor and uniform in a wrapper comes from the
manifests (the GLSL manifest's passes through :func:`.cross.hlsl_interface`, the Vulkan manifest's
``bindings``); the text comes from :mod:`.engine_templates`. No engine runs here: the HLSL the Unity and
Unreal wrappers bind runs on Vulkan (tests/test_hlsl_target.py), the SPIR-V the Godot wrapper loads runs
on Vulkan too (tests/test_vulkan_target.py).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import onnx

from neuralao.export.glsl.cross import hlsl_interface
from neuralao.export.glsl.engine_templates import fill_engine
from neuralao.export.glsl.image import generate_compute
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_bytes

log = logging.getLogger(__name__)

_UNITY_FORMATS = {"RGBA32F": "ARGBFloat", "RGBA16F": "ARGBHalf"}
_GODOT_FORMATS = {"RGBA32F": "DATA_FORMAT_R32G32B32A32_SFLOAT", "RGBA16F": "DATA_FORMAT_R16G16B16A16_SFLOAT"}
_GODOT_KINDS = {"sampled_image": "texture", "storage_image": "image", "storage_buffer": "weights"}


def class_name(model: str) -> str:
    """``unet-gtao`` -> ``NeuralAOUnetGtao``."""
    return "NeuralAO" + "".join(part.capitalize() for part in model.replace("_", "-").split("-") if part)


def dispatch_divisors(manifest: dict, p: dict) -> tuple[str, int, int, int]:
    """(texture the groups are counted on, texels x a group, texels y a group, groups z) of pass ``p``:
    groups = (ceil(width / x), ceil(height / y), z), as the manifest's ``dispatch`` states."""
    (lx, ly, _), (bx, by, bl) = p["local_size"], p.get("block", [1, 1, 1])
    size_of = p["dispatch"]["size_of"]
    return size_of, lx * bx, ly * by, int(manifest["textures"][size_of]["layers"]) // bl


def _dim(d: dict) -> str:
    """A texture dimension ``of * num / den + offset`` as an integer expression (C#, C++)."""
    if d["num"] == 0:
        return str(d["offset"])
    expr = d["of"] if d["num"] == d["den"] == 1 else f"{d['of']} * {d['num']} / {d['den']}"
    return expr if d["offset"] == 0 else f"{expr} + {d['offset']}"


def _scalars(manifest: dict) -> list[dict]:
    """The scalar graph inputs (uniform passes' floats), in graph order."""
    return list(manifest.get("uniforms", []))


def _keyword(k: int) -> str:
    return "#if" if k == 0 else "#elif"


def _unity(m: dict, model: str, cls: str) -> dict[str, str]:
    generated = fill_engine("generated", model=model)
    passes = m["passes"]
    kernels = [fill_engine("unity_kernel", entry=p["name"], index=k) for k, p in enumerate(passes)]
    includes = [
        fill_engine("unity_include", keyword=_keyword(k), index=k, file=f"{p['name']}.hlsl")
        for k, p in enumerate(passes)
    ]
    weights, dispatches = [], []
    for k, p in enumerate(passes):
        binds = []
        for r in hlsl_interface(p)["resources"]:
            if "texture" in r:
                binds.append(fill_engine("unity_set_texture", name=r["name"], texture=r["texture"]))
            elif "weights" in r:
                w = r["weights"]
                weights.append(fill_engine("unity_weights", index=k, offset=w["offset"], bytes=w["bytes"]))
                binds.append(fill_engine("unity_set_buffer", name=r["name"], index=k))
            elif r["name"] == "u_flip_y":
                binds.append(fill_engine("unity_set_int", name=r["name"]))
            else:
                binds.append(fill_engine("unity_set_float", name=r["name"], value=r["name"]))
        size_of, gx, gy, gz = dispatch_divisors(m, p)
        dispatches.append(
            fill_engine(
                "unity_pass",
                entry=p["name"],
                ops=" + ".join(p["ops"]),
                binds="\n".join(binds),
                size_of=size_of,
                gx=gx,
                gy=gy,
                gz=gz,
            )
        )
    textures = [
        fill_engine(
            "unity_texture",
            texture=ident,
            width=_dim(t["width"]),
            height=_dim(t["height"]),
            layers=t["layers"],
            format=_UNITY_FORMATS[t["format"]],
        )
        for ident, t in m["textures"].items()
    ]
    cs = fill_engine(
        "unity_cs",
        generated=generated,
        model=model,
        cls=cls,
        passes=len(passes),
        input=m["input"]["texture"],
        channels=m["input"]["channels"],
        output=m["outputs"][0]["texture"],
        multiple=m["pad"]["multiple"],
        weight_buffers="\n".join(weights),
        textures="\n".join(textures),
        scalar_params="".join(f"float {u['glsl_name']}, " for u in _scalars(m)),
        dispatches="\n".join(dispatches),
    )
    compute = fill_engine(
        "unity_compute",
        generated=generated,
        kernels="\n".join(kernels),
        includes="\n".join(includes) + "\n#endif",
    )
    return {f"unity/{cls}.cs": cs, f"unity/{cls}.compute": compute}


_UNREAL_PARAMS = {
    "Texture2DArray<float4>": "unreal_param_srv",
    "RWTexture2DArray<float4>": "unreal_param_uav",
    "ByteAddressBuffer": "unreal_param_buffer",
}


def _unreal(m: dict, model: str, cls: str) -> dict[str, str]:
    generated = fill_engine("generated", model=model)
    passes = m["passes"]
    classes, implements, dispatches = [], [], []
    for k, p in enumerate(passes):
        params, binds = [], []
        for r in hlsl_interface(p)["resources"]:
            if r["type"] in _UNREAL_PARAMS:
                params.append(fill_engine(_UNREAL_PARAMS[r["type"]], name=r["name"], register=r["register"]))
            else:
                params.append(
                    fill_engine(
                        "unreal_param_scalar", type="int32" if r["type"] == "int" else "float", name=r["name"]
                    )
                )
            if r["type"] == "Texture2DArray<float4>":
                binds.append(fill_engine("unreal_bind_srv", name=r["name"], texture=r["texture"]))
            elif r["type"] == "RWTexture2DArray<float4>":
                binds.append(fill_engine("unreal_bind_uav", name=r["name"], texture=r["texture"]))
            elif r["type"] == "ByteAddressBuffer":
                binds.append(fill_engine("unreal_bind_buffer", name=r["name"], index=k))
            elif r["name"] == "u_flip_y":
                binds.append(fill_engine("unreal_bind_flip", name=r["name"]))
            else:
                binds.append(fill_engine("unreal_bind_scalar", name=r["name"], value=r["name"]))
        classes.append(fill_engine("unreal_class", entry=p["name"], parameters="\n".join(params), index=k))
        implements.append(fill_engine("unreal_implement", entry=p["name"], usf=f"{cls}.usf"))
        size_of, gx, gy, gz = dispatch_divisors(m, p)
        dispatches.append(
            fill_engine(
                "unreal_pass",
                entry=p["name"],
                ops=" + ".join(p["ops"]),
                binds="\n".join(binds),
                size_of=size_of,
                gx=gx,
                gy=gy,
                gz=gz,
            )
        )
    scalar_params = "".join(f"float {u['glsl_name']}, " for u in _scalars(m))
    header = fill_engine(
        "unreal_h",
        generated=generated,
        namespace=cls,
        multiple=m["pad"]["multiple"],
        classes="\n\n".join(classes),
        input=m["input"]["texture"],
        output=m["outputs"][0]["texture"],
        scalar_params=scalar_params,
    )
    cpp = fill_engine(
        "unreal_cpp",
        generated=generated,
        cls=cls,
        namespace=cls,
        implements="\n".join(implements),
        scalar_params=scalar_params,
        dispatches="\n".join(dispatches),
    )
    includes = [
        fill_engine("unreal_include", keyword=_keyword(k), index=k, file=f"{p['name']}.ush")
        for k, p in enumerate(passes)
    ]
    usf = fill_engine("unreal_usf", generated=generated, cls=cls, includes="\n".join(includes) + "\n#endif")
    return {f"unreal/{cls}.h": header, f"unreal/{cls}.cpp": cpp, f"unreal/{cls}.usf": usf}


def _godot_binding(p: dict, b: dict) -> str:
    if b["kind"] == "storage_buffer":
        return f'[{b["binding"]}, "weights", [{p["params"]["offset"]}, {p["params"]["bytes"]}]]'
    if b["kind"] == "uniform_buffer":
        (member,) = p["uniform_block"]["members"]
        return f'[{b["binding"]}, "uniform", "{member["name"]}"]'
    return f'[{b["binding"]}, "{_GODOT_KINDS[b["kind"]]}", "{b["resource"]}"]'


def _godot(vk: dict, model: str, cls: str) -> dict[str, str]:
    passes = []
    for p in vk["passes"]:
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
    textures = [
        fill_engine(
            "godot_texture",
            texture=ident,
            wof=t["width"]["of"],
            wnum=t["width"]["num"],
            wden=t["width"]["den"],
            woff=t["width"]["offset"],
            hof=t["height"]["of"],
            hnum=t["height"]["num"],
            hden=t["height"]["den"],
            hoff=t["height"]["offset"],
            layers=t["layers"],
            format=_GODOT_FORMATS[t["format"]],
        )
        for ident, t in vk["textures"].items()
    ]
    scalar_exports = "".join(
        fill_engine(
            "godot_scalar_export",
            onnx=u["onnx_input"],
            meaning=u["meaning"].split(":")[0],
            name=u["glsl_name"],
        )
        for u in _scalars(vk)
    )
    gd = fill_engine(
        "godot_gd",
        generated=fill_engine("generated", model=model),
        cls=cls,
        model=model,
        scalar_exports=scalar_exports,
        channels=vk["input"]["channels"],
        multiple=vk["pad"]["multiple"],
        passes="\n".join(passes),
        textures="\n".join(textures),
        input=vk["input"]["texture"],
        output=vk["outputs"][0]["texture"],
    )
    return {f"godot/{model.replace('-', '_')}_network.gd": gd}


def engine_wrappers(glsl_manifest: dict, vulkan_manifest: dict, model: str) -> dict[str, str]:
    """{relative path: text} of the Unity, Unreal and Godot wrappers of one program: ``glsl_manifest``
    (format neuralao-glsl-compute: the HLSL's passes) and ``vulkan_manifest`` (neuralao-vulkan-compute,
    the same passes: the SPIR-V's) of the same model and settings; ``model`` names it."""
    if glsl_manifest.get("format") != "neuralao-glsl-compute":
        raise NeuralaoError("engine wrappers need the GLSL 4.30 program's manifest (its HLSL)")
    if vulkan_manifest.get("format") != "neuralao-vulkan-compute":
        raise NeuralaoError("engine wrappers need the Vulkan program's manifest (its SPIR-V)")
    if [p["name"] for p in glsl_manifest["passes"]] != [p["name"] for p in vulkan_manifest["passes"]]:
        raise NeuralaoError("the GLSL and Vulkan manifests are not of the same program")
    cls = class_name(model)
    return (
        _unity(glsl_manifest, model, cls)
        | _unreal(glsl_manifest, model, cls)
        | _godot(vulkan_manifest, model, cls)
    )


def write_engine_wrappers(model_path: str | Path, out_dir: str | Path, name: str) -> list[Path]:
    """Generate the compute program of the ONNX file ``model_path`` (defaults) in GLSL and Vulkan GLSL and
    write its wrappers under ``out_dir``/``name``; returns the paths written."""
    model = onnx.load(str(model_path))
    files = engine_wrappers(
        generate_compute(model).manifest, generate_compute(model, dialect="vulkan").manifest, name
    )
    written = []
    for rel, text in files.items():
        path = Path(out_dir) / name / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes(path, text.encode())
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write the Unity, Unreal and Godot wrappers of a model.")
    parser.add_argument("model", help="the ONNX file")
    parser.add_argument("name", help="the model's name (folder and class names)")
    parser.add_argument("out", help="folder: the wrappers go to OUT/NAME/{unity,unreal,godot}")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for path in write_engine_wrappers(args.model, args.out, args.name):
        log.info("wrote %s", path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
