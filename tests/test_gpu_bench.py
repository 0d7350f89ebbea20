"""bench/gpu.sh runs unchanged on llvmpipe: one small frame, one timed run, the fast model, both presets."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_gpu_bench_runs_small(tmp_path):
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler (Debian: gcc)")
    if not Path("/usr/include/EGL/egl.h").exists():
        pytest.skip("no EGL/egl.h (Debian: libegl-dev)")
    out = tmp_path / "gpu.json"
    env = os.environ | {
        "BENCH_GPU_SMALL": "1",
        "MODELS": "unet-fast",
        "PRECISIONS": "fp32",
        "OUT": str(out),
    }
    r = subprocess.run(["bench/gpu.sh"], cwd=REPO, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "| 128x96 | unet-fast | gpu | fp32 |" in r.stdout
    result = json.loads(out.read_text())
    assert {row["preset"] for row in result["rows"]} == {"gpu", "cpu"}
    assert all(row["frame_ms"] > 0 for row in result["rows"])
