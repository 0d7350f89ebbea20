"""The selection rule: per scene, the cheapest representation that meets an SSIM target (pure functions).

Candidates for a scene: every representation measured on it in a report result (``report.json``):
the screen-space baselines (SSAO, GTAO), the vertex bakes (sampled, least-squares, least-squares
stored as 8 bits), every baked MLP and every AO field trained for that scene's mesh, and the
U-Nets (one network for all scenes). Ray tracing is the reference, not a candidate. They are tried
cheapest first: stored bytes, then measured GL time per frame; the first whose masked SSIM on the
scene's held-back frames is at least ``target`` is chosen. The document records, per scene, the
order tried, the choice, whether the target was met (if nothing meets it the best-scoring one is
recorded with ``met_target: false``), and what the choice saves against the largest candidate.

:mod:`neuralao.pipeline.evaluation.report_writing` (which writes the report's selection section) and
:mod:`neuralao.pipeline.cli.select` (the command) both import this module; it imports neither (the model
families come from :mod:`neuralao.runtime.kinds`).
"""

from __future__ import annotations

from neuralao.runtime import kinds
from neuralao.runtime.foundation.errors import NeuralaoError

DEFAULT_TARGET = 0.95


def candidate_families() -> tuple[str, ...]:
    """The families a selection picks from: screen-space, baked and every reported model kind."""
    return ("screen-space", "baked", *kinds.reported())


def scene_candidates(result: dict) -> dict[str, list[dict]]:
    """Per scene: [{name, family, bytes, ssim, seconds, frames}] of the available models measured on it."""
    out: dict[str, list[dict]] = {}
    families = candidate_families()
    for name, e in result["methods"].items():
        if e.get("family") not in families or not e.get("available"):
            continue
        for scene, ps in e.get("per_scene", {}).items():
            out.setdefault(scene, []).append(
                {
                    "name": name,
                    "family": e["family"],
                    "bytes": ps.get("bytes", e.get("bytes")),
                    "ssim": ps["ssim"],
                    "rmse": ps["rmse"],
                    "seconds": ps.get("seconds", e.get("seconds")),
                    "frames": ps["frames"],
                }
            )
    return out


def choose(candidates: list[dict], target: float) -> dict:
    """Cheapest-first selection among ``candidates`` (dicts with name, bytes, ssim, seconds): bytes, then
    time."""
    if not candidates:
        raise NeuralaoError("no candidate model to choose from")
    inf = float("inf")
    ordered = sorted(
        candidates,
        key=lambda c: (
            inf if c["bytes"] is None else c["bytes"],
            inf if c["seconds"] is None else c["seconds"],
            c["name"],
        ),
    )
    tried, chosen = [], None
    for c in ordered:
        tried.append(
            {"name": c["name"], "bytes": c["bytes"], "ssim": c["ssim"], "meets": c["ssim"] >= target}
        )
        if c["ssim"] >= target:
            chosen = c
            break
    met = chosen is not None
    if chosen is None:
        chosen = max(ordered, key=lambda c: c["ssim"])
    largest = max(ordered, key=lambda c: (c["bytes"] if c["bytes"] is not None else -1, c["name"]))
    entry = {
        "chosen": chosen["name"],
        "family": chosen["family"],
        "met_target": met,
        "ssim": chosen["ssim"],
        "rmse": chosen["rmse"],
        "bytes": chosen["bytes"],
        "seconds": chosen["seconds"],
        "frames": chosen["frames"],
        "tried": tried,
        "largest": largest["name"],
        "largest_bytes": largest["bytes"],
        "largest_seconds": largest["seconds"],
        "largest_ssim": largest["ssim"],
    }
    if chosen["bytes"] is not None and largest["bytes"]:
        entry["bytes_saved"] = largest["bytes"] - chosen["bytes"]
        entry["bytes_ratio"] = chosen["bytes"] / largest["bytes"]
    if chosen["seconds"] is not None and largest["seconds"]:
        entry["seconds_saved"] = largest["seconds"] - chosen["seconds"]
        entry["time_ratio"] = chosen["seconds"] / largest["seconds"]
    return entry


