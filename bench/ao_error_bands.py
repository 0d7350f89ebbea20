"""Where screen-space AO's error against ray-traced ground truth sits: by distance to the nearest edge.

    PYOPENGL_PLATFORM=osmesa .venv/bin/python bench/ao_error_bands.py --config configs/eval.json \
        [--size 256 256] [--models runtime/models/unet-gtao runtime/models/unet-fast] \
        [--categories scans gltf ...] [--rays N] [--out build/bench/error_bands]

The frames are `neuralao evaluate`'s (:mod:`neuralao.pipeline.evaluation.categories`): the config's
categories at the resolution of ``--size`` (its rays and views, ``--rays`` / ``--views`` override them),
built or resumed under ``OUT/frames/<W>x<H>`` by the same dataset stage, and every method scored as
evaluate scores it: each U-Net export at its manifest's internal-resolution policy, GTAO and SSAO with
the label radius as their kernel radius, over the valid foreground pixels of each (frame, radius) pair.
The categories held aside (``held_aside: true``) are left out unless named in ``--categories`` together
with ``--include-held-aside``: their meshes stay out of every analysis that informs a choice.

Edge rule. A foreground pixel is a *boundary* pixel when one of its 4-neighbours is background (a
silhouette against the background) or is foreground across a depth discontinuity: view depths d_p, d_q
with ``|d_p - d_q| > jump * min(d_p, d_q)`` (``--jump``, default 0.05; both pixels of such a pair are
boundary pixels: the occluder's rim and the occluded surface beside it). At 256 rows and a 45-60 degree
field of view one pixel's step on a continuous surface passes 5% only beyond about 85 degrees of
incidence. A pixel's edge distance is the Euclidean distance (pixel centres) to the nearest boundary
pixel: 0 on one, 1 one pixel in (scipy.ndimage.distance_transform_edt). The frame's border is not an
edge unless ``--border-is-edge`` (what lies off screen is another blind spot of a screen-space method).
Bands: [0, 2), [2, 8), [8, 32), [32, inf) pixels of the frame.

Per category x method: the RMSE in each band, the band's share of the pixels and of the method's
squared error (pixels and squared errors pooled over frames and radii), the pooled RMSE, and
``eval RMSE``, the mean over (frame, radius) pairs of each pair's RMSE as evaluate reports it. The
oracles replace the method by ground truth outside some bands: ``silhouette oracle`` keeps its error only
in the 0-2 and 2-8 px bands, ``interior oracle`` only beyond 8 px; both as a ratio to GTAO's RMSE (pooled,
and per pair averaged as evaluate averages). A model whose silhouette oracle is near its own ratio has
its error at the edges; one whose silhouette oracle is far below 0.8 could reach 0.8x GTAO by fixing the
interior alone.

Writes OUT/error_bands.json (every pair's per-band sums, the summary, the settings) and
OUT/error_bands.md, and prints the markdown.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from neuralao.pipeline.datasets.dataset import open_dataset
from neuralao.pipeline.evaluation.categories import (
    EvalResolution,
    EvalSettings,
    baseline_predictors,
    category_of,
    check_frames,
    dataset_settings,
    ensure_frames,
    unet_predictors,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json, write_text
from neuralao.runtime.foundation.settings import load_settings, settings_to_dict

log = logging.getLogger(__name__)

BAND_EDGES = (0.0, 2.0, 8.0, 32.0, float("inf"))  # pixels; band i is [BAND_EDGES[i], BAND_EDGES[i + 1])
BAND_NAMES = ("0-2", "2-8", "8-32", ">32")
SILHOUETTE_BANDS = (0, 1)  # the bands the silhouette oracle keeps; the interior oracle keeps the others
DEFAULT_JUMP = 0.05


# ------------------------------------------------------------------------------------------ edges


def boundary_pixels(depth: np.ndarray, fg: np.ndarray, jump: float = DEFAULT_JUMP, border: bool = False):
    """Foreground pixels with a 4-neighbour that is background or across a relative depth jump > ``jump``
    (``|d_p - d_q| > jump * min(d_p, d_q)``, both pixels of the pair); ``border``: the frame's outer rows
    and columns too. depth, fg : (H, W). Returns (H, W) bool."""
    d = np.asarray(depth, np.float64)
    fg = np.asarray(fg, bool)
    out = np.zeros_like(fg)
    for axis in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[axis], b[axis] = slice(None, -1), slice(1, None)
        a, b = tuple(a), tuple(b)
        fa, fb = fg[a], fg[b]
        da, db = d[a], d[b]
        both = fa & fb
        cut = both & (np.abs(da - db) > jump * np.minimum(da, db))
        out[a] |= (fa & ~fb) | cut  # p foreground, its neighbour background or across a jump
        out[b] |= (fb & ~fa) | cut
    if border:
        edge = np.zeros_like(fg)
        edge[0, :] = edge[-1, :] = edge[:, 0] = edge[:, -1] = True
        out |= edge & fg
    return out


def edge_distance(
    depth: np.ndarray, fg: np.ndarray, jump: float = DEFAULT_JUMP, border: bool = False
) -> np.ndarray:
    """Each pixel's Euclidean distance in pixels to the nearest boundary pixel (:func:`boundary_pixels`);
    inf everywhere when the frame has none (all foreground, no discontinuity, no border edge)."""
    edges = boundary_pixels(depth, fg, jump, border)
    if not edges.any():
        return np.full(edges.shape, np.inf)
    return distance_transform_edt(~edges)


def band_index(dist: np.ndarray) -> np.ndarray:
    """The band (0..3) of each distance: [0, 2), [2, 8), [8, 32), [32, inf)."""
    return np.searchsorted(np.asarray(BAND_EDGES[1:-1]), dist, side="right")


def band_sums(err2: np.ndarray, bands: np.ndarray, mask: np.ndarray) -> tuple[list[float], list[int]]:
    """Sum of squared error and pixel count of each band over ``mask``."""
    b = bands[mask]
    se = np.bincount(b, weights=err2[mask].astype(np.float64), minlength=len(BAND_NAMES))
    n = np.bincount(b, minlength=len(BAND_NAMES))
    return [float(v) for v in se], [int(v) for v in n]


# ------------------------------------------------------------------------------------------ summary


def summarise(
    rows: list[dict], methods: list[str], groups: dict[str, list[str]] | None = None, reference: str = "gtao"
) -> dict:
    """category (then each group of categories, then ``all``) -> method -> figures from the pairs' band
    sums (see the module doc)."""
    cats = sorted({r["category"] for r in rows})
    pools = {c: [c] for c in cats} | {g: cs for g, cs in (groups or {}).items() if len(cs) > 1}
    if len(cats) > 1:
        pools["all"] = cats
    out: dict[str, dict] = {}
    for cat, members in pools.items():
        out[cat] = {}
        for m in methods:
            sel = [r for r in rows if r["method"] == m and r["category"] in members]
            if not sel:
                continue
            se = np.sum([r["se"] for r in sel], axis=0)
            n = np.sum([r["n"] for r in sel], axis=0)
            total_se, total_n = float(se.sum()), int(n.sum())
            sil = [i for i in range(len(BAND_NAMES)) if i in SILHOUETTE_BANDS]
            inner = [i for i in range(len(BAND_NAMES)) if i not in SILHOUETTE_BANDS]

            def pair_mean(keep, sel=sel):
                return float(np.mean([np.sqrt(np.sum(np.take(r["se"], keep)) / np.sum(r["n"])) for r in sel]))

            out[cat][m] = {
                "pairs": len(sel),
                "pixels": total_n,
                "rmse": float(np.sqrt(total_se / total_n)),
                "eval_rmse": pair_mean(list(range(len(BAND_NAMES)))),
                "bands": {
                    name: {
                        "rmse": float(np.sqrt(se[i] / n[i])) if n[i] else float("nan"),
                        "pixel_share": float(n[i] / total_n),
                        "error_share": float(se[i] / total_se) if total_se > 0 else float("nan"),
                    }
                    for i, name in enumerate(BAND_NAMES)
                },
                "silhouette_only_rmse": float(np.sqrt(se[sil].sum() / total_n)),
                "interior_only_rmse": float(np.sqrt(se[inner].sum() / total_n)),
                "eval_silhouette_only_rmse": pair_mean(sil),
                "eval_interior_only_rmse": pair_mean(inner),
            }
        ref = out[cat].get(reference)
        for fig in out[cat].values():
            if ref is None:
                continue
            fig["ratio"] = fig["rmse"] / ref["rmse"]
            fig["eval_ratio"] = fig["eval_rmse"] / ref["eval_rmse"]
            fig["silhouette_oracle"] = fig["silhouette_only_rmse"] / ref["rmse"]
            fig["interior_oracle"] = fig["interior_only_rmse"] / ref["rmse"]
            fig["eval_silhouette_oracle"] = fig["eval_silhouette_only_rmse"] / ref["eval_rmse"]
            fig["eval_interior_oracle"] = fig["eval_interior_only_rmse"] / ref["eval_rmse"]
    return out


def markdown(summary: dict, reference: str = "gtao") -> str:
    f3 = lambda v: f"{v:.3f}"  # noqa: E731
    pct = lambda v: f"{100 * v:.0f}%"  # noqa: E731
    lines = [
        "### Error by distance to the nearest edge (pixels)",
        "",
        "RMSE per band; in brackets the band's share of the method's squared error. Pixel share per band "
        "in the category's first row.",
        "",
        "| category | method | px share | "
        + " | ".join(f"{b} px" for b in BAND_NAMES)
        + " | RMSE | eval RMSE |",
        "|---|---|---|" + "---:|" * (len(BAND_NAMES) + 2),
    ]
    for cat, by_method in summary.items():
        for k, (m, fig) in enumerate(by_method.items()):
            share = " / ".join(pct(fig["bands"][b]["pixel_share"]) for b in BAND_NAMES) if k == 0 else ""
            cells = [
                f"{f3(fig['bands'][b]['rmse'])} ({pct(fig['bands'][b]['error_share'])})" for b in BAND_NAMES
            ]
            lines.append(
                f"| {cat} | {m} | {share} | "
                + " | ".join(cells)
                + f" | {f3(fig['rmse'])} | {f3(fig['eval_rmse'])} |"
            )
    lines += [
        "",
        f"### Ratio to {reference.upper()}'s RMSE, and the oracles",
        "",
        "ratio: the method's RMSE / GTAO's. silhouette oracle: the method's error kept only within 8 px "
        "of an edge (ground truth elsewhere) / GTAO's RMSE. interior oracle: kept only beyond 8 px. "
        "Pooled over pixels; in brackets as evaluate averages (mean over (frame, radius) pairs).",
        "",
        "| category | method | ratio | silhouette oracle | interior oracle |",
        "|---|---|---:|---:|---:|",
    ]
    for cat, by_method in summary.items():
        for m, fig in by_method.items():
            if "ratio" not in fig:
                continue
            lines.append(
                f"| {cat} | {m} | {f3(fig['ratio'])} ({f3(fig['eval_ratio'])}) "
                f"| {f3(fig['silhouette_oracle'])} ({f3(fig['eval_silhouette_oracle'])}) "
                f"| {f3(fig['interior_oracle'])} ({f3(fig['eval_interior_oracle'])}) |"
            )
    lines.append("")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ run


def select_categories(
    settings: EvalSettings, names: list[str] | None, include_held_aside: bool
) -> EvalSettings:
    """The config with only the chosen categories: by default every one not held aside; a held-aside one
    only when named and ``include_held_aside``."""
    known = {c.name: c for c in settings.categories}
    if names is None:
        chosen = [c for c in settings.categories if not c.held_aside]
    else:
        unknown = [n for n in names if n not in known]
        if unknown:
            raise NeuralaoError(f"--categories: {', '.join(unknown)} not in the config ({', '.join(known)})")
        chosen = [known[n] for n in names]
        held = [c.name for c in chosen if c.held_aside]
        if held and not include_held_aside:
            raise NeuralaoError(
                f"--categories: {', '.join(held)} is held aside (its meshes stay out of analyses that inform "
                "choices); add --include-held-aside to score it anyway"
            )
    if not chosen:
        raise NeuralaoError("no category to analyse")
    return replace(settings, categories=chosen)


def at_size(
    settings: EvalSettings, size: list[int], rays: int | None, views: int | None, config: str
) -> tuple[EvalSettings, EvalResolution]:
    """``settings`` reduced to its resolution of ``size`` (W, H), with ``rays`` / ``views`` when given."""
    w, h = size
    matching = [r for r in settings.resolutions if tuple(int(v) for v in r.size) == (w, h)]
    if not matching:
        sizes = ", ".join(f"{r.size[0]}x{r.size[1]}" for r in settings.resolutions)
        raise NeuralaoError(f"--size {w} {h}: not a resolution of {config} ({sizes})")
    res = replace(
        matching[0],
        rays=matching[0].rays if rays is None else rays,
        views=matching[0].views if views is None else views,
    )
    return replace(settings, resolutions=[res]), res


def camera_groups(settings: EvalSettings) -> dict[str, list[str]]:
    """The isolated objects and the interiors together: category names by the cameras they are seen with."""
    return {
        f"{kind} cameras": [c.name for c in settings.categories if c.cameras == kind]
        for kind in sorted({c.cameras for c in settings.categories})
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--config", default="configs/eval.json", help="evaluation config (as neuralao evaluate)")
    p.add_argument("--size", nargs=2, type=int, default=[256, 256], metavar=("W", "H"))
    p.add_argument(
        "--models", nargs="+", default=["runtime/models/unet-gtao", "runtime/models/unet-fast"], type=Path
    )
    p.add_argument("--out", default="build/bench/error_bands", type=Path)
    p.add_argument("--categories", nargs="+", default=None, help="default: every category not held aside")
    p.add_argument(
        "--include-held-aside", action="store_true", help="allow a held-aside category named above"
    )
    p.add_argument("--rays", type=int, default=None, help="label rays per pixel (default: the config's)")
    p.add_argument("--views", type=int, default=None, help="views per scene (default: the config's)")
    p.add_argument("--jump", type=float, default=DEFAULT_JUMP, help="relative depth jump that is an edge")
    p.add_argument("--border-is-edge", action="store_true", help="the frame's border counts as an edge")
    p.add_argument("--no-ssao", action="store_true", help="leave SSAO out")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        return run(args)
    except NeuralaoError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1


def run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    if not args.jump > 0:
        raise NeuralaoError(f"--jump must be > 0, got {args.jump}")
    settings = select_categories(
        load_settings(EvalSettings, args.config), args.categories, args.include_held_aside
    )
    w, h = args.size
    settings, res = at_size(settings, args.size, args.rays, args.views, args.config)
    check_frames(settings, args.out)  # every setting, and the frames' memory and disk, before any work

    methods = {}
    for folder in args.models:
        methods.update(unet_predictors(Path(folder), ["model"]))
    baselines = baseline_predictors()
    methods["gtao"] = baselines["gtao"]
    if not args.no_ssao:
        methods["ssao"] = baselines["ssao"]

    folder = args.out / "frames" / f"{w}x{h}"
    t0 = time.perf_counter()
    ensure_frames(
        dataset_settings(settings, res), folder, Path(args.config).resolve().parent, not args.no_progress
    )
    label_seconds = time.perf_counter() - t0
    log.info("frames ready in %.0f s", label_seconds)

    t0 = time.perf_counter()
    rows: list[dict] = []
    for frame in open_dataset(folder).frames(split="test"):
        category = category_of(frame["scene"], settings)
        fg = np.asarray(frame["mask"], bool)
        bands = band_index(edge_distance(frame["depth"], fg, args.jump, args.border_is_edge))
        for j, radius in enumerate(np.asarray(frame["radii"], np.float64).reshape(-1)):
            mask = fg & np.asarray(frame["valid_radii"][..., j], bool)  # as score_frame masks a pair
            if not mask.any():
                continue
            gt = np.asarray(frame["ao_radii"][..., j], np.float32)
            for name, fn in methods.items():
                pred = np.asarray(fn(frame, float(radius)), np.float32)
                if not np.isfinite(pred[mask]).all():
                    raise NeuralaoError(f"{name} returned non-finite AO on {frame['scene']}/{frame['view']}")
                se, n = band_sums((pred - gt) ** 2, bands, mask)
                rows.append(
                    {
                        "category": category,
                        "scene": frame["scene"],
                        "view": frame["view"],
                        "radius": j,
                        "method": name,
                        "se": se,
                        "n": n,
                    }
                )
    score_seconds = time.perf_counter() - t0
    if not rows:
        raise NeuralaoError("no (frame, radius) pair with valid foreground pixels")

    groups = camera_groups(settings)
    summary = summarise(rows, list(methods), groups)
    per_radius = {
        f"{settings.radii_rel[j]:g}": summarise([r for r in rows if r["radius"] == j], list(methods), groups)
        for j in sorted({r["radius"] for r in rows})
    }
    text = markdown(summary)
    header = (
        f"## Screen-space AO error by distance to the nearest edge, {w}x{h}, {res.rays} rays, "
        f"{res.views} views\n\nEdges: background 4-neighbours and relative depth jumps > {args.jump:g}"
        f"{' and the frame border' if args.border_is_edge else ''}. Categories: "
        f"{', '.join(c.name for c in settings.categories)}.\n\n"
    )
    result = {
        "config": settings_to_dict(settings),
        "models": [str(m) for m in args.models],
        "methods": list(methods),
        "size": [w, h],
        "rays": res.rays,
        "views": res.views,
        "edge_rule": {
            "jump": args.jump,
            "border_is_edge": bool(args.border_is_edge),
            "bands": list(BAND_NAMES),
        },
        "summary": summary,
        "per_radius": per_radius,
        "rows": rows,
        "seconds": {
            "frames": label_seconds,
            "scoring": score_seconds,
            "total": time.perf_counter() - t_start,
        },
    }
    write_json(args.out / "error_bands.json", result)
    write_text(args.out / "error_bands.md", header + text)
    print(header + text)
    log.info(
        "frames %.0f s, scoring %.0f s; wrote %s and %s",
        label_seconds,
        score_seconds,
        args.out / "error_bands.json",
        args.out / "error_bands.md",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
