"""SPIR-V of the generated compute passes, and HLSL and MSL through it: glslangValidator compiles the
GLSL 4.30 source to (OpenGL) SPIR-V, SPIRV-Cross writes HLSL (shader model 5.0) and MSL (2.1) from it;
the Vulkan dialect's source compiles to Vulkan SPIR-V, the files an engine loads. The GLSL stays the
one source; nothing here writes shader text of its own.

    spirv_cross_available() -> bool
    cross_compile(source, entry="main") -> {"hlsl": str, "msl": str}
    compile_hlsl(source, entry="main") -> bytes   (HLSL -> Vulkan SPIR-V, glslang's HLSL front end)
    hlsl_spirv_binding(register) -> int   the binding an HLSL register gets in compile_hlsl's SPIR-V
    validate_hlsl(source, entry="main") -> None
    hlsl_interface(pass_entry) -> dict    the HLSL file's entry, threads and resources (manifest "hlsl")
    msl_interface(pass_entry) -> dict     the MSL file's kernel, threads and argument indices ("msl")
    compile_spirv(source) -> bytes       (Vulkan GLSL -> SPIR-V: glslangValidator -V, spirv-val if present)

Names are stable: each pass's entry point is the pass's name (``p02_conv``) in both languages; input i is
``src<i>``, the output ``dst``, the parameter buffer ``params`` (glslang leaves the GLSL's block instance
unnamed, so its OpName is set before SPIRV-Cross reads the module, which would call it ``_<id>``), a
network pass's uniform keeps its GLSL name (``u_flip_y``, ``u_radius``). A frame pass's uniform block is
``cbuffer FrameUniforms`` in HLSL, its members ``frame_u_proj``, ``frame_u_radius``,
``frame_u_pixels_per_unit``, ``frame_u_flip_y`` (the instance is named ``frame``), and the argument
``constant FrameUniforms& frame`` in MSL (members as in GLSL).

HLSL registers: input i ``t<i>`` (plus an unused ``SamplerState s<i>``: the passes only ``Load``), the
output ``u0``, the params ``ByteAddressBuffer`` ``t16`` (shifted past the inputs so the two never share a
register), a network pass's uniform a member of ``$Globals`` (the compiler's ``b0``), a frame pass's
``FrameUniforms`` ``b0``. MSL: the output ``texture(0)``, input i ``texture(i + 1)`` (its unused sampler
``sampler(i + 1)``), the uniform or ``FrameUniforms`` ``buffer(0)``, the params ``buffer(1)``
(``--msl-decoration-binding``: the SPIR-V bindings, shifted, are the indices; none is left to
SPIRV-Cross's order). The frame passes' GLSL numbers its bindings in one sequence (inputs, output, block:
Vulkan's and WebGPU's single namespace), so the output and the block are moved to binding 0 in the SPIR-V
SPIRV-Cross reads (:data:`FIXED_BINDINGS`): the same registers and indices in every pass.

The params buffer of a pass is a buffer of its own: its range of ``weights.bin`` (``params.offset``,
``params.bytes``), which the HLSL and MSL read from byte 0. Unity and Unreal bind whole buffers, so
each pass gets one; D3D12 and Metal may instead view one buffer at the offset (256-byte aligned).
"""

from __future__ import annotations

import shutil
import struct
import subprocess
import tempfile
from pathlib import Path

from neuralao.export.glsl.frame import UNIFORM_BLOCK_BYTES, UNIFORM_MEMBERS
from neuralao.runtime.foundation.errors import NeuralaoError

