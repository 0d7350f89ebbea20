"""The frame passes: every compute pass a screen-space U-Net's frame needs besides the network, from one
description, in every compute dialect (GLSL 4.30, Vulkan GLSL, WGSL; HLSL and MSL come from the GLSL
through :mod:`.cross`), and the manifest section that lists the whole frame in order.

A frame of a U-Net export that declares ``internal_height`` (the shipped ones), in order:

    gtao, gtao_blur GTAO and its blur at W x H                          (a hybrid: GTAO-input U-Net)
    downsample      the engine's depth and normal (and GTAO) point-sampled to the network's w x h
    depth_columns,  the mean foreground depth of the point-sampled G-buffer, on the GPU
    depth_mean                                                          (preprocess version 2 only)
    network_input   the network's input texture (depth as the model's contract says, normal, GTAO)
    network_radius  the network's radius input rho, into the texture its uniform pass would write
    the network's passes (pad .. crop), its uniform pass left out
    upsample        joint bilateral upsampling of the network's AO to W x H; a hybrid upsamples the
                    correction (network AO minus point-sampled GTAO) and adds it to GTAO, clamped
    (composite      instead of downsample / upsample when the network runs at the frame's own size)

No pass reads a full-resolution copy of the G-buffer: the passes read the engine's linear depth and
normal and reconstruct camera-space positions from depth, the pixel and the projection (as XeGTAO does).
At fp16 the AO target is R16F and a hybrid's GTAO targets, the network's input, R16 (16-bit unsigned
normalised); WGSL keeps both r32float (see :data:`AO_FORMATS`, :data:`GTAO_FORMATS`).

Each pass is a :class:`FramePass` (template, fields, textures); :func:`_write_pass` is the one writer,
filling :mod:`.frame_templates`. The maths are those of the Python references the shipped models were
trained and are checked with: ``neuralao.runtime.baselines`` (GTAO, ``GTAOSettings``),
``neuralao.runtime.internal_resolution`` (point sampling, ``UpsampleSettings``),
``neuralao.runtime.unet_input`` (the input contract); their settings arrive as a :class:`FrameSettings`
(this layer imports no runtime module: ``neuralao.runtime.frame_runner.frame_settings()`` builds it).

    frame_passes(manifest, settings, dialect) -> (list[FramePass], dict of FrameTexture)
    slice_directions(settings) -> list of (cos, sin)      GTAO's baked slice directions
    generate_frame(program, settings) -> ComputeProgram   (the program with its frame: sources + "frame")
    shader_entries(manifest) -> list[dict]                every pass entry with a shader (network + frame)
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from neuralao.export.glsl.frame_templates import FILLS
from neuralao.export.glsl.graph import glsl_float
from neuralao.export.glsl.image import ComputeProgram
from neuralao.export.glsl.memory import memory_section
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.metadata import metadata_internal_height, metadata_pad_mode

FRAME_FORMAT_VERSION = 1
# Workgroup of every frame pass but the reductions (which run one invocation per column / one in all).
FRAME_LOCAL_SIZE = (8, 8)
# The per-frame uniform block every frame pass binds (std140; WGSL's struct has the same offsets).
UNIFORM_BLOCK_BYTES = 32
UNIFORM_MEMBERS = (
    ("u_proj", "vec2", 0, "(P00, P11) of the projection matrix: (f * H / W, f), f = 1 / tan(yfov / 2)"),
    ("u_radius", "float", 8, "R, the AO radius in scene units"),
    ("u_pixels_per_unit", "float", 12, "0.5 * H * P11 (H: the frame's height in pixels)"),
    (
        "u_flip_y",
        "int",
        16,
        "1: every texture of the frame is stored bottom-up (GL: row 0 = the bottom row); 0: row 0 is the "
        "top row (D3D, Vulkan, Metal, WebGPU). Set the u_flip_y of the network's passes that have one "
        "(pad and crop, or the convs they were fused into) the same",
    ),
)
FORMATS = {"RGBA32F": "rgba32f", "R32F": "r32f", "R16F": "r16f", "R16": "r16"}
# The frame's full-resolution AO target at each precision of the program and dialect. AO lies in [0, 1],
# where half floats step by at most 2^-11, so fp16 stores it R16F: GL's r16f and Vulkan's r16f (a storage
# image with shaderStorageImageExtendedFormats) are storage formats; core WebGPU has no r16float storage
# texture, so WGSL keeps r32float. Depth-derived data (the point-sampled position) stays 32-bit at either
# precision.
AO_FORMATS = {"fp32": "R32F", "fp16": "R16F"}
# A hybrid's GTAO targets (gtao_raw, gtao), the network's input, at each precision: a trained correction
# moves by up to 20x a change of its GTAO input, and R16F's rounding of GTAO near 1 (up to 2.4e-4) moved
# the default's AO by 0.01. GTAO lies in [0, 1] (the GTAO pass clamps it, its blur averages it), so fp16
# stores it R16: 16-bit unsigned normalised, steps of 1/65535 (32x finer than R16F near 1) in R16F's 2
# bytes; GL's r16 and Vulkan's r16 (shaderStorageImageExtendedFormats) are storage formats. Core WebGPU
# has no 16-bit normalised storage texture, so WGSL keeps r32float.
GTAO_FORMATS = {"fp32": "R32F", "fp16": "R16"}
WGSL_AO_FORMAT_NOTE = (
    "WGSL: r16float is not a storage texture format in core WebGPU, so the AO targets stay r32float at fp16"
)
WGSL_GTAO_FORMAT_NOTE = (
    "WGSL: core WebGPU has no 16-bit normalised storage texture (r16unorm), so GTAO stays r32float at fp16"
)


@dataclass(frozen=True)
class FrameSettings:
    """What the frame passes bake in: the GTAO and upsampling settings of the runtime references.

    noise : GTAO's noise tile, (noise_size * noise_size * 4) floats, RGBA per texel, GL rows (the
    ``noise.texels`` of ``neuralao.runtime.baselines.gtao_pass_description``); only lanes 0 and 1 are used.
    """

    slices: int = 4  # GTAO slice directions per pixel
    steps: int = 8  # GTAO horizon samples per side of a slice
    falloff: float = 0.2  # fraction of the radius over which an occluder's weight fades
    noise_size: int = 4  # side of GTAO's noise tile and of its blur window
    blur: bool = True  # GTAO's blur pass
    noise: tuple[float, ...] = ()  # see the class docstring
    spatial_sigma: float = 0.6  # upsampling: Gaussian of the distance to a low texel, in low texels
    plane_sigma: float = 0.03  # upsampling: tangent-plane distance / depth at which weight drops by 1/e
    normal_power: float = 8.0  # upsampling: exponent of the normals' cosine
    floor: float = 1e-3  # upsampling: share of the spatial weight kept where geometry disagrees
    thickness_cap: float = 4.0  # input version 4: the thickness channel's clamp (unet_input.THICKNESS_CAP)

    def as_json(self) -> dict:
        return {
            "gtao": {
                "slices": self.slices,
                "steps": self.steps,
                "falloff": self.falloff,
                "noise_size": self.noise_size,
                "blur": self.blur,
                "noise_texels": "baked into the gtao pass as constants (GL rows): per texel its slice "
                "directions (cos, sin) of (slice + lane 0) * pi / slices and its step jitter (lane 1)",
            },
            "upsample": {
                "spatial_sigma": self.spatial_sigma,
                "plane_sigma": self.plane_sigma,
                "normal_power": self.normal_power,
                "floor": self.floor,
            },
        }


@dataclass(frozen=True)
class FrameTexture:
    """A texture of the frame: size formulas over the frame's symbols (W, H: the frame; w, h: the
    network's input; wp, hp: that padded), layers of 4 channels (one lane for R32F / R16F / R16), format."""

    ident: str
    width: str
    height: str
    layers: int
    format: str  # the format this program's passes write
    meaning: str
    fp16_format: str = ""  # the format at fp16 where it differs from format at fp32 ("": the same)


