"""The level LOD per piece at one shared quadric error, against the one global simplification.

    .venv/bin/python bench/bench_level_lod.py --rays 32 --radius 1.37 --errors 1e-4 1e-3  # Table 1 (minutes)
    .venv/bin/python bench/bench_level_lod.py --preset small --rays 16           # a quick run

Generates the seeded level (pipeline/geometry/level_gen.py) and bakes it once per LOD setting (the global
pass with ``lod.target_reduction``, then ``lod.max_error`` = each of ``--errors``), each bake fresh, one after
the other in this process. Per bake: the LOD stage's seconds, its simplification tasks (count, largest),
faces kept per kind of piece, and the LOD error table per kind of piece (terrain, Sponzas, houses), from
each piece's held-out points (``OUT/stages/lod/PIECE.npz``) and the gold standard there
(``OUT/stages/lod_reference/``). Writes OUT/level_lod/PRESET/bench_lod.json
and .md.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.pipeline.bakes.level import bake_level  # noqa: E402
from neuralao.pipeline.bakes.level_pieces import index_level  # noqa: E402
from neuralao.pipeline.bakes.level_settings import load_level_settings  # noqa: E402
from neuralao.pipeline.bakes.level_stages import LOD_HELD_OUT, TaskFiles, lod_piece_errors  # noqa: E402
from neuralao.pipeline.geometry.level_files import read_level  # noqa: E402
from neuralao.pipeline.geometry.level_gen import settings_for, write_level  # noqa: E402
from neuralao.runtime.foundation.io import read_npz, write_json, write_text  # noqa: E402


def piece_kinds(level_path: Path, piece_faces: int) -> dict[int, str]:
    """Piece number -> its kind: the name of its meshes' family (terrain, Sponza, houses, mixed)."""
    level = read_level(level_path)
    index = index_level(level, piece_faces)
    kinds = {}
    for p in index.pieces:
        names = {level.meshes[index.nodes[k].mesh].name for k in index.table[p.first : p.stop, 0]}
        fams = {"houses" if n.startswith("house") else n.removeprefix("building_") for n in names}
        kinds[p.index] = fams.pop() if len(fams) == 1 else "houses + " + "/".join(sorted(fams - {"houses"}))
    return kinds


def per_kind(
    bake: Path, keys: dict[str, str], kinds: dict[int, str], source_faces: dict[int, int]
) -> dict[str, dict]:
    """LOD faces kept and the RMSE table per kind, from the pieces' weighted error sums (``keys``: the bake
    log's stage keys)."""
    out: dict[str, dict] = {}
    lod_files = TaskFiles(bake / "stages" / "lod", keys["lod"])
    reference = TaskFiles(bake / "stages" / "lod_reference", keys["lod_check"])
    for i, kind in kinds.items():
        r = lod_files.get(f"p{i:05d}", LOD_HELD_OUT)
        stems = sorted(f.stem for f in reference.folder.glob(f"p{i:05d}_*.npz"))  # its trace blocks
        row = out.setdefault(kind, {"sums": np.zeros(6), "faces": 0, "source_faces": 0})
        row["sums"] += lod_piece_errors(r, reference, stems)
        row["faces"] += len(read_npz(bake / "stages" / "lod_meshes" / f"p{i:05d}.npz")["faces"])
        row["source_faces"] += source_faces[i]
    for row in out.values():
        s = row.pop("sums")
        w = max(s[0], 1e-300)
        mean = s[3] / w
        row.update(
            kept=row["faces"] / max(row["source_faces"], 1),
            holdout=int(s[5]),
            rmse_vertex=float(np.sqrt(s[1] / w)) if s[0] else None,
            rmse_least_squares=float(np.sqrt(s[2] / w)) if s[0] else None,
            rmse_constant=float(np.sqrt(max(s[4] / w - mean**2, 0.0))) if s[0] else None,
        )
    return out


