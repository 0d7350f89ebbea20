"""Readable report figures: contact sheets cropped to the object, a handful of methods side by side, a
zoomed error inset.

A sheet (:func:`contact_sheet`) has a first column with the ground truth, the pixels whose ground truth is
invalid, and the colour scale, then one column per method: its AO, ``|AO - ground truth|`` as a heat map
with the worst window outlined, and that window magnified (ground truth left, method right,
nearest-neighbour, so every pixel stays a pixel). The report picks the methods
(``ReportSettings.contact_methods``). Every panel is cropped to the bounding box of the object (the foreground
mask plus a small margin), which at 128x128 orbit views is often a third of the frame or less.
"""

from __future__ import annotations

import html
import logging
from pathlib import Path

import numpy as np
from scipy.ndimage import uniform_filter

from neuralao.pipeline.bakes.viewer_inputs import method_from_export
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path, write_text
from neuralao.runtime.viewer import ViewerMethod, corner_arrays, write_page

CROP_MARGIN = 3  # pixels kept around the foreground's bounding box
ERROR_VMAX = 0.3  # top of the |error| colour scale (AO units)


def crop_box(fg: np.ndarray, margin: int = CROP_MARGIN) -> tuple[slice, slice]:
    """Rows and columns of the foreground's bounding box grown by ``margin`` (the whole image if empty)."""
    rows, cols = np.flatnonzero(fg.any(axis=1)), np.flatnonzero(fg.any(axis=0))
    if len(rows) == 0:
        return slice(0, fg.shape[0]), slice(0, fg.shape[1])
    r0, r1 = max(rows[0] - margin, 0), min(rows[-1] + 1 + margin, fg.shape[0])
    c0, c1 = max(cols[0] - margin, 0), min(cols[-1] + 1 + margin, fg.shape[1])
    return slice(r0, r1), slice(c0, c1)


def worst_window(error: np.ndarray, valid: np.ndarray, size: int) -> tuple[int, int]:
    """Top-left (row, col) of the ``size`` x ``size`` window with the largest mean error over valid pixels."""
    h, w = error.shape
    size = max(1, min(size, h, w))
    e = uniform_filter(np.where(valid, error, 0.0), size=size, mode="constant")
    half = size // 2
    inner = e[half : h - (size - 1 - half), half : w - (size - 1 - half)]  # windows fully inside
    r, c = np.unravel_index(int(np.argmax(inner)), inner.shape)
    return int(r), int(c)


