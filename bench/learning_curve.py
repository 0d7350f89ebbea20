"""Learning curves of the screen-space U-Net: quality against training time, corpus size, crops and width.

    .venv/bin/python bench/learning_curve.py --config configs/curve.json --out build/curve \
        [--only main corpus-half] [--report-only] [--results docs/results.md]

Each run of the config trains one model (the config's ``base`` settings, the run's ``train`` overrides)
for ``hours`` CPU-hours (wall-clock hours times the run's ``threads``) at a constant learning rate after
warm-up, and keeps a snapshot of the
weights when the run's plan reaches each of ``points_hours``: the curve's points come from one run, as
a longer run passes through them (the release run then anneals over the budget the curve chooses).
The plan (epochs for the budget) is measured once when the run starts and stored in its checkpoint,
so a run killed midway resumes from its last epoch and keeps the same snapshots: rerun the command. A
run with ``steps_per_hour`` is not measured: it takes ``hours`` x that many optimiser steps (whole epochs),
the same on any machine (the rate of the runs it is compared with, so its points sit at their steps).

At each point: the validation split's SSIM and RMSE (from the training run) and the evaluation
categories (``eval`` in the config, the same frames for every point) against GTAO and SSAO at every
radius. The held-aside meshes are not in it: they stay out of every choice until the final score.

Writes BUILD/<run>/ (checkpoints, snapshots, light exports), BUILD/curve.json (every figure) and
BUILD/curve.md, the plot BUILD/learning_curve.png, and with ``--results`` replaces the section between
the learning-curve markers of that markdown file (copying the plot beside it, and every point's figures
as learning_curve.json: points measured earlier and not trained again, ``--only``, or another machine's,
are kept from that file).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import shutil
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

from neuralao.export.unet import export_onnx, load_model, onnx_metadata  # noqa: E402
from neuralao.pipeline.evaluation.categories import EvalSettings, evaluate  # noqa: E402
from neuralao.pipeline.models.checkpoint import save_checkpoint  # noqa: E402
from neuralao.pipeline.models.unet_frames import load_dataset_frames  # noqa: E402
from neuralao.pipeline.models.unet_train import UNetTrainSettings, epoch_steps, train  # noqa: E402
from neuralao.runtime.foundation.errors import NeuralaoError  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402
from neuralao.runtime.foundation.manifest import read_json  # noqa: E402
from neuralao.runtime.foundation.settings import from_dict  # noqa: E402

log = logging.getLogger("learning_curve")

BEGIN, END = "<!-- learning-curve:begin -->", "<!-- learning-curve:end -->"
KEPT = "learning_curve.json"  # every point's figures, beside the results file the report rewrites


def point_name(hours: float) -> str:
    return f"{hours:g}h"


def snapshot_epochs(plan_epochs: int, hours: float, points: list[float]) -> dict[int, float]:
    """Epoch -> point (hours) for every point within a run of ``hours``: the last epoch the plan reaches
    by that share of the budget (at least 1). Fixed by the stored plan, so a resumed run keeps them."""
    return {max(1, int(plan_epochs * p / hours)): p for p in points if p <= hours}


def train_run(cfg: dict, run: dict, out: Path, cache: dict) -> Path:
    """Train (or resume) one run; its snapshots land in ``out / run / <point>.pt``. Returns the run folder."""
    folder = out / run["name"]
    folder.mkdir(parents=True, exist_ok=True)
    merged = cfg["base"] | run.get("train", {})
    threads = max(1, int(merged.get("threads", 1)))
    merged["budget_minutes"] = 60.0 * float(run["hours"]) / threads  # CPU-hours over the run's threads
    settings = from_dict(UNetTrainSettings, merged, prefix=f"runs.{run['name']}.train.")
    points = [float(p) for p in cfg["points_hours"]]
    done = folder / "model.pt"
    if done.exists() and all((folder / f"{point_name(p)}.pt").exists() for p in points if p <= run["hours"]):
        return folder
    key = (
        settings.internal_height,
        settings.gtao_input,
        settings.preprocess_version,
        settings.gtao_blur,
        settings.gtao_raw_input,
    )
    if cache.get("key") != key:
        cache.clear()
        cache.update(
            key=key,
            sets=load_dataset_frames(
                Path(cfg["dataset"]),
                internal_height=key[0],
                gtao=key[1],
                version=key[2],
                gtao_blur=key[3],
                gtao_raw=key[4],
            ),
        )
    sets = cache["sets"]
    if settings.train_fraction != 1.0:
        sets = load_dataset_frames(
            Path(cfg["dataset"]),
            settings.train_fraction,
            loaded=cache["sets"],
            internal_height=key[0],
            gtao=key[1],
            version=key[2],
            gtao_blur=key[3],
            gtao_raw=key[4],
        )
    train_set, val_set, info = sets
    if "steps_per_hour" in run:  # a fixed step count per CPU-hour: the same points on any machine
        rate = run["steps_per_hour"]
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0 < rate < 1e9:
            raise NeuralaoError(f"runs.{run['name']}.steps_per_hour must be a positive number, got {rate!r}")
        per_epoch = epoch_steps(settings, len(train_set))
        epochs = max(1, round(float(run["hours"]) * float(rate) / per_epoch))
        settings = dataclasses.replace(settings, budget_minutes=0.0, epochs=epochs)

    def keep_snapshot(epoch: int, ckpt: dict) -> None:
        at = snapshot_epochs(int(ckpt["plan"]["epochs"]), float(run["hours"]), points)
        if epoch in at:
            save_checkpoint(folder / f"{point_name(at[epoch])}.pt", dict(ckpt, complete=True))

    log.info("%s: %d training frames, %s h", run["name"], len(train_set), run["hours"])
    train(settings, train_set, val_set, done, info, on_epoch_end=keep_snapshot)
    return folder


def light_export(model, ckpt: dict, out: Path) -> Path:
    """model.onnx and a manifest of a snapshot: what `neuralao evaluate` reads (no GLSL, no parity)."""
    if (out / "manifest.json").exists():
        return out
    meta = onnx_metadata(model, ckpt)
    out.mkdir(parents=True, exist_ok=True)
    export_onnx(model, out / "model.onnx", meta)
    internal = (ckpt.get("dataset") or {}).get("internal_height") or None
    write_json(
        out / "manifest.json",
        {"kind": "unet", "onnx": "model.onnx", "metadata": meta, "internal_height": internal},
    )
    return out


def score_point(cfg: dict, run: dict, folder: Path, hours: float, out: Path) -> dict:
    """The figures of one point: validation (from the snapshot) and the evaluation categories."""
    path = folder / f"{point_name(hours)}.json"
    if path.exists():
        return read_json(path)
    model, ckpt = load_model(folder / f"{point_name(hours)}.pt")
    export = light_export(model, ckpt, folder / point_name(hours))
    settings = from_dict(EvalSettings, cfg["eval"], prefix="eval.")
    result = evaluate(settings, out / "eval", [export], ["model"], ROOT, flip=False, progress=False)
    record = {
        "run": run["name"],
        "hours": hours,
        "epoch": int(ckpt["epoch"]),
        "steps": int(ckpt["epoch"]) * int(ckpt["plan"]["steps_per_epoch"]),
        "wall_seconds": float(ckpt.get("wall_seconds", 0.0)),
        "val_ssim": (ckpt.get("metrics") or {}).get("val_ssim"),
        "val_rmse": (ckpt.get("metrics") or {}).get("val_rmse"),
        "categories": {
            m: result["methods"][name]["cells"]
            for m, name in (("model", export.name), ("gtao", "gtao"), ("ssao", "ssao"))
            if name in result["methods"]
        },
    }
    write_json(path, record)
    return record


def ratio_to_gtao(record: dict, metric: str) -> dict[str, float]:
    """category -> the model's mean ``metric`` over resolutions divided by GTAO's (a kept record whose
    cells were not kept carries the ratios themselves, ``<metric>_to_gtao``)."""
    if f"{metric}_to_gtao" in record:
        return dict(record[f"{metric}_to_gtao"])
    cats = record.get("categories", {})
    out = {}
    for cat, cells in cats.get("model", {}).items():
        ref = cats.get("gtao", {}).get(cat, {})
        mine = [c[metric] for r, c in cells.items() if r in ref]
        theirs = [ref[r][metric] for r in cells if r in ref]
        if mine and theirs and sum(theirs):
            out[cat] = (sum(mine) / len(mine)) / (sum(theirs) / len(theirs))
    return out


def markdown(records: list[dict], cfg: dict, machine: str) -> str:
    cats = sorted({c for r in records for c in ratio_to_gtao(r, "rmse")})
    head = (
        "| run | CPU-hours | steps | val SSIM | val RMSE | "
        + " | ".join(f"{c} RMSE / GTAO" for c in cats)
        + " |"
    )
    lines = [
        f"Measured on {machine} by `bench/learning_curve.py --config configs/curve.json`; "
        "each run at a constant learning rate after warm-up, snapshots on the way; categories at "
        + ", ".join(f"{w}x{h}" for w, h in (r["size"] for r in cfg["eval"]["resolutions"]))
        + " over every radius (RMSE below 1 beats GTAO).",
        "",
        head,
        "|" + "---|" * (5 + len(cats)),
    ]
    for r in sorted(records, key=lambda r: (r["run"] != "main", r["run"], r["hours"])):
        ratios = ratio_to_gtao(r, "rmse")
        cells = " | ".join(f"{ratios[c]:.3f}" if c in ratios else "-" for c in cats)
        ssim = "-" if r["val_ssim"] is None else f"{r['val_ssim']:.4f}"
        rmse = "-" if r["val_rmse"] is None else f"{r['val_rmse']:.4f}"
        steps = "-" if r.get("steps") is None else str(r["steps"])
        lines.append(f"| {r['run']} | {r['hours']:g} | {steps} | {ssim} | {rmse} | {cells} |")
    return "\n".join(lines) + "\n"


def plot(records: list[dict], path: Path) -> None:
    import matplotlib  # only the report needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    common = set.intersection(*(set(ratio_to_gtao(r, "rmse")) for r in records))  # every point has them
    for run in sorted({r["run"] for r in records}):
        pts = sorted((r for r in records if r["run"] == run), key=lambda r: r["hours"])
        if not pts:
            continue
        hours = [p["hours"] for p in pts]
        val = [p for p in pts if p["val_rmse"] is not None]
        axes[0].plot([p["hours"] for p in val], [p["val_rmse"] for p in val], marker="o", label=run)
        means = [sum(ratio_to_gtao(p, "rmse")[c] for c in common) / max(1, len(common)) for p in pts]
        axes[1].plot(hours, means, marker="o", label=run)
    right = f"RMSE / GTAO's, mean of {', '.join(sorted(common))}"
    for ax, title in zip(axes, ("validation RMSE", right), strict=True):
        ax.set_xscale("log", base=2)
        ax.set_xlabel("training CPU-hours (wall clock x threads)")
        ax.set_title(title)
        ax.grid(True, alpha=0.3)
    axes[1].axhline(1.0, color="k", lw=0.8)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


def merge_kept(records: list[dict], kept_path: Path) -> list[dict]:
    """The records measured now, and every point of ``kept_path`` (the records a report committed beside
    the results) that was not measured now: a run trained on another machine, or whose folder is gone,
    stays in the curve until it is trained again."""
    now = {(r["run"], float(r["hours"])) for r in records}
    kept = read_json(kept_path, "kept learning-curve records")["records"] if kept_path.exists() else []
    return records + [r for r in kept if (r["run"], float(r["hours"])) not in now]


def write_results(md: str, png: Path, results: Path) -> None:
    """Replace the learning-curve section of ``results`` (between the markers) and copy the plot beside it."""
    text = results.read_text()
    if BEGIN not in text or END not in text:
        raise NeuralaoError(f"{results} has no {BEGIN} ... {END} section")
    shutil.copy2(png, results.parent / png.name)
    section = f"{BEGIN}\n{md}\n![learning curves]({png.name})\n{END}"
    write_text(results, text[: text.index(BEGIN)] + section + text[text.index(END) + len(END) :])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", default=str(ROOT / "configs" / "curve.json"))
    p.add_argument("--out", default=str(ROOT / "build" / "curve"))
    p.add_argument("--only", nargs="*", help="runs to train and score (default: every run)")
    p.add_argument("--report-only", action="store_true", help="score and report what has finished")
    p.add_argument("--results", help="markdown file whose learning-curve section to replace")
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        cfg = read_json(args.config, "curve config")
        out = Path(args.out)
        runs = [r for r in cfg["runs"] if not args.only or r["name"] in args.only]
        cache: dict = {}
        records = []
        for run in runs:
            folder = out / run["name"]
            if not args.report_only:
                t0 = time.perf_counter()
                folder = train_run(cfg, run, out, cache)
                log.info("%s trained in %.0f s", run["name"], time.perf_counter() - t0)
            for hours in cfg["points_hours"]:
                if hours <= run["hours"] and (folder / f"{point_name(hours)}.pt").exists():
                    records.append(score_point(cfg, run, folder, float(hours), out))
        kept = Path(args.results).parent / KEPT if args.results else None
        shown = merge_kept(records, kept) if kept is not None else records
        if not shown:
            raise NeuralaoError(f"no point of any run has finished under {out}")
        machine = cpu_name()
        md = markdown(shown, cfg, machine)
        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "curve.json", {"config": cfg, "machine": machine, "records": records})
        write_text(out / "curve.md", md)
        plot(shown, out / "learning_curve.png")
        if args.results:
            write_results(md, out / "learning_curve.png", Path(args.results))
            write_json(kept, {"config": cfg, "records": shown})
        print(md)
        return 0
    except NeuralaoError as e:
        print(f"learning_curve: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