# SSBO bindings move by this many, so the params buffer (GLSL binding 0) never shares an HLSL t register
# with an input texture (at most this many inputs a pass).
PARAMS_REGISTER_SHIFT = 16
HLSL_SHADER_MODEL = "50"
MSL_VERSION = "20100"
# MSL indices (--msl-decoration-binding): sampled textures move past the output image's texture(0), the
# params buffer past the uniform's buffer(0) (a loose uniform has no binding, so it takes 0).
MSL_TEXTURE_SHIFT = 1
MSL_BUFFER_SHIFT = 1
# GLSL block types whose instance is anonymous -> the name the instance gets in HLSL / MSL.
BLOCK_INSTANCE_NAMES = {"Params": "params", "FrameUniforms": "frame"}
# Variables (by name, after BLOCK_INSTANCE_NAMES) given a fixed binding in the SPIR-V SPIRV-Cross reads:
# the output and the frame passes' uniform block, whatever binding the pass's GLSL gives them.
FIXED_BINDINGS = {"dst": 0, "frame": 0}
# A frame pass's uniform block in HLSL / MSL: the GLSL block name, its instance, its std140 bytes.
FRAME_BLOCK, FRAME_INSTANCE, FRAME_BLOCK_BYTES = "FrameUniforms", "frame", UNIFORM_BLOCK_BYTES
_HLSL_TYPES = {"vec2": "float2", "float": "float", "int": "int"}
# glslang's HLSL front end (the HLSL compiled back to Vulkan SPIR-V): each register class in its own
# binding range, textures and SRV buffers at their register numbers, $Globals auto-mapped into 64..
HLSL_BINDING_SHIFTS = {"uav": 32, "sampler": 48, "cbuffer": 64}
# glslang's HLSL front end has no min16float4x4 constructor (SPIRV-Cross writes one in the fp16 passes'
# matrix products); a minimum-precision type is "at least 16 bits", so it compiles as float4x4 here, what
# a D3D driver without 16-bit ALUs does too. FXC and DXC take the text as it is.
HLSL_DEFINES = {"min16float4x4": "float4x4"}
HLSL_SPIRV_COMMAND = (
    "glslangValidator -D -V -S comp -e <entry> --hlsl-iomap --auto-map-bindings "
    + " ".join(f"--shift-{k}-binding comp {v}" for k, v in HLSL_BINDING_SHIFTS.items())
    + "".join(f" -D{k}={v}" for k, v in HLSL_DEFINES.items())
)
# Vulkan SPIR-V: Vulkan 1.0's environment (SPIR-V 1.0), which every Vulkan driver takes.
SPIRV_TARGET_ENV = "vulkan1.0"
SPIRV_COMMAND = f"glslangValidator -V --target-env {SPIRV_TARGET_ENV}"

_OP_NAME, _OP_TYPE_POINTER, _OP_VARIABLE, _OP_DECORATE, _DECORATION_BINDING = 5, 32, 59, 71, 33


def spirv_cross_available() -> bool:
    return shutil.which("spirv-cross") is not None and shutil.which("glslangValidator") is not None


def _run(args: list[str], what: str) -> None:
    r = subprocess.run(args, capture_output=True, text=True, timeout=120)
    if r.returncode != 0:
        lines = [ln for ln in (r.stdout + r.stderr).splitlines() if "ERROR" in ln or "error" in ln]
        raise NeuralaoError(f"{what} failed: {(lines or [r.stdout.strip() or r.stderr.strip()])[0]}")


def _spirv_string(words: list[int]) -> str:
    return struct.pack(f"<{len(words)}I", *words).split(b"\0")[0].decode()


def _spirv_words(text: str) -> list[int]:
    data = text.encode() + b"\0"
    data += b"\0" * (-len(data) % 4)
    return list(struct.unpack(f"<{len(data) // 4}I", data))


def name_block_instances(spv: bytes, names: dict[str, str] = BLOCK_INSTANCE_NAMES) -> bytes:
    """SPIR-V ``spv`` with the OpName of each variable whose type is a block named in ``names`` (by its
    type's OpName) set to the name given: glslang names an anonymous instance "", which SPIRV-Cross
    writes as ``_<id>``. Only debug names change; NeuralaoError when such a variable has no OpName."""
    words = list(struct.unpack(f"<{len(spv) // 4}I", spv))
    header, insts, i = words[:5], [], 5
    while i < len(words):
        count = words[i] >> 16
        insts.append(words[i : i + count])
        i += count
    op_names = {w[1]: _spirv_string(w[2:]) for w in insts if w[0] & 0xFFFF == _OP_NAME}
    pointee = {w[1]: w[3] for w in insts if w[0] & 0xFFFF == _OP_TYPE_POINTER}
    wanted = {}
    for w in insts:
        if w[0] & 0xFFFF == _OP_VARIABLE:
            block = op_names.get(pointee.get(w[1], -1), "")
            if block in names:
                wanted[w[2]] = names[block]
    out = []
    for w in insts:
        if w[0] & 0xFFFF == _OP_NAME and w[1] in wanted:
            body = [w[1], *_spirv_words(wanted.pop(w[1]))]
            w = [(len(body) + 1) << 16 | _OP_NAME, *body]
        out.append(w)
    if wanted:
        raise NeuralaoError(f"SPIR-V variables {sorted(wanted)} have no OpName to set")
    flat = header + [x for w in out for x in w]
    return struct.pack(f"<{len(flat)}I", *flat)


