"""The shipped models in `neuralao report`: what ``runtime/models`` holds, as a summary and as plots.

Source: ``runtime/models/index.json`` (``pipeline/release/ship.py``: per model its kind, scale, widths, test
figures, GL times; ``baselines``: SSAO and GTAO on the same test split) and each model's
``manifest.json`` (``provenance``: budget, wall time, ``history`` = one record per epoch with
``wall_seconds`` and ``val_ssim``; ``config``: the training settings, ``train_fraction`` among them).
An index entry's own ``history`` / ``test`` are used when present, else the manifest's provenance.

Plots (PNG, each skipped, returning None, when its data is absent):

* ``learning_curves.png``: validation SSIM against wall-clock minutes, one curve per model with a
  history (the 30- and 90-minute budget runs are two of them);
* ``corpus_size.png``: test SSIM against the corpus size (training frames, else training scenes, else
  the fraction), one series per architecture + budget whose models differ in ``train_fraction``;
* ``shipped_front.png``: test RMSE against GL time of every shipped model and the SSAO / GTAO
  baselines of the index (the speed-error front of the release).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

from neuralao.pipeline.evaluation.categories import markdown as evaluation_markdown
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.shipped import read_index

log = logging.getLogger(__name__)

# Which GL time of the index the front plot uses (the first present).
FRONT_SIZES = ("512x512", "1920x1080")


def _read_json(path: Path) -> dict | None:
    try:
        data = read_json(path)
    except NeuralaoError:
        return None
    return data if isinstance(data, dict) else None


def corpus_size(manifest: dict, provenance: dict) -> tuple[float | None, str]:
    """(size, unit) of the corpus a model trained on: training frames, else training scenes, else the
    training fraction; (None, "") when none is recorded."""
    frames = provenance.get("train_frames") or (manifest.get("dataset") or {}).get("train_frames")
    if frames:
        return float(frames), "training frames"
    scenes = (manifest.get("metadata") or {}).get("training_scenes")
    if isinstance(scenes, list) and scenes:
        return float(len(scenes)), "training scenes"
    fraction = (manifest.get("config") or {}).get("train_fraction")
    if fraction is not None:
        return float(fraction), "fraction of the training scenes"
    return None, ""


def shipped_summary(models_dir: str | Path) -> dict:
    """What the report needs of a shipped-models folder.

    Returns {"folder": str, "models": {name: summary}, "baselines": {...}, "default": {...},
    "note": str | None}; ``note`` (one line) says why there is no model (no index, unreadable, empty).
    A model summary: kind, folder, scale, widths, bytes, epochs, wall_seconds, budget_minutes, init,
    train_fraction, corpus_size + corpus_unit, test {ssim, rmse, per_radius, ...}, gl_seconds,
    history [{epoch, wall_seconds, val_ssim, ...}].
    """
    folder = Path(models_dir)
    out: dict = {
        "folder": str(folder),
        "models": {},
        "baselines": {},
        "default": {},
        "fast": {},
        "note": None,
    }
    try:
        index = read_index(folder)
    except NeuralaoError as e:
        out["note"] = str(e)
        return out
    out["baselines"] = index.get("baselines") or {}
    out["default"] = index.get("default") or {}
    out["fast"] = index.get("fast") or {}  # per kind, the fast model's name (optional in index.json)
    for name, entry in index["models"].items():
        entry = entry if isinstance(entry, dict) else {}
        manifest = _read_json(folder / name / "manifest.json") or {}
        prov = manifest.get("provenance") or {}
        config = manifest.get("config") or {}
        meta = manifest.get("metadata") or {}
        size, unit = corpus_size(manifest, prov)
        out["models"][name] = {
            "kind": entry.get("kind") or manifest.get("kind"),
            "folder": str(folder / name),
            "manifest": bool(manifest),
            "scale": int(entry.get("scale") or meta.get("scale") or 1),
            "widths": entry.get("widths") or (meta.get("model_args") or {}).get("widths"),
            "bytes": entry.get("bytes"),
            "epochs": entry.get("epochs", prov.get("epochs")),
            "wall_seconds": entry.get("wall_seconds", prov.get("wall_seconds")),
            "budget_minutes": prov.get("budget_minutes", config.get("budget_minutes")),
            "init": entry.get("init", prov.get("init")),
            "train_fraction": config.get("train_fraction"),
            "corpus_size": size,
            "corpus_unit": unit,
            "test": entry.get("test") or prov.get("test") or {},
            "gl_seconds": entry.get("gl_seconds") or prov.get("gl_seconds") or {},
            "history": entry.get("history") or prov.get("history") or [],
            "evaluation": manifest.get(
                "evaluation"
            ),  # `neuralao evaluate --write-manifest`: by category x resolution
        }
    if not out["models"]:
        out["note"] = f"{folder / 'index.json'} lists no models"
    return out


# --------------------------------------------------------------------------- plots


def _pyplot():
    import matplotlib  # lazy: matplotlib + pyplot cost 0.6 s measured; only the plots need them

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _finite(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    _pyplot().close(fig)
    return path


def learning_curves_plot(shipped: dict, path: Path) -> Path | None:
    """Validation SSIM against wall-clock minutes, one curve per shipped model with a history."""
    curves = []
    for name, m in shipped.get("models", {}).items():
        pts = [
            (h["wall_seconds"] / 60.0, h["val_ssim"])
            for h in m.get("history") or []
            if _finite(h.get("wall_seconds")) and _finite(h.get("val_ssim"))
        ]
        if pts:
            curves.append((name, m, sorted(pts)))
    if not curves:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=110)
    for name, m, pts in curves:
        xs, ys = zip(*pts, strict=True)
        budget = m.get("budget_minutes")
        label = name + (f" (budget {budget:g} min)" if _finite(budget) and budget > 0 else "")
        ax.plot(xs, ys, marker="o" if len(pts) < 30 else None, ms=3, lw=1.4, label=label)
    ax.set_xlabel("wall-clock training time (minutes)")
    ax.set_ylabel("validation masked SSIM")
    ax.set_title("Shipped U-Nets: learning curves")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=7, loc="lower right")
    return _save(fig, path)


def corpus_size_series(shipped: dict) -> dict[str, list[tuple[float, float, str]]]:
    """Series label -> [(corpus size, test SSIM, model)] for models that share widths, scale and budget
    but differ in ``train_fraction`` (at least two sizes per series), ascending in size."""
    groups: dict[tuple, list] = {}
    for name, m in shipped.get("models", {}).items():
        ssim = (m.get("test") or {}).get("ssim")
        if m.get("train_fraction") is None or m.get("corpus_size") is None or not _finite(ssim):
            continue
        key = (tuple(m.get("widths") or ()), m.get("scale", 1), m.get("budget_minutes"), m.get("corpus_unit"))
        groups.setdefault(key, []).append((float(m["corpus_size"]), float(ssim), name, m["train_fraction"]))
    out = {}
    for (widths, scale, budget, unit), pts in groups.items():
        if len({p[3] for p in pts}) < 2:
            continue
        label = f"widths {'/'.join(map(str, widths)) or '?'}" + (f", 1/{scale} res" if scale != 1 else "")
        label += f", {budget:g} min" if _finite(budget) else ""
        out[f"{label} [{unit}]"] = sorted((p[0], p[1], p[2]) for p in pts)
    return out


def corpus_size_plot(shipped: dict, path: Path) -> Path | None:
    """Test SSIM against corpus size (:func:`corpus_size_series`), the baselines' test SSIM as lines."""
    series = corpus_size_series(shipped)
    if not series:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 4.5), dpi=110)
    units = set()
    for label, pts in series.items():
        xs, ys, names = zip(*pts, strict=True)
        units.add(label.rsplit("[", 1)[1].rstrip("]"))
        ax.plot(xs, ys, marker="o", lw=1.4, label=label.rsplit(" [", 1)[0])
        for x, y, n in pts:
            ax.annotate(n, (x, y), textcoords="offset points", xytext=(4, -10), fontsize=7)
    _baseline_lines(ax, shipped, "ssim")
    ax.set_xscale("log")
    _plain_log_ticks(ax, [p[0] for pts in series.values() for p in pts])
    ax.set_xlabel(f"corpus size ({', '.join(sorted(units))}, log)")
    ax.set_ylabel("test masked SSIM (meshes never trained on)")
    ax.set_title("Shipped U-Nets: test SSIM against corpus size")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=7, loc="lower right")
    return _save(fig, path)


