"""Export folders: write the shaders, parameter files and manifest.json of either target (each file
atomically, the manifest last, every file hashed in it) and load them back, hashes checked."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from neuralao.export.glsl.cross import (
    HLSL_SHADER_MODEL,
    HLSL_SPIRV_COMMAND,
    MSL_BUFFER_SHIFT,
    MSL_TEXTURE_SHIFT,
    MSL_VERSION,
    PARAMS_REGISTER_SHIFT,
    SPIRV_COMMAND,
    SPIRV_TARGET_ENV,
    compile_spirv,
    cross_compile,
    hlsl_interface,
    msl_interface,
    spirv_validator_available,
    validate_hlsl,
)
from neuralao.export.glsl.dialects import FRAGMENT_FILES
from neuralao.export.glsl.frame import shader_entries
from neuralao.export.glsl.graph import sha256_hex
from neuralao.export.glsl.image import ComputeProgram
from neuralao.export.glsl.validate import _can_validate, glslang_available, validate_glsl
from neuralao.export.glsl.vector import MLPShader
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_bytes, write_json
from neuralao.runtime.foundation.manifest import read_manifest

log = logging.getLogger(__name__)

COMPUTE_FORMATS = ("neuralao-glsl-compute", "neuralao-wgsl-compute", "neuralao-vulkan-compute")


def _write_export_files(out_dir: Path, files: dict[str, bytes], manifest: dict) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest = dict(manifest)
    manifest["files"] = {name: sha256_hex(data) for name, data in sorted(files.items())}
    for name, data in files.items():
        write_bytes(out_dir / name, data)
    write_json(out_dir / "manifest.json", manifest)  # last: its presence marks a complete export
    return out_dir / "manifest.json"


def write_mlp_export(shader: MLPShader, out_dir: str | Path, validate: bool = True) -> Path:
    """Write mlp.vert/.frag (GLSL 3.30), mlp_es300.vert/.frag, mlp_430.vert/.frag, one
    mlp_block<binding>.bin per uniform block (float32 little-endian std140) and manifest.json,
    each atomically. ``validate`` runs glslangValidator on every shader first (skipped with a log
    line when it is not installed). Returns the manifest path."""
    out_dir = Path(out_dir)
    files: dict[str, bytes] = {}
    validate = validate and _can_validate()
    for name, (vert, frag) in shader.sources.items():
        vname, fname = FRAGMENT_FILES[name]
        if validate:
            validate_glsl(vert, "vert")
            validate_glsl(frag, "frag")
        files[vname], files[fname] = vert.encode(), frag.encode()
    for b in shader.manifest["uniform_blocks"]:
        data = next(arr for (n, _, arr) in shader.uniform_blocks if n == b["name"])
        files[b["file"]] = np.ascontiguousarray(data, dtype="<f4").tobytes()
    return _write_export_files(out_dir, files, shader.manifest)


def _read_export(export_dir: str | Path) -> tuple[Path, dict]:
    return Path(export_dir), read_manifest(export_dir)


def _read_checked(d: Path, manifest: dict, name: str) -> bytes:
    try:
        data = (d / name).read_bytes()
    except FileNotFoundError:
        raise NeuralaoError(f"export {d} lacks {name}") from None
    want = manifest.get("files", {}).get(name)
    if want is not None and sha256_hex(data) != want:
        raise NeuralaoError(f"{d / name} does not match its manifest hash (modified or truncated)")
    return data


def load_mlp_export(export_dir: str | Path, dialect: str = "glsl330") -> MLPShader:
    """Rebuild an :class:`MLPShader` from an export folder (what an engine reads)."""
    d, manifest = _read_export(export_dir)
    if manifest.get("format") != "neuralao-glsl-fragment":
        raise NeuralaoError(f"{d} is not a fragment-shader export")
    sources = {}
    for name, files in manifest["dialects"].items():
        sources[name] = (
            _read_checked(d, manifest, files["vertex"]).decode(),
            _read_checked(d, manifest, files["fragment"]).decode(),
        )
    if dialect not in sources:
        raise NeuralaoError(f"export {d} has no {dialect!r} shaders")
    ubos = [
        (
            b["name"],
            int(b["binding"]),
            np.frombuffer(_read_checked(d, manifest, b["file"]), dtype="<f4").copy(),
        )
        for b in manifest["uniform_blocks"]
    ]
    return MLPShader(sources[dialect][1], sources[dialect][0], ubos, manifest, dialect, sources)


def write_compute_export(
    program: ComputeProgram, out_dir: str | Path, validate: bool = True, cross: bool = False
) -> Path:
    """Write every pass as <name>.comp (GLSL) or <name>.wgsl, weights.bin and manifest.json (atomically);
    returns the manifest path. ``cross``: also <name>.hlsl and <name>.metal beside each GLSL pass
    (SPIR-V + SPIRV-Cross, :mod:`.cross`; see :func:`_with_cross`). A Vulkan
    program's passes get <name>.spv beside them (:func:`_with_spirv`)."""
    files: dict[str, bytes] = {}
    manifest = program.manifest
    if manifest.get("format") == "neuralao-vulkan-compute":
        if cross:
            raise NeuralaoError("HLSL / MSL are made from the GLSL 4.30 passes, not the Vulkan ones")
        files.update({name: src.encode() for name, src in program.sources.items()})
        files["weights.bin"] = program.weights
        return _write_export_files(Path(out_dir), files, _with_spirv(program, files, validate))
    validate = validate and _can_validate()
    if cross and manifest.get("format") != "neuralao-glsl-compute":
        raise NeuralaoError(
            "HLSL / MSL are made from the GLSL passes: export the image target (GLSL) for them"
        )
    for name, src in program.sources.items():
        if validate and name.endswith(".comp"):  # WGSL is checked by the WebGPU runtime that compiles it
            validate_glsl(src, "comp")
        files[name] = src.encode()
    if cross:
        manifest = _with_cross(program, files, validate)
    files["weights.bin"] = program.weights
    return _write_export_files(Path(out_dir), files, manifest)


