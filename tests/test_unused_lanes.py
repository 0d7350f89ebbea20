"""The input texture's unused lanes (manifest ``input.unused_lanes``: the lanes past the last channel of the
last layer) change nothing: the generated pad pass, the only reader of the input texture, zeroes them
(with the gpu preset, the convs that read the input in the pad pass's place zero them as they read).

NaN, inf or finite garbage there gives the same output, bit for bit, as zeros, in GLSL on Mesa llvmpipe
and, on Mesa lavapipe through wgpu, in WGSL and in the Vulkan passes' SPIR-V: the shipped hybrid U-Net
(5 channels: 3 unused lanes), a static-size 6-channel conv graph (2 unused lanes) and per-pixel ops on a
5-channel input computed in one pointwise pass.
"""

from __future__ import annotations

import shutil

import numpy as np
import onnx
import pytest
from helpers import image_model, named_node, seeded_weights

from neuralao.export.glsl import generate_compute
from neuralao.runtime.glsl_runner import _ComputeRun, compute_outputs, scalar_values
from neuralao.runtime.shipped import shipped_models

GARBAGE = {"nan": np.nan, "inf": np.inf, "large": 3.0e38}


def _programs(dialect: str) -> dict[str, tuple]:
    """{case: (program, {scalar input: value})} of the two graphs in ``dialect``."""
    hybrid = onnx.load(shipped_models()["unet-gtao"] / "model.onnx")
    conv = image_model(
        [named_node("Conv", ("x", "w"), pads=[1, 1, 1, 1])],
        [("w", seeded_weights((3, 6, 3, 3)))],
        (1, 6, 9, 11),
    )
    # per-pixel ops on a 5-channel input: one pointwise pass that reads the input reflect-padded
    pointwise = image_model(
        [named_node("Mul", ("x", "x"), "a"), named_node("Conv", ("a", "w"))],
        [("w", seeded_weights((3, 5, 1, 1)))],
        (1, 5, 9, 11),
    )
    return {
        "unet-gtao": (generate_compute(hybrid, dialect=dialect), {"radius": np.float32(0.2)}),
        "conv6": (generate_compute(conv, dialect=dialect), {}),
        "pointwise5": (generate_compute(pointwise, dialect=dialect), {}),
    }


def _input(manifest: dict, height: int, width: int, fill: float) -> np.ndarray:
    """(1, 4 * layers, H, W) float32: the input's channels, then ``fill`` in every unused lane."""
    c = manifest["input"]["channels"]
    lanes = 4 * -(-c // 4)
    x = np.full((1, lanes, height, width), fill, np.float32)
    x[:, :c] = np.random.default_rng(3).normal(size=(1, c, height, width))
    return x


def _run_gl(program, x: np.ndarray, scalars: dict) -> dict:
    m = program.manifest
    run = _ComputeRun(program, x.shape[2], x.shape[3], scalar_values(m, scalars))
    try:
        run.upload(x)  # every lane of every layer as given
        run.dispatch()
        return compute_outputs(m, run.read)
    finally:
        run.release()


def _run_wgpu(program, x: np.ndarray, scalars: dict, via: str) -> dict:
    wgpu = pytest.importorskip("wgpu", reason="the wgpu package is not installed (pyproject pins it)")
    if wgpu.gpu.request_adapter_sync() is None:
        pytest.skip("no WebGPU adapter (Debian: mesa-vulkan-drivers)")
    from neuralao.runtime.wgsl_runner import _WgslRun

    m = program.manifest
    run = _WgslRun(program, x.shape[2], x.shape[3], scalar_values(m, scalars), False, via)
    run.upload(x)
    run.dispatch()
    return compute_outputs(m, run.read)


def _run(dialect: str, program, x: np.ndarray, scalars: dict) -> dict:
    if dialect == "glsl430":
        return _run_gl(program, x, scalars)
    return _run_wgpu(program, x, scalars, "passthrough" if dialect == "vulkan" else "naga")


@pytest.mark.parametrize("dialect", ["glsl430", "wgsl", "vulkan"])
def test_garbage_in_unused_lanes_changes_nothing(dialect):
    if dialect == "vulkan" and shutil.which("glslangValidator") is None:
        pytest.skip("glslangValidator not installed (Debian: glslang-tools)")
    for case, (program, scalars) in _programs(dialect).items():
        m = program.manifest
        zeroed_by = (
            "the passes reading the input zero them"
            if m["pad"]["pass"] is None
            else "the pad pass zeroes them"
        )
        assert m["input"]["unused_lanes"].endswith(zeroed_by), m["input"]
        h, w = (16, 24) if case == "unet-gtao" else (9, 11)
        clean = _run(dialect, program, _input(m, h, w, 0.0), scalars)
        for name, fill in GARBAGE.items():
            got = _run(dialect, program, _input(m, h, w, fill), scalars)
            for out, ref in clean.items():
                assert np.isfinite(ref).all()
                assert np.array_equal(got[out], ref), (
                    f"{dialect} {case}: {name} in unused lanes changed {out}"
                )