def _plain_log_ticks(ax, at: list[float] | None = None) -> None:
    """Log x axis labelled in plain numbers: at ``at`` (the data), else at 1, 2, 5 x 10^k."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter  # lazy, as _pyplot

    ax.xaxis.set_major_locator(FixedLocator(sorted(set(at))) if at else LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())


def _baseline_lines(ax, shipped: dict, metric: str) -> None:
    for name, colour in (("ssao", "tab:blue"), ("gtao", "tab:green")):
        v = ((shipped.get("baselines") or {}).get(name) or {}).get("test", {}).get(metric)
        if _finite(v):
            ax.axhline(v, color=colour, lw=0.9, ls=":", label=f"{name} (test)")


def front_points(shipped: dict) -> tuple[str | None, list[tuple[str, float, float, bool]]]:
    """(size key, [(name, GL ms, test RMSE, is_baseline)]) at the first of FRONT_SIZES any model has."""
    rows = [(n, m, False) for n, m in shipped.get("models", {}).items()]
    rows += [(n, b, True) for n, b in (shipped.get("baselines") or {}).items()]
    for size in FRONT_SIZES:
        pts = []
        for name, m, base in rows:
            t, e = (m.get("gl_seconds") or {}).get(size), (m.get("test") or {}).get("rmse")
            if _finite(t) and t > 0 and _finite(e):
                pts.append((name, t * 1e3, e, base))
        if any(not p[3] for p in pts):
            return size, pts
    return None, []


def shipped_front_plot(shipped: dict, path: Path) -> Path | None:
    """Test RMSE against GL time of the shipped models and the baselines, the Pareto front dashed."""
    size, pts = front_points(shipped)
    if not pts:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 4.5), dpi=110)
    for name, t, e, base in pts:
        ax.scatter([t], [e], color="tab:blue" if base else "tab:red", marker="s" if base else "o", zorder=3)
        ax.annotate(name, (t, e), textcoords="offset points", xytext=(5, 4), fontsize=7)
    front = sorted(
        (t, e)
        for _, t, e, _ in pts
        if not any(t2 <= t and e2 <= e and (t2, e2) != (t, e) for _, t2, e2, _ in pts)
    )
    if len(front) > 1:
        xs, ys = zip(*front, strict=True)
        ax.step(xs, ys, where="post", color="k", lw=1, ls="--", label="Pareto front")
        ax.legend(fontsize=7)
    ax.set_xscale("log")
    _plain_log_ticks(ax)
    ax.set_xlabel(f"GL time per frame at {size} (ms, log; from index.json)")
    ax.set_ylabel("test RMSE (all radii)")
    ax.set_title("Shipped U-Nets and baselines: speed against error (test split)")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    return _save(fig, path)


def write_shipped_plots(shipped: dict | None, out: Path) -> dict[str, str]:
    """Every plot that has data, under ``out``: figure key -> file name."""
    if not shipped or not shipped.get("models"):
        return {}
    figures = {}
    for key, fn, name in (
        ("learning_curves", learning_curves_plot, "learning_curves.png"),
        ("corpus_size", corpus_size_plot, "corpus_size.png"),
        ("shipped_front", shipped_front_plot, "shipped_front.png"),
    ):
        path = fn(shipped, Path(out) / name)
        if path is not None:
            figures[key] = path.name
        else:
            log.info("%s: no data, skipped", name)
    return figures


# --------------------------------------------------------------------------- markdown


def _f(v, spec: str) -> str:
    return format(v, spec) if _finite(v) else "-"


def shipped_note(shipped: dict) -> str:
    """One line saying why no shipped model is reported."""
    note = (shipped.get("note") or "none listed").rstrip(".")
    return (
        note[0].upper() + note[1:] if note.startswith("no shipped model") else f"No shipped model: {note}"
    ) + "."


def shipped_markdown(shipped: dict | None, figures: dict) -> list[str]:
    """The report's "Shipped models" section (lines): one line when none is shipped."""
    if shipped is None:
        return []
    lines = ["", "## Shipped models (runtime/models)", ""]
    if not shipped.get("models"):
        return lines + [shipped_note(shipped)]
    default = shipped.get("default", {}).get("unet")
    lines += [
        f"From `{shipped['folder']}/index.json` (their own test split, every radius; `neuralao ship`). "
        "Rows `shipped:<name>` of the tables above are the same models on this report's frames."
        + (
            f" Not shown: {', '.join(shipped['not_shown'])} (`neuralao report --shipped all` adds them)."
            if shipped.get("not_shown")
            else ""
        ),
        "",
        "| model | scale | widths | budget (min) | epochs | train fraction | test SSIM | test RMSE | "
        "GL ms (512x512) | bytes |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, m in shipped["models"].items():
        test = m.get("test") or {}
        t = (m.get("gl_seconds") or {}).get("512x512")
        lines.append(
            f"| {name}{' (default)' if name == default else ''} | {m.get('scale', 1)} | "
            f"{'/'.join(map(str, m.get('widths') or [])) or '-'} | {_f(m.get('budget_minutes'), 'g')} | "
            f"{m.get('epochs') if m.get('epochs') is not None else '-'} | "
            f"{_f(m.get('train_fraction'), 'g')} | {_f(test.get('ssim'), '.4f')} | "
            f"{_f(test.get('rmse'), '.4f')} | {_f(t * 1e3 if _finite(t) else None, '.1f')} | "
            f"{m.get('bytes') if m.get('bytes') is not None else '-'} |"
        )
    for name, b in (shipped.get("baselines") or {}).items():
        test = b.get("test") or {}
        t = (b.get("gl_seconds") or {}).get("512x512")
        lines.append(
            f"| {name} (baseline) | - | - | - | - | - | {_f(test.get('ssim'), '.4f')} | "
            f"{_f(test.get('rmse'), '.4f')} | {_f(t * 1e3 if _finite(t) else None, '.1f')} | - |"
        )
    for name, m in shipped["models"].items():
        evaluation = m.get("evaluation")
        if evaluation and evaluation.get("methods"):
            lines += [
                "",
                f"### {name} where users run it (`neuralao evaluate`: test meshes by category and "
                "resolution)",
                "",
            ]
            lines += evaluation_markdown(evaluation["methods"], level=4).splitlines()
    captions = {
        "learning_curves": "learning curves (validation SSIM against wall-clock minutes)",
        "corpus_size": "test SSIM against corpus size",
        "shipped_front": "shipped models: test RMSE against GL time",
    }
    for key, caption in captions.items():
        if figures.get(key):
            lines += ["", f"![{caption}]({figures[key]})"]
        else:
            lines += ["", f"({caption}: no data in the index, not plotted)"]
    return lines