def _with_cross(program: ComputeProgram, files: dict[str, bytes], validate: bool) -> dict:
    """The GLSL program's manifest with each pass's HLSL and MSL: <name>.hlsl and <name>.metal into
    ``files``, the pass's ``hlsl`` ({"file", "entry", "numthreads", "resources"}) and ``msl`` ({"file",
    "kernel", "threads_per_threadgroup", "arguments"}) saying what an engine binds by which name and
    register / index; ``validate``: each HLSL file is compiled back by glslang's HLSL front end."""
    manifest = json.loads(json.dumps(program.manifest))
    for entry in shader_entries(manifest):  # the network's passes and the frame's
        out = cross_compile(program.sources[entry["shader"]], entry["name"])
        if validate:
            validate_hlsl(out["hlsl"], entry["name"])
        stem = entry["shader"].removesuffix(".comp")
        entry["hlsl"] = {"file": f"{stem}.hlsl", **hlsl_interface(entry)}
        entry["msl"] = {"file": f"{stem}.metal", **msl_interface(entry)}
        files[entry["hlsl"]["file"]] = out["hlsl"].encode()
        files[entry["msl"]["file"]] = out["msl"].encode()
    manifest["cross_compiled"] = {
        "how": "GLSL -> SPIR-V (glslangValidator -G; HLSL: SSBO bindings shifted by "
        f"{PARAMS_REGISTER_SHIFT}; "
        f"MSL: sampled textures by {MSL_TEXTURE_SHIFT}, SSBOs by {MSL_BUFFER_SHIFT}; the params block "
        "instance named 'params', the FrameUniforms instance 'frame'; dst and FrameUniforms at binding 0) "
        f"-> spirv-cross --hlsl --shader-model {HLSL_SHADER_MODEL} / --msl "
        f"--msl-version {MSL_VERSION} --msl-decoration-binding; entry points renamed to the pass names",
        "hlsl": "shader model 5.0, one file and entry point per pass (the pass's name), [numthreads] = "
        "local_size; input i: Texture2DArray src<i> at t<i> (its SamplerState s<i> is unused: Load only, "
        f"bind none); output: RWTexture2DArray dst at u0; params: ByteAddressBuffer params at "
        f"t{PARAMS_REGISTER_SHIFT}, a buffer of its own holding the pass's range of weights.bin "
        "(params.offset, params.bytes; read from byte 0); u_flip_y / a scalar input: a member of $Globals; "
        "a frame pass's uniform block: cbuffer FrameUniforms at b0 (members frame_<GLSL name>). "
        "Per pass: hlsl.resources",
        "msl": "MSL 2.1, kernel named after the pass; output texture(0), input i texture(i + 1) (its "
        "sampler(i + 1) unused), the uniform or a frame pass's FrameUniforms buffer(0), params buffer(1) "
        "(the pass's range of "
        "weights.bin, from its start or at its offset); threadsPerThreadgroup = local_size. Per pass: "
        "msl.arguments",
        "validated": f"HLSL compiled back by glslang's HLSL front end ({HLSL_SPIRV_COMMAND})"
        if validate
        else "not validated",
    }
    return manifest