def contact_sheet(scene: str, sheet: dict, order: list[str], path: Path) -> Path:
    """The module doc's sheet for one view: sheet = {"gt", "mask", "fg", "view", "images": {name: (H, W)}}.

    Methods side by side: a column each (ground truth first), three rows: the AO, ``|AO - GT|`` with
    the worst window outlined, and that window magnified (the ground truth's column shows it for the
    first method's window; each method's column its own window, GT | method)."""
    import matplotlib  # lazy: matplotlib + pyplot cost 0.55 s measured; only the contact sheets need them

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    names = [n for n in order if n in sheet["images"]]
    rs, cs = crop_box(sheet["fg"])
    fg, mask, gt = sheet["fg"][rs, cs], sheet["mask"][rs, cs], sheet["gt"][rs, cs]
    h, w = fg.shape
    win = max(8, min(h, w) // 4)
    cols = 1 + len(names)
    panel = 1.9
    fig, axes = plt.subplots(3, cols, figsize=(cols * panel, 3 * panel + 0.5), dpi=100, squeeze=False)
    bg = 0.5
    axes[0, 0].imshow(np.where(fg, gt, bg), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    axes[0, 0].set_title("ground truth", fontsize=9)
    axes[1, 0].imshow(
        np.where(fg & ~mask, 1.0, np.where(fg, 0.6, 0.2)),
        cmap="gray",
        vmin=0,
        vmax=1,
        interpolation="nearest",
    )
    axes[1, 0].set_xlabel("invalid GT (white)", fontsize=8)
    axes[2, 0].imshow(
        np.linspace(0, ERROR_VMAX, 256)[:, None][::-1],
        cmap="magma",
        aspect="auto",
        extent=(0, 1, 0, ERROR_VMAX),
    )
    axes[2, 0].set_xlabel(f"|error| scale, 0-{ERROR_VMAX:g}", fontsize=8)
    axes[2, 0].tick_params(labelsize=7)
    for k, n in enumerate(names, start=1):
        pred = sheet["images"][n][rs, cs]
        err = np.abs(pred - gt)
        rmse = float(np.sqrt(np.mean(err[mask] ** 2))) if mask.any() else float("nan")
        axes[0, k].imshow(np.where(fg, pred, bg), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        axes[0, k].set_title(f"{n}\nRMSE {rmse:.3f}", fontsize=9)
        axes[1, k].imshow(
            np.ma.masked_array(err, mask=~mask),
            cmap="magma",
            vmin=0,
            vmax=ERROR_VMAX,
            interpolation="nearest",
        )
        r, c = worst_window(err, mask, win)
        axes[1, k].add_patch(Rectangle((c - 0.5, r - 0.5), win, win, fill=False, edgecolor="#39d0ff", lw=1.0))
        zoom_gt = np.where(fg, gt, bg)[r : r + win, c : c + win]
        zoom_pred = np.where(fg, pred, bg)[r : r + win, c : c + win]
        gap = np.full((zoom_gt.shape[0], 1), 1.0)
        axes[2, k].imshow(
            np.concatenate([zoom_gt, gap, zoom_pred], axis=1),
            cmap="gray",
            vmin=0,
            vmax=1,
            interpolation="nearest",
        )
        axes[2, k].set_xlabel("worst window: GT | method", fontsize=8)
    for ax in axes.ravel():
        ax.set_xticks([])
        if ax is not axes[2, 0]:
            ax.set_yticks([])
    fig.suptitle(f"{scene}, view {sheet['view']} (cropped to the object)", fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


# --------------------------------------------------------------------------- viewer pages and HTML


def write_viewer_pages(sheets: dict, out: Path) -> dict[str, str]:
    """One `neuralao view` page per scene of the sheets: the report's least-squares vertex bake and the
    scene's MLP / field exports (their ES 3.00 shaders). Returns scene -> relative index.html path.
    A page that cannot be built is left out with a warning (it must not sink the report)."""
    log = logging.getLogger(__name__)
    links = {}
    for scene, sheet in sheets.items():
        obj = sheet.get("scene")
        if obj is None:
            continue
        try:
            methods = []
            bake = sheet.get("bakes", {}).get("vertex-lsq")
            if bake is not None:
                pos, nrm = corner_arrays(obj.vertices, obj.faces)
                ao = np.asarray(bake, np.float32)[obj.faces].reshape(-1)
                methods.append(ViewerMethod("vertex-lsq (report bake)", "vertex", pos, nrm, ao=ao))
            for name, folder in sorted(sheet.get("exports", {}).items()):
                m = method_from_export(Path(folder), obj.source or None)
                m.name = f"{name} ES 3.00 shader"
                methods.append(m)
            if methods:
                page = write_page(methods, out / "viewer" / scene)
                links[scene] = str(page.relative_to(out))
        except (NeuralaoError, OSError) as e:
            log.warning("viewer page of %s left out: %s", scene, e)
    return links


def write_html(result: dict, out: Path, figures: dict, viewer_links: dict[str, str]) -> Path:
    """report.html: the main table, the figures and links to the viewer pages (report.md has the full
    text)."""
    ms = result["methods"]
    esc = html.escape
    fmt = lambda v, spec: "-" if v is None else format(v, spec)  # noqa: E731
    rows = []
    for n, e in ms.items():
        if not e.get("available"):
            continue
        ms_frame = None if e.get("seconds") is None else e["seconds"] * 1e3
        rows.append(
            f"<tr><td>{esc(n)}</td><td>{esc(str(e.get('scope', '')))}</td><td>{e.get('frames', '')}</td>"
            f"<td>{fmt(e.get('ssim'), '.3f')}</td><td>{fmt(e.get('rmse'), '.4f')}</td>"
            f"<td>{fmt(e.get('flip'), '.4f')}</td>"
            f"<td>{fmt(ms_frame, '.2f')}</td><td>{fmt(e.get('bytes'), 'd')}</td></tr>"
        )
    w, h = result["settings"]["time_size"]
    figs = []
    if figures.get("scatter"):
        figs.append(f'<h2>Speed against error</h2><img src="{esc(figures["scatter"])}" alt="speed vs error">')
    for scene, p in figures.get("contact_sheets", {}).items():
        link = viewer_links.get(scene)
        viewer = f' &middot; <a href="{esc(link)}">open {esc(scene)} in the viewer</a>' if link else ""
        figs.append(f'<h3>{esc(scene)}{viewer}</h3><img src="{esc(p)}" alt="{esc(scene)} contact sheet">')
    pages = "".join(f'<li><a href="{esc(p)}">{esc(s)}</a></li>' for s, p in viewer_links.items())
    text = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>neuralao report</title>
<style>body{{font:14px/1.45 system-ui,sans-serif;margin:2em;max-width:1200px}}\
table{{border-collapse:collapse}}
td,th{{padding:3px 8px;border-bottom:1px solid #ddd;text-align:right}}\
td:first-child,th:first-child,td:nth-child(2){{text-align:left}}
img{{max-width:100%}}</style></head><body>
<h1>neuralao report: speed against error</h1>
<p>Dataset <code>{esc(str(result["dataset"].get("name")))}</code>; the full text, selection and notes are in
<a href="report.md">report.md</a>, the numbers in <a href="report.json">report.json</a>. Masked SSIM, RMSE and
NVIDIA FLIP over foreground pixels with valid ground truth, mean over frames; time per {w}x{h} frame.</p>
<table><tr><th>method</th><th>scope</th><th>frames</th><th>SSIM</th><th>RMSE</th><th>FLIP</th>\
<th>ms / frame</th><th>bytes</th></tr>
{"".join(rows)}</table>
{"<h2>Viewer</h2><ul>" + pages + "</ul>" if pages else ""}
{"".join(figs)}
</body></html>
"""
    write_text(out / "report.html", text)
    return out / "report.html"
