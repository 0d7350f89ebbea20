"""The table of bench/gpu.sh: JSON lines of the C host's timed runs -> a markdown table (stdout) and JSON.

    python3 bench/gpu_table.py RUNS.jsonl OUT.json

Standard library only: it runs where bench/gpu.sh runs, a GPU machine without the project's venv.
A model's frame time is its network passes, plus its GTAO passes for a hybrid (GTAO is its input);
GTAO's own row is the default model's GTAO passes at the same size, from the same runs.
"""

from __future__ import annotations

import json
import sys


def _ms(run: dict, key: str) -> float:
    """GPU ms, or the wall clock where GL reports no GPU time (llvmpipe's compute)."""
    gpu = run[f"{key}_ms"]
    return gpu if gpu > 0 else run[f"{key}_wall_ms"]


def main(src: str, out: str) -> None:
    runs = [json.loads(line) for line in open(src) if line.strip()]
    rows, gtao = [], {}
    for r in runs:
        size = f"{r['width']}x{r['height']}"
        hybrid = r["gtao_ms"] >= 0
        ms = _ms(r, "network") + (_ms(r, "gtao") if hybrid else 0.0)
        if hybrid:
            gtao.setdefault(size, _ms(r, "gtao"))
        rows.append(
            {
                **r,
                "size": size,
                "frame_ms": ms,
                "clock": "GL_TIME_ELAPSED" if r["network_ms"] > 0 else "wall (glFinish)",
            }
        )
    for r in rows:
        r["over_gtao"] = r["frame_ms"] / gtao[r["size"]] if gtao.get(r["size"]) else None
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
