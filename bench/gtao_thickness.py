"""GTAO's thickness heuristics against ray-traced labels, per category, and what they cost at 1080p in GL.

    PYOPENGL_PLATFORM=osmesa .venv/bin/python bench/gtao_thickness.py [--config configs/eval.json] \
        [--frames build/bench/error_bands/frames/256x256] [--blends 0.5 0.8 0.9 0.95 0.98] \
        [--compensation 0.35 0.7] [--time-size 1920 1080] [--rounds 3] [--repeats 4] \
        [--out build/bench/gtao_thickness]

Plain GTAO (``neuralao.runtime.baselines``, default settings) against ``gtao-t<beta>``, the same pass with
the thickness heuristic of Jimenez et al. 2016 at blend beta (``GTAOSettings.thickness_blend``), and
``gtao-c<c>``, with XeGTAO's thin occluder compensation c (``GTAOSettings.thin_occluder_compensation``).

Frames: `neuralao evaluate`'s, as bench/ao_error_bands.py builds them under ``OUT/frames/<W>x<H>`` (run it
first; this script reads that folder and builds nothing). Categories held aside (``held_aside: true``) are
left out. Every method is scored as evaluate scores it
(:func:`neuralao.pipeline.evaluation.test_split.score_frame`: masked SSIM and RMSE over the valid foreground
pixels of each (frame, radius) pair, the label radius as the kernel radius), and a category's figure is the
mean over its pairs; the camera groups (orbit: the isolated objects, interior: the rooms) average the
pairs of their categories. Ratios are to plain GTAO's figure.

Timing (``--time-size``, 0 0 to skip): :func:`neuralao.runtime.baselines.time_screen_space` (AO pass and
blur, G-buffer resident, median of ``--repeats`` frames each ended by glFinish) on a seeded interior
camera of ``--mesh`` (all foreground, as a game frame), radius 1/4 of the scene diagonal, plain GTAO
and the last blend and compensation given (the cost depends on neither value) once a round, the order
rotating each round; the median over rounds and its ratio to GTAO.

Writes OUT/gtao_thickness.json (every pair's scores, the summary, the times) and OUT/gtao_thickness.md,
and prints the markdown.
"""

from __future__ import annotations

import argparse
import importlib.util
import logging
import sys
import time
from pathlib import Path

import numpy as np

from neuralao.pipeline.datasets.dataset import open_dataset
from neuralao.pipeline.evaluation.categories import EvalSettings, category_of
from neuralao.pipeline.evaluation.test_split import score_frame, screen_space_predictor
from neuralao.runtime.baselines import GTAOSettings, gtao_pass_description
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json, write_text
from neuralao.runtime.foundation.settings import load_settings, settings_to_dict

log = logging.getLogger(__name__)