def _ao_format(precision: str, dialect: str, formats: dict[str, str] = AO_FORMATS) -> str:
    """The format of a frame's full-resolution one-channel target (``formats``: :data:`AO_FORMATS`, the AO,
    or :data:`GTAO_FORMATS`) for a program at ``precision`` in ``dialect``."""
    return "R32F" if dialect == "wgsl" else formats[precision]


def _ao_texture(
    ident: str, precision: str, dialect: str, meaning: str, formats: dict[str, str] = AO_FORMATS
) -> FrameTexture:
    fp16 = _ao_format("fp16", dialect, formats)
    return FrameTexture(ident, "W", "H", 1, _ao_format(precision, dialect, formats), meaning, fp16)


@dataclass(frozen=True)
class FramePass:
    """One frame pass: body template and its fields, input textures (bindings 0..n-1), the output
    texture, the workgroup, and where it runs (before or after the network)."""

    name: str
    body: str
    inputs: tuple[str, ...]
    output: str
    summary: str
    stage: str
    fields: dict = field(default_factory=dict)
    local_size: tuple[int, int] = FRAME_LOCAL_SIZE


def _model_facts(manifest: dict) -> tuple[bool, int, int | None]:
    """(hybrid, preprocess version, internal height) of a U-Net compute manifest."""
    meta = manifest.get("source_model_metadata", {})
    if meta.get("neuralao_kind") != "unet":
        raise NeuralaoError("frame passes are generated for neuralao U-Nets (metadata neuralao_kind 'unet')")
    try:
        version = int(str(meta.get("preprocess_version")))
    except ValueError:
        raise NeuralaoError(f"unknown preprocess_version {meta.get('preprocess_version')!r}") from None
    if version not in (2, 3, 4):
        raise NeuralaoError(f"frame passes know preprocess versions 2, 3 and 4, the model has {version}")
    internal = metadata_internal_height(meta, "the U-Net")
    metadata_pad_mode(meta, "the U-Net")
    hybrid = str(meta.get("input_channels", "")).split(",")[-1] == "gtao"
    return hybrid, version, internal


