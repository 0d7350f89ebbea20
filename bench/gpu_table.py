"""The table of bench/gpu.sh: JSON lines of the C hosts' timed runs -> a markdown table (stdout) and JSON.

    python3 bench/gpu_table.py RUNS.jsonl OUT.json

Standard library only: it runs where bench/gpu.sh runs, a GPU machine without the project's venv.

Rows per frame size and API (gl: the GL host, vulkan: the Vulkan runner; a run's "api", gl when it has
none): GTAO (the hybrid's own GTAO steps, f_gtao + f_gtao_blur, median over its runs), SSAO (the project's
SSAO and its blur, timed in every GL run, median), then each model's whole frame (every step of its
frame.steps; a host without frame steps reports network + GTAO passes, summed here) with its network steps
alone beside it. Ratios to GTAO are taken within one host run where that run timed GTAO (a hybrid's frame
over its own GTAO steps, SSAO over the hybrid runs' GTAO), so a load that changes between runs (a shared
machine) does not move them; a pure model's ratio is to the median GTAO of its size and API.

JSON: {"renderer" (the first run's), "renderers": {api: renderer}, "gtao_ms", "ssao_ms", "ssao_over_gtao"
(each {api: {size: value}}), "rows"}.
"""

from __future__ import annotations

import json
import statistics
import sys


def _gpu_clock(run: dict) -> bool:
    """Whether the API reported GPU time for the run's compute passes (GL on llvmpipe reports 0 for compute,
    not for fragment passes; a Vulkan queue without timestamps -1: such a run reads every figure off the wall
    clock, so its ratios compare alike)."""
    return run["network_ms"] > 0


_CLOCKS = {"gl": ("GL_TIME_ELAPSED", "wall (glFinish)"), "vulkan": ("vkCmdWriteTimestamp", "wall (fence)")}


def _ms(run: dict, key: str) -> float:
    """The run's ms of ``key`` on its clock (:func:`_gpu_clock`); -1 when not timed."""
    return run.get(f"{key}_ms" if _gpu_clock(run) else f"{key}_wall_ms", -1.0)


def _frame_ms(run: dict) -> float:
    """The whole frame; from a host that times no frame steps, its network (+ a hybrid's GTAO) passes."""
    if run.get("frame_ms", -1.0) >= 0:
        return _ms(run, "frame")
    return _ms(run, "network") + (_ms(run, "gtao") if run["gtao_ms"] >= 0 else 0.0)


def _ratio(value: float, gtao: float | None) -> float | None:
    return value / gtao if gtao else None


def _cell(ratio: float | None) -> str:
    return f"{ratio:.2f}" if ratio else "-"


def main(src: str, out: str) -> None:
    runs = [json.loads(line) for line in open(src) if line.strip()]
    rows, gtao_runs, ssao_runs, ssao_ratios, renderers = [], {}, {}, {}, {}
    for r in runs:
        key = (f"{r['width']}x{r['height']}", r.get("api", "gl"))  # (size, api)
        renderers.setdefault(key[1], (r["renderer"], r["version"]))
        gtao = _ms(r, "gtao") if r["gtao_ms"] >= 0 else None
        ssao = _ms(r, "ssao") if r.get("ssao_ms", -1.0) >= 0 else None
        if gtao is not None:
            gtao_runs.setdefault(key, []).append(gtao)
        if ssao is not None:
            ssao_runs.setdefault(key, []).append(ssao)
            if gtao:
                ssao_ratios.setdefault(key, []).append(ssao / gtao)
        rows.append(
            {
                **r,
                "api": key[1],
                "size": key[0],
                "frame_ms": _frame_ms(r),
                "network_ms": _ms(r, "network"),
                "own_gtao_ms": gtao,
                "clock": _CLOCKS[key[1]][0 if _gpu_clock(r) else 1],
            }
        )
    gtao = {key: statistics.median(v) for key, v in gtao_runs.items()}
    ssao = {key: statistics.median(v) for key, v in ssao_runs.items()}
    ssao_over_gtao = {
        key: statistics.median(ssao_ratios[key]) if key in ssao_ratios else _ratio(ms, gtao.get(key))
        for key, ms in ssao.items()
    }
    for r in rows:
        r["over_gtao"] = _ratio(r["frame_ms"], r.pop("own_gtao_ms") or gtao.get((r["size"], r["api"])))
    names = {"gl": "GL renderer", "vulkan": "Vulkan device"}
    for api, (renderer, version) in renderers.items():
        print(f"{names.get(api, api)}: {renderer} ({version})")
    print("\n| size | api | model | preset | precision | frame ms | network ms | / GTAO | clock |")
    print("|---|---|---|---|---|---:|---:|---:|---|")
    for key in dict.fromkeys((r["size"], r["api"]) for r in rows):
        size, api = key
        mine = [r for r in rows if (r["size"], r["api"]) == key]
        clock = " / ".join(dict.fromkeys(r["clock"] for r in mine))
        if key in gtao:
            print(f"| {size} | {api} | GTAO | - | fp32 | {gtao[key]:.3f} | - | 1.00 | {clock} |")
        if key in ssao:
            ratio = _cell(ssao_over_gtao[key])
            print(f"| {size} | {api} | SSAO | - | fp32 | {ssao[key]:.3f} | - | {ratio} | {clock} |")
        for r in mine:
            print(
                f"| {size} | {api} | {r['model']} | {r['preset']} | {r['precision']} | {r['frame_ms']:.3f} | "
                f"{r['network_ms']:.3f} | {_cell(r['over_gtao'])} | {r['clock']} |"
            )

    def by_api(values: dict) -> dict:
        out: dict = {}
        for (size, api), v in values.items():
            out.setdefault(api, {})[size] = v
        return out

    result = {
        "renderer": runs[0]["renderer"] if runs else "-",
        "renderers": {api: renderer for api, (renderer, _) in renderers.items()},
        "gtao_ms": by_api(gtao),
        "ssao_ms": by_api(ssao),
        "ssao_over_gtao": by_api(ssao_over_gtao),
        "rows": rows,
    }
    with open(out, "w") as f:
        json.dump(result, f, indent=1)


if __name__ == "__main__":
    main(*sys.argv[1:3])