def _sibling(name: str):
    """A script beside this one, as a module (bench/ is no package)."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parent / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_bands = _sibling("ao_error_bands")
select_categories = _bands.select_categories


def variants(blends: list[float], compensation: list[float]) -> dict[str, GTAOSettings]:
    """Method name -> GTAO settings: plain ``gtao``, ``gtao-t<beta>`` and ``gtao-c<c>``."""
    out = {"gtao": GTAOSettings()}
    out |= {f"gtao-t{b:g}": GTAOSettings(thickness_blend=float(b)) for b in blends}
    out |= {f"gtao-c{c:g}": GTAOSettings(thin_occluder_compensation=float(c)) for c in compensation}
    return out


def summarise(rows: list[dict], methods: list[str], groups: dict[str, list[str]]) -> dict:
    """pool (each category, each camera group, ``all``) -> method -> {ssim, rmse, pairs, ssim_ratio,
    rmse_ratio}: means over the pool's (frame, radius) pairs, ratios to plain GTAO's."""
    cats = sorted({r["category"] for r in rows})
    pools = {c: [c] for c in cats} | {g: cs for g, cs in groups.items() if len(cs) > 1} | {"all": cats}
    out: dict[str, dict] = {}
    for pool, members in pools.items():
        figs = {}
        for m in methods:
            sel = [r for r in rows if r["method"] == m and r["category"] in members]
            if sel:
                figs[m] = {
                    "ssim": float(np.mean([r["ssim"] for r in sel])),
                    "rmse": float(np.mean([r["rmse"] for r in sel])),
                    "pairs": len(sel),
                }
        ref = figs.get("gtao")
        for fig in figs.values():
            if ref is not None:
                fig["ssim_ratio"] = fig["ssim"] / ref["ssim"]
                fig["rmse_ratio"] = fig["rmse"] / ref["rmse"]
        if figs:
            out[pool] = figs
    return out


def markdown(summary: dict, times: dict | None) -> str:
    lines = score_lines(summary) if summary else []
    if times:
        lines += [
            f"### GL time at {times['size'][0]}x{times['size'][1]} ({times['renderer']}), AO pass + blur",
            "",
            "| method | ms (median of rounds) | ratio to GTAO | rounds (ms) |",
            "|---|---:|---:|---|",
        ]
        for m, t in times["methods"].items():
            rounds = ", ".join(f"{1e3 * v:.0f}" for v in t["rounds"])
            lines.append(f"| {m} | {1e3 * t['median']:.1f} | {t['ratio']:.3f} | {rounds} |")
        lines.append("")
    return "\n".join(lines)


def score_lines(summary: dict) -> list[str]:
    pools = list(summary)
    methods = list(summary["all"])
    lines = [
        "### Ratio to plain GTAO, RMSE / SSIM (mean over (frame, radius) pairs, as evaluate averages)",
        "",
        "| method | " + " | ".join(pools) + " |",
        "|---|" + "---:|" * len(pools),
    ]
    for m in methods:
        cells = []
        for pool in pools:
            fig = summary[pool].get(m)
            cells.append(f"{fig['rmse_ratio']:.3f} / {fig['ssim_ratio']:.3f}" if fig else "")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    lines += ["", "Plain GTAO's own figures, RMSE / SSIM:", ""]
    lines.append(
        ", ".join(f"{p} {summary[p]['gtao']['rmse']:.4f} / {summary[p]['gtao']['ssim']:.4f}" for p in pools)
    )
    return lines + [""]


def time_methods(
    settings: dict[str, GTAOSettings], size: tuple[int, int], mesh: str, rounds: int, repeats: int, seed: int
) -> dict:
    """Median seconds per frame of each GTAO variant at ``size`` on an interior view of ``mesh``, in
    interleaved rounds (the order rotates each round)."""
    from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
    from neuralao.pipeline.geometry.camera import interior
    from neuralao.pipeline.geometry.scene import load_scene
    from neuralao.runtime import gl
    from neuralao.runtime.baselines import time_screen_space

    w, h = size
    scene = load_scene(mesh)
    radius = 0.25 * scene.diagonal
    with GBufferRenderer(scene) as r:
        frame = r.render(interior(scene, 1, w, h, seed=seed)[0])
    names = list(settings)
    per: dict[str, list[float]] = {m: [] for m in names}
    for k in range(rounds):
        for m in names[k % len(names) :] + names[: k % len(names)]:
            per[m].append(time_screen_space(frame, "gtao", radius, settings[m], repeats=repeats, warmup=1))
    med = {m: float(np.median(v)) for m, v in per.items()}
    return {
        "size": [w, h],
        "mesh": mesh,
        "renderer": gl.context().info.renderer,
        "foreground": float(np.mean(frame["mask"])),
        "methods": {m: {"median": med[m], "ratio": med[m] / med["gtao"], "rounds": per[m]} for m in names},
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--config", default="configs/eval.json", help="evaluation config (as neuralao evaluate)")
    p.add_argument("--frames", default="build/bench/error_bands/frames/256x256", type=Path)
    p.add_argument("--blends", nargs="*", type=float, default=[0.5, 0.8, 0.9, 0.95, 0.98])
    p.add_argument("--compensation", nargs="*", type=float, default=[0.35, 0.7])
    p.add_argument("--time-size", nargs=2, type=int, default=[1920, 1080], metavar=("W", "H"))
    p.add_argument("--time-only", action="store_true", help="skip the scoring")
    p.add_argument("--mesh", default="sponza_partial", help="scene of the timed frame")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--repeats", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="build/bench/gtao_thickness", type=Path)
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        return run(args)
    except NeuralaoError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1


def run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    full = load_settings(EvalSettings, args.config)
    settings = select_categories(full, None, False)
    kept = {c.name for c in settings.categories}
    gtao = variants(args.blends, args.compensation)
    for s in gtao.values():  # every setting checked before any work (the description checks it)
        gtao_pass_description(s)

    rows: list[dict] = []
    summary: dict = {}
    if not args.time_only:
        if not (args.frames / "manifest.json").is_file():
            raise NeuralaoError(f"no frames at {args.frames}: build them with bench/ao_error_bands.py first")
        methods = {m: screen_space_predictor("gtao", s) for m, s in gtao.items()}
        for frame in open_dataset(args.frames).frames(split="test"):
            category = category_of(frame["scene"], full)
            if category not in kept:  # held aside
                continue
            for row in score_frame(frame, methods, flip=False):
                rows.append(row | {"category": category, "scene": frame["scene"], "view": frame["view"]})
        if not rows:
            raise NeuralaoError("no (frame, radius) pair with valid foreground pixels")
        groups = _bands.camera_groups(settings)
        summary = summarise(rows, list(gtao), groups)
    times = None
    if all(v > 0 for v in args.time_size):
        # the cost does not depend on the blend or the stretch: plain GTAO and the last of each
        timed = ["gtao", *[m for m in gtao if m.startswith("gtao-t")][-1:]]
        timed += [m for m in gtao if m.startswith("gtao-c")][-1:]
        timed_settings = {m: gtao[m] for m in timed}
        times = time_methods(
            timed_settings, tuple(args.time_size), args.mesh, args.rounds, args.repeats, args.seed
        )
    text = markdown(summary, times)
    result = {
        "config": settings_to_dict(settings),
        "frames": str(args.frames),
        "settings": {m: settings_to_dict(s) for m, s in gtao.items()},
        "summary": summary,
        "times": times,
        "rows": rows,
        "seconds": time.perf_counter() - t_start,
    }
    write_json(args.out / "gtao_thickness.json", result)
    write_text(args.out / "gtao_thickness.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