def set_bindings(spv: bytes, bindings: dict[str, int] = FIXED_BINDINGS) -> bytes:
    """SPIR-V ``spv`` with the Binding decoration of each variable named in ``bindings`` (by its OpName)
    set to the binding given; names the module does not have are skipped."""
    words = list(struct.unpack(f"<{len(spv) // 4}I", spv))
    ids, i = {}, 5
    while i < len(words):
        count = words[i] >> 16
        if words[i] & 0xFFFF == _OP_NAME and _spirv_string(words[i + 2 : i + count]) in bindings:
            ids[words[i + 1]] = bindings[_spirv_string(words[i + 2 : i + count])]
        i += count
    i = 5
    while i < len(words):
        count = words[i] >> 16
        op = words[i : i + count]
        if op[0] & 0xFFFF == _OP_DECORATE and count == 4 and op[2] == _DECORATION_BINDING and op[1] in ids:
            words[i + 3] = ids[op[1]]
        i += count
    return struct.pack(f"<{len(words)}I", *words)


def _glsl_to_spirv(d: Path, shifts: dict[str, int], out: str) -> Path:
    args = ["glslangValidator", "-G"]
    for kind, n in shifts.items():
        args += [f"--shift-{kind}-binding", "comp", str(n)]
    _run([*args, "-o", str(d / out), str(d / "pass.comp")], "glslangValidator (GLSL -> SPIR-V)")
    path = d / out
    path.write_bytes(set_bindings(name_block_instances(path.read_bytes())))
    return path


def cross_compile(source: str, entry: str = "main") -> dict[str, str]:
    """GLSL 4.30 compute ``source`` -> {"hlsl": HLSL SM 5.0 text, "msl": MSL 2.1 text}, each with its
    entry point (HLSL function, MSL kernel) named ``entry``."""
    if not spirv_cross_available():
        raise NeuralaoError(
            "HLSL / MSL need spirv-cross and glslangValidator (apt-get install spirv-cross glslang-tools)"
        )
    rename = ["--rename-entry-point", "main", entry, "comp"]
    with tempfile.TemporaryDirectory(prefix="nao_cross_") as tmp:
        d = Path(tmp)
        (d / "pass.comp").write_text(source)
        hlsl_spv = _glsl_to_spirv(d, {"ssbo": PARAMS_REGISTER_SHIFT}, "hlsl.spv")
        msl_spv = _glsl_to_spirv(d, {"texture": MSL_TEXTURE_SHIFT, "ssbo": MSL_BUFFER_SHIFT}, "msl.spv")
        _run(
            [
                "spirv-cross",
                str(hlsl_spv),
                "--hlsl",
                "--shader-model",
                HLSL_SHADER_MODEL,
                *rename,
                "--output",
                str(d / "pass.hlsl"),
            ],
            "spirv-cross --hlsl",
        )
        _run(
            [
                "spirv-cross",
                str(msl_spv),
                "--msl",
                "--msl-version",
                MSL_VERSION,
                "--msl-decoration-binding",
                *rename,
                "--output",
                str(d / "pass.metal"),
            ],
            "spirv-cross --msl",
        )
        return {"hlsl": (d / "pass.hlsl").read_text(), "msl": (d / "pass.metal").read_text()}


