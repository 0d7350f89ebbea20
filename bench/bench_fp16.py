"""What fp16 costs the shipped U-Nets' AO: the whole frame (frame passes + network, GL on llvmpipe) at fp32
and at fp16, each against onnxruntime's AO and against the ray-traced labels, on test frames.

    PYOPENGL_PLATFORM=osmesa .venv/bin/python bench/bench_fp16.py --out build/bench \
        [--models runtime/models] [--size 256] [--views 2] [--rays 512] [--preset cpu]

The frames are `neuralao evaluate`'s kind (test-split meshes alone, glTF assets, composed rooms; labels
by Embree at the four trained radii, every radius of each frame scored), built under
DIR/fp16/frames (resumable). Per model: the largest |fp16 - fp32| AO over all pixels, each precision's
largest |AO - onnxruntime| (the reference predictor, at the model's internal height), and masked RMSE /
SSIM against the labels, with the change fp16 makes. The generator preset does not change the
arithmetic's order of rounding in a way that matters here (both are checked against onnxruntime by the
tests); ``--preset cpu`` is the default because it is the fast one on llvmpipe.
Writes DIR/fp16.json and DIR/fp16.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.pipeline.datasets.dataset import open_dataset  # noqa: E402
from neuralao.pipeline.evaluation.categories import (  # noqa: E402
    EvalCategory,
    EvalResolution,
    EvalSettings,
    dataset_settings,
    ensure_frames,
)
from neuralao.pipeline.evaluation.test_split import score_frame  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.frame_runner import FrameRunner, frame_program  # noqa: E402
from neuralao.runtime.predict import unet_predictor  # noqa: E402
from neuralao.runtime.shipped import shipped_models  # noqa: E402

CATEGORIES = [
    EvalCategory("scans", meshes=["lucy", "horse"]),
    EvalCategory("gltf", meshes=["KnightArmor", "CesiumMilkTruck"]),
    EvalCategory("rooms", composed=2, composed_seed=20000, cameras="interior"),
]


def _gl(program, runners: list):
    """A predictor running ``program``'s whole frame; one runner per frame size, kept in ``runners``."""
    by_size: dict[tuple[int, int], FrameRunner] = {}

    def predict(frame, radius):
        h, w = np.shape(frame["depth"])
        if (w, h) not in by_size:
            by_size[(w, h)] = FrameRunner(program, w, h)
            runners.append(by_size[(w, h)])
        return by_size[(w, h)].run(frame, radius)

    return predict


def measure(models: Path, out: Path, size: int, views: int, rays: int, preset: str) -> dict:
    settings = EvalSettings(name="fp16", categories=CATEGORIES)
    res = EvalResolution(size=(size, size), rays=rays, views=views)
    folder = out / "fp16" / "frames" / f"{size}x{size}"
    ensure_frames(dataset_settings(settings, res), folder, Path.cwd(), progress=True)
    frames = list(open_dataset(folder).frames(split="test"))
    result = {"size": [size, size], "frames": len(frames), "preset": preset, "models": {}}
    for name, model_dir in sorted(shipped_models(models).items()):
        onnx_path = Path(model_dir) / "model.onnx"
        runners: list[FrameRunner] = []
        methods = {
            "onnxruntime": unet_predictor(onnx_path, "model"),
            **{
                p: _gl(frame_program(onnx_path, precision=p, preset=preset), runners)
                for p in ("fp32", "fp16")
            },
        }
        diffs = {"fp16_vs_fp32": 0.0, "fp32_vs_onnxruntime": 0.0, "fp16_vs_onnxruntime": 0.0}
        rows = []
        for frame in frames:
            for radius in np.asarray(frame["radii"], np.float64).reshape(-1):
                ao = {k: fn(frame, float(radius)) for k, fn in methods.items()}
                for key, (a, b) in {
                    "fp16_vs_fp32": ("fp16", "fp32"),
                    "fp32_vs_onnxruntime": ("fp32", "onnxruntime"),
                    "fp16_vs_onnxruntime": ("fp16", "onnxruntime"),
                }.items():
                    diffs[key] = max(diffs[key], float(np.abs(ao[a] - ao[b]).max()))
            rows += score_frame(frame, methods, flip=False)
        for runner in runners:
            runner.release()
        scores = {
            k: {m: float(np.mean([r[m] for r in rows if r["method"] == k])) for m in ("rmse", "ssim")}
            for k in methods
        }
        result["models"][name] = {"max_abs": diffs, "labels": scores, "pairs": len(rows) // len(methods)}
        print(name, diffs, scores, flush=True)
    return result


def markdown(result: dict) -> str:
    w, h = result["size"]
    lines = [
        f"{result['frames']} test frames at {w}x{h}, every trained radius; whole frame on GL (llvmpipe), "
        f"{result['preset']} preset",
        "",
        "| model | max abs fp16 - fp32 | fp32 vs onnxruntime | fp16 vs onnxruntime | RMSE vs labels fp32 / "
        "fp16 | SSIM vs labels fp32 / fp16 |",
        "|---|---:|---:|---:|---|---|",
    ]
    for name, m in result["models"].items():
        d, s = m["max_abs"], m["labels"]
        lines.append(
            f"| `{name}` | {d['fp16_vs_fp32']:.2g} | {d['fp32_vs_onnxruntime']:.2g} | "
            f"{d['fp16_vs_onnxruntime']:.2g} | {s['fp32']['rmse']:.5f} / {s['fp16']['rmse']:.5f} | "
            f"{s['fp32']['ssim']:.5f} / {s['fp16']['ssim']:.5f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("build/bench"))
    p.add_argument("--models", type=Path, default=Path("runtime/models"))
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--views", type=int, default=2)
    p.add_argument("--rays", type=int, default=512)
    p.add_argument("--preset", default="cpu", choices=["cpu", "gpu"])
    a = p.parse_args()
    result = measure(a.models, a.out, a.size, a.views, a.rays, a.preset)
    write_json(a.out / "fp16.json", result)
    write_text(a.out / "fp16.md", markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
