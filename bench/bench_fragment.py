"""Benchmark the fragment (vector) target's weight placement: uniform blocks against shader constants.

    .venv/bin/python bench/bench_fragment.py --out build/bench [--size 512] [--repeats 10]

For the baked-MLP sizes (16x8, 32x16, 64x32; seeded random weights, the 48-input graph as exported) and
the AO-field sizes (16x8, 32x16; 4 octaves), the same ONNX graph is generated twice,
``weights="uniform"`` (std140 blocks) and ``weights="constant"`` (const arrays in the source), and both
are timed at SIZE x SIZE on Mesa's llvmpipe in one run, every pixel foreground, beside SSAO on a real
G-buffer of bunny. Also: compile + first draw seconds, and the largest difference between the variants'
outputs (they evaluate the same floats; only the compiler's folding differs).

Writes DIR/fragment.json and DIR/fragment.md.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import onnx
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402


def mlp_graph(hidden) -> onnx.ModelProto:
    from neuralao.export.mlp import onnx_bytes
    from neuralao.pipeline.models.mlp import BakedMLP

    torch.manual_seed(0)
    return onnx.load_from_string(onnx_bytes(BakedMLP(hidden)))


def field_graph(hidden) -> onnx.ModelProto:
    from neuralao.export.field import onnx_bytes
    from neuralao.pipeline.models.field import FieldNet

    torch.manual_seed(0)
    return onnx.load_from_string(onnx_bytes(FieldNet(hidden, 4, [0, 0, 0], [1, 1, 1])))


def variants(name: str, proto: onnx.ModelProto, size: int, repeats: int) -> dict:
    from neuralao.export.field import bindings
    from neuralao.export.glsl import generate_vector_fragment
    from neuralao.runtime.glsl_runner import run_vector_fragment, texture_names, time_vector_fragment

    binds = None if name.startswith("mlp") else bindings()
    row: dict = {}
    outputs = {}
    for weights in ("uniform", "constant"):
        sh = generate_vector_fragment(proto, binds, kind=name.split("-")[0], weights=weights)
        rng = np.random.default_rng(1)
        tex = {t: rng.uniform(-1, 1, size=(64, 64, 4)).astype(np.float32) for t in texture_names(sh)}
        tex[texture_names(sh)[0]][..., 3] = 1.0
        t0 = time.perf_counter()
        outputs[weights] = run_vector_fragment(sh, tex)
        row[f"{weights}_compile_s"] = time.perf_counter() - t0
        row[f"{weights}_ms"] = 1e3 * time_vector_fragment(sh, size, size, repeats=repeats)
        row[f"{weights}_blocks"] = len(sh.uniform_blocks)
    row["speedup"] = row["uniform_ms"] / row["constant_ms"]
    row["max_abs_diff"] = float(np.abs(outputs["uniform"] - outputs["constant"]).max())
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="build/bench")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--repeats", type=int, default=10)
    args = ap.parse_args()
    from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
    from neuralao.pipeline.geometry.camera import orbit
    from neuralao.pipeline.geometry.scene import load_scene
    from neuralao.runtime.baselines import time_screen_space

    scene = load_scene("bunny")
    with GBufferRenderer(scene) as r:
        frame = r.render(orbit(scene, 1, args.size, args.size)[0])
    ssao = 1e3 * time_screen_space(frame, "ssao", 0.25 * scene.diagonal, repeats=args.repeats)
    rows = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, proto in [(f"mlp-{h[0]}x{h[1]}", mlp_graph(h)) for h in ((16, 8), (32, 16), (64, 32))] + [
            (f"field-{h[0]}x{h[1]}", field_graph(h)) for h in ((16, 8), (32, 16))
        ]:
            rows[name] = variants(name, proto, args.size, args.repeats)
            rows[name]["uniform_vs_ssao"] = rows[name]["uniform_ms"] / ssao
            rows[name]["constant_vs_ssao"] = rows[name]["constant_ms"] / ssao
    result = {"cpu": cpu_name(), "size": args.size, "ssao_ms": ssao, "networks": rows}
    lines = [
        f"# Fragment target: weights in uniform blocks vs shader constants ({result['cpu']}, llvmpipe)",
        "",
        f"{args.size}x{args.size}, every pixel foreground, median of {args.repeats} frames, one run; SSAO "
        f"{ssao:.2f} ms on a real bunny G-buffer in the same run.",
        "",
        "| network | uniform ms (x SSAO) | constant ms (x SSAO) | speed-up | "
        "compile s uniform / constant | max abs diff |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for n, r in rows.items():
        lines.append(
            f"| {n} | {r['uniform_ms']:.2f} ({r['uniform_vs_ssao']:.2f}) | {r['constant_ms']:.2f} "
            f"({r['constant_vs_ssao']:.2f}) | {r['speedup']:.2f} | {r['uniform_compile_s']:.2f} / "
            f"{r['constant_compile_s']:.2f} | {r['max_abs_diff']:.1e} |"
        )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "fragment.json", result)
    write_text(out / "fragment.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
