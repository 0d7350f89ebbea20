"""glslangValidator: compile a generated shader offline (optional at export time)."""

from __future__ import annotations

import logging
import shutil
import subprocess
import tempfile
from pathlib import Path

from neuralao.runtime.foundation.errors import NeuralaoError

log = logging.getLogger(__name__)


def validate_glsl(source: str, stage: str) -> None:
    """Compile ``source`` with glslangValidator (stage: vert | frag | comp); NeuralaoError on failure.

    Raises NeuralaoError when glslangValidator is not installed (callers that treat validation as
    optional check :func:`glslang_available` first).
    """
    exe = shutil.which("glslangValidator")
    if exe is None:
        raise NeuralaoError("glslangValidator is not installed (apt-get install glslang-tools)")
    if stage not in ("vert", "frag", "comp"):
        raise NeuralaoError(f"unknown shader stage {stage!r}")
    with tempfile.TemporaryDirectory(prefix="nao_glsl_") as tmp:
        path = Path(tmp) / f"shader.{stage}"
        path.write_text(source)
        r = subprocess.run([exe, str(path)], capture_output=True, text=True, timeout=60)
    if r.returncode != 0:
        lines = [ln for ln in (r.stdout + r.stderr).splitlines() if "ERROR" in ln] or [r.stdout.strip()]
        raise NeuralaoError(f"glslangValidator rejected the {stage} shader: {lines[0]}")


def glslang_available() -> bool:
    return shutil.which("glslangValidator") is not None


def _can_validate() -> bool:
    if not glslang_available():
        log.warning("glslangValidator not found: exporting shaders without validating them")
        return False
    return True
