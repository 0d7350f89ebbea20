"""GL time of every shipped U-Net (runtime/models) beside SSAO and GTAO, in the same rounds.

    PYOPENGL_PLATFORM=osmesa .venv/bin/python bench/bench_shipped.py --out build/bench \
        [--models runtime/models] [--sizes 512x512 1920x1080] [--rounds 3] [--mesh sponza_partial]

``neuralao ship`` records a model's GL time when it installs it, under whatever load the machine had
then, so times of models shipped in different runs do not compare. This bench times all of them and
the two screen-space baselines in interleaved rounds (the order rotates each round) and reports
medians and ratios from the same rounds:

* each shipped model: its generated GLSL compute passes (pad, network, crop; dispatch only, the input
  already resident, as in an engine) through ``neuralao.runtime.glsl_runner.time_compute`` on random input
  (the cost does not depend on the input or the radius uniform);
* ``<model>@h<N>``: the same network at an internal height of N rows (same aspect ratio) between the
  point-sampling and upsampling passes of ``neuralao.runtime.internal_resolution`` (both timed at the frame's
  size), as a frame at a resolution taller than N runs it; N from ``--internal-height`` or the
  model's manifest (``internal_height``);
* a hybrid (GTAO as its fifth input channel): the GTAO pass at the frame's size is added to its time;
* SSAO and GTAO: ``neuralao.runtime.baselines.time_screen_space`` on a real G-buffer of ``--mesh`` (a seeded
  interior camera: all foreground, as in a game frame; they skip background pixels) at each size,
  radius 1/4 of the scene diagonal (the largest label radius), blur included.

Ratios: to the index's default model (a reduced-resolution variant should cost at most 1/4 of the
full network's time) and to GTAO; test-split SSIM / RMSE come from index.json (``neuralao ship``
measured them).
Writes DIR/shipped.json and DIR/shipped.md. No shipped models: one line, exit 0.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.runtime.foundation.errors import NeuralaoError  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402

LARGE_PIXELS = 1_000_000  # sizes above this get --large-repeats timed dispatches a round


def _manifest(folder: Path) -> dict:
    import json

    path = folder / "manifest.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 1920x1080, got {text!r}") from None
    return w, h


def measure(args) -> dict:
    from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
    from neuralao.pipeline.geometry.camera import interior
    from neuralao.pipeline.geometry.scene import load_scene
    from neuralao.runtime import gl
    from neuralao.runtime.baselines import GTAOSettings, time_screen_space
    from neuralao.runtime.glsl_runner import time_compute
    from neuralao.runtime.internal_resolution import internal_size, time_scaling_passes
    from neuralao.runtime.shipped import read_index
    from neuralao.runtime.unet_input import hybrid_gtao_blur, scales_up

    models_dir = Path(args.models)
    index = read_index(models_dir)
    names = sorted(index["models"]) if not args.only else [n for n in args.only if n in index["models"]]
    default = index.get("default", {}).get("unet")
    scene = load_scene(args.mesh)
    radius = 0.25 * scene.diagonal
    frames = {}
    with GBufferRenderer(scene) as r:
        for w, h in args.sizes:
            frames[(w, h)] = r.render(interior(scene, 1, w, h, seed=args.seed)[0])
    # model@h<N>: the network at N rows (same aspect), between the point-sampling and upsampling passes
    internal = {}
    for m in names:
        height = args.internal_height or _manifest(models_dir / m).get("internal_height")
        if height:
            internal[f"{m}@h{int(height)}"] = (m, int(height))
    methods = [*names, *internal, "ssao", "gtao"]

    # a hybrid reads GTAO's output: its frame time includes the GTAO pass at the frame's size
    hybrid = {
        m
        for m in names
        if _manifest(models_dir / m).get("metadata", {}).get("input_channels", "").endswith(",gtao")
    }

    def seconds(m: str, w: int, h: int, repeats: int, warmup: int) -> float:
        if m in ("ssao", "gtao"):  # a pass is ~10x cheaper than a U-Net: 4x the repeats
            return time_screen_space(frames[(w, h)], m, radius, repeats=4 * repeats, warmup=max(warmup, 1))
        if internal.get(m, (m,))[0] in hybrid:
            meta = _manifest(models_dir / internal.get(m, (m,))[0]).get("metadata", {})
            gtao = time_screen_space(  # the GTAO the hybrid reads: with its blur, or the pass alone
                frames[(w, h)],
                "gtao",
                radius,
                GTAOSettings(blur=hybrid_gtao_blur(meta)),
                repeats=2 * repeats,
                warmup=max(warmup, 1),
            )
            return gtao + network_seconds(m, w, h, repeats, warmup)
        return network_seconds(m, w, h, repeats, warmup)

    def network_seconds(m: str, w: int, h: int, repeats: int, warmup: int) -> float:
        if m in internal:
            model, height = internal[m]
            version = _manifest(models_dir / model).get("metadata", {}).get("preprocess_version", 3)
            lw, lh = internal_size(w, h, height, scales_up(int(version)))
            if (lw, lh) == (w, h):
                return time_compute(models_dir / model / "glsl", h, w, repeats=repeats, warmup=warmup)
            net = time_compute(models_dir / model / "glsl", lh, lw, repeats=repeats, warmup=warmup)
            return net + time_scaling_passes(
                frames[(w, h)], (lw, lh), repeats=2 * repeats, warmup=max(warmup, 1)
            )
        return time_compute(models_dir / m / "glsl", h, w, repeats=repeats, warmup=warmup)

    times: dict[str, dict[str, list[float]]] = {m: {} for m in methods}
    for w, h in args.sizes:  # untimed first run of each: compiles (or reads Mesa's cache), JIT variants
        for m in methods:
            seconds(m, w, h, 1, 0)
    for k in range(args.rounds):
        order = methods[k % len(methods) :] + methods[: k % len(methods)]
        for w, h in args.sizes:
            reps = args.large_repeats if w * h > LARGE_PIXELS else args.repeats
            for m in order:
                times[m].setdefault(f"{w}x{h}", []).append(seconds(m, w, h, reps, 1))
    rows = {}
    for m in methods:
        info = index["models"].get(internal.get(m, (m,))[0]) or index.get("baselines", {}).get(m, {})
        test = info.get("test", {})
        med = {s: float(np.median(v)) for s, v in times[m].items()}
        rows[m] = {
            "ms": {s: 1e3 * v for s, v in med.items()},
            "rounds": times[m],
            "test_ssim": test.get("ssim"),
            "test_rmse": test.get("rmse"),
            "scale": info.get("scale"),
            "widths": info.get("widths"),
            "init": info.get("init"),
        }
    for row in rows.values():
        for ref in (default, "gtao"):
            if ref in rows:
                row[f"over_{ref}"] = {s: row["ms"][s] / rows[ref]["ms"][s] for s in row["ms"]}
    foreground = {f"{w}x{h}": float(np.mean(frames[(w, h)]["mask"])) for w, h in args.sizes}
    return {
        "foreground": foreground,
        "cpu": cpu_name(),
        "gl_renderer": gl.context().info.renderer,
        "models": str(models_dir),
        "default": default,
        "mesh": args.mesh,
        "sizes": [f"{w}x{h}" for w, h in args.sizes],
        "rounds": args.rounds,
        "rows": rows,
    }


def markdown(result: dict) -> str:
    sizes, default = result["sizes"], result["default"]
    head = " | ".join(f"{s} ms | / {default} | / GTAO" for s in sizes)
    lines = [
        "# Shipped U-Nets vs SSAO and GTAO: GL time in the same rounds",
        "",
        f"GL on {result['gl_renderer']} ({result['cpu']}); median of {result['rounds']} interleaved rounds; "
        f"SSAO / GTAO on a {result['mesh']} G-buffer from an interior camera (foreground "
        f"{', '.join(f'{100 * v:.0f}%' for v in result['foreground'].values())} of the pixels: "
        "their cost falls with the background they skip) at radius 1/4 of its diagonal. "
        "Test SSIM / RMSE: the test split, from index.json.",
        "",
        f"| method | scale | widths | test SSIM | test RMSE | {head} |",
        "|---|---:|---|---:|---:|" + "---:|" * (3 * len(sizes)),
    ]

    def f(v, spec):
        return "-" if v is None else format(v, spec)

    order = sorted(result["rows"], key=lambda m: (m in ("ssao", "gtao"), -result["rows"][m]["ms"][sizes[0]]))
    for m in order:
        r = result["rows"][m]
        cells = " | ".join(
            f"{r['ms'][s]:,.1f} | {f(r.get(f'over_{default}', {}).get(s), '.2f')}x | "
            f"{f(r.get('over_gtao', {}).get(s), '.2f')}x"
            for s in sizes
        )
        widths = "/".join(str(w) for w in r["widths"]) if r.get("widths") else "-"
        lines.append(
            f"| {m} | {f(r.get('scale'), 'd')} | {widths} | {f(r['test_ssim'], '.4f')} | "
            f"{f(r['test_rmse'], '.4f')} | {cells} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="build/bench")
    p.add_argument("--models", default=str(Path(__file__).resolve().parents[1] / "runtime" / "models"))
    p.add_argument("--sizes", nargs="+", type=parse_size, default=[(512, 512), (1920, 1080)])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--repeats", type=int, default=3, help="timed dispatches per model per round")
    p.add_argument("--large-repeats", type=int, default=1, help="the same above one megapixel")
    p.add_argument("--mesh", default="sponza_partial")
    p.add_argument("--seed", type=int, default=0, help="seed of the interior camera")
    p.add_argument("--only", nargs="+", help="time only these shipped models (default: all)")
    p.add_argument(
        "--internal-height",
        type=int,
        default=None,
        help="also time each model at this internal height (default: the height its manifest declares)",
    )
    args = p.parse_args()
    if min(args.rounds, args.repeats, args.large_repeats) < 1:
        p.error("--rounds, --repeats and --large-repeats must be at least 1")
    if not (Path(args.models) / "index.json").is_file():
        print(f"bench_shipped: no shipped models in {args.models} (run `make models`); nothing to time")
        return
    try:
        result = measure(args)
    except NeuralaoError as e:
        sys.exit(f"bench_shipped: {e}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "shipped.json", result)
    write_text(out / "shipped.md", markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
