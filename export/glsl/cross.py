"""SPIR-V of the generated compute passes, and HLSL and MSL through it: glslangValidator compiles the
GLSL 4.30 source to (OpenGL) SPIR-V, SPIRV-Cross writes HLSL (shader model 5.0) and MSL (2.1) from it;
the Vulkan dialect's source compiles to Vulkan SPIR-V, the files an engine loads. The GLSL stays the
one source; nothing here writes shader text of its own.

    spirv_cross_available() -> bool
    cross_compile(source) -> {"hlsl": str, "msl": str}
    validate_hlsl(source) -> None        (glslang's HLSL front end: -D -V -e main -S comp)
    compile_spirv(source) -> bytes       (Vulkan GLSL -> SPIR-V: glslangValidator -V, spirv-val if present)

Registers and buffer indices follow the GLSL bindings: input i is ``t<i>`` (HLSL; MSL texture(i+1),
the output image taking texture(0)), the output ``u0``, the params buffer ``t16`` (HLSL
``ByteAddressBuffer``; shifted past the inputs so the two never share a register), a pass's loose
uniform (``u_flip_y``, a scalar input) a member of the ``$Globals`` constant buffer (HLSL); in MSL the
params and uniform buffers take ``[[buffer(k)]]`` in declaration order (``main0``'s signature).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

from neuralao.runtime.foundation.errors import NeuralaoError

# SSBO bindings move by this many, so the params buffer (GLSL binding 0) never shares an HLSL t register
# with an input texture (at most this many inputs a pass).
PARAMS_REGISTER_SHIFT = 16
HLSL_SHADER_MODEL = "50"
MSL_VERSION = "20100"
# Vulkan SPIR-V: Vulkan 1.0's environment (SPIR-V 1.0), which every Vulkan driver takes.
SPIRV_TARGET_ENV = "vulkan1.0"
SPIRV_COMMAND = f"glslangValidator -V --target-env {SPIRV_TARGET_ENV}"


def spirv_cross_available() -> bool:
    return shutil.which("spirv-cross") is not None and shutil.which("glslangValidator") is not None


def _run(args: list[str], what: str) -> None:
    r = subprocess.run(args, capture_output=True, text=True, timeout=120)
    if r.returncode != 0:
        lines = [ln for ln in (r.stdout + r.stderr).splitlines() if "ERROR" in ln or "error" in ln]
        raise NeuralaoError(f"{what} failed: {(lines or [r.stdout.strip() or r.stderr.strip()])[0]}")


def cross_compile(source: str) -> dict[str, str]:
    """GLSL 4.30 compute ``source`` -> {"hlsl": HLSL SM 5.0 text, "msl": MSL 2.1 text}."""
    if not spirv_cross_available():
        raise NeuralaoError(
            "HLSL / MSL need spirv-cross and glslangValidator (apt-get install spirv-cross glslang-tools)"
        )
    with tempfile.TemporaryDirectory(prefix="nao_cross_") as tmp:
        d = Path(tmp)
        (d / "pass.comp").write_text(source)
        _run(
            [
                "glslangValidator",
                "-G",
                "--shift-ssbo-binding",
                "comp",
                str(PARAMS_REGISTER_SHIFT),
                "-o",
                str(d / "pass.spv"),
                str(d / "pass.comp"),
            ],
            "glslangValidator (GLSL -> SPIR-V)",
        )
        _run(
            [
                "spirv-cross",
                str(d / "pass.spv"),
                "--hlsl",
                "--shader-model",
                HLSL_SHADER_MODEL,
                "--output",
                str(d / "pass.hlsl"),
            ],
            "spirv-cross --hlsl",
        )
        _run(
            [
                "spirv-cross",
                str(d / "pass.spv"),
                "--msl",
                "--msl-version",
                MSL_VERSION,
                "--output",
                str(d / "pass.metal"),
            ],
            "spirv-cross --msl",
        )
        return {"hlsl": (d / "pass.hlsl").read_text(), "msl": (d / "pass.metal").read_text()}


def validate_hlsl(source: str) -> None:
    """Compile HLSL compute ``source`` (entry ``main``) with glslang's HLSL front end; NeuralaoError on
    failure."""
    if shutil.which("glslangValidator") is None:
        raise NeuralaoError("glslangValidator is not installed (apt-get install glslang-tools)")
    with tempfile.TemporaryDirectory(prefix="nao_hlsl_") as tmp:
        path = Path(tmp) / "pass.hlsl"
        path.write_text(source)
        _run(
            [
                "glslangValidator",
                "-D",
                "-V",
                "-e",
                "main",
                "-S",
                "comp",
                "-o",
                str(Path(tmp) / "pass.spv"),
                str(path),
            ],
            "glslangValidator -D (HLSL)",
        )


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
