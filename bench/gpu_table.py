"""The table of bench/gpu.sh: JSON lines of the C host's timed runs -> a markdown table (stdout) and JSON.

    python3 bench/gpu_table.py RUNS.jsonl OUT.json

Standard library only: it runs where bench/gpu.sh runs, a GPU machine without the project's venv.
A model's frame time is its network passes, plus its GTAO passes for a hybrid (GTAO is its input).
GTAO's own row is the median of the hybrid runs' GTAO passes at that size. A hybrid's ratio to GTAO is
taken within its own run (its frame over its own GTAO passes), so a load that changes between runs (a
shared machine) does not move it; a pure model's ratio is to the median.
"""

from __future__ import annotations

import json
import statistics
import sys


def _ms(run: dict, key: str) -> float:
    """GPU ms, or the wall clock where GL reports no GPU time (llvmpipe's compute)."""
    gpu = run[f"{key}_ms"]
    return gpu if gpu > 0 else run[f"{key}_wall_ms"]


def main(src: str, out: str) -> None:
    runs = [json.loads(line) for line in open(src) if line.strip()]
    rows, gtao_runs = [], {}
    for r in runs:
        size = f"{r['width']}x{r['height']}"
        hybrid = r["gtao_ms"] >= 0
        ms = _ms(r, "network") + (_ms(r, "gtao") if hybrid else 0.0)
        if hybrid:
            gtao_runs.setdefault(size, []).append(_ms(r, "gtao"))
        rows.append(
            {
                **r,
                "size": size,
                "frame_ms": ms,
                "clock": "GL_TIME_ELAPSED" if r["network_ms"] > 0 else "wall (glFinish)",
            }
        )
    gtao = {size: statistics.median(v) for size, v in gtao_runs.items()}
    for r in rows:
        own = _ms(r, "gtao") if r["gtao_ms"] >= 0 else gtao.get(r["size"])
        r["over_gtao"] = r["frame_ms"] / own if own else None
    renderer = runs[0]["renderer"] if runs else "-"
    print(f"GL renderer: {renderer} ({runs[0]['version'] if runs else '-'})\n")
    print("| size | model | preset | precision | ms | / GTAO | clock |")
    print("|---|---|---|---|---:|---:|---|")
    for size, ms in gtao.items():
        print(f"| {size} | GTAO | - | fp32 | {ms:.3f} | 1.00 | |")
    for r in rows:
        ratio = f"{r['over_gtao']:.2f}" if r["over_gtao"] else "-"
        print(
            f"| {r['size']} | {r['model']} | {r['preset']} | {r['precision']} | "
            f"{r['frame_ms']:.3f} | {ratio} | {r['clock']} |"
        )
    with open(out, "w") as f:
        json.dump({"renderer": renderer, "gtao_ms": gtao, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main(*sys.argv[1:3])
