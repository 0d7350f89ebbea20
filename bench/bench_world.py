"""A level bake on a local Ray cluster, from the command line, with every process's memory watched.

    .venv/bin/python bench/bench_world.py                              # world10x: ~18M faces, hours
    .venv/bin/python bench/bench_world.py --preset table1 --workers 2  # Table 1 on Ray (minutes)

Generates the seeded level (``neuralao level --preset PRESET``; kept and reused), then runs
``neuralao bake LEVEL --config CFG --out OUT/bake --engine ray --ray-workers N`` as a child process and
samples, twice a second, the resident memory (RSS) of the driver (that process), of each Ray worker
(``ray::`` processes under it) and of Ray's own services, and the object store's shared memory. The bake
resumes where a killed run stopped: rerun the same command (the stage files under OUT/bake/stages/ are
kept; the watch starts again). Writes OUT/bench_world.json and OUT/bench_world.md: wall time, every
stage's seconds and the driver's peak RSS per stage (from the bake log), the peaks of the driver, of the
largest worker and of all processes together, the bytes written, and whether the driver stayed within
``--budget-gib``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _children(pid: int) -> list[int]:
    """Every descendant of ``pid`` (from /proc/*/stat parent links)."""
    parent: dict[int, int] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
                parent[int(d.name)] = int(fields[1])
            except (OSError, IndexError, ValueError):
                continue
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        kids = [c for c, pp in parent.items() if pp == p]
        out += kids
        todo += kids
    return out


def _rss_and_name(pid: int) -> tuple[int, str]:
    try:
        rss = 0
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1]) * 1024
        name = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
        return rss, name
    except OSError:
        return 0, ""


def _shm_bytes() -> int:
    """Bytes in /dev/shm (Ray's object store lives there on Linux)."""
    total = 0
    for p in Path("/dev/shm").rglob("*"):
        try:
            if p.is_file():
                total += p.stat().st_blocks * 512
        except OSError:
            pass
    return total


class Watch:
    """Peak RSS per role (driver, each worker, Ray's services) and of all processes together."""

    def __init__(self, pid: int):
        self.pid = pid
        self.peak = {"driver": 0, "worker": 0, "ray_services": 0, "all": 0, "object_store_shm": 0}
        self.workers: dict[int, int] = {}

    def sample(self) -> None:
        driver, _ = _rss_and_name(self.pid)
        services, total = 0, driver
        for c in _children(self.pid):
            rss, name = _rss_and_name(c)
            total += rss
            if name.startswith("ray::"):
                self.workers[c] = max(self.workers.get(c, 0), rss)
            else:
                services += rss
        p = self.peak
        p["driver"] = max(p["driver"], driver)
        p["worker"] = max([p["worker"], *self.workers.values()])
        p["ray_services"] = max(p["ray_services"], services)
        p["all"] = max(p["all"], total)
        p["object_store_shm"] = max(p["object_store_shm"], _shm_bytes())


def _folder_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def markdown(r: dict) -> str:
    log = r.get("bake_log") or {}
    c = log.get("counts", {})
    gib = 2**30
    lines = [
        f"Level {r['preset']}: {c.get('receiver_faces', 0):,} faces baked, "
        f"{c.get('samples', 0):,} samples x {r['rays']} rays, {c.get('pieces', 0)} pieces; "
        f"Ray, {r['workers']} workers on {r['cpu_count']} cores.",
        "",
        "| stage | seconds | tasks | longest task (s) | driver peak RSS (MiB) | reused |",
        "|---|---:|---:|---:|---:|:---:|",
    ]
    for st in log.get("stages", []):
        lines.append(
            f"| {st['stage']} | {st['seconds']:.1f} | {st.get('tasks', '')} | "
            f"{st.get('task_seconds_max', float('nan')):.1f} | {st.get('peak_rss_bytes', 0) / 2**20:,.0f} | "
            f"{'yes' if st['reused'] else ''} |"
        )
    p = {k: v / gib for k, v in r["peak_bytes"].items()}
    lines += [
        f"| **this run, wall** | **{r['seconds_wall']:.0f}** | | | | |",
        "",
        f"Peak RSS: driver {p['driver']:.2f} GiB (budget {r['budget_gib']:g} GiB: "
        f"{'within' if r['driver_within_budget'] else 'OVER'}), "
        f"largest worker {p['worker']:.2f} GiB, Ray's services {p['ray_services']:.2f} GiB, "
        f"all processes {p['all']:.2f} GiB; "
        f"object store (/dev/shm) {p['object_store_shm']:.2f} GiB.",
        f"Bytes written: glTF {r['output_bytes'] / gib:.2f} GiB, "
        f"stage files {r['stage_bytes'] / gib:.2f} GiB. "
        f"Load average {r['load_before'][0]:.2f} before, {r['load_after'][0]:.2f} after.",
    ]
    return "\n".join(lines) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", default="world10x")
    p.add_argument("--workers", type=int, default=2, help="Ray workers (one CPU each)")
    p.add_argument("--out", default=None, help="default build/bench/world/PRESET")
    p.add_argument("--budget-gib", type=float, default=2.0, help="the driver's stated memory budget")
    p.add_argument("--set", action="append", default=[], help="bake setting override")
    args = p.parse_args()
    out = Path(args.out or f"build/bench/world/{args.preset}")
    level = out / "level" / "level.gltf"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if not level.is_file():
        cmd = [
            sys.executable,
            "-m",
            "neuralao.pipeline.cli",
            "level",
            "--preset",
            args.preset,
            "--out",
            str(out / "level"),
        ]
        subprocess.run(cmd, check=True, env=env)
    cfg = out / "level" / "bake.json"
    bake = [sys.executable, "-m", "neuralao.pipeline.cli", "bake", str(level), "--config", str(cfg), "--out"]
    bake += [str(out / "bake"), "--engine", "ray", "--ray-workers", str(args.workers)]
    for kv in args.set:
        bake += ["--set", kv]
    load_before = list(os.getloadavg())
    t0 = time.perf_counter()
    proc = subprocess.Popen(bake, env=env)
    watch = Watch(proc.pid)
    while proc.poll() is None:
        watch.sample()
        time.sleep(0.5)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        print(f"bench_world: the bake exited with {proc.returncode}; rerun to resume", file=sys.stderr)
        return proc.returncode
    log = json.loads((out / "bake" / "bake_log.json").read_text())
    result = {
        "preset": args.preset,
        "workers": args.workers,
        "command": " ".join(bake),
        "rays": log["settings"]["trace"]["rays"],
        "seconds_wall": wall,
        "peak_bytes": watch.peak,
        "worker_peaks_bytes": sorted(watch.workers.values(), reverse=True),
        "budget_gib": args.budget_gib,
        "driver_within_budget": watch.peak["driver"] <= args.budget_gib * 2**30,
        "output_bytes": int(log.get("output_bytes", 0)),
        "stage_bytes": _folder_bytes(out / "bake" / "stages"),
        "load_before": load_before,
        "load_after": list(os.getloadavg()),
        "cpu_count": os.cpu_count(),
        "bake_log": log,
    }
    write_json(out / "bench_world.json", result)
    write_text(out / "bench_world.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