def select_from_results(result: dict, target: float = DEFAULT_TARGET) -> dict:
    """The selection document (select.json) from a report result (report.json content)."""
    per_scene = {}
    for scene, cands in sorted(scene_candidates(result).items()):
        per_scene[scene] = choose(cands, target)
    families = candidate_families()
    unavailable = {
        n: e.get("reason", "")
        for n, e in result["methods"].items()
        if e.get("family") in families and not e.get("available")
    }
    return {
        "format": "neuralao-select",
        "version": 1,
        "target_ssim": target,
        "rule": "per scene, candidates (SSAO, GTAO, vertex bakes incl. 8-bit, "
        "MLPs and fields of that scene, U-Nets) sorted by stored bytes, then GL time; "
        "the first with masked SSIM >= target on held-back frames is chosen; "
        "savings against the largest candidate",
        "time_size": result.get("settings", {}).get("time_size"),
        "time_on": "GL (headless context of the report run)",
        "dataset_hash": result.get("dataset", {}).get("dataset_hash"),
        "scenes": per_scene,
        "unavailable_models": unavailable,
    }


def _kib(v) -> str:
    return "-" if v is None else (f"{v / 1024:.1f} KiB" if v >= 1024 else f"{v} B")


def _ms(v) -> str:
    return "-" if v is None else f"{v * 1e3:.2f} ms"


def render_markdown(selection: dict, heading: str = "# Model selection") -> str:
    t = selection["target_ssim"]
    lines = [
        heading,
        "",
        f"Cheapest representation per scene with masked SSIM >= {t} on held-back views (tried by bytes, "
        "then time).",
        "",
    ]
    if not selection["scenes"]:
        lines.append("No representation was measured, so nothing to select.")
    else:
        lines += [
            "| scene | chosen | SSIM | bytes | time | tried | largest | bytes saved | time saved |",
            "|---|---|---:|---:|---:|---|---|---:|---:|",
        ]
        for scene, e in selection["scenes"].items():
            tried = ", ".join(f"{c['name']} ({c['ssim']:.3f})" for c in e["tried"])
            chosen = e["chosen"] + ("" if e["met_target"] else " (target not met: best SSIM)")
            saved_b = f"{_kib(e.get('bytes_saved'))} ({e['bytes_ratio']:.3g}x)" if "bytes_ratio" in e else "-"
            saved_t = f"{_ms(e.get('seconds_saved'))} ({e['time_ratio']:.3g}x)" if "time_ratio" in e else "-"
            lines.append(
                f"| {scene} | {chosen} | {e['ssim']:.3f} | {_kib(e['bytes'])} | "
                f"{_ms(e['seconds'])} | {tried} | {e['largest']} | {saved_b} | {saved_t} |"
            )
    if selection.get("unavailable_models"):
        lines += [
            "",
            "Not available: " + "; ".join(f"{n} ({r})" for n, r in selection["unavailable_models"].items()),
        ]
    return "\n".join(lines) + "\n"


def render_targets_markdown(
    selections: dict[float, dict], heading: str = "## Selection at several targets"
) -> str:
    """One row per scene, one column group per target: the choice, its bytes and time, and the savings."""
    targets = sorted(selections)
    scenes = sorted({sc for sel in selections.values() for sc in sel["scenes"]})
    lines = [
        heading,
        "",
        "Per scene, the cheapest representation (bytes, then time) whose masked SSIM meets the target; "
        "`(not met)`: nothing does, the best is shown. Saved: against the largest candidate of the scene.",
        "",
        "| scene | "
        + " | ".join(f"target {t}: choice (SSIM) | bytes / time | saved vs largest" for t in targets)
        + " |",
        "|---|" + "---|---:|---:|" * len(targets),
    ]
    for scene in scenes:
        cells = []
        for t in targets:
            e = selections[t]["scenes"].get(scene)
            if e is None:
                cells += ["-", "-", "-"]
                continue
            cells.append(f"{e['chosen']} ({e['ssim']:.3f})" + ("" if e["met_target"] else " (not met)"))
            cells.append(f"{_kib(e['bytes'])} / {_ms(e['seconds'])}")
            saved = []
            if "bytes_ratio" in e:
                saved.append(f"{e['bytes_ratio']:.3g}x bytes")
            if "time_ratio" in e:
                saved.append(f"{e['time_ratio']:.3g}x time")
            cells.append(", ".join(saved) or "-")
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
