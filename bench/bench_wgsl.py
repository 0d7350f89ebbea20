"""The WGSL target on the shipped U-Nets: parity against onnxruntime per model, and GLSL (llvmpipe) vs
WGSL (lavapipe) time for the shipped default, in one run on the same CPU.

    .venv/bin/python bench/bench_wgsl.py --out build/bench [--size 64] [--time-size 256] [--repeats 5]

Parity: each model's WGSL (generate_compute(dialect="wgsl")) on a seeded G-buffer-like input of
size x size (depth in [0.5, 1.5], unit-free normals, radius 0.3), against onnxruntime on the same input;
the GLSL passes' error is listed beside it. Time: median of ``repeats`` frames (pad, network, crop), GL
closed by glFinish, WebGPU by reading one output texel back. Writes DIR/wgsl.json and DIR/wgsl.md.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np
import onnx

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.export.glsl import generate_compute  # noqa: E402
from neuralao.export.onnx_io import run_onnxruntime  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402
from neuralao.runtime.glsl_runner import run_compute, time_compute  # noqa: E402
from neuralao.runtime.shipped import INDEX, MODELS_DIR  # noqa: E402
from neuralao.runtime.wgsl_runner import adapter_info, run_wgsl, time_wgsl  # noqa: E402

log = logging.getLogger("bench_wgsl")


def _input(size: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 1.5, (1, 1, size, size))
    normal = rng.normal(size=(1, 3, size, size))
    return np.concatenate([depth, normal / np.linalg.norm(normal, axis=1, keepdims=True)], 1).astype(
        np.float32
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("build/bench"))
    ap.add_argument("--size", type=int, default=64, help="parity input size (a multiple of 8)")
    ap.add_argument("--time-size", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    index = json.loads(INDEX.read_text())
    default = index["default"]["unet"]
    x = _input(args.size)
    scalars = {"radius": np.full((1, 1, 1, 1), 0.3, np.float32)}
    rows = []
    for name in sorted(index["models"]):
        path = MODELS_DIR / name / "model.onnx"
        model = onnx.load(path)
        channels = model.graph.input[0].type.tensor_type.shape.dim[1].dim_value
        if channels > x.shape[1]:  # a hybrid's extra input (GTAO): seeded values in [0, 1]
            extra = np.random.default_rng(1).uniform(size=(1, channels - x.shape[1], *x.shape[2:]))
            x = np.concatenate([x[:, :4], extra.astype(np.float32)], 1)
        else:
            x = x[:, :channels]
        ref = run_onnxruntime(path.read_bytes(), {model.graph.input[0].name: x, **scalars})[0]
        t0 = time.perf_counter()
        wgsl = generate_compute(model, dialect="wgsl")
        got_w = run_wgsl(wgsl, x, scalars=scalars)
        seconds = time.perf_counter() - t0
        got_g = run_compute(generate_compute(model), x, scalars=scalars)
        rows.append(
            {
                "model": name,
                "default": name == default,
                "passes": len(wgsl.manifest["passes"]),
                "wgsl_max_abs_err": float(np.abs(got_w - ref).max()),
                "glsl_max_abs_err": float(np.abs(got_g - ref).max()),
                "wgsl_compile_and_run_s": seconds,
            }
        )
        log.info("%s: WGSL %.2g, GLSL %.2g", name, rows[-1]["wgsl_max_abs_err"], rows[-1]["glsl_max_abs_err"])
    model = onnx.load(MODELS_DIR / default / "model.onnx")
    n = args.time_size
    gl_s = time_compute(generate_compute(model), n, n, repeats=args.repeats, scalars=scalars)
    wgsl_s = time_wgsl(generate_compute(model, dialect="wgsl"), n, n, repeats=args.repeats, scalars=scalars)
    timing = {
        "model": default,
        "size": [n, n],
        "repeats": args.repeats,
        "glsl_llvmpipe_s": gl_s,
        "wgsl_lavapipe_s": wgsl_s,
    }
    result = {
        "date": time.strftime("%Y-%m-%d"),
        "cpu": cpu_name(),
        "adapter": adapter_info(),
        "parity_size": args.size,
        "parity": rows,
        "timing": timing,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "wgsl.json", result)
    lines = ["| model | passes | WGSL vs onnxruntime | GLSL vs onnxruntime |", "|---|---|---|---|"]
    for r in rows:
        name = f"{r['model']} (default)" if r["default"] else r["model"]
        lines.append(
            f"| {name} | {r['passes']} | {r['wgsl_max_abs_err']:.1e} | {r['glsl_max_abs_err']:.1e} |"
        )
    lines += [
        "",
        f"{default} at {n}x{n}: GLSL on llvmpipe {gl_s * 1e3:.0f} ms, WGSL on lavapipe {wgsl_s * 1e3:.0f} ms "
        f"(median of {args.repeats}; {result['cpu']}; {result['adapter']['description']})",
    ]
    write_text(args.out / "wgsl.md", "\n".join(lines) + "\n")
    log.info("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
