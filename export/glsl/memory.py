"""Texture memory of a compute program: when each texture is alive, which textures can share memory
(the aliasing plan) and how many bytes a frame needs, with and without sharing. No shader text.

A frame is a list of **steps**. A program with frame passes (the manifest's ``frame`` section, written
by :mod:`.frame`: the shipped U-Nets) runs the frame's ``steps`` in order: the frame passes before the
network, the network's passes (its uniform pass left out: ``f_network_radius`` writes its texture), the
frame passes after it (``f_upsample``, or ``f_composite`` when the network runs at the frame's own size:
both are steps, one of them runs). Its textures are every texture of the frame section (the frame's own
at the formats its passes write, and the network's) but the engine's G-buffer (``depth``, ``normal``).
A program without frame passes runs its own passes, and, for a model that declares ``internal_height``,
the fragment steps around them that run the network at that height (the export's ``internal/`` folder,
the reference host's: docs/engine-integration.md, "Internal-resolution passes" and "The hybrid"): the
GTAO passes of a hybrid, the point-sampling pass, the engine building the network input, the engine
taking the network's AO, the upsampling pass and, for a hybrid, the sum with GTAO. A texture is
**alive** from the first step that writes or reads it to the last one (both included); an input the
engine writes from the first step (it writes it before), the output the engine reads until the last.

Textures whose lifetimes are disjoint may share a **slot**: one block of memory as large as its
largest member at the frame's size. The slots are planned once, from the lifetimes alone, so one plan
holds at every frame size (only the slots' sizes change): textures in decreasing order of their size
at :data:`REFERENCE_FRAME`, each into the smallest slot whose members are all dead or not yet alive
when it lives, else a new slot (the "greedy by size" of shared-object planners; slots sized to their
largest member favour size order over first-use order, which minimises the count of slots, not bytes).

    memory_schedule(manifest) -> MemorySchedule     steps, lifetimes and slots (no sizes)
    memory_plan(manifest, width, height, precision="fp32") -> MemoryPlan   bytes at one frame size
    texture_sizes(manifest, width, height) -> {id: (w, h)}      the program's textures at one frame size
    memory_section(manifest) -> dict                the manifest's "memory" entry
    plan_slots(lifetimes, sizes) -> list[list[str]] the slot planner on its own
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from fractions import Fraction

from neuralao.runtime.foundation.errors import NeuralaoError

# Pass kinds whose output stays RGBA32F when the program stores textures as fp16: the cropped outputs
# and the scalar inputs (an engine's radius keeps its float32 value). The raw input is RGBA32F too, and so
# is what a program computes from it pixel by pixel (a pass's ``output.fp16_format`` says which).
FP32_KINDS = ("crop", "uniform")

# The frame's textures that are the engine's G-buffer (the frame section's inputs the engine writes each
# frame): read by the frame passes directly (no pass copies them), never counted.
ENGINE_TEXTURES = ("depth", "normal")

# Bytes per texel of every format a frame allocates.
TEXEL_BYTES = {"RGBA32F": 16, "RGBA16F": 8, "R32F": 4, "R16F": 2, "R16": 2}
# Programs without frame passes (the fragment steps of internal/): at fp16 the one-channel AO targets
# around the network (full resolution and the network's AO) are R16F: AO lies in [0, 1], where half floats
# step by at most 2^-11. The point-sampled G-buffer stays
# RGBA32F (camera-space positions need float32's range and precision). The frame passes (frame.py) give
# each of their own targets' format at each precision in the frame section (``formats``; at fp16 the AO
# target is R16F and a hybrid's GTAO, the network's input, R16 (16-bit unsigned normalised), but in WGSL:
# R32F).
FP16_FRAME_FORMATS = {"R32F": "R16F"}

# The frame whose texture sizes order the slot planner, and the frames the manifest gives figures for.
REFERENCE_FRAME = (1920, 1080)
MANIFEST_FRAMES = ((1920, 1080), (3840, 2160))

PRECISIONS = ("fp32", "fp16")

# The GTAO noise tile a hybrid export carries (its manifest's internal_resolution.gtao.noise: the
# default GTAOSettings of neuralao.runtime.baselines), texels per side.
GTAO_NOISE_SIZE = 4

_NETWORK_SYMBOLS = {"W": "w", "H": "h", "Wp": "wp", "Hp": "hp"}


@dataclass(frozen=True)
class Step:
    """One step of a frame: a generated pass (``pass_index`` into the manifest's ``passes``), a
    fragment pass of the export's ``internal/`` folder or work the engine does (``runs`` says which)."""

    name: str
    runs: str
    reads: tuple[str, ...] = ()
    writes: tuple[str, ...] = ()
    pass_index: int | None = None


@dataclass(frozen=True)
class TextureLife:
    """A texture of the frame and its lifetime.

    first, last : indices into the schedule's steps, both included. width, height : size formulas,
    dicts ``{"of": symbol, "num", "den", "offset", "formula"}`` = symbol * num / den + offset, symbol
    one of W, H (the frame), w, h (the network's input), wp, hp (that input padded); num 0 is a fixed
    size. formats : {precision: GL internal format} (at fp16 a frame's one-channel AO target is R16F, a
    hybrid's GTAO R16).
    """

    ident: str
    first: int
    last: int
    width: dict
    height: dict
    layers: int
    formats: dict[str, str]
    network: bool  # one of the program's own textures (its manifest's "textures")
    meaning: str = ""


@dataclass(frozen=True)
class MemorySchedule:
    """Steps, lifetimes and the aliasing plan of a compute program's frame: the same at every size.

    internal_height : the network's rows whatever the frame's (None: it runs at the frame's size);
    static_size : (width, height) of a program generated for one input size, else None.
    slots : lists of texture ids; textures of one slot are never alive at the same step.
    frame_passes : the steps are the manifest's frame section's (else the program's passes and, with an
    internal height, the fragment steps of its internal/ folder).
    """

    steps: tuple[Step, ...]
    textures: dict[str, TextureLife]
    slots: tuple[tuple[str, ...], ...]
    internal_height: int | None
    hybrid: bool
    pad_multiple: int
    static_size: tuple[int, int] | None
    frame_passes: bool = False


@dataclass(frozen=True)
class PlannedTexture:
    """A texture at one frame size: width, height in texels, layers of 4 channels, format, bytes."""

    ident: str
    first: int
    last: int
    width: int
    height: int
    layers: int
    format: str
    bytes: int
    network: bool


@dataclass(frozen=True)
class MemoryPlan:
    """Texture memory of one frame (width x height pixels) at one storage precision.

    network_size : (w, h) the network's input. textures : {id: PlannedTexture}. slots : the schedule's
    slots; slot_bytes[i] = the largest member of slots[i], in bytes. All figures in bytes.
    """

    width: int
    height: int
    precision: str
    network_size: tuple[int, int]
    steps: tuple[str, ...]
    textures: dict[str, PlannedTexture]
    slots: tuple[tuple[str, ...], ...]
    slot_bytes: tuple[int, ...]

    @property
    def separate_bytes(self) -> int:
        """Every texture in its own memory."""
        return sum(t.bytes for t in self.textures.values())

    @property
    def aliased_bytes(self) -> int:
        """Textures sharing the plan's slots: the sum of the slots' sizes."""
        return sum(self.slot_bytes)

    @property
    def live_bytes(self) -> int:
        """The most bytes alive at one step: no plan needs less (an allocator placing textures at
        offsets of one heap could reach it; slots of one size each cannot always)."""
        return max(
            sum(t.bytes for t in self.textures.values() if t.first <= i <= t.last)
            for i in range(len(self.steps))
        )

    def figures(self) -> dict[str, int]:
        """{"separate", "aliased", "live"}: bytes, as the manifest's peak_bytes gives them."""
        return {"separate": self.separate_bytes, "aliased": self.aliased_bytes, "live": self.live_bytes}


# --------------------------------------------------------------------------- the slot planner


def plan_slots(lifetimes: Mapping[str, tuple[int, int]], sizes: Mapping[str, float]) -> list[list[str]]:
    """Slots of textures with disjoint lifetimes, planned greedily by size.

    lifetimes : {id: (first, last)} step indices, both included. sizes : {id: bytes (or any measure of
    size)}, the same ids. Textures in decreasing size (ties: earlier first step, then the mappings'
    order) each go into the smallest slot (ties: the first made) whose members' lifetimes all miss
    its own, else into a new slot; a slot's size is then its first member's. Returns the slots, each
    in order of first step, the slots in order of their first member.
    """
    rank = {k: i for i, k in enumerate(lifetimes)}
    order = sorted(lifetimes, key=lambda k: (-sizes[k], lifetimes[k][0], rank[k]))

    def apart(a: str, b: str) -> bool:
        return lifetimes[a][1] < lifetimes[b][0] or lifetimes[b][1] < lifetimes[a][0]

    slots: list[list[str]] = []
    for ident in order:
        free = [i for i, s in enumerate(slots) if all(apart(ident, m) for m in s)]
        if free:
            slots[min(free, key=lambda i: (sizes[slots[i][0]], i))].append(ident)
        else:
            slots.append([ident])
    for s in slots:
        s.sort(key=lambda m: (lifetimes[m][0], rank[m]))
    return sorted(slots, key=lambda s: (lifetimes[s[0]][0], rank[s[0]]))


# --------------------------------------------------------------------------- sizes


def _dim_json(of: str, num: int, den: int, offset: int) -> dict:
    """A size formula as the manifests write it: of * num / den + offset (num 0: fixed)."""
    if num == 0:
        formula = str(offset)
    else:
        formula = of if (num, den) == (1, 1) else f"{of}*{num}/{den}"
        formula = formula if offset == 0 else f"{formula}{offset:+d}"
    return {"of": of, "num": num, "den": den, "offset": offset, "formula": formula}


def _dim_value(dim: dict, sizes: Mapping[str, int | Fraction], exact: bool) -> int | Fraction:
    v = Fraction(sizes[dim["of"]]) * dim["num"] / dim["den"] + dim["offset"]
    if not exact:
        return v
    if v.denominator != 1:
        raise NeuralaoError(
            f"texture size {dim['formula']} is fractional for {dim['of']} = {sizes[dim['of']]}"
        )
    return int(v)


def network_size(schedule: MemorySchedule, width: int, height: int) -> tuple[int, int]:
    """(w, h) the network's input for a width x height frame: the program's fixed size, or
    (max(1, round(width * internal_height / height)), internal_height) (halves to even, as Python's
    round and C's rint), or the frame's own size."""
    if schedule.static_size is not None:
        return schedule.static_size
    if schedule.internal_height is not None:
        return max(1, round(width * schedule.internal_height / height)), schedule.internal_height
    return width, height


def _symbols(schedule: MemorySchedule, width: int, height: int) -> dict[str, int]:
    """The size symbols of texture formulas (see :class:`TextureLife`) for a width x height frame."""
    w, h = network_size(schedule, width, height)
    m = schedule.pad_multiple
    return {"W": width, "H": height, "w": w, "h": h, "wp": -(-w // m) * m, "hp": -(-h // m) * m}


def _bytes(t: TextureLife, sizes: Mapping[str, int], precision: str, exact: bool) -> tuple:
    """(width, height, bytes) of a texture; exact: whole sizes or a NeuralaoError, else rationals."""
    tw, th = _dim_value(t.width, sizes, exact), _dim_value(t.height, sizes, exact)
    return tw, th, tw * th * t.layers * TEXEL_BYTES[t.formats[precision]]


# --------------------------------------------------------------------------- the schedule


def _internal_height(metadata: Mapping[str, str]) -> int | None:
    value = metadata.get("internal_height")
    if value in (None, "", "None"):
        return None
    try:
        height = int(value)
    except (TypeError, ValueError):
        raise NeuralaoError(f"metadata internal_height must be an integer, got {value!r}") from None
    if height < 1:
        raise NeuralaoError(f"metadata internal_height must be >= 1, got {height}")
    return height


def _frame_texture(fmt: str, size: str, meaning: str) -> dict:
    """A target around the network: one layer of ``fmt`` at the frame's size, the network's or the
    noise tile's."""
    of = {"frame": ("W", "H"), "network": ("w", "h")}.get(size)
    if of is None:  # the noise tile: a fixed size
        width = height = _dim_json("W", 0, 1, GTAO_NOISE_SIZE)
    else:
        width, height = _dim_json(of[0], 1, 1, 0), _dim_json(of[1], 1, 1, 0)
    return {
        "width": width,
        "height": height,
        "layers": 1,
        "formats": {"fp32": fmt, "fp16": FP16_FRAME_FORMATS.get(fmt, fmt)},
        "meaning": meaning,
    }


def _frame_steps(hybrid: bool, net_in: str, net_out: str) -> tuple[list[Step], list[Step], dict[str, dict]]:
    """The steps before and after the network when it runs at an internal height, and their textures
    (the formats the export's internal passes and the reference host, runtime/host, use)."""
    gtao = ("gtao",) if hybrid else ()
    ao = "upsampled" if hybrid else "ao"
    before = [
        Step("downsample", "internal/downsample.frag", (), ("low_position", "low_normal")),
        Step(
            "network_input",
            "the engine: the network's input from the low targets"
            + (" and GTAO point-sampled" if hybrid else "")
            + ", depth over the mean foreground depth",
            ("low_position", "low_normal", *gtao),
            (net_in,),
        ),
    ]
    after = [
        Step(
            "low_ao",
            "the engine: the network's AO"
            + (" minus GTAO point-sampled (its correction)" if hybrid else "")
            + ", 1 on background, into a one-channel target",
            (net_out, "low_position", *gtao),
            ("low_ao",),
        ),
        Step("upsample", "internal/upsample.frag", ("low_ao", "low_position", "low_normal"), (ao,)),
    ]
    textures = {
        "low_position": _frame_texture(
            "RGBA32F", "network", "the G-buffer's camera-space position and mask, point-sampled"
        ),
        "low_normal": _frame_texture(
            "RGBA32F", "network", "the G-buffer's camera-space normal, point-sampled"
        ),
        "low_ao": _frame_texture("R32F", "network", "upsample.frag's u_low_ao"),
        ao: _frame_texture("R32F", "frame", "the upsampled correction" if hybrid else "the AO"),
    }
    if hybrid:
        before[:0] = [
            Step("gtao", "internal/gtao.frag", ("gtao_noise",), ("gtao_raw",)),
            Step("gtao_blur", "internal/gtao_blur.frag", ("gtao_raw",), ("gtao",)),
        ]
        after.append(
            Step(
                "composite",
                "the engine: clamp(GTAO + upsampled correction, 0, 1)",
                ("gtao", "upsampled"),
                ("ao",),
            )
        )
        textures |= {
            "gtao_noise": _frame_texture("RGBA32F", "tile", "GTAO's noise tile, uploaded once"),
            "gtao_raw": _frame_texture("R32F", "frame", "gtao.frag's output"),
            "gtao": _frame_texture("R32F", "frame", "the blurred GTAO"),
            "ao": _frame_texture("R32F", "frame", "the AO"),
        }
    return before, after, textures


def _network_textures(manifest: Mapping) -> dict[str, dict]:
    """The program's textures with their sizes in the network's symbols and formats at each precision."""
    fp32_outputs = {
        p["output"]["texture"]
        for p in manifest["passes"]
        if p["output"].get("fp16_format", "rgba16f" if p["kind"] not in FP32_KINDS else "rgba32f")
        == "rgba32f"
    }
    out = {}
    for ident, t in manifest["textures"].items():
        raw = t["width"]["of"] == "W"
        fp16 = "RGBA32F" if raw or ident in fp32_outputs else "RGBA16F"
        out[ident] = {
            "width": _dim_json(
                _NETWORK_SYMBOLS[t["width"]["of"]], *(t["width"][k] for k in ("num", "den", "offset"))
            ),
            "height": _dim_json(
                _NETWORK_SYMBOLS[t["height"]["of"]], *(t["height"][k] for k in ("num", "den", "offset"))
            ),
            "layers": int(t["layers"]),
            "formats": {"fp32": "RGBA32F", "fp16": fp16},
            "meaning": f"ONNX {t['onnx_tensor']!r}" if t.get("onnx_tensor") else "",
        }
    return out


_FORMULA = re.compile(r"(?:(W|H|w|h|wp|hp)(?:\*(\d+)/(\d+))?)?([+-]?\d+)?")


def _parse_dim(formula: str) -> dict:
    """A size formula of the frame section (``W``, ``w``, ``1``, ``wp*1/4``, ``hp*1/2+1``) as a dict of
    :func:`_dim_json`."""
    m = _FORMULA.fullmatch(str(formula))
    if m is None or not (m.group(1) or m.group(4)):
        raise NeuralaoError(f"size formula {formula!r} is not symbol[*num/den][+-offset]")
    of, num, den, offset = m.groups()
    if of is None:
        return _dim_json("W", 0, 1, int(offset))
    return _dim_json(of, int(num or 1), int(den or 1), int(offset or 0))


def _frame_pass_steps(manifest: Mapping) -> tuple[tuple[Step, ...], dict[str, dict]]:
    """The steps of a program with frame passes (its frame section's ``steps``, the skipped uniform pass
    left out) and the textures they allocate: the frame's own but the engine's G-buffer
    (:data:`ENGINE_TEXTURES`), at the formats their passes write at either precision, and the network's,
    in order of first use (whatever the order of the manifest's mappings, so that a manifest read back
    from disk plans the same slots)."""
    frame = manifest["frame"]
    by_name = {p["name"]: p for p in frame["passes"]}
    steps = []
    for entry in frame["steps"]:
        if "frame_pass" in entry:
            p = by_name[entry["frame_pass"]]
            runs = "frame pass" + (f", when {entry['when']}" if "when" in entry else "")
            reads = tuple(i["texture"] for i in p["inputs"])
            steps.append(Step(p["name"], runs, reads, (p["output"]["texture"],)))
        elif "network_pass" in entry:
            k = int(entry["index"])
            p = manifest["passes"][k]
            reads = tuple(i["texture"] for i in p["inputs"])
            steps.append(Step(p["name"], "pass", reads, (p["output"]["texture"],), k))
    network = _network_textures(manifest)
    specs = {}
    for ident, t in frame["textures"].items():
        if ident in ENGINE_TEXTURES or ident in network:
            continue
        specs[ident] = {
            "width": _parse_dim(t["width"]),
            "height": _parse_dim(t["height"]),
            "layers": int(t["layers"]),
            "formats": dict(t.get("formats") or dict.fromkeys(PRECISIONS, t["format"])),
            "meaning": t["meaning"],
        }
    specs |= network
    used = [i for s in steps for i in (*s.reads, *s.writes) if i in specs]
    order = [*dict.fromkeys(used), *sorted(set(specs) - set(used))]
    return tuple(steps), {ident: specs[ident] for ident in order}


def _network_steps(manifest: Mapping) -> list[Step]:
    """The program's own passes as steps, in the manifest's order."""
    return [
        Step(p["name"], "pass", tuple(i["texture"] for i in p["inputs"]), (p["output"]["texture"],), k)
        for k, p in enumerate(manifest["passes"])
    ]


def memory_schedule(manifest: Mapping) -> MemorySchedule:
    """Steps, texture lifetimes and the aliasing plan of a compute manifest (``neuralao-glsl-compute`` or
    ``neuralao-wgsl-compute``: its passes, textures, input, outputs and source_model_metadata). Needs no
    ``memory`` entry, so it reads manifests written before there was one."""
    metadata = manifest.get("source_model_metadata", {})
    static = manifest.get("static_input_size")
    internal = None if static is not None else _internal_height(metadata)
    hybrid = internal is not None and str(metadata.get("input_channels", "")).split(",")[-1] == "gtao"
    net_in, outputs = manifest["input"]["texture"], [o["texture"] for o in manifest["outputs"]]
    if "frame" in manifest:
        steps, specs = _frame_pass_steps(manifest)
        # every texture is written by a step of the frame; the frame's AO is what the engine reads
        engine_input, engine_outputs = [], [manifest["frame"]["output"], *outputs[1:]]
    elif internal is None:
        steps = tuple(_network_steps(manifest))
        specs = _network_textures(manifest)
        engine_input, engine_outputs = [net_in], outputs  # written before the first pass, read after the last
    else:
        before, after, frame = _frame_steps(hybrid, net_in, outputs[0])
        steps = (*before, *_network_steps(manifest), *after)
        specs = _network_textures(manifest) | frame
        # the network's input is written by a step of the frame; the frame's AO is what the engine reads
        engine_input, engine_outputs = (["gtao_noise"] if hybrid else []), ["ao", *outputs[1:]]
    touched: dict[str, list[int]] = {}
    for i, s in enumerate(steps):
        for ident in (*s.reads, *s.writes):
            touched.setdefault(ident, []).append(i)
    end = len(steps) - 1
    textures = {}
    for ident, spec in specs.items():
        used = touched.get(ident, [0])  # a texture no step touches: allocated all the same
        first = 0 if ident in engine_input else min(used)
        last = end if ident in engine_outputs or ident == "gtao_noise" else max(used)
        textures[ident] = TextureLife(ident, first, last, network=ident in manifest["textures"], **spec)
    schedule = MemorySchedule(
        steps=steps,
        textures=textures,
        slots=(),
        internal_height=internal,
        hybrid=hybrid,
        pad_multiple=int(manifest["pad"]["multiple"]),
        static_size=None if static is None else (int(static[1]), int(static[0])),
        frame_passes="frame" in manifest,
    )
    sizes = _symbols(schedule, *REFERENCE_FRAME)
    reference = {k: _bytes(t, sizes, "fp32", exact=False)[2] for k, t in textures.items()}
    slots = plan_slots({k: (t.first, t.last) for k, t in textures.items()}, reference)
    return replace(schedule, slots=tuple(tuple(s) for s in slots))


def memory_plan(manifest: Mapping, width: int, height: int, precision: str = "fp32") -> MemoryPlan:
    """Texture memory of a compute manifest's frame at width x height pixels (the engine's G-buffer).

    precision : "fp32" (every texture as the manifest gives it at fp32) or "fp16" (the network's
    textures as ``generate_compute(precision="fp16")`` stores them: RGBA16F, the input, what is
    computed from it pixel by pixel, outputs and scalar textures RGBA32F; a program with frame passes:
    the frame's own targets as its fp16 passes write them, the frame section's ``formats``: the AO target
    R16F and a hybrid's GTAO R16 (WGSL: both R32F), the depth-derived ones RGBA32F; else the fragment
    steps' AO targets R16F, their point-sampled G-buffer RGBA32F). Whatever the manifest's own precision.
    Raises NeuralaoError where the program cannot run at that size (a fixed size, below the pad multiple,
    a fractional size).
    """
    return _plan(memory_schedule(manifest), width, height, precision)


def texture_sizes(manifest: Mapping, width: int, height: int) -> dict[str, tuple[int, int]]:
    """{texture id: (width, height) in texels} of a compute manifest's own textures for a width x height
    frame (the network's internal size where the model declares one). Raises NeuralaoError where the
    program cannot run at that size."""
    plan = memory_plan(manifest, width, height)
    return {k: (t.width, t.height) for k, t in plan.textures.items() if t.network}


def _plan(schedule: MemorySchedule, width: int, height: int, precision: str) -> MemoryPlan:
    if precision not in PRECISIONS:
        raise NeuralaoError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if int(width) < 1 or int(height) < 1:
        raise NeuralaoError(f"frame size must be positive, got {width}x{height}")
    sizes = _symbols(schedule, int(width), int(height))
    if min(sizes["w"], sizes["h"]) < schedule.pad_multiple:
        raise NeuralaoError(
            f"the network's input {sizes['w']}x{sizes['h']} is smaller than the pad multiple "
            f"{schedule.pad_multiple}"
        )
    textures = {}
    for ident, t in schedule.textures.items():
        tw, th, nbytes = _bytes(t, sizes, precision, exact=True)
        textures[ident] = PlannedTexture(
            ident, t.first, t.last, tw, th, t.layers, t.formats[precision], nbytes, t.network
        )
    return MemoryPlan(
        width=int(width),
        height=int(height),
        precision=precision,
        network_size=(sizes["w"], sizes["h"]),
        steps=tuple(s.name for s in schedule.steps),
        textures=textures,
        slots=schedule.slots,
        slot_bytes=tuple(max(textures[m].bytes for m in s) for s in schedule.slots),
    )


# --------------------------------------------------------------------------- the manifest entry

_RULE = (
    "Textures share a slot only when their lifetimes (first..last step, both included) are disjoint: a "
    "texture's memory is free after its last step, and the next member's first step overwrites it. A "
    "slot is one block of memory the size of its largest member at the frame's size: members of any "
    "format, size or layer count are placed at its start (a transient resource pool or heap with "
    "aliasing: Vulkan and D3D12 placed resources, Metal heap aliasing). The plan is valid at every frame "
    "size; only the slots' sizes change. Planned greedily: textures largest first (sizes at 1920x1080), "
    "each into the smallest slot none of whose members is alive at the same time. A texture the engine "
    "writes is alive from the first step, the output the engine reads until the last step. APIs without "
    "memory aliasing (GL, WebGPU) can share one texture among a slot's members of the same format, width "
    "and height, allocated with the most layers of them: the passes read and write only their own layers."
)


def _counted(schedule: MemorySchedule, manifest: Mapping) -> str:
    weights = f"weights.bin ({manifest['weights']['bytes']} bytes, a buffer)"
    if schedule.frame_passes:
        own = [k for k, t in schedule.textures.items() if not t.network]
        return (
            "every texture of the frame's steps (frame.textures): the network's (textures) and the frame's "
            f"own ({', '.join(own)}), in the formats their passes write. Not counted: the engine's G-buffer "
            f"that the frame passes read ({', '.join(ENGINE_TEXTURES)}: frame.inputs, written by the engine "
            f"each frame; no pass copies it), {weights} and the frame's uniform block "
            f"({manifest['frame']['uniform_block']['bytes']} bytes)."
        )
    what = "every texture of the program's passes (textures)"
    if schedule.internal_height is not None:
        what += (
            " and the targets of the steps that run the network at its internal height ("
            + ("GTAO's passes and noise tile, " if schedule.hybrid else "")
            + "the point-sampled G-buffer, the network's AO at its size, the upsampled AO"
            + (" and the final AO" if schedule.hybrid else "")
            + ")"
        )
    return (
        f"{what}. Not counted: the engine's G-buffer (position, normal), its mean-depth reduction and "
        f"{weights}."
    )


def _fp16_text(schedule: MemorySchedule) -> str:
    network = (
        "fp16: the network's textures as --precision fp16 stores them (RGBA16F; its input, what is "
        "computed from it pixel by pixel, scalar and output textures RGBA32F)"
    )
    if schedule.frame_passes:
        one = {k: t.formats["fp16"] for k, t in schedule.textures.items() if not t.network and t.layers == 1}
        ao = ", ".join(f"{k} {f}" for k, f in sorted(one.items()) if f in ("R16F", "R16", "R32F"))
        if "R16" in one.values():
            ao += " (R16: 16-bit unsigned normalised, steps of 1/65535 over [0, 1])"
        if "R16F" not in one.values():
            unorm = " or r16unorm" if "gtao" in one else ""
            ao += f" (WGSL: core WebGPU has no r16float{unorm} storage texture)"
        return (
            f"{network}; of the frame passes' own one-channel targets {ao}, the depth-derived ones RGBA32F."
        )
    if schedule.internal_height is None:
        return network + "."
    return (
        f"{network}; the one-channel AO targets around the network (full resolution and the network's AO) "
        "R16F, the point-sampled G-buffer RGBA32F."
    )


def _sizes_text(schedule: MemorySchedule) -> dict[str, str]:
    m = schedule.pad_multiple
    if schedule.static_size is not None:
        network = f"fixed: {schedule.static_size[0]} x {schedule.static_size[1]} (static_input_size)"
    elif schedule.internal_height is not None:
        ih = schedule.internal_height
        network = f"max(1, round(W * {ih} / H)) x {ih} (internal_height; round halves to even)"
    else:
        network = "W x H"
    return {
        "W, H": "the frame: the engine's G-buffer, in pixels",
        "w, h": f"the network's input: {network}; the W, H of textures' formulas",
        "wp, hp": f"w, h rounded up to a multiple of {m} (pad.multiple); the Wp, Hp of textures' formulas",
    }


def memory_section(manifest: Mapping) -> dict:
    """The ``memory`` entry of a compute manifest: what is counted, the size symbols, the frame's steps,
    every texture's lifetime, format at each precision and size formula, the aliasing rule and slots,
    and the peak bytes (separate, aliased, live) at :data:`MANIFEST_FRAMES` (the fixed size of a static
    program) at fp32 and fp16, each computed by :func:`memory_plan`."""
    schedule = memory_schedule(manifest)
    steps = []
    for s in schedule.steps:
        entry: dict = {"name": s.name}
        if s.pass_index is not None:
            entry["pass"] = s.pass_index
        else:
            entry.update(runs=s.runs, reads=list(s.reads), writes=list(s.writes))
        steps.append(entry)
    textures = {}
    for ident, t in schedule.textures.items():
        textures[ident] = {
            "first": t.first,
            "last": t.last,
            "first_step": schedule.steps[t.first].name,
            "last_step": schedule.steps[t.last].name,
            "format": dict(t.formats),
            "layers": t.layers,
            "width": t.width,
            "height": t.height,
        }
        if not t.network:
            textures[ident]["meaning"] = t.meaning
    frames = [schedule.static_size] if schedule.static_size is not None else list(MANIFEST_FRAMES)
    peaks = {}
    for w, h in frames:
        try:
            plans = {p: _plan(schedule, w, h, p) for p in PRECISIONS}
        except NeuralaoError:
            continue  # a size this program cannot take
        peaks[f"{w}x{h}"] = {"network_input": list(plans["fp32"].network_size)} | {
            p: plan.figures() for p, plan in plans.items()
        }
    return {
        "counted": _counted(schedule, manifest),
        "sizes": _sizes_text(schedule),
        "texel_bytes": dict(TEXEL_BYTES),
        "steps": steps,
        "textures": textures,
        "aliasing": {"rule": _RULE, "slots": [list(s) for s in schedule.slots]},
        "peak_bytes": peaks,
        "peak_bytes_are": "separate: every texture its own memory; aliased: the sum of the slots' sizes; "
        "live: the most bytes alive at one step (no plan needs less). " + _fp16_text(schedule),
        "compute": "neuralao.export.glsl.memory_plan(manifest, width, height, precision) gives the same "
        "figures and each slot's size for any frame",
    }
