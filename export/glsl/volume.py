"""The vertex-shader GLSL function of the per-region volume AO models (pipeline/bakes/volumes.py), its
packed uniform layout and a numpy evaluator of exactly that layout.

An engine tags each dynamic object with the region it is in, blends that region's packed model with
the one it used on the previous frame (:class:`neuralao.runtime.probe.TemporalBlend`) and uploads the result
as
``uniform vec4 u_nao_volume[SIZE]``; the vertex shader calls ``nao_volume_ao(world_position,
world_normal)`` per vertex. The short and long distances are pre-blended (``blend``, Sloan et al.'s
97% long), so one function is evaluated, with linear SH (the paper's engine: 8 vec4 = 128 bytes per
region) or quadratic SH (22 vec4 = 352 bytes).

Packed layout (``SIZE = 1 + 7 * chunks`` vec4, chunks = 1 linear, 3 quadratic):

* ``[0]``: the model's centre c in xyz (w = 0);
* ``[1 + 7 k + t]``: chunk k of term t (t = mean, +x, -x, +y, -y, +z, -z) of the blended AO-space SH
  coefficients multiplied by the SH normalisation constants, so AO is a dot product with the plain
  polynomials of the normal: chunk 0 with (1, n.y, n.z, n.x), chunk 1 with (n.x n.y, n.y n.z,
  3 n.z^2 - 1, n.x n.z), chunk 2 with (n.x^2 - n.y^2, 0, 0, 0).

``AO = clamp(sum_k dot(v_k(p), b_k(n)), 0, 1)`` with ``v_k(p) = [1+7k] + dp.x [2+7k] + dn.x [3+7k] + ...``,
``dp = max(p - c, 0)``, ``dn = min(p - c, 0)``: eq. 4 (a vector difference and 6 multiply-adds per
chunk). Shader text lives in the named templates below, filled strictly by one writer (STYLE 3).
"""

from __future__ import annotations

from pathlib import Path
from string import Template

import numpy as np

from neuralao.export.glsl.dialects import get_dialect
from neuralao.export.glsl.templates import fill_from
from neuralao.runtime.foundation import sh
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_bytes, write_json, write_text

UNIFORM = "u_nao_volume"
CHUNKS = {"linear": 1, "quadratic": 3}

_T: dict[str, str] = {}

_T[
    "function"
] = """// neuralao volume AO (Sloan et al. 2013, eq. 4): centre + constant + 6 directional derivatives per
// SH coefficient, ${order} SH, distances blended ${blend} long. One region's model in ${size} vec4:
// [0].xyz = centre; [1 + 7 k + t] = chunk k of term t (mean, +x, -x, +y, -y, +z, -z), premultiplied
// by the SH constants. p: world position, n: unit world normal. Returns AO in [0, 1].
uniform vec4 ${uniform}[${size}];

float nao_volume_ao(vec3 p, vec3 n) {
    vec3 d = p - ${uniform}[0].xyz;
    vec3 dp = max(d, vec3(0.0));
    vec3 dn = min(d, vec3(0.0));
${basis}
    float ao = 0.0;
${chunks}
    return clamp(ao, 0.0, 1.0);
}
"""

_T["basis_0"] = "    vec4 b0 = vec4(1.0, n.y, n.z, n.x);"
_T["basis_1"] = "    vec4 b1 = vec4(n.x * n.y, n.y * n.z, 3.0 * n.z * n.z - 1.0, n.x * n.z);"
_T["basis_2"] = "    vec4 b2 = vec4(n.x * n.x - n.y * n.y, 0.0, 0.0, 0.0);"

_T["chunk"] = """    ao += dot(${u}[${i0}] + dp.x * ${u}[${i1}] + dn.x * ${u}[${i2}] + dp.y * ${u}[${i3}]
              + dn.y * ${u}[${i4}] + dp.z * ${u}[${i5}] + dn.z * ${u}[${i6}], b${k});"""

# A vertex shader that evaluates the function per point (transform feedback of v_ao): the check of
# the function against the numpy evaluator, and the shape of how an engine calls it.
_T["probe_vertex"] = """${header}
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
out float v_ao;

${function}
void main() {
    v_ao = nao_volume_ao(a_position, a_normal);
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
}
"""

_T["probe_fragment"] = """${header}
layout(location = 0) out vec4 o_colour;
void main() {
    o_colour = vec4(1.0);
}
"""

TEMPLATES = {k: Template(v) for k, v in _T.items()}


def fill(template: str, /, **fields: object) -> str:
    return fill_from(TEMPLATES, template, "volume GLSL", **fields)


def _chunks(order: str) -> int:
    try:
        return CHUNKS[order]
    except KeyError:
        raise NeuralaoError(f"order must be 'linear' or 'quadratic', got {order!r}") from None


def packed_size(order: str) -> int:
    """vec4 count of one packed model."""
    return 1 + 7 * _chunks(order)


