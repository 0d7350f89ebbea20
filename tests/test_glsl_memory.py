"""Texture lifetimes, the aliasing plan and peak texture memory of compute programs (the manifest's
``memory`` entry, :func:`neuralao.export.glsl.memory_plan`).

The plan holds on random lifetimes, random ONNX graphs and the shipped U-Nets; running the passes on
Mesa with textures aliased as it says gives the same output bit for bit, and a plan that lets two
textures live at once does not; the peak figures of the shipped frames (the frame section's steps and
textures) equal a count done here from those steps with sizes computed independently (the frame
section's own sizes, the internal-resolution module's network size), as do those of a program without
frame passes (the fragment steps; the GL runner's texture sizes); the shipped models' figures are the
ones docs/engine-integration.md and docs/results.md give.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import onnx
import pytest
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import (
    generate_compute,
    load_compute_export,
    memory_plan,
    memory_schedule,
    plan_slots,
)
from neuralao.export.glsl.frame import frame_sizes
from neuralao.export.glsl.memory import MANIFEST_FRAMES, PRECISIONS, TEXEL_BYTES
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.frame_runner import frame_program
from neuralao.runtime.glsl_runner import run_compute, run_compute_all, texture_sizes
from neuralao.runtime.internal_resolution import internal_size
from neuralao.runtime.shipped import MODELS_DIR

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ("unet-gtao", "unet-fast")
MIB = float(1 << 20)


def _shipped(name: str) -> Path:
    folder = MODELS_DIR / name
    if not (folder / "glsl" / "manifest.json").is_file():
        pytest.skip(f"{name} is not shipped here (make models)")
    return folder


# ----------------------------------------------------------------------------- brute force


def _alive(lifetimes: dict[str, tuple[int, int]], step: int) -> list[str]:
    return [k for k, (a, b) in lifetimes.items() if a <= step <= b]


def _assert_valid(slots, lifetimes: dict[str, tuple[int, int]]) -> None:
    """Every texture in exactly one slot; at no step are two members of one slot alive."""
    members = [t for s in slots for t in s]
    assert sorted(members) == sorted(lifetimes)
    slot_of = {t: k for k, s in enumerate(slots) for t in s}
    steps = max(b for _, b in lifetimes.values()) + 1
    for i in range(steps):
        alive = [slot_of[t] for t in _alive(lifetimes, i)]
        assert len(alive) == len(set(alive)), f"step {i}: two textures of one slot alive"


def _figures(slots, lifetimes: dict[str, tuple[int, int]], nbytes: dict[str, int]) -> dict[str, int]:
    steps = max(b for _, b in lifetimes.values()) + 1
    return {
        "separate": sum(nbytes.values()),
        "aliased": sum(max(nbytes[t] for t in s) for s in slots),
        "live": max(sum(nbytes[t] for t in _alive(lifetimes, i)) for i in range(steps)),
    }


# ----------------------------------------------------------------------------- the planner alone


def test_plan_slots_on_random_lifetimes():
    """Random intervals and sizes: the slots are valid, never need more than separate textures and
    never less than the most bytes alive at once; equal sizes and disjoint lifetimes share one slot."""
    rng = np.random.default_rng(0)
    for case in range(300):
        n, steps = int(rng.integers(1, 30)), int(rng.integers(1, 40))
        lifetimes = {}
        for i in range(n):
            a = int(rng.integers(0, steps))
            lifetimes[f"t{i}"] = (a, int(rng.integers(a, steps)))
        sizes = {k: int(rng.choice([1, 2, 4, 8, 4096]) * rng.integers(1, 4)) for k in lifetimes}
        slots = plan_slots(lifetimes, sizes)
        _assert_valid(slots, lifetimes)
        f = _figures(slots, lifetimes, sizes)
        assert f["live"] <= f["aliased"] <= f["separate"], case
        # the most textures alive at once is the fewest slots any valid plan can have
        assert len(slots) >= max(len(_alive(lifetimes, i)) for i in range(steps))
    chain = {f"t{i}": (i, i) for i in range(5)}
    assert plan_slots(chain, dict.fromkeys(chain, 16)) == [list(chain)]


# ----------------------------------------------------------------------------- random graphs


def _random_model(seed: int) -> onnx.ModelProto:
    """A random image DAG on (1, 4, H, W): 3x3 convs (+ Relu), Add, Concat, 2x2 average pools down to
    a quarter, nearest x2 upsampling; one or two graph outputs at any level. pad_multiple 4."""
    rng = np.random.default_rng(seed)
    values = [("x", 4, 0)]  # (name, channels, level: size / 2**level)
    nodes, inits = [], []

    def const(a: np.ndarray) -> str:
        inits.append(nh.from_array(np.asarray(a, np.float32), f"c{len(inits)}"))
        return inits[-1].name

    def conv(x: str, c_in: int, c_out: int) -> str:
        y = f"v{len(nodes)}"
        w = rng.normal(size=(c_out, c_in, 3, 3)) * 0.3
        nodes.append(oh.make_node("Conv", [x, const(w), const(rng.normal(size=c_out))], [y], pads=[1] * 4))
        return y

    scales = const(np.array([1, 1, 2, 2]))
    for _ in range(int(rng.integers(4, 11))):
        name, c, level = values[int(rng.integers(len(values)))]
        peers = [v for v in values if v[2] == level and v[0] != name]
        op = str(rng.choice(["conv", "add", "pool", "up", "concat"]))
        y = f"v{len(nodes)}"
        if op == "pool" and level < 2:
            nodes.append(oh.make_node("AveragePool", [name], [y], kernel_shape=[2, 2], strides=[2, 2]))
            values.append((y, c, level + 1))
        elif op == "up" and level > 0:
            nodes.append(oh.make_node("Resize", [name, "", scales], [y], mode="nearest"))
            values.append((y, c, level - 1))
        elif op == "add" and any(v[1] == c for v in peers):
            other = [v for v in peers if v[1] == c][0]
            nodes.append(oh.make_node("Add", [name, other[0]], [y]))
            values.append((y, c, level))
        elif op == "concat" and peers:
            other = peers[int(rng.integers(len(peers)))]
            nodes.append(oh.make_node("Concat", [name, other[0]], [y], axis=1))
            k = int(rng.integers(1, 9))
            values.append((conv(y, c + other[1], k), k, level))
        else:
            k = int(rng.integers(1, 9))
            z = conv(name, c, k)
            if rng.random() < 0.5:
                nodes.append(oh.make_node("Relu", [z], [f"r{len(nodes)}"]))
                z = nodes[-1].output[0]
            values.append((z, k, level))
    outputs = [values[-1][0]]
    extra = [v[0] for v in values[1:-1]]
    if extra and rng.random() < 0.5:
        outputs.append(extra[int(rng.integers(len(extra)))])
    graph = oh.make_graph(
        nodes,
        f"random{seed}",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4, "H", "W"])],
        [oh.make_tensor_value_info(o, TensorProto.FLOAT, None) for o in outputs],
        inits,
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)])
    p = model.metadata_props.add()
    p.key, p.value = "pad_multiple", "4"
    return model


def _lifetimes_from_passes(manifest: dict) -> dict[str, tuple[int, int]]:
    """A network-only program's lifetimes recounted from its passes: the steps each texture is read or
    written at, the input from step 0 (the engine writes it first), the outputs to the last step."""
    steps: dict[str, list[int]] = {}
    for i, p in enumerate(manifest["passes"]):
        for t in [*(x["texture"] for x in p["inputs"]), p["output"]["texture"]]:
            steps.setdefault(t, []).append(i)
    end = len(manifest["passes"]) - 1
    steps[manifest["input"]["texture"]].append(0)
    for o in manifest["outputs"]:
        steps[o["texture"]].append(end)
    return {t: (min(s), max(s)) for t, s in steps.items()}


@pytest.mark.parametrize("seed", range(8))
def test_random_graph_plan_holds_and_aliased_run_is_bit_identical(seed):
    model = _random_model(seed)
    program = generate_compute(model)
    m = program.manifest
    lifetimes = _lifetimes_from_passes(m)
    entry = m["memory"]["textures"]
    assert {t: (e["first"], e["last"]) for t, e in entry.items()} == lifetimes
    _assert_valid(m["memory"]["aliasing"]["slots"], lifetimes)
    x = np.random.default_rng(seed).normal(size=(1, 4, 20, 28)).astype(np.float32)
    plain = run_compute_all(program, x)
    aliased = run_compute_all(program, x, aliasing=True)
    assert plain.keys() == aliased.keys()
    for name in plain:
        assert np.isfinite(plain[name]).all()
        np.testing.assert_array_equal(aliased[name], plain[name])


def test_random_graphs_share_textures():
    """The runs above alias something: most random graphs put several textures in one slot."""
    shared = [
        any(len(s) > 1 for s in memory_schedule(generate_compute(_random_model(seed)).manifest).slots)
        for seed in range(8)
    ]
    assert sum(shared) >= 6


# ----------------------------------------------------------------------------- the shipped models


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_model_runs_aliased_bit_for_bit(name):
    """The shipped passes, from disk, with the export's own plan: the same AO bit for bit. A plan that
    puts two textures alive at once in one slot (the longest-lived, a skip connection the decoder
    reads, and the one written right after it) poisons a texture still to be read: the AO changes."""
    program = load_compute_export(_shipped(name) / "glsl")
    schedule = memory_schedule(program.manifest)
    x = np.random.default_rng(1).normal(size=(1, program.manifest["input"]["channels"], 64, 96))
    x = x.astype(np.float32)
    radius = {"radius": 0.3}
    plain = run_compute(program, x, scalars=radius)
    assert np.isfinite(plain).all()
    np.testing.assert_array_equal(run_compute(program, x, scalars=radius, aliasing=True), plain)
    life = schedule.textures
    network = [t for t in life.values() if t.network]
    skip = max(network, key=lambda t: (t.last - t.first, t.ident))  # the longest-lived: a skip connection
    overlapping = next(t for t in life.values() if t.network and t.first == skip.first + 1)
    broken = [[m for m in s if m not in (skip.ident, overlapping.ident)] for s in schedule.slots]
    broken = [s for s in broken if s] + [[skip.ident, overlapping.ident]]
    wrong = run_compute(program, x, scalars=radius, aliasing=broken)
    assert not np.array_equal(wrong, plain)


def _preset(folder) -> str:
    """The preset a shipped export was generated with (exports from before presets: cpu's passes)."""
    manifest = json.loads((folder / "glsl" / "manifest.json").read_text())
    return manifest.get("preset", {}).get("name", "cpu")


def _frame_bytes(
    name: str, frame: tuple[int, int], net: tuple[int, int], noise: int, precision: str = "fp32"
) -> int:
    """Bytes of the fragment steps' resampling / GTAO targets as runtime/host allocates them (at fp16 the
    one-channel AO targets are R16F)."""
    (W, H), (w, h) = frame, net
    ao = 4 if precision == "fp32" else 2
    return {
        "low_position": w * h * 16,
        "low_normal": w * h * 16,
        "low_ao": w * h * ao,
        "upsampled": W * H * ao,
        "ao": W * H * ao,
        "gtao_raw": W * H * ao,
        "gtao": W * H * ao,
        "gtao_noise": noise * noise * 16,
    }[name]


def _lifetimes_from_frame(manifest: dict) -> dict[str, tuple[int, int]]:
    """A frame program's lifetimes recounted from its frame section: the steps (the skipped uniform pass
    left out) each texture is read or written at, the frame's output to the last step; the engine's
    depth and normal left out."""
    frame = manifest["frame"]
    by_name = {p["name"]: p for p in frame["passes"]}
    steps: dict[str, list[int]] = {}
    active = [s for s in frame["steps"] if "skip" not in s]
    for i, step in enumerate(active):
        p = by_name[step["frame_pass"]] if "frame_pass" in step else manifest["passes"][step["index"]]
        for t in [*(x["texture"] for x in p["inputs"]), p["output"]["texture"]]:
            steps.setdefault(t, []).append(i)
    steps[frame["output"]].append(len(active) - 1)
    return {t: (min(s), max(s)) for t, s in steps.items() if t not in ("depth", "normal")}


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_peaks_equal_a_brute_force_count(name):
    """For the shipped frame programs at fp32 and at fp16 (the fp16 one generated from model.onnx), at
    the manifest's frames and others: every texture of the frame but the engine's depth and normal, its
    bytes from the frame section's own sizes and formats (at fp16: the formats the fp16 passes write),
    and separate / aliased / live, counted here from the frame's steps."""
    folder = _shipped(name)
    top = json.loads((folder / "manifest.json").read_text())
    manifests = {
        "fp32": json.loads((folder / "glsl" / "manifest.json").read_text()),
        # the passes the shipped fp32 manifest has (its preset), stored as fp16
        "fp16": frame_program(folder / "model.onnx", precision="fp16", preset=_preset(folder)).manifest,
    }
    schedule = memory_schedule(manifests["fp32"])
    lifetimes = _lifetimes_from_frame(manifests["fp32"])
    assert {k: (t.first, t.last) for k, t in schedule.textures.items()} == lifetimes
    assert [s.name for s in schedule.steps] == [
        s.get("frame_pass", s.get("network_pass"))
        for s in manifests["fp32"]["frame"]["steps"]
        if "skip" not in s
    ]
    _assert_valid(schedule.slots, lifetimes)
    for W, H in (*MANIFEST_FRAMES, (1280, 720), (640, 480), (200, 300)):
        net = internal_size(W, H, top["internal_resolution"]["height"])
        for precision, m in manifests.items():
            sizes = frame_sizes(m, W, H)
            nbytes = {k: tw * th * layers * TEXEL_BYTES[fmt] for k, (tw, th, layers, fmt) in sizes.items()}
            nbytes = {k: v for k, v in nbytes.items() if k in lifetimes}
            plan = memory_plan(manifests["fp32"], W, H, precision)
            assert plan.network_size == net == sizes[m["input"]["texture"]][:2]
            assert {k: t.bytes for k, t in plan.textures.items()} == nbytes
            want = _figures(schedule.slots, lifetimes, nbytes)
            assert plan.figures() == want, (W, H, precision)
            assert memory_plan(m, W, H, precision).figures() == want  # whatever the manifest's precision
            if (W, H) in MANIFEST_FRAMES:
                assert m["memory"]["peak_bytes"][f"{W}x{H}"][precision] == want


def test_fp16_counts_the_formats_the_passes_write():
    """At fp16 the network's textures are RGBA16F but its input, what is computed from it pixel by pixel,
    its radius and output; the frame passes' AO target is R16F, the hybrid's GTAO (the network's input)
    R16, 16-bit unsigned normalised (WGSL: both r32float, no r16float or r16unorm storage texture in core
    WebGPU), the depth-derived ones RGBA32F: memory_plan's formats are the fp16 program's, pass by pass,
    at 2 bytes a texel for R16."""
    folder = _shipped("unet-gtao")
    m16 = frame_program(folder / "model.onnx", precision="fp16", preset=_preset(folder)).manifest
    plan = memory_plan(m16, 1920, 1080, "fp16")
    written = {p["output"]["texture"]: p["output"]["format"] for p in m16["frame"]["passes"]}
    for ident, t in plan.textures.items():
        assert t.format == m16["frame"]["textures"][ident]["format"], ident
        if ident in written:
            assert written[ident] == t.format.lower(), ident
    own = {ident: t.format for ident, t in plan.textures.items() if not t.network}
    assert own["ao"] == "R16F" and own["gtao_raw"] == own["gtao"] == "R16"
    assert plan.textures["gtao"].bytes == 1920 * 1080 * 2
    assert {f for k, f in own.items() if k not in ("gtao_raw", "gtao", "ao")} == {"RGBA32F"}
    assert {"RGBA16F", "RGBA32F"} <= {t.format for t in plan.textures.values() if t.network}
    assert (
        "ao R16F, gtao R16, gtao_raw R16 (R16: 16-bit unsigned normalised" in m16["memory"]["peak_bytes_are"]
    )
    assert "depth, normal" in m16["memory"]["counted"]
    w16 = frame_program(folder / "model.onnx", "wgsl", precision="fp16", preset=_preset(folder)).manifest
    wgsl = memory_plan(w16, 1920, 1080, "fp16")
    assert {wgsl.textures[k].format for k in ("gtao_raw", "gtao", "ao")} == {"R32F"}
    assert "r16float or r16unorm" in w16["memory"]["peak_bytes_are"]
    assert (
        "r16float" in w16["frame"]["ao_formats"]["why"] and "r16unorm" in w16["frame"]["gtao_formats"]["why"]
    )


@pytest.mark.parametrize("name", SHIPPED)
def test_fragment_steps_without_frame_passes(name):
    """A program without frame passes (generate_compute alone) keeps the schedule of the fragment steps
    of its internal/ folder: their targets in the formats runtime/host allocates, counted here from the
    lifetimes with sizes from the GL runner and the internal-resolution module."""
    folder = _shipped(name)
    top = json.loads((folder / "manifest.json").read_text())
    proto = onnx.load(folder / "model.onnx")
    manifests = {p: generate_compute(proto, precision=p, preset=_preset(folder)).manifest for p in PRECISIONS}
    internal = top["internal_resolution"]
    noise = internal["gtao"]["noise"] if "gtao" in internal else {"width": 4, "height": 4}
    assert noise["width"] == noise["height"] == 4  # memory.GTAO_NOISE_SIZE
    schedule = memory_schedule(manifests["fp32"])
    frame_textures = {k for k, t in schedule.textures.items() if not t.network}
    hybrid = "gtao" in internal["sources"]
    assert frame_textures == {"low_position", "low_normal", "low_ao", "ao"} | (
        {"upsampled", "gtao_raw", "gtao", "gtao_noise"} if hybrid else set()
    )
    for step in schedule.steps:  # the internal passes the steps name are the export's own
        if step.runs.startswith("internal/"):
            assert step.runs.removeprefix("internal/") in internal["sources"].values()
            assert (folder / "glsl" / step.runs).is_file()
    lifetimes = {k: (t.first, t.last) for k, t in schedule.textures.items()}
    _assert_valid(schedule.slots, lifetimes)
    for W, H in (MANIFEST_FRAMES[0], (640, 480)):
        net = internal_size(W, H, internal["height"])
        for precision, m in manifests.items():
            nbytes = {k: v[3] for k, v in texture_sizes(m, net[1], net[0]).items()}
            nbytes |= {k: _frame_bytes(k, (W, H), net, 4, precision) for k in frame_textures}
            plan = memory_plan(manifests["fp32"], W, H, precision)
            assert {k: t.bytes for k, t in plan.textures.items()} == nbytes
            want = _figures(schedule.slots, lifetimes, nbytes)
            assert plan.figures() == want, (W, H, precision)
            if (W, H) in MANIFEST_FRAMES:
                assert m["memory"]["peak_bytes"][f"{W}x{H}"][precision] == want


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_manifest_memory_is_what_the_generator_writes(name):
    """The shipped glsl/manifest.json carries the entry the generator writes for its model.onnx and its
    frame; the Vulkan program's entry is the same, the WGSL program's the same at fp32 and larger at fp16
    (its AO targets stay r32float: core WebGPU has no r16float storage texture)."""
    folder = _shipped(name)
    shipped = json.loads((folder / "glsl" / "manifest.json").read_text())
    generated = frame_program(folder / "model.onnx", preset=_preset(folder)).manifest
    assert shipped["memory"] == json.loads(json.dumps(generated["memory"]))
    assert memory_schedule(shipped).slots == memory_schedule(generated).slots  # whatever the mappings' order
    vulkan = frame_program(folder / "model.onnx", dialect="vulkan", preset=_preset(folder)).manifest
    assert vulkan["memory"] == generated["memory"]
    wgsl = frame_program(folder / "model.onnx", dialect="wgsl", preset=_preset(folder)).manifest
    assert wgsl["memory"]["aliasing"] == generated["memory"]["aliasing"]
    for frame, peaks in generated["memory"]["peak_bytes"].items():
        assert wgsl["memory"]["peak_bytes"][frame]["fp32"] == peaks["fp32"]
        assert wgsl["memory"]["peak_bytes"][frame]["fp16"]["separate"] > peaks["fp16"]["separate"]


# Texture memory at 1080p, MiB (2**20 bytes) to 2 decimals, as memory_plan computes it (the docs table
# gives them to 1): fp32 separate, fp32 aliased, fp16 separate, fp16 aliased, fp32 live; then the
# network's own textures at fp32: separate, the most alive at one step.
SHIPPED_1080P = {
    "unet-gtao": (49.31, 31.39, 32.66, 21.91, 23.93, 20.25, 10.69),
    "unet-fast": (37.73, 21.26, 24.2, 13.29, 14.24, 26.27, 10.69),
}


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_figures_at_1080p(name):
    folder = _shipped(name)
    m = json.loads((folder / "glsl" / "manifest.json").read_text())
    fp32, fp16 = (memory_plan(m, 1920, 1080, p) for p in ("fp32", "fp16"))
    assert fp32.network_size == (455, 256)
    network = {k: (t.first, t.last) for k, t in fp32.textures.items() if t.network}
    alone = _figures([[k] for k in network], network, {k: fp32.textures[k].bytes for k in network})
    got = (
        fp32.separate_bytes,
        fp32.aliased_bytes,
        fp16.separate_bytes,
        fp16.aliased_bytes,
        fp32.live_bytes,
        alone["separate"],
        alone["live"],
    )
    assert tuple(round(b / MIB, 2) for b in got) == SHIPPED_1080P[name]


def test_docs_table_is_memory_plan():
    """Every row of the memory table in docs/engine-integration.md is what memory_plan gives."""
    text = (ROOT / "docs" / "engine-integration.md").read_text()
    rows = re.findall(r"^\| `(unet-[a-z]+)`[^|]*\| (\d+)x(\d+) \| \d+x\d+ \|((?: [\d.]+ \|)+)$", text, re.M)
    assert len(rows) == 4
    for name, w, h, cells in rows:
        m = json.loads((_shipped(name) / "glsl" / "manifest.json").read_text())
        fp32, fp16 = (memory_plan(m, int(w), int(h), p) for p in ("fp32", "fp16"))
        want = [fp32.separate_bytes, fp32.aliased_bytes, fp16.separate_bytes, fp16.aliased_bytes]
        want.append(fp32.live_bytes)
        assert [float(c) for c in cells.split("|") if c.strip()] == [round(b / MIB, 1) for b in want]


def test_results_table_is_memory_plan():
    """Every row of the peak-memory table in docs/results.md (the default model, both presets) is what
    memory_plan gives for the frame program of that preset."""
    text = (ROOT / "docs" / "results.md").read_text()
    rows = re.findall(r"^\| (\d+)x(\d+) \((cpu|gpu) passes\) \|((?: [\d.]+ \|)+)$", text, re.M)
    assert len(rows) == 4
    onnx_path = _shipped("unet-gtao") / "model.onnx"
    programs = {p: frame_program(onnx_path, preset=p).manifest for p in ("cpu", "gpu")}
    for w, h, preset, cells in rows:
        fp32, fp16 = (memory_plan(programs[preset], int(w), int(h), p) for p in PRECISIONS)
        want = [fp32.separate_bytes, fp32.aliased_bytes, fp16.separate_bytes, fp16.aliased_bytes]
        assert [float(c) for c in cells.split("|") if c.strip()] == [round(b / MIB, 1) for b in want]


# ----------------------------------------------------------------------------- the function's contract


def test_memory_plan_of_a_network_without_internal_height():
    """No internal height: the steps are the passes, the network runs at the frame's size, the fp16
    figures are those of the program generated at fp16, sizes it cannot take are one-line errors."""
    model = _random_model(3)
    m32, m16 = (generate_compute(model, precision=p).manifest for p in ("fp32", "fp16"))
    schedule = memory_schedule(m32)
    assert [s.name for s in schedule.steps] == [p["name"] for p in m32["passes"]]
    assert all(t.network for t in schedule.textures.values())
    plan = memory_plan(m32, 640, 480, "fp16")
    assert plan.network_size == (640, 480)
    assert {k: t.bytes for k, t in plan.textures.items()} == {
        k: v[3] for k, v in texture_sizes(m16, 480, 640).items()
    }
    assert m16["memory"] == m32["memory"]
    for t in plan.textures.values():
        assert t.bytes == t.width * t.height * t.layers * TEXEL_BYTES[t.format]
    with pytest.raises(NeuralaoError, match="pad multiple"):
        memory_plan(m32, 2, 480)
    with pytest.raises(NeuralaoError, match="precision"):
        memory_plan(m32, 640, 480, "fp8")


def test_static_program_gives_its_own_size():
    w = nh.from_array(np.ones((4, 3, 3, 3), np.float32), "w")
    graph = oh.make_graph(
        [oh.make_node("Conv", ["x", "w"], ["y"], pads=[1] * 4)],
        "static",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 8, 12])],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4, 8, 12])],
        [w],
    )
    m = generate_compute(oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)])).manifest
    assert list(m["memory"]["peak_bytes"]) == ["12x8"]
    plan = memory_plan(m, 1920, 1080)
    assert plan.network_size == (12, 8)
    assert plan.separate_bytes == sum(v[3] for v in texture_sizes(m, 8, 12).values())
