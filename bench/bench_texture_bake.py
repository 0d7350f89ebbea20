"""Texture bakes against vertex bakes on low-poly meshes, and against the closed form of a floor by a wall.

Error: area-weighted RMSE at held-out stratified surface samples against a 1024-ray Embree reference
(other positions, other rays), the texture read the way a viewer reads it (bilinear lookup of the
8-bit map), vertex bakes interpolated across faces. Bytes: the AO payload only (PNG file, or the raw
N x N 8-bit texels; vertex AO as 8-bit grey per vertex or float32), plus the UVs a texture needs
(2 float32 per output vertex). Writes build/bench/texture_bake.json and .md.

    .venv/bin/python bench/bench_texture_bake.py [--meshes cornell_box suzanne] [--resolutions 64 128 256 512]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from neuralao.pipeline.bakes.texture import (  # noqa: E402
    TextureBakeSettings,
    bake_texture,
    load_uv_mesh,
    point_uvs,
    quantise,
    sample_bilinear,
)
from neuralao.pipeline.bakes.vertex import BakeSettings, bake, reference_at_samples  # noqa: E402
from neuralao.pipeline.geometry.scene import load_scene  # noqa: E402
from neuralao.pipeline.geometry.surface import interpolate, surface_samples  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402


def png_bytes(image_u8: np.ndarray) -> int:
    buf = io.BytesIO()
    Image.fromarray(image_u8, mode="L").save(buf, format="PNG")
    return len(buf.getvalue())


def weighted_rmse(pred, ref, valid, weights) -> float:
    w = weights[valid] / weights[valid].sum()
    d = pred[valid] - ref[valid]
    return float(math.sqrt(np.sum(w * d * d)))


def bench_mesh(name: str, resolutions: list[int], rays: int) -> list[dict]:
    scene = load_scene(name)
    settings = BakeSettings(rays=rays)
    held = surface_samples(scene, 20000, cap=4000, seed=99)
    ref, ref_valid = reference_at_samples(scene, held, settings, rays=1024)
    rows = []
    for method in ("vertex", "least-squares"):
        r = bake(scene, replace(settings, method=method))
        pred8 = interpolate(scene, np.rint(r.ao * 255) / 255, held.face, held.bary)
        rows.append(
            {
                "mesh": name,
                "method": f"{method} (8-bit)",
                "rmse": weighted_rmse(pred8, ref, ref_valid, held.weights),
                "bytes": len(scene.vertices),
                "bytes_uv": 0,
                "seconds": r.info["seconds"],
            }
        )
    for n in resolutions:
        tset = TextureBakeSettings(resolution=n, rays=rays)
        mesh = load_uv_mesh(name, tset)
        # the atlas keeps the face order (checked), so scene face f is mesh face f
        assert np.allclose(mesh.vertices[mesh.faces], scene.triangles)
        result = bake_texture(mesh, tset)
        img8 = quantise(result.ao)
        pred = sample_bilinear(img8 / 255.0, point_uvs(mesh, held.face, held.bary))
        rows.append(
            {
                "mesh": name,
                "method": f"texture {n}x{n} ({mesh.uv_source} UVs)",
                "rmse": weighted_rmse(pred, ref, ref_valid, held.weights),
                "bytes": png_bytes(img8),
                "bytes_raw": n * n,
                "bytes_uv": 8 * len(mesh.vertices),
                "seconds": result.info["seconds"],
                "coverage": result.info["coverage"],
            }
        )
    return rows


def bench_corner(resolutions: list[int], rays: int) -> list[dict]:
    from test_texture_bake import R, closed_form, corner_mesh, random_surface_points

    mesh = corner_mesh()
    face, bary, points = random_surface_points(mesh, 20000, seed=7)
    expected, ok = closed_form(points)
    rows = []
    scene = mesh.scene()
    for method in ("vertex", "least-squares"):
        r = bake(
            scene,
            BakeSettings(
                rays=rays, max_distance=R, method=method, samples_per_vertex=512, samples_per_face_cap=2048
            ),
        )
        pred = np.einsum("kc,kc->k", bary, r.ao[mesh.faces[face]].astype(np.float64))
        rows.append(
            {
                "mesh": "floor+wall (closed form)",
                "method": method,
                "rmse": float(np.sqrt(np.mean((pred - expected)[ok] ** 2))),
                "bytes": len(scene.vertices),
            }
        )
    for n in resolutions:
        result = bake_texture(mesh, TextureBakeSettings(resolution=n, margin=2, rays=rays, max_distance=R))
        img8 = quantise(result.ao)
        pred = sample_bilinear(img8 / 255.0, point_uvs(mesh, face, bary))
        rows.append(
            {
                "mesh": "floor+wall (closed form)",
                "method": f"texture {n}x{n}",
                "rmse": float(np.sqrt(np.mean((pred - expected)[ok] ** 2))),
                "bytes": png_bytes(img8),
                "bytes_raw": n * n,
            }
        )
    return rows


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", nargs="+", default=["cornell_box", "suzanne"])
    ap.add_argument("--resolutions", nargs="+", type=int, default=[64, 128, 256, 512])
    ap.add_argument("--rays", type=int, default=256)
    ap.add_argument("--out", default=str(ROOT / "build" / "bench"))
    args = ap.parse_args()
    rows = bench_corner(args.resolutions, args.rays)
    for m in args.meshes:
        rows += bench_mesh(m, args.resolutions, args.rays)
    out = Path(args.out)
    write_json(out / "texture_bake.json", {"rays": args.rays, "rows": rows})
    lines = ["| mesh | method | RMSE | AO bytes | + UV bytes |", "|---|---|---:|---:|---:|"]
    for r in rows:
        raw = f" (raw {r['bytes_raw']})" if "bytes_raw" in r else ""
        lines.append(
            f"| {r['mesh']} | {r['method']} | {r['rmse']:.4f} | {r['bytes']}{raw} | {r.get('bytes_uv', 0)} |"
        )
    write_text(out / "texture_bake.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    print(json.dumps({"out": str(out / "texture_bake.json")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