def volume_function(order: str = "linear", blend: float = 0.97) -> str:
    """The GLSL text of ``uniform vec4 u_nao_volume[SIZE]`` and ``float nao_volume_ao(vec3 p, vec3 n)``
    (no #version line: include it in any GLSL 3.30 / ES 3.00 / 4.x vertex shader)."""
    k = _chunks(order)
    chunks = "\n".join(
        fill("chunk", u=UNIFORM, k=c, **{f"i{t}": 1 + 7 * c + t for t in range(7)}) for c in range(k)
    )
    basis = "\n".join(fill(f"basis_{c}") for c in range(k))
    return fill(
        "function",
        order=order,
        blend=f"{blend:g}",
        size=packed_size(order),
        uniform=UNIFORM,
        basis=basis,
        chunks=chunks,
    )


def probe_shaders(order: str = "linear", blend: float = 0.97, dialect: str = "glsl330") -> tuple[str, str]:
    """(vertex, fragment) sources of the transform-feedback probe program in a dialect."""
    header = get_dialect(dialect).header()
    return (
        fill("probe_vertex", header=header, function=volume_function(order, blend)),
        fill("probe_fragment", header=header),
    )


def pack_model(centre: np.ndarray, coefficients: np.ndarray, order: str, blend: float) -> np.ndarray:
    """One region's model -> (SIZE, 4) float32 in the layout of the module doc.

    centre (3,), coefficients (7, 2, 9) AO-space SH (neuralao.pipeline.bakes.volumes.RegionModel).
    """
    k = _chunks(order)
    f = (1.0 - blend) * coefficients[:, 0, :] + blend * coefficients[:, 1, :]  # (7, 9)
    g = np.zeros((7, 4 * k))
    n = min(4 * k, sh.QUADRATIC)
    g[:, :n] = f[:, :n] * sh.NORMALISATION[:n]
    out = np.zeros((packed_size(order), 4))
    out[0, :3] = centre
    for c in range(k):
        out[1 + 7 * c : 8 + 7 * c] = g[:, 4 * c : 4 * c + 4]
    return out.astype(np.float32)


def pack_volumes(vol, order: str = "linear") -> np.ndarray:
    """(regions, SIZE, 4) float32: every region's packed model (neuralao.pipeline.bakes.volumes.Volumes)."""
    return np.stack([pack_model(m.centre, m.coefficients, order, vol.blend) for m in vol.models])


def evaluate_packed(packed: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """What ``nao_volume_ao`` computes, in float64: packed (SIZE, 4) or (n, SIZE, 4) (one model per
    point), points (n, 3), unit normals (n, 3) -> ao (n,) float64 in [0, 1]."""
    packed = np.asarray(packed, np.float64)
    p = np.asarray(points, np.float64)
    n = np.asarray(normals, np.float64)
    if packed.ndim == 2:
        packed = np.broadcast_to(packed, (len(p), *packed.shape))
    k = (packed.shape[1] - 1) // 7
    d = p - packed[:, 0, :3]
    dp, dn = np.maximum(d, 0.0), np.minimum(d, 0.0)
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    zero = np.zeros_like(x)
    basis = [
        np.stack([np.ones_like(x), y, z, x], axis=1),
        np.stack([x * y, y * z, 3.0 * z * z - 1.0, x * z], axis=1),
        np.stack([x * x - y * y, zero, zero, zero], axis=1),
    ]
    ao = np.zeros(len(p))
    for c in range(k):
        u = packed[:, 1 + 7 * c : 8 + 7 * c]  # (n, 7, 4)
        v = u[:, 0] + dp[:, 0:1] * u[:, 1] + dn[:, 0:1] * u[:, 2] + dp[:, 1:2] * u[:, 3]
        v = v + dn[:, 1:2] * u[:, 4] + dp[:, 2:3] * u[:, 5] + dn[:, 2:3] * u[:, 6]
        ao += (v * basis[c]).sum(axis=1)
    return np.clip(ao, 0.0, 1.0)


def write_volume_glsl(vol, out_dir: str | Path, order: str = "linear") -> dict:
    """``nao_volume.glsl`` (the function), ``models.bin`` ((regions, SIZE, 4) float32 little endian)
    and ``manifest.json`` (layout, order, blend, sizes, region boxes) into ``out_dir``, atomically."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise NeuralaoError(f"--glsl {out} exists and is not a folder")
    packed = pack_volumes(vol, order)
    manifest = {
        "format": "neuralao-volume-glsl",
        "version": 1,
        "function": "float nao_volume_ao(vec3 p, vec3 n)",
        "source": "nao_volume.glsl",
        "uniform": {"name": UNIFORM, "type": "vec4", "count": packed_size(order)},
        "order": order,
        "blend": vol.blend,
        "half_distances": list(vol.half_distances),
        "models": {"file": "models.bin", "dtype": "float32-le", "shape": list(packed.shape)},
        "bytes_per_region": int(packed[0].nbytes),
        "layout": "[0].xyz centre; [1 + 7k + t] chunk k of term t (mean,+x,-x,+y,-y,+z,-z), "
        "SH constants folded in",
        "regions": [{"name": r.name, "min": list(r.lo), "max": list(r.hi)} for r in vol.regions],
        "temporal_blend": "engine side, per object and frame: linearise target and previous state at the "
        "object's position (neuralao.runtime.probe.anchored), then state = target + (previous - target) * "
        "exp(-dt / tau)",
    }
    write_text(out / "nao_volume.glsl", volume_function(order, vol.blend))
    write_bytes(out / "models.bin", packed.astype("<f4").tobytes())
    write_json(out / "manifest.json", manifest)
    return manifest
