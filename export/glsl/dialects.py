"""The shading-language dialects: desktop GLSL 4.3 (explicit bindings), the 3.30 / ES 3.00 overrides
and where each dialect's fragment-target files go, and, for the compute target, WGSL (WebGPU) and
Vulkan GLSL (SPIR-V)."""

from __future__ import annotations

from neuralao.export.glsl.templates import fill, fill_vulkan, fill_wgsl
from neuralao.runtime.foundation.errors import NeuralaoError


class Dialect:
    """Desktop GLSL 4.3 core: explicit ``binding`` qualifiers, no precision statements."""

    name = "glsl430"
    version = "430 core"
    precision = "precision_none"
    explicit_bindings = True
    # compute target: shader file suffix and manifest format
    extension = ".comp"
    compute_format = "neuralao-glsl-compute"

    def fill(self, template: str, /, **fields: object) -> str:
        """Fill one of this dialect's templates (strict, see :func:`neuralao.export.glsl.templates.fill`)."""
        return fill(template, **fields)

    def header(self) -> str:
        return fill("header", version=self.version, precision=fill(self.precision))

    def compute_slots(self, n_inputs: int) -> dict[str, int]:
        """Where a compute pass's resources go: input i at binding i (texture unit), the output image,
        the params buffer and the uniform at their own bindings / location."""
        return {"output": 0, "params": 0, "uniform": 0}

    def ubo_layout(self, binding: int) -> str:
        return fill("ubo_layout_binding", binding=binding) if self.explicit_bindings else fill("ubo_layout")

    def sampler2d(self, name: str, binding: int) -> str:
        if self.explicit_bindings:
            return fill("sampler2d_decl_binding", name=name, binding=binding)
        return fill("sampler2d_decl", name=name)


class GLSL330(Dialect):
    """Desktop GLSL 3.30 core: no binding qualifiers (the host binds blocks and samplers)."""

    name = "glsl330"
    version = "330 core"
    explicit_bindings = False


class ES300(GLSL330):
    """GLSL ES 3.00: as 3.30, plus highp default precisions."""

    name = "es300"
    version = "300 es"
    precision = "precision_es"


class WGSL(Dialect):
    """WGSL for WebGPU, compute target only: the same writer and template names; its table is the
    shared templates in WGSL words plus the WGSL overrides (``templates._WGSL_WORDS``, ``templates._W``).
    One bind group whose bindings run inputs, output, params, uniform."""

    name = "wgsl"
    extension = ".wgsl"
    compute_format = "neuralao-wgsl-compute"

    def fill(self, template: str, /, **fields: object) -> str:
        return fill_wgsl(template, **fields)

    def header(self) -> str:
        return fill_wgsl("header")

    def compute_slots(self, n_inputs: int) -> dict[str, int]:
        return {"output": n_inputs, "params": n_inputs + 1, "uniform": n_inputs + 2}


class Vulkan(Dialect):
    """Vulkan GLSL 4.50 (compiled to SPIR-V by ``glslangValidator -V``), compute target only: the GLSL
    table with the overrides of ``templates._V`` (version line, resource declarations). Bindings as
    WGSL's, all in descriptor set 0; a pass's scalar uniform is a std140 block at its own binding."""

    name = "vulkan"
    version = "450"
    compute_format = "neuralao-vulkan-compute"

    def fill(self, template: str, /, **fields: object) -> str:
        return fill_vulkan(template, **fields)

    def header(self) -> str:
        return fill_vulkan("header", version=self.version)

    compute_slots = WGSL.compute_slots


DIALECTS: dict[str, Dialect] = {d.name: d() for d in (Dialect, GLSL330, ES300)}
COMPUTE_DIALECTS: dict[str, Dialect] = {"glsl430": DIALECTS["glsl430"], "wgsl": WGSL(), "vulkan": Vulkan()}
FRAGMENT_FILES = {
    "glsl330": ("mlp.vert", "mlp.frag"),
    "es300": ("mlp_es300.vert", "mlp_es300.frag"),
    "glsl430": ("mlp_430.vert", "mlp_430.frag"),
}


def get_dialect(name: str) -> Dialect:
    try:
        return DIALECTS[name]
    except KeyError:
        raise NeuralaoError(f"unknown GLSL dialect {name!r} (expected one of {sorted(DIALECTS)})") from None