def markdown(result: dict) -> str:
    lines = [
        f"# LOD per piece vs one global simplification ({result['preset']}, {result['rays']} rays)",
        "",
        f"load average before {result['load_before']}, after {result['load_after']} "
        f"({result['cpu_count']} CPUs)",
        "",
        "| LOD | faces kept | LOD stage s | simplify s | simplify tasks (largest s) | RMSE vertex "
        "| RMSE lsq | constant |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["runs"]:
        e = r["errors"]
        lines.append(
            f"| {r['name']} | {r['lod_faces']:,} ({r['kept']:.2f}) | {r['lod_seconds']:.1f} | "
            f"{r['simplify_seconds']:.1f} | {r['simplify_tasks']} ({r['simplify_largest_s']:.2f}) | "
            f"{e['rmse_vertex']:.4f} | {e['rmse_least_squares']:.4f} | {e['rmse_constant']:.4f} |"
        )
    lines += [
        "",
        "| LOD | kind | faces kept | held-out | RMSE vertex | RMSE lsq | constant |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in result["runs"]:
        for kind, k in r["per_kind"].items():
            vals = [
                f"{k[x]:.4f}" if k[x] is not None else "-"
                for x in ("rmse_vertex", "rmse_least_squares", "rmse_constant")
            ]
            lines.append(f"| {r['name']} | {kind} | {k['kept']:.2f} | {k['holdout']} | {' | '.join(vals)} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", default="table1")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--rays", type=int, default=32, help="trace.rays of every bake (the LOD is what differs)")
    p.add_argument("--errors", type=float, nargs="+", default=[3e-5, 1e-4, 1e-3], help="lod.max_error values")
    p.add_argument(
        "--radius", type=float, default=None, help="lod.radius of every bake (default: each its own)"
    )
    p.add_argument("--out", default="build/bench")
    p.add_argument(
        "--keep", action="store_true", help="keep the bake folders (default: removed after reading)"
    )
    args = p.parse_args()
    out = Path(args.out) / "level_lod" / args.preset
    level, cfg = write_level(out / "level", settings_for(args.preset, args.seed), args.preset)
    load_before = list(os.getloadavg())
    runs = []
    variants = [("global", [])] + [
        (f"per piece, max_error {e:g}", [f"lod.max_error={e!r}"]) for e in args.errors
    ]
    kinds = None
    for name, extra in variants:
        fixed = [f"lod.radius={args.radius!r}"] if args.radius else []
        settings = load_level_settings(cfg, [f"trace.rays={args.rays}", *fixed, *extra])
        bake = out / f"bake_{len(runs)}"
        shutil.rmtree(bake, ignore_errors=True)
        info = bake_level(level, settings, bake, progress=False)
        if kinds is None:
            kinds = piece_kinds(level, settings.piece_faces)
            idx = index_level(read_level(level), settings.piece_faces)
            source_faces = {q.index: q.nf for q in idx.pieces}
        st = next(s for s in info["stages"] if s["stage"] == "lod")
        tasks = info["task_seconds"].get("lod", [])
        n_simplify = int(st.get("simplify_tasks", 1))  # one of the whole level, or per piece and tile
        beside = int(st.get("simplified_beside", 0))  # in the solve's wave: not timed apart
        runs.append(
            {
                "name": name,
                "overrides": extra,
                "lod_faces": st["lod_faces"],
                "kept": st["lod_faces"] / info["counts"]["receiver_faces"],
                "lod_seconds": st["seconds"],
                "simplify_seconds": st["seconds_simplify"],
                "simplify_tasks": n_simplify + beside,
                "simplify_largest_s": max(tasks[:n_simplify], default=0.0) if not beside else float("nan"),
                "errors": info["errors"]["lod"],
                "per_kind": per_kind(bake, info["keys"], kinds, source_faces),
            }
        )
        print(json.dumps(runs[-1], indent=1), flush=True)
        if not args.keep:
            shutil.rmtree(bake, ignore_errors=True)
    result = {
        "preset": args.preset,
        "rays": args.rays,
        "radius": args.radius,
        "runs": runs,
        "load_before": load_before,
        "load_after": list(os.getloadavg()),
        "cpu_count": os.cpu_count(),
    }
    write_json(out / "bench_lod.json", result)
    write_text(out / "bench_lod.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
