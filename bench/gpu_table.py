"""The table of bench/gpu.sh: JSON lines of the C host's timed runs -> a markdown table (stdout) and JSON.

    python3 bench/gpu_table.py RUNS.jsonl OUT.json

Standard library only: it runs where bench/gpu.sh runs, a GPU machine without the project's venv.

Rows per frame size: GTAO (the hybrid's own GTAO steps, f_gtao + f_gtao_blur, median over its runs), SSAO
(the project's SSAO and its blur, timed in every run, median), then each model's whole frame (every step
of its frame.steps; a host without frame steps reports network + GTAO passes, summed here) with its
network steps alone beside it. Ratios to GTAO are taken within one host run where that run timed GTAO (a
hybrid's frame over its own GTAO steps, SSAO over the hybrid runs' GTAO), so a load that changes between
runs (a shared machine) does not move them; a pure model's ratio is to the size's median GTAO.
"""

from __future__ import annotations

import json
import statistics
import sys


def _gpu_clock(run: dict) -> bool:
    """Whether GL reported GPU time for the run's compute passes (llvmpipe reports 0 for compute, not
    for fragment passes: such a run reads every figure off the wall clock, so its ratios compare alike)."""
    return run["network_ms"] > 0


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
    rows, gtao_runs, ssao_runs, ssao_ratios = [], {}, {}, {}
    for r in runs:
        size = f"{r['width']}x{r['height']}"
        gtao = _ms(r, "gtao") if r["gtao_ms"] >= 0 else None
        ssao = _ms(r, "ssao") if r.get("ssao_ms", -1.0) >= 0 else None
        if gtao is not None:
            gtao_runs.setdefault(size, []).append(gtao)
        if ssao is not None:
            ssao_runs.setdefault(size, []).append(ssao)
            if gtao:
                ssao_ratios.setdefault(size, []).append(ssao / gtao)
        rows.append(
            {
                **r,
                "size": size,
                "frame_ms": _frame_ms(r),
                "network_ms": _ms(r, "network"),
                "own_gtao_ms": gtao,
                "clock": "GL_TIME_ELAPSED" if _gpu_clock(r) else "wall (glFinish)",
            }
        )
    gtao = {size: statistics.median(v) for size, v in gtao_runs.items()}
    ssao = {size: statistics.median(v) for size, v in ssao_runs.items()}
    ssao_over_gtao = {
        size: statistics.median(ssao_ratios[size]) if size in ssao_ratios else _ratio(ms, gtao.get(size))
        for size, ms in ssao.items()
    }
    for r in rows:
        r["over_gtao"] = _ratio(r["frame_ms"], r.pop("own_gtao_ms") or gtao.get(r["size"]))
    renderer = runs[0]["renderer"] if runs else "-"
    print(f"GL renderer: {renderer} ({runs[0]['version'] if runs else '-'})\n")
    print("| size | model | preset | precision | frame ms | network ms | / GTAO | clock |")
    print("|---|---|---|---|---:|---:|---:|---|")
    for size in dict.fromkeys(r["size"] for r in rows):
        clock = " / ".join(dict.fromkeys(r["clock"] for r in rows if r["size"] == size))
        if size in gtao:
            print(f"| {size} | GTAO | - | fp32 | {gtao[size]:.3f} | - | 1.00 | {clock} |")
        if size in ssao:
            ratio = _cell(ssao_over_gtao[size])
            print(f"| {size} | SSAO | - | fp32 | {ssao[size]:.3f} | - | {ratio} | {clock} |")
        for r in rows:
            if r["size"] == size:
                print(
                    f"| {size} | {r['model']} | {r['preset']} | {r['precision']} | {r['frame_ms']:.3f} | "
                    f"{r['network_ms']:.3f} | {_cell(r['over_gtao'])} | {r['clock']} |"
                )
    result = {
        "renderer": renderer,
        "gtao_ms": gtao,
        "ssao_ms": ssao,
        "ssao_over_gtao": ssao_over_gtao,
        "rows": rows,
    }
    with open(out, "w") as f:
        json.dump(result, f, indent=1)


if __name__ == "__main__":
    main(*sys.argv[1:3])
