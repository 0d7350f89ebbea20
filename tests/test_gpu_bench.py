"""bench/gpu.sh runs unchanged on llvmpipe: one small frame, one timed run, both shipped models, both
presets, and an untrained architecture (the gpu preset); its table has GTAO's and SSAO's rows and each
model's ratio to GTAO, for the GL host and, where the Vulkan runner was built (vulkan/vulkan.h), for
Vulkan on lavapipe too. The SSAO the host times is the
project's SSAO: its output on a frame matches ``neuralao.runtime.baselines.run_ssao``."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers import analytic_gbuffer

from neuralao.runtime.baselines import run_ssao
from neuralao.runtime.foundation.tolerances import TOL

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench(tmp_path_factory) -> tuple[str, dict, Path]:
    """(stdout, gpu.json, build folder) of one small bench run."""
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler (Debian: gcc)")
    if not Path("/usr/include/EGL/egl.h").exists():
        pytest.skip("no EGL/egl.h (Debian: libegl-dev)")
    out = tmp_path_factory.mktemp("bench") / "gpu.json"
    env = os.environ | {
        "BENCH_GPU_SMALL": "1",
        "MODELS": "unet-gtao unet-fast",
        "PRECISIONS": "fp32",
        "ARCHS": "v3-small=4,8+gtao",  # an untrained architecture timed beside the shipped models
        "OUT": str(out),
    }
    r = subprocess.run(["bench/gpu.sh"], cwd=REPO, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout, json.loads(out.read_text()), REPO / "build/bench-gpu"


def test_gpu_bench_runs_small(bench):
    stdout, result, build = bench
    for row in (
        "| 128x96 | gl | GTAO | - | fp32 |",
        "| 128x96 | gl | SSAO | - | fp32 |",
        "| 128x96 | gl | unet-fast | gpu | fp32 |",
        "| 128x96 | gl | v3-small | gpu | fp32 |",
    ):
        assert row in stdout, stdout
    # the Vulkan runner is built where its headers are (the Makefile's system-deps install them) and runs
    # on lavapipe: a row per case, with GTAO's (the Vulkan runner has no SSAO)
    apis = {"gl", "vulkan"} if (build / "neuralao_vk").exists() else {"gl"}
    assert {row["api"] for row in result["rows"]} == apis
    if "vulkan" in apis:
        assert (
            "| 128x96 | vulkan | GTAO | - | fp32 |" in stdout and "| 128x96 | vulkan | SSAO |" not in stdout
        )
        assert "| 128x96 | vulkan | unet-gtao | cpu | fp32 |" in stdout, stdout
        assert result["gtao_ms"]["vulkan"]["128x96"] > 0 and "vulkan" not in result["ssao_ms"]
    for api in apis:
        rows = [row for row in result["rows"] if row["api"] == api]
        assert len(rows) == 5  # 2 models x 2 presets x fp32, the architecture with the first preset only
        assert {row["preset"] for row in rows} == {"gpu", "cpu"}
        assert {row["model"] for row in rows} == {"unet-gtao", "unet-fast", "v3-small"}
    assert all(
        row["path"] == "frame" and row["frame_ms"] > 0 and row["network_ms"] > 0 for row in result["rows"]
    )
    assert all(row["over_gtao"] and row["over_gtao"] > 0 for row in result["rows"])
    assert result["gtao_ms"]["gl"]["128x96"] > 0 and result["ssao_ms"]["gl"]["128x96"] > 0
    # a hybrid's frame has GTAO steps, timed on their own; the fast model's has none (times are not
    # compared here: one run on a shared machine orders them by chance)
    for row in result["rows"]:
        timed = max(row["gtao_ms"], row["gtao_wall_ms"]) > 0
        assert timed == (row["model"] in ("unet-gtao", "v3-small")), row


def test_host_ssao_is_the_projects_ssao(bench, tmp_path):
    """The SSAO entry bench/gpu.sh prepares, run by the host (NEURALAO_HOST_SSAO_OUT): the same fragment
    shaders with the same kernel, noise, bias and blur as run_ssao, on the same driver."""
    _, _, build = bench
    frame = analytic_gbuffer(75, 53)
    h, w = frame["depth"].shape
    gbuffer = np.concatenate([frame["depth"][..., None], frame["normal_cam"], frame["mask"][..., None]], -1)
    gbuffer.astype("<f4").tofile(tmp_path / "gbuffer.f32")
    radius = 0.4
    args = [str(tmp_path / "gbuffer.f32"), str(w), str(h), repr(radius), repr(math.degrees(frame["yfov"]))]
    export = build / "exports" / "unet-fast-gpu-fp32"
    env = os.environ | {"NEURALAO_HOST_SSAO_OUT": str(tmp_path / "ssao.f32")}
    r = subprocess.run(
        [str(build / "neuralao_host"), str(export), *args, str(tmp_path / "ao.f32")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    ssao = np.fromfile(tmp_path / "ssao.f32", "<f4").reshape(h, w)
    want = run_ssao(frame, radius)
    assert float(np.abs(ssao - want).max()) <= TOL.glsl_op_fp32
    assert float(want[frame["mask"]].min()) < 0.8  # occlusion somewhere: the comparison means something


def test_gpu_bench_profiles_every_step(bench):
    """profile.txt: per model, each step of its frame timed alone, as many lines as the frame has passes."""
    _, result, build = bench
    text = (build / "profile.txt").read_text()
    for row in result["rows"]:
        if row["api"] != "gl" or row["preset"] != "gpu":
            continue
        block = text.split(f"== {row['model']}-gpu-fp32 128x96 (GL)\n", 1)[1].split("==", 1)[0]
        steps = [ln for ln in block.splitlines() if " step " in ln]
        assert len(steps) == row["passes"] and all("ms (wall" in ln for ln in steps), block