def compile_hlsl(source: str, entry: str = "main") -> bytes:
    """HLSL compute ``source`` with entry ``entry`` -> Vulkan SPIR-V (little-endian words) by glslang's
    HLSL front end, each register class at its own bindings (:data:`HLSL_BINDING_SHIFTS`); the
    resources keep their HLSL names. NeuralaoError when glslang rejects it or is missing."""
    if shutil.which("glslangValidator") is None:
        raise NeuralaoError("glslangValidator is not installed (apt-get install glslang-tools)")
    with tempfile.TemporaryDirectory(prefix="nao_hlsl_") as tmp:
        path = Path(tmp) / "pass.hlsl"
        path.write_text(source)
        args = [
            "glslangValidator",
            "-D",
            "-V",
            "-S",
            "comp",
            "-e",
            entry,
            "--hlsl-iomap",
            "--auto-map-bindings",
        ]
        for kind, n in HLSL_BINDING_SHIFTS.items():
            args += [f"--shift-{kind}-binding", "comp", str(n)]
        args += [f"-D{k}={v}" for k, v in HLSL_DEFINES.items()]
        _run([*args, "-o", str(Path(tmp) / "pass.spv"), str(path)], "glslangValidator -D (HLSL)")
        return (Path(tmp) / "pass.spv").read_bytes()


def hlsl_spirv_binding(register: str) -> int:
    """The Vulkan binding (set 0) that an HLSL register ("t3", "u0", "b0") gets in :func:`compile_hlsl`'s
    SPIR-V ($Globals, the compiler's b0, is auto-mapped to the first cbuffer binding)."""
    base = {"t": 0, "u": HLSL_BINDING_SHIFTS["uav"], "s": HLSL_BINDING_SHIFTS["sampler"]}
    base["b"] = HLSL_BINDING_SHIFTS["cbuffer"]
    return base[register[0]] + int(register[1:])


def validate_hlsl(source: str, entry: str = "main") -> None:
    """Compile HLSL compute ``source`` (entry ``entry``) with glslang's HLSL front end; NeuralaoError on
    failure."""
    compile_hlsl(source, entry)


def _uniform_type(name: str, u: dict) -> str:
    return "int" if name == "u_flip_y" else u.get("type", "float")


# The HLSL element type SPIRV-Cross gives a pass's output, by its GLSL format: one lane for a one-channel
# texture (``unorm`` for a 16-bit unsigned normalised one), four otherwise.
_HLSL_OUTPUT_TYPES = {"r32f": "float", "r16f": "float", "r16": "unorm float"}


def _output_lanes(p: dict) -> str:
    """The HLSL element type of a pass's output (:data:`_HLSL_OUTPUT_TYPES`)."""
    return _HLSL_OUTPUT_TYPES.get(p["output"].get("format"), "float4")


def _frame_cbuffer() -> dict:
    """A frame pass's FrameUniforms resource in HLSL: register b0, each member's HLSL name and offset."""
    return {
        "name": FRAME_BLOCK,
        "type": "cbuffer",
        "register": "b0",
        "bytes": FRAME_BLOCK_BYTES,
        "uniform_block": FRAME_BLOCK,
        "members": [
            {"name": f"{FRAME_INSTANCE}_{name}", "type": _HLSL_TYPES[kind], "offset": offset}
            for name, kind, offset, _ in UNIFORM_MEMBERS
        ],
    }


def hlsl_interface(p: dict) -> dict:
    """What an engine binds for GLSL 4.30 manifest pass ``p`` (a network pass or a frame pass) in its
    HLSL: {"entry", "numthreads", "resources": [{"name", "type", "register", and "texture" (an input, the
    output) or "weights" (params: the pass's range of weights.bin, a buffer of its own) or "cbuffer" +
    "offset" (a network pass's uniform, a $Globals member) or "uniform_block" + "bytes" + "members" (a
    frame pass's FrameUniforms, a cbuffer of its own)}]}.
    """
    res = [
        {
            "name": f"src{inp['binding']}",
            "type": "Texture2DArray<float4>",
            "register": f"t{inp['binding']}",
            "texture": inp["texture"],
        }
        for inp in p["inputs"]
    ]
    out = p["output"]
    res.append(
        {
            "name": "dst",
            "type": f"RWTexture2DArray<{_output_lanes(p)}>",
            "register": f"u{FIXED_BINDINGS['dst']}",
            "texture": out["texture"],
        }
    )
    if "params" in p:
        prm = p["params"]
        res.append(
            {
                "name": "params",
                "type": "ByteAddressBuffer",
                "register": f"t{PARAMS_REGISTER_SHIFT + prm['binding']}",
                "weights": {"file": prm["buffer"], "offset": prm["offset"], "bytes": prm["bytes"]},
            }
        )
    if "uniform_block" in p:
        res.append(_frame_cbuffer())
    uniforms = p.get("uniforms", {})
    if len(uniforms) > 1:  # pragma: no cover - one uniform a pass (pad, crop: u_flip_y; uniform: its input)
        raise NeuralaoError(f"pass {p['name']}: more than one uniform")
    for name, u in uniforms.items():
        res.append(
            {
                "name": name,
                "type": _uniform_type(name, u),
                "register": "b0",
                "cbuffer": "$Globals",
                "offset": 0,
            }
        )
    return {"entry": p["name"], "numthreads": list(p["local_size"]), "resources": res}


