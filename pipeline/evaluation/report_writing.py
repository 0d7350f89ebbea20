"""Writing `neuralao report`'s result: the tables of ``report.md`` (:func:`render_markdown`, with the
per-radius section), the speed-against-error scatter plot, the contact sheets, the selection section,
``report.json`` and ``report.html`` (:func:`write_report`); :func:`method_order` is the tables' row
order."""

from __future__ import annotations

import math
from pathlib import Path

from neuralao.pipeline.evaluation.figures import contact_sheet as readable_sheet
from neuralao.pipeline.evaluation.figures import write_html, write_viewer_pages
from neuralao.pipeline.evaluation.plots import shipped_markdown, write_shipped_plots
from neuralao.pipeline.evaluation.report_baselines import BASELINE_ORDER, family_colour, family_order
from neuralao.pipeline.evaluation.report_settings import SHIPPED_PREFIX, ReportSettings
from neuralao.pipeline.evaluation.report_truth import radius_key
from neuralao.pipeline.evaluation.selection import render_markdown as select_markdown
from neuralao.pipeline.evaluation.selection import render_targets_markdown as targets_markdown
from neuralao.pipeline.evaluation.selection import select_from_results
from neuralao.runtime import kinds
from neuralao.runtime.foundation.io import atomic_path, write_json, write_text


def method_order(methods: dict) -> list[str]:
    def key(n: str):
        e = methods[n]
        fam = family_order(e["family"])
        sub = BASELINE_ORDER.index(n) if n in BASELINE_ORDER else (e.get("bytes") or 0)
        if e["family"] == "traced":
            sub = int(n.split("-")[1])
        return (fam, sub, n)

    return sorted(methods, key=key)


def _fmt(v, spec: str, none: str = "-") -> str:
    return none if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def _bytes(v) -> str:
    if v is None:
        return "-"
    return f"{v / 1024:.1f} KiB" if v >= 1024 else f"{v} B"