def _reads_gtao_raw(manifest: dict) -> bool:
    """Whether the U-Net also reads GTAO before its blur (an input channel ``gtao_raw`` before ``gtao``)."""
    channels = str(manifest.get("source_model_metadata", {}).get("input_channels", "")).split(",")
    return "gtao_raw" in channels


def _network_io(manifest: dict) -> tuple[str, str, str]:
    """(input texture, radius texture, output texture) of the network: what the frame writes and reads."""
    radius = [p for p in manifest["passes"] if p["kind"] == "uniform"]
    if len(radius) != 1 or not manifest.get("outputs"):
        raise NeuralaoError("a U-Net program has one scalar input (the radius) and an output")
    return manifest["input"]["texture"], radius[0]["output"]["texture"], manifest["outputs"][0]["texture"]


def frame_passes(
    manifest: dict, settings: FrameSettings, dialect: str = "glsl430"
) -> tuple[list[FramePass], dict[str, FrameTexture]]:
    """The frame passes of a U-Net compute manifest (in order) and the frame's own textures, for the
    manifest's precision in ``dialect`` (glsl430, vulkan or wgsl)."""
    precision = str(manifest.get("precision", "fp32"))
    hybrid, version, internal = _model_facts(manifest)
    raw = hybrid and _reads_gtao_raw(manifest)
    if raw and not settings.blur:
        raise NeuralaoError(
            "a hybrid that reads GTAO before its blur needs the blur pass, which these frame settings skip"
        )
    net_in, net_radius, net_out = _network_io(manifest)
    scaled = internal is not None
    back = version == 4  # the back layer: one more engine input, a thickness channel
    s = settings
    tex = {
        "depth": FrameTexture(
            "depth", "W", "H", 1, "R32F", "the engine's linear depth -z_cam, 0 on background"
        ),
        "normal": FrameTexture(
            "normal", "W", "H", 1, "RGBA32F", "the engine's camera-space unit normal (xyz), facing the viewer"
        ),
    }
    if back:
        tex["depth_back"] = FrameTexture(
            "depth_back",
            "W",
            "H",
            1,
            "R32F",
            "the engine's back layer: linear depth where the pixel's camera ray leaves the solid it entered, "
            "0 where the visible surface is thin and on background",
        )
    passes = []
    if hybrid:
        if s.blur:
            tex["gtao_raw"] = _ao_texture(
                "gtao_raw", precision, dialect, "GTAO before its blur", GTAO_FORMATS
            )
        about = "GTAO, 1 on background" if s.blur else "GTAO's pass without its blur, 1 on background"
        tex["gtao"] = _ao_texture("gtao", precision, dialect, about, GTAO_FORMATS)
        passes.append(
            FramePass(
                "f_gtao",
                "gtao_body",
                ("depth", "normal"),
                "gtao_raw" if s.blur else "gtao",
                f"GTAO, {s.slices} slices x {s.steps} steps per side",
                "before",
                {"slices": s.slices, "steps": s.steps, "falloff": glsl_float(s.falloff)},
            )
        )
        if s.blur:
            passes.append(
                FramePass(
                    "f_gtao_blur",
                    "gtao_blur_body",
                    ("depth", "gtao_raw"),
                    "gtao",
                    f"GTAO's {s.noise_size}x{s.noise_size} foreground-only blur",
                    "before",
                    {"size": s.noise_size, "half": s.noise_size // 2},
                )
            )
    low = "low_gbuffer"
    tex[low] = FrameTexture(
        low,
        "w",
        "h",
        3 if hybrid else 2,
        "RGBA32F",
        "the engine's depth and normal point-sampled to the network's size: layer 0 camera-space position "
        "+ mask (w), layer 1 normal"
        + (" + the back layer's depth (w)" if back else "")
        + ("; layer 2: GTAO point-sampled" if hybrid else "")
        + (" (x) and GTAO before its blur (y)" if raw else ""),
    )
    sampled = (
        ("depth", "normal")
        + (("gtao",) if hybrid else ())
        + (("gtao_raw",) if raw else ())
        + (("depth_back",) if back else ())
    )
    passes.append(
        FramePass(
            "f_downsample",
            "downsample_body",
            sampled,
            low,
            "point sampling to the network's size, position from depth"
            + (", the back layer" if back else "")
            + (", GTAO" if hybrid else ""),
            "before",
            {
                "gtao": ("downsample_gtao", {"raw": "nao_load(src3, q, 0).x" if raw else "0.0"})
                if hybrid
                else "",
                "back": ("downsample_back", {"src": f"src{len(sampled) - 1}"}) if back else "0.0",
            },
        )
    )
    if version == 2:
        tex["depth_columns"] = FrameTexture(
            "depth_columns", "w", "1", 1, "RGBA32F", "per column: sum of foreground depth, count"
        )
        tex["depth_mean"] = FrameTexture(
            "depth_mean", "1", "1", 1, "RGBA32F", "the mean foreground depth m (1 with none), count, sum"
        )
        passes += [
            FramePass(
                "f_depth_columns",
                "depth_columns_body",
                (low,),
                "depth_columns",
                "foreground depth summed per column",
                "before",
                local_size=(64, 1),
            ),
            FramePass(
                "f_depth_mean",
                "depth_mean_body",
                ("depth_columns",),
                "depth_mean",
                "the mean foreground depth",
                "before",
                local_size=(1, 1),
            ),
        ]
    depth = ("depth_over_mean", {}) if version == 2 else ("log_depth", {})
    passes.append(
        FramePass(
            "f_network_input",
            "network_input_body",
            (low, "depth_mean") if version == 2 else (low,),
            net_in,
            "the network's input: "
            + ("depth / m" if version == 2 else "log depth")
            + ", normal"
            + (", thickness" if back else "")
            + (", GTAO" if hybrid else ""),
            "before",
            {
                "foreground": ("foreground_mask" if version == 2 else "foreground_positive", {}),
                "depth": depth,
                "gtao": _network_input_rest(hybrid, back, s.thickness_cap, raw),
            },
        )
    )
    passes.append(
        FramePass(
            "f_network_radius",
            "network_radius_body",
            ("depth_mean",) if version == 2 else (),
            net_radius,
            "the network's radius input " + ("R P11 / m" if version == 2 else "log(R P11)"),
            "before",
            {"rho": ("rho_over_mean", {}) if version == 2 else ("rho_log", {})},
            local_size=(1, 1),
        )
    )
    tex["ao"] = _ao_texture("ao", precision, dialect, "the AO, in [0, 1], 1 on background")
    if scaled:
        passes.append(
            FramePass(
                "f_upsample",
                "upsample_body",
                ("depth", "normal", net_out, low, "gtao") if hybrid else ("depth", "normal", net_out, low),
                "ao",
                "joint bilateral upsampling"
                + (" of the correction to GTAO, added to GTAO and clamped" if hybrid else " of the AO"),
                "after",
                {
                    "spatial_sigma": glsl_float(s.spatial_sigma),
                    "plane_sigma": glsl_float(s.plane_sigma),
                    "normal_power": glsl_float(s.normal_power),
                    "floor": glsl_float(s.floor),
                    "empty": glsl_float(0.0 if hybrid else 1.0),
                    "low_value": ("low_correction" if hybrid else "low_ao", {}),
                    "result": ("result_combined" if hybrid else "result_ao", {}),
                },
            )
        )
    # at the network's own size (no internal height, or a frame of exactly w x h) nothing is resampled
    passes.append(
        FramePass(
            "f_composite",
            "composite_body",
            ("depth", net_out),
            "ao",
            "the network's AO, 1 on background",
            "after",
        )
    )
    return passes, tex


def _network_input_rest(hybrid: bool, back: bool, cap: float, raw: bool = False) -> tuple[str, dict] | str:
    """The network input's layer 1, its channels after the fourth in order: GTAO (a hybrid), the thickness
    (version 4) then GTAO, GTAO before its blur in front of GTAO where the model reads it, or nothing."""
    if back and raw:
        return ("network_input_back_raw", {"cap": glsl_float(cap)})
    if back:
        return (
            "network_input_back",
            {
                "gtao_empty": "1.0" if hybrid else "0.0",
                "gtao_load": ("network_input_back_gtao", {}) if hybrid else "",
                "cap": glsl_float(cap),
            },
        )
    if not hybrid:
        return ""
    return ("network_input_gtao_raw", {}) if raw else ("network_input_gtao", {})


# --------------------------------------------------------------------------- the writer


def slice_directions(settings: FrameSettings) -> list[tuple[float, float]]:
    """GTAO's screen-space slice directions (cos phi, sin phi), phi = (slice + noise.x) * pi / slices, for
    every texel i of the noise tile and slice k (entry i * slices + k). phi is rounded to float32 step by
    step as a float32 shader computes it, its cosine and sine taken in float64: each direction is the
    float32 nearest the exact one, the same on every GPU (a GPU's own cos / sin may err by 2^-11)."""
    n, slices = settings.noise_size, settings.slices
    if len(settings.noise) != n * n * 4:
        raise NeuralaoError(f"GTAO noise tile needs {n * n * 4} floats, got {len(settings.noise)}")
    f32 = np.float32
    step = f32(f32(math.pi) / f32(slices))
    out = []
    for i in range(n * n):
        for k in range(slices):
            phi = float(f32(f32(f32(k) + f32(settings.noise[4 * i])) * step))
            out.append((float(f32(math.cos(phi))), float(f32(math.sin(phi)))))
    return out


def _noise_table(settings: FrameSettings, fill: Callable[..., str]) -> str:
    """GTAO's noise tile as constants: the slice directions and the step jitter (noise.y) per texel."""
    n = settings.noise_size
    directions = [
        fill("direction_item", x=glsl_float(x), y=glsl_float(y)) for x, y in slice_directions(settings)
    ]
    jitter = [fill("jitter_item", y=glsl_float(settings.noise[4 * i + 1])) for i in range(n * n)]
    return fill(
        "noise_table",
        count=n * n,
        entries=n * n * settings.slices,
        size=n,
        slices=settings.slices,
        directions=",\n".join(directions),
        jitter=",\n".join(jitter),
    )


def _field(value: object, fill: Callable[..., str]) -> str:
    """A body field: text as it is, or (template, fields) filled in the pass's dialect (fields likewise)."""
    if isinstance(value, tuple):
        name, sub = value
        return fill(name, **{k: _field(v, fill) for k, v in sub.items()})
    return str(value)


def _write_pass(p: FramePass, textures: dict[str, str], settings: FrameSettings, dialect: str) -> str:
    """One frame pass's source in ``dialect``; textures: {id: format} of the frame and the network."""
    fill = FILLS[dialect]
    decls = [fill("input_decl", binding=i, name=f"src{i}") for i in range(len(p.inputs))]
    n = len(p.inputs)
    decls.append(fill("output_decl", binding=n, format=fill(f"format_{FORMATS[textures[p.output]]}")))
    decls.append(fill("uniforms_decl", binding=n + 1))
    fields = {k: _field(v, fill) for k, v in p.fields.items()}
    body = (
        fill(p.body, **fields)
        if p.body != "gtao_body"
        else fill(
            p.body,
            **fields,
            sample0=fill("gtao_sample", q="q0", hc="hc0", low="low0"),
            sample1=fill("gtao_sample", q="q1", hc="hc1", low="low1"),
        )
    )
    prelude = fill("prelude") if dialect == "wgsl" else fill("prelude", sampler=fill("sampler"))
    functions = _noise_table(settings, fill) if p.body == "gtao_body" else ""
    lx, ly = p.local_size
    skeleton = {"local_x": lx, "local_y": ly, "load": ""}
    if dialect == "wgsl":
        skeleton["builtins"] = ""
    if p.body == "upsample_body":  # its workgroup shares the low texels (see the template)
        tile = max(lx, ly) + 4
        decls.append(fill("upsample_shared", entries=tile * tile))
        functions = fill("upsample_functions")
        tile_load = fill(
            "upsample_load",
            last_x=lx - 1,
            last_y=ly - 1,
            tile=tile,
            threads=lx * ly,
            low_value=fields["low_value"],
        )
        skeleton["load"] = fill("frame_pass_load", local_x=lx, local_y=ly, tile_load=tile_load)
        if dialect == "wgsl":
            skeleton["builtins"] = fill("frame_pass_builtins")
    return fill(
        "frame_pass",
        header=fill("header"),
        name=p.name,
        summary=p.summary,
        declarations="\n".join(decls),
        prelude=prelude,
        functions=functions,
        body=body,
        **skeleton,
    )


# --------------------------------------------------------------------------- the manifest section

_NETWORK_SYMBOLS = {"W": "w", "H": "h", "Wp": "wp", "Hp": "hp"}
_DIALECT = {
    "neuralao-glsl-compute": "glsl430",
    "neuralao-vulkan-compute": "vulkan",
    "neuralao-wgsl-compute": "wgsl",
}


def _network_size(dim: dict) -> str:
    """A network texture's size formula in the frame's symbols (its W, H are the network's w, h)."""
    if dim["num"] == 0:
        return str(dim["offset"])
    of = _NETWORK_SYMBOLS[dim["of"]]
    text = of if (dim["num"], dim["den"]) == (1, 1) else f"{of}*{dim['num']}/{dim['den']}"
    return text if dim["offset"] == 0 else f"{text}{dim['offset']:+d}"


def _pass_entry(p: FramePass, dialect: str, textures: dict[str, FrameTexture | dict]) -> dict:
    n = len(p.inputs)
    ext = ".wgsl" if dialect == "wgsl" else ".comp"
    fmt = _format_of(textures[p.output])
    entry = {
        "name": p.name,
        "shader": p.name + ext,
        "stage": p.stage,
        "summary": p.summary,
        "inputs": [{"texture": t, "binding": i} for i, t in enumerate(p.inputs)],
        "output": {"texture": p.output, "binding": n, "format": FORMATS[fmt]},
        "uniform_block": {"name": "FrameUniforms", "binding": n + 1, "bytes": UNIFORM_BLOCK_BYTES},
        "local_size": [p.local_size[0], p.local_size[1], 1],
        "dispatch": {
            "size_of": p.output,
            "groups": [
                f"ceil(width({p.output}) / {p.local_size[0]})",
                f"ceil(height({p.output}) / {p.local_size[1]})",
                "1",
            ],
        },
    }
    if dialect == "vulkan":
        entry["bindings"] = (
            [{"set": 0, "binding": i, "kind": "sampled_image", "resource": t} for i, t in enumerate(p.inputs)]
            + [{"set": 0, "binding": n, "kind": "storage_image", "resource": p.output}]
            + [{"set": 0, "binding": n + 1, "kind": "uniform_buffer", "resource": "FrameUniforms"}]
        )
    return entry


def _texture_entry(t: FrameTexture) -> dict:
    entry = {
        "width": t.width,
        "height": t.height,
        "layers": t.layers,
        "format": t.format,
        "meaning": t.meaning,
    }
    if t.fp16_format:  # the memory plan's formats at each precision (memory.memory_section)
        entry["formats"] = {"fp32": "R32F", "fp16": t.fp16_format}
    return entry


def _format_of(t: FrameTexture | dict) -> str:
    return t.format if isinstance(t, FrameTexture) else t["format"]


def _order(manifest: dict, passes: list[FramePass]) -> list[dict]:
    """The whole frame in order: frame passes before the network, its passes, frame passes after."""
    steps = [{"frame_pass": p.name} for p in passes if p.stage == "before"]
    for k, p in enumerate(manifest["passes"]):
        if p["kind"] == "uniform":
            steps.append({"skip": p["name"], "why": "f_network_radius writes its texture"})
            continue
        step = {"network_pass": p["name"], "index": k}
        if "u_flip_y" in p.get("uniforms", {}):  # pad and crop, or the convs they were fused into
            step["u_flip_y"] = "the frame's u_flip_y"
        steps.append(step)
    for p in passes:
        if p.stage == "after":
            step = {"frame_pass": p.name}
            if any(q.name == "f_upsample" for q in passes):
                step["when"] = "(w, h) == (W, H)" if p.name == "f_composite" else "(w, h) != (W, H)"
            steps.append(step)
    return steps


def _formats_entry(formats: dict[str, str], precision: str, dialect: str, why: str, wgsl_note: str) -> dict:
    """The frame section's formats of one kind of full-resolution target (the AO, a hybrid's GTAO) at each
    precision and in this program, and why."""
    fp16 = _ao_format("fp16", dialect, formats)
    return {
        "fp32": _ao_format("fp32", dialect, formats),
        "fp16": fp16,
        "this_program": _ao_format(precision, dialect, formats),
        "why": why
        + (
            "; " + wgsl_note
            if dialect == "wgsl"
            else f"; Vulkan: {FORMATS[fp16]} is a storage image format under "
            "shaderStorageImageExtendedFormats"
        ),
    }


def _section(
    manifest: dict, passes: list[FramePass], tex: dict[str, FrameTexture], settings, dialect
) -> dict:
    hybrid, version, internal = _model_facts(manifest)
    network = {
        ident: {
            "width": _network_size(t["width"]),
            "height": _network_size(t["height"]),
            "layers": int(t["layers"]),
            "format": t["format"],
            "meaning": "the network's "
            + (f"ONNX tensor {t['onnx_tensor']!r}" if t.get("onnx_tensor") else "texture"),
        }
        for ident, t in manifest["textures"].items()
    }
    textures = {t.ident: _texture_entry(t) for t in tex.values()} | network
    entries = [_pass_entry(p, dialect, tex | network) for p in passes]
    precision = str(manifest.get("precision", "fp32"))
    ao_formats = _formats_entry(
        AO_FORMATS,
        precision,
        dialect,
        "AO lies in [0, 1], where half floats step by at most 2^-11; depth-derived textures stay 32-bit at "
        "either precision",
        WGSL_AO_FORMAT_NOTE,
    )
    gtao_formats = _formats_entry(
        GTAO_FORMATS,
        precision,
        dialect,
        "gtao_raw and gtao, the network's input: GTAO lies in [0, 1], where R16 (16-bit unsigned normalised) "
        "steps by 1/65535, 32x finer than half floats near 1, in the same 2 bytes; the trained correction "
        "moves by up to 20x a change of its GTAO input",
        WGSL_GTAO_FORMAT_NOTE,
    )
    size = f"max(1, round(W * {internal} / H)) x {internal} (round halves to even)" if internal else "W x H"
    multiple = int(manifest["pad"]["multiple"])
    return {
        "format_version": FRAME_FORMAT_VERSION,
        "what": "Every pass of a frame in order (steps): the frame passes (passes) and the network's "
        "(the manifest's passes, its uniform pass left out). Bind each pass's inputs, output and uniform "
        "block at its bindings, dispatch its groups, then a barrier (the manifest's barrier).",
        "hybrid": hybrid,
        "preprocess_version": version,
        "internal_height": internal,
        "sizes": {
            "W, H": "the frame: the engine's G-buffer, in pixels",
            "w, h": f"the network's input: {size}",
            "wp, hp": f"w, h rounded up to a multiple of {multiple}",
        },
        "inputs": {
            "depth": "write each frame: linear depth -z_cam in scene units (lane 0), 0 on background; the "
            "passes reconstruct camera-space positions from it, the pixel and u_proj",
            "normal": "write each frame: camera-space unit normal (xyz), OpenGL axes, facing the viewer",
            **(
                {
                    "depth_back": "write each frame: the back layer, linear depth (lane 0) of the first "
                    "surface more than 1e-5 relative depth behind the visible one where it faces the camera "
                    "ray the other way (where the ray leaves the solid), else 0; one more depth pass of the "
                    "opaque geometry"
                }
                if version == 4
                else {}
            ),
        },
        "output": "ao",
        "ao_formats": ao_formats,
        **({"gtao_formats": gtao_formats} if hybrid else {}),
        "origin": {
            "uniform": "u_flip_y",
            "values": {
                "1": "textures bottom-up (GL's glTexImage2D row 0 = the bottom row)",
                "0": "row 0 is the top row (D3D, Vulkan, Metal, WebGPU)",
            },
            "note": "the passes compute in GL order and address texels through u_flip_y: a frame stored "
            "either way gives the same AO, stored the same way",
        },
        "uniform_block": {
            "name": "FrameUniforms",
            "layout": "std140 (WGSL: the struct FrameUniforms, same offsets)",
            "bytes": UNIFORM_BLOCK_BYTES,
            "members": [
                {"name": name, "type": kind, "offset": off, "value": value}
                for name, kind, off, value in UNIFORM_MEMBERS
            ],
            "how": "one buffer written once per frame, bound to every frame pass at its uniform_block "
            "binding",
        },
        "settings": settings.as_json(),
        "textures": textures,
        "passes": entries,
        "steps": _order(manifest, passes),
    }


def generate_frame(program: ComputeProgram, settings: FrameSettings) -> ComputeProgram:
    """``program`` (a U-Net's compute program in any compute dialect) with its frame: the frame passes'
    sources added to ``sources``, the manifest's ``frame`` section (textures, passes, steps) and its
    ``memory`` entry recomputed for the whole frame (:func:`.memory.memory_section`)."""
    dialect = _DIALECT.get(program.manifest.get("format", ""))
    if dialect is None:
        raise NeuralaoError(f"no frame passes for a {program.manifest.get('format')!r} program")
    passes, tex = frame_passes(program.manifest, settings, dialect)
    formats = {t.ident: t.format for t in tex.values()} | {
        ident: t["format"] for ident, t in program.manifest["textures"].items()
    }
    sources = dict(program.sources)
    for p in passes:
        ext = ".wgsl" if dialect == "wgsl" else ".comp"
        sources[p.name + ext] = _write_pass(p, formats, settings, dialect)
    manifest = dict(program.manifest)
    manifest["frame"] = _section(program.manifest, passes, tex, settings, dialect)
    manifest["memory"] = memory_section(manifest)  # the frame's steps and textures, not the network's alone
    return replace(program, sources=sources, manifest=manifest)


def shader_entries(manifest: dict) -> list[dict]:
    """Every pass entry of a compute manifest that has a shader file: the network's, then the frame's."""
    return [*manifest["passes"], *manifest.get("frame", {}).get("passes", [])]


def frame_sizes(manifest: dict, width: int, height: int) -> dict[str, tuple[int, int, int, str]]:
    """{texture id: (width, height, layers, format)} of every texture of a manifest's frame (its own and
    the network's) for a width x height frame; NeuralaoError where the network's input would be smaller
    than the pad multiple."""
    frame = manifest["frame"]
    ih = frame["internal_height"]
    w, h = (max(1, round(width * ih / height)), ih) if ih else (int(width), int(height))
    m = int(manifest["pad"]["multiple"])
    if min(w, h) < m:
        raise NeuralaoError(f"the network's input {w}x{h} is smaller than the pad multiple {m}")
    sym = {"W": int(width), "H": int(height), "w": w, "h": h, "wp": -(-w // m) * m, "hp": -(-h // m) * m}
    return {
        k: (_eval(t["width"], sym), _eval(t["height"], sym), int(t["layers"]), t["format"])
        for k, t in frame["textures"].items()
    }


def active_steps(manifest: dict, width: int, height: int) -> list[dict]:
    """The frame's steps that run for a width x height frame: not the skipped uniform pass, and of the
    steps with a ``when`` the one whose condition holds (upsampling unless the network runs at the
    frame's own size)."""
    sizes = frame_sizes(manifest, width, height)
    low = sizes[manifest["input"]["texture"]][:2]
    same = low == (int(width), int(height))
    out = []
    for step in manifest["frame"]["steps"]:
        if "skip" in step:
            continue
        if "when" in step and (step["when"] == "(w, h) == (W, H)") != same:
            continue
        out.append(step)
    return out


def dispatch_counts(manifest: dict, width: int, height: int) -> dict:
    """{"passes", "workgroups"} of the whole frame (the frame's steps) at width x height pixels."""
    frame = manifest["frame"]
    size = frame_sizes(manifest, width, height)
    by_name = {p["name"]: p for p in frame["passes"]}
    groups = passes = 0
    for step in active_steps(manifest, width, height):
        passes += 1
        if "frame_pass" in step:
            p = by_name[step["frame_pass"]]
            tw, th, _, _ = size[p["output"]["texture"]]
            groups += math.ceil(tw / p["local_size"][0]) * math.ceil(th / p["local_size"][1])
        else:
            p = manifest["passes"][step["index"]]
            tw, th, layers, _ = size[p["output"]["texture"]]
            lx, ly, _ = p["local_size"]
            bx, by, bl = p.get("block", [1, 1, 1])
            groups += math.ceil(tw / (lx * bx)) * math.ceil(th / (ly * by)) * (layers // bl)
    return {"passes": passes, "workgroups": groups}


def _eval(formula: str, sym: dict[str, int]) -> int:
    """A size formula of the frame section (``W``, ``w*1/8``, ``hp*1/2+1``, ``1``) at the symbols' values."""
    m = re.fullmatch(r"(?:(\w+)(?:\*(\d+)/(\d+))?)?([+-]?\d+)?", str(formula))
    if m is None or not (m.group(1) or m.group(4)):
        raise NeuralaoError(f"size formula {formula!r} is not symbol[*num/den][+-offset]")
    name, num, den, offset = m.groups()
    if name is not None and name.isdigit():  # a fixed size
        return int(name)
    value = sym[name] * int(num or 1) // int(den or 1) if name else 0
    return value + int(offset or 0)