def msl_interface(p: dict) -> dict:
    """What an engine binds for GLSL 4.30 manifest pass ``p`` in its MSL: {"kernel",
    "threads_per_threadgroup", "arguments": [{"name", "type", "index" ("texture(k)", "buffer(k)"), and
    "texture" / "weights" / "value" as in :func:`hlsl_interface`, or "uniform_block" + "bytes" (a frame
    pass's FrameUniforms, set with setBytes or a buffer)}]}. The unused samplers are left out."""
    args = [
        {
            "name": "dst",
            "type": "texture2d_array<float, access::write>",
            "index": f"texture({FIXED_BINDINGS['dst']})",
            "texture": p["output"]["texture"],
        }
    ]
    args += [
        {
            "name": f"src{inp['binding']}",
            "type": "texture2d_array<float>",
            "index": f"texture({inp['binding'] + MSL_TEXTURE_SHIFT})",
            "texture": inp["texture"],
        }
        for inp in p["inputs"]
    ]
    if "params" in p:
        prm = p["params"]
        args.append(
            {
                "name": "params",
                "type": "const device Params&",
                "index": f"buffer({prm['binding'] + MSL_BUFFER_SHIFT})",
                "weights": {"file": prm["buffer"], "offset": prm["offset"], "bytes": prm["bytes"]},
            }
        )
    if "uniform_block" in p:
        args.append(
            {
                "name": FRAME_INSTANCE,
                "type": f"constant {FRAME_BLOCK}&",
                "index": f"buffer({FIXED_BINDINGS[FRAME_INSTANCE]})",
                "uniform_block": FRAME_BLOCK,
                "bytes": FRAME_BLOCK_BYTES,
            }
        )
    for name, u in p.get("uniforms", {}).items():
        args.append(
            {
                "name": name,
                "type": f"constant {_uniform_type(name, u)}&",
                "index": "buffer(0)",
                "value": "setBytes",
            }
        )
    return {"kernel": p["name"], "threads_per_threadgroup": list(p["local_size"]), "arguments": args}


def spirv_validator_available() -> bool:
    return shutil.which("spirv-val") is not None


def compile_spirv(source: str, validate: bool = True) -> bytes:
    """Vulkan GLSL compute ``source`` -> SPIR-V (the words as little-endian bytes), by
    ``glslangValidator -V``; ``validate``: the module is checked by ``spirv-val`` for the same Vulkan
    environment too, where it is installed. NeuralaoError when glslangValidator is missing or rejects it."""
    if shutil.which("glslangValidator") is None:
        raise NeuralaoError("SPIR-V needs glslangValidator (apt-get install glslang-tools)")
    with tempfile.TemporaryDirectory(prefix="nao_spirv_") as tmp:
        d = Path(tmp)
        (d / "pass.comp").write_text(source)
        _run(
            [*SPIRV_COMMAND.split(), "-o", str(d / "pass.spv"), str(d / "pass.comp")],
            "glslangValidator -V (Vulkan GLSL -> SPIR-V)",
        )
        if validate and spirv_validator_available():
            _run(["spirv-val", "--target-env", SPIRV_TARGET_ENV, str(d / "pass.spv")], "spirv-val")
        return (d / "pass.spv").read_bytes()