def render_markdown(result: dict, selection: dict | None, figures: dict) -> str:
    ms = result["methods"]
    d = result["dataset"]
    w, h = result["settings"]["time_size"]
    lines = [
        "# neuralao report: speed against error",
        "",
        f"Dataset `{d['name']}` ({d['dataset_hash'][:12] if d.get('dataset_hash') else '?'}), "
        f"{sum(1 for f in result['frames'] if 'skipped' not in f)} held-back frames at "
        f"{d['size'][0]}x{d['size'][1]}; ground truth: {result['settings']['gt_rays']} rays, "
        f"kernel {d['labels']['kernel']}, max distance {d['labels']['max_distance_rel']} x scene diagonal. "
        f"Times: {w}x{h} frames, GL on {result['device']['gl_renderer']} "
        f"({result['device']['gl_platform']}); CPU: {result['device']['cpu']}.",
        "",
        f"| method | scope | frames | SSIM | RMSE | FLIP | ms / frame ({w}x{h}) | time / SSAO | "
        "RMSE / SSAO | (1-SSIM) / SSAO | bytes | timed on |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for n in method_order(ms):
        e = ms[n]
        if not e.get("available"):
            continue
        pareto = " *" if n in result.get("pareto", []) else ""
        lines.append(
            f"| {n}{pareto} | {e['scope']} | {e['frames']} | {_fmt(e['ssim'], '.3f')} | "
            f"{_fmt(e['rmse'], '.4f')} | {_fmt(e.get('flip'), '.4f')} | "
            f"{_fmt(e['seconds'] * 1e3 if e.get('seconds') is not None else None, '.2f')} | "
            f"{_fmt(e.get('time_ratio_vs_ssao'), '.2f')} | {_fmt(e.get('rmse_ratio_vs_ssao'), '.2f')} | "
            f"{_fmt(e.get('dssim_ratio_vs_ssao'), '.2f')} | {_bytes(e.get('bytes'))} | {e['time_on']} |"
        )
    lines += [
        "",
        "`*` on the Pareto front of (time, RMSE / SSAO). Ratios are over SSAO on the same frames "
        "(an MLP or a field is measured on its own scene only). FLIP: NVIDIA's perceptual error "
        "(flip-evaluator, LDR, 67 pixels per degree; 0 = identical), AO shown as grey with the "
        "background set to 1 in both images, averaged over the foreground.",
    ]
    one_sided = [n for n in method_order(ms) if ms[n].get("available") and ms[n].get("two_sided") is False]
    if one_sided:
        lines += [
            "",
            "Single-sided surfaces: " + ", ".join(one_sided) + " store one value per vertex and so show "
            "the same AO on both sides of an open sheet (the G-buffer turns the normal towards the viewer); "
            "the fields, MLPs, U-Nets, screen-space and traced methods can tell the sides apart.",
        ]
    ort = [(n, ms[n]["seconds_onnxruntime"]) for n in method_order(ms) if ms[n].get("seconds_onnxruntime")]
    if ort:
        lines += [
            "",
            f"onnxruntime (CPU) at {w}x{h}: " + ", ".join(f"{n} {t * 1e3:.1f} ms" for n, t in ort) + ".",
        ]
    missing = [n for n in method_order(ms) if not ms[n].get("available")]
    if missing:
        lines += ["", "Not available:", ""] + [
            f"- {n}: {ms[n].get('reason') or 'not available'}" for n in missing
        ]
    lines += ["", "## Per scene (SSIM / RMSE)", ""]
    scenes = [s for s, info in result["scenes"].items() if "skipped" not in info]
    avail = [n for n in method_order(ms) if ms[n].get("available")]
    lines += ["| method | " + " | ".join(scenes) + " |", "|---|" + "---:|" * len(scenes)]
    for n in avail:
        cells = []
        for s in scenes:
            ps = ms[n].get("per_scene", {}).get(s)
            cells.append(f"{ps['ssim']:.3f} / {ps['rmse']:.3f}" if ps else "")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    skipped = {s: i["skipped"] for s, i in result["scenes"].items() if "skipped" in i}
    if skipped:
        lines += [""] + [f"- scene {s} skipped: {why}" for s, why in skipped.items()]
    lines += radius_markdown(result)
    lines += shipped_markdown(result.get("shipped"), figures)
    if figures:
        lines += ["", "## Figures", ""]
        if figures.get("scatter"):
            lines += [f"![speed vs error]({figures['scatter']})", ""]
        for s, p in figures.get("contact_sheets", {}).items():
            lines += [f"![{s}]({p})", ""]
        if figures.get("viewer"):
            lines += [
                "WebGL2 viewer pages (`neuralao view`; also linked from report.html): "
                + ", ".join(f"[{s}]({p})" for s, p in figures["viewer"].items()),
                "",
            ]
    if selection is not None:
        lines += ["", select_markdown(selection, heading="## Model selection")]
    if result.get("select_at"):
        lines += ["", targets_markdown({float(t): sel for t, sel in result["select_at"].items()})]
    lines += [
        "",
        "## How this was measured",
        "",
        "- Error: masked SSIM (Gaussian window 11, sigma 1.5) and RMSE over foreground pixels with valid "
        "ground truth, mean over frames. SSAO, GTAO and the MLP: their GLSL on the frames' G-buffers; "
        "U-Net: onnxruntime (its generated GLSL matches it within the parity tolerance); "
        "vertex AO: barycentric interpolation of the baked values (what the vertex-colour draw shows); "
        "traced: Embree.",
        "- Time: median seconds per frame at the stated size, G-buffer resident; "
        "GL methods with glFinish around each frame in this process's headless context; traced AO: "
        "wall time of the CPU trace; the U-Net's GL time covers all generated compute passes. "
        "A method's time is the median over scenes.",
        "- Bytes: float32 weights for the networks, 4 bytes per vertex for baked AO, "
        "shader constants for SSAO/GTAO.",
    ]
    return "\n".join(lines) + "\n"


def radius_markdown(result: dict) -> list[str]:
    """The per-radius section: every method of a radius family at each radius of ``radii_rel``."""
    ms = result["methods"]
    keys = [radius_key(r) for r in result.get("radii_rel") or []]
    rows = [n for n in method_order(ms) if ms[n].get("available") and ms[n].get("per_radius")]
    labels = result["dataset"]["labels"]
    main = (
        f"r = {labels['max_distance_rel']:g}"
        if labels.get("max_distance") is None
        else f"{labels['max_distance']:g} scene units"
    )
    if not keys or not rows:
        return ["", f"Per-radius evaluation: none (only the labels' max distance, {main})."]
    lines = [
        "",
        "## Per radius (SSAO, GTAO and the U-Nets given the same radius)",
        "",
        "Radius r as a fraction of each scene's diagonal; ground truth at every radius from one "
        f"{result['settings']['gt_rays']}-ray trace. The tables above are at the labels' max distance "
        f"({main}); the vertex bakes, MLPs, fields and traced rows have that radius baked in. Cells: "
        "SSIM / RMSE (RMSE / SSAO's RMSE at the same radius).",
        "",
        "| method | " + " | ".join(f"r = {k}" for k in keys) + " |",
        "|---|" + "---:|" * len(keys),
    ]
    for n in rows:
        cells = []
        for k in keys:
            e = ms[n]["per_radius"].get(k)
            ratio = (
                f" ({e['rmse_ratio_vs_ssao']:.2f}x)" if e and e.get("rmse_ratio_vs_ssao") is not None else ""
            )
            cells.append(f"{e['ssim']:.3f} / {e['rmse']:.4f}{ratio}" if e else "-")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return lines


def scatter_plot(result: dict, path: Path) -> Path | None:
    """Speed (ms, log) against RMSE relative to SSAO, with the Pareto front."""
    import matplotlib  # imported here: a measured import-time cost (~0.5 s), for this plot only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    ms = result["methods"]
    pts = [
        (n, ms[n]["seconds"] * 1e3, ms[n]["rmse_ratio_vs_ssao"], ms[n]["family"])
        for n in method_order(ms)
        if ms[n].get("available") and ms[n].get("seconds") and ms[n].get("rmse_ratio_vs_ssao") is not None
    ]
    if not pts:
        return None
    fig, ax = plt.subplots(figsize=(7.5, 5.0), dpi=110)
    for n, t, r, fam in pts:
        on = n in result.get("pareto", [])
        ax.scatter(
            [t],
            [r],
            s=60 if on else 36,
            color=family_colour(fam),
            edgecolors="k" if on else "none",
            zorder=3,
        )
        ax.annotate(n, (t, r), textcoords="offset points", xytext=(5, 4), fontsize=8)
    front = [(ms[n]["seconds"] * 1e3, ms[n]["rmse_ratio_vs_ssao"]) for n in result.get("pareto", [])]
    if len(front) > 1:
        xs, ys = zip(*sorted(front), strict=True)
        ax.step(xs, ys, where="post", color="k", lw=1, ls="--", zorder=2, label="Pareto front")
        ax.legend(loc="upper right", fontsize=8)
    ax.axhline(1.0, color="tab:blue", lw=0.6, ls=":")
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    w, h = result["settings"]["time_size"]
    ax.set_xlabel(
        f"time per frame at {w}x{h} (ms, log; GL on {result['device']['gl_renderer'][:40]}, traced on CPU)"
    )
    ax.set_ylabel("RMSE / SSAO's RMSE (same frames)")
    ax.set_title("AO methods: speed against error")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


def contact_order(result: dict, wanted: list[str]) -> list[str]:
    """The methods of a contact sheet: ``wanted`` (ReportSettings.contact_methods) resolved against the
    report's rows: ``shipped:default`` / ``shipped:fast`` to the shipped rows of those roles, ``field`` /
    ``mlp`` to the smallest row of that family; names not in the report are left out. Empty: every row."""
    ms = result["methods"]
    roles = (result.get("shipped") or {}).get("roles") or {}
    order: list[str] = []
    for name in wanted:
        role = name[len(SHIPPED_PREFIX) :] if name.startswith(SHIPPED_PREFIX) else None
        if role in ("default", "fast"):
            name = SHIPPED_PREFIX + roles.get(role, "")
        elif name in kinds.reported() and name not in ms:
            rows = sorted((ms[n].get("bytes") or 0, n) for n in ms if ms[n].get("family") == name)
            name = rows[0][1] if rows else name
        if name in ms and ms[name].get("available", True) and name not in order:
            order.append(name)
    return order or method_order(ms)


def contact_sheet(scene: str, sheet: dict, order: list[str], path: Path) -> Path:
    """The scene's contact sheet (:func:`neuralao.pipeline.evaluation.figures.contact_sheet`)."""
    return readable_sheet(scene, sheet, order, path)


def write_report(result: dict, out: Path, settings: ReportSettings) -> dict:
    """Figures, the selection section, report.json and report.md (written last) under ``out``."""
    sheets = result.pop("_sheets", {})
    figures: dict = {"contact_sheets": {}}
    scatter = scatter_plot(result, out / "speed_vs_error.png")
    if scatter is not None:
        figures["scatter"] = scatter.name
    figures.update(write_shipped_plots(result.get("shipped"), out))
    if settings.contact_sheets:
        order = contact_order(result, settings.contact_methods)
        for scene, sheet in sheets.items():
            figures["contact_sheets"][scene] = contact_sheet(
                scene, sheet, order, out / f"contact_{scene}.png"
            ).name
    selection = select_from_results(result, settings.target_ssim)
    result["select"] = selection
    result["select_at"] = {
        str(t): select_from_results(result, t) for t in sorted(set(settings.select_targets))
    }
    viewer_links = write_viewer_pages(sheets, out) if settings.viewer_pages else {}
    figures["viewer"] = viewer_links
    result["figures"] = figures
    write_json(out / "report.json", result)
    write_html(result, out, figures, viewer_links)
    write_text(out / "report.md", render_markdown(result, selection, figures))
    return result