def _with_spirv(program: ComputeProgram, files: dict[str, bytes], validate: bool) -> dict:
    """The Vulkan program's manifest with its SPIR-V: each pass compiled by glslangValidator -V (which
    also validates the source; ``validate``: spirv-val checks the module too, where installed) into
    ``files`` as <name>.spv, recorded in the pass's ``spirv`` (file, bytes, sha256) and the manifest's.
    Without glslangValidator the passes are written as source only and the manifest says how to
    compile them."""
    manifest = json.loads(json.dumps(program.manifest))
    if not glslang_available():
        log.warning("glslangValidator not found: writing the Vulkan passes without their SPIR-V")
        manifest["spirv"] = {"compiled": False, "how": f"{SPIRV_COMMAND} -o <name>.spv <name>.comp"}
        return manifest
    for entry in shader_entries(manifest):  # the network's passes and the frame's
        words = compile_spirv(program.sources[entry["shader"]], validate=validate)
        name = entry["shader"].removesuffix(".comp") + ".spv"
        files[name] = words
        entry["spirv"] = {"file": name, "bytes": len(words), "sha256": sha256_hex(words)}
    manifest["spirv"] = {
        "compiled": True,
        "how": f"{SPIRV_COMMAND} -o <name>.spv <name>.comp",
        "target_env": SPIRV_TARGET_ENV,
        "entry_point": "main",
        "validated": f"spirv-val --target-env {SPIRV_TARGET_ENV}"
        if validate and spirv_validator_available()
        else "glslangValidator only",
    }
    return manifest


def load_compute_export(export_dir: str | Path) -> ComputeProgram:
    """Rebuild a :class:`ComputeProgram` from an export folder (manifest + shaders + weights.bin, and a
    Vulkan export's SPIR-V where it holds them)."""
    d, manifest = _read_export(export_dir)
    if manifest.get("format") not in COMPUTE_FORMATS:
        raise NeuralaoError(f"{d} is not a compute-shader export")
    sources = {
        p["shader"]: _read_checked(d, manifest, p["shader"]).decode() for p in shader_entries(manifest)
    }
    weights = _read_checked(d, manifest, manifest["weights"]["file"])
    spirv = {
        p["shader"]: _read_checked(d, manifest, p["spirv"]["file"])
        for p in shader_entries(manifest)
        if "spirv" in p
    }
    return ComputeProgram(sources, weights, manifest, spirv)


def load_cross_sources(export_dir: str | Path, language: str = "hlsl") -> dict[str, str]:
    """{pass name: HLSL (``language="hlsl"``) or MSL (``"msl"``) text} of every pass of an export written
    with ``cross=True`` (the network's and the frame's), hashes checked."""
    if language not in ("hlsl", "msl"):
        raise NeuralaoError(f"language must be 'hlsl' or 'msl', got {language!r}")
    d, manifest = _read_export(export_dir)
    if "cross_compiled" not in manifest:
        raise NeuralaoError(f"export {d} has no HLSL / MSL (write it with --hlsl-msl)")
    return {
        p["name"]: _read_checked(d, manifest, p[language]["file"]).decode() for p in shader_entries(manifest)
    }
