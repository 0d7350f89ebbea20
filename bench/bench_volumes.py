"""Benchmark the per-region volume AO models (Sloan et al. 2013 section 2.3; pipeline/bakes/volumes.py).

    .venv/bin/python bench/bench_volumes.py --out build/bench [--plot build/bench/volumes_path.png]
        [--seed 3] [--probes 1000] [--directions 1024] [--grid 16]

1. Ground plane: AO above an infinite plane at height z with half distance h, exact by quadrature,
   against its exact linear-SH (bands 0-1) and quadratic-SH (bands 0-2) projections convolved with the
   clamped cosine, over 2,000 normals, for z / h from 0.05 to unbounded (h -> inf: the step, exactly
   linear); plus the traced 1024-direction projection at z / h = 1.
2. Synthetic level: a composed room (pipeline/geometry/compose.py: floor, 4 walls, ceiling, meshes and
   primitives of the train split) split by a partition wall 0.1 thick with a doorway; regions from the
   free space. RMSE of blended AO against traced cosine-weighted obscurance (labeller, ``--ref-rays``,
   both half distances, same blend) at random valid probe positions with random normals: quadratic and
   linear SH, before and after regularisation, for several beta; the SH of each probe point itself
   (no spatial model: the SH truncation floor); boundary jumps at boundary centres and over faces.
3. Cost: bake time (regions, trace, fit, regularisation) and bytes per region.
4. A path that crosses several regions: AO per frame (30 fps, 1.5 units/s) traced, model without
   temporal blending and with tau = 0.15 s (anchored, and blending the packed numbers); drawn to
   ``--plot`` (PNG, matplotlib; default DIR/volumes_path.png).

Writes DIR/volumes.json and DIR/volumes.md.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.pipeline.bakes.volumes import (
    bake_volumes,
    boundary_jumps,
    face_jumps,
    fill_fallbacks,
    make_labeller,
    spherical_ao,
)
from neuralao.pipeline.bakes.volumes import regularise as regularise_models  # noqa: E402
from neuralao.pipeline.geometry.compose import ComposeSettings, compose  # noqa: E402
from neuralao.pipeline.geometry.scene import Scene, scene_from_arrays  # noqa: E402
from neuralao.pipeline.tracing.labeller import LabelSettings  # noqa: E402
from neuralao.runtime.foundation import sh  # noqa: E402
from neuralao.runtime.foundation.io import atomic_path, write_json, write_text  # noqa: E402
from neuralao.runtime.probe import VolumeProbe, blended_path  # noqa: E402
from neuralao.runtime.volumes import Volumes, VolumeSettings

BETAS = (0.0, 0.25, 1.0, 4.0, 16.0)
Z_OVER_H = (0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0, math.inf)


# --------------------------------------------------------------------------- 1. ground plane


def _sphere_quadrature(n_mu: int = 128, n_phi: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Directions (m, 3) and weights (m,) integrating exactly over the sphere up to high order,
    Gauss-Legendre in cos(theta) on [-1, 0] and [0, 1] (the plane's horizon is a node boundary)."""
    g, w = np.polynomial.legendre.leggauss(n_mu)
    mu = np.concatenate([(g - 1) / 2, (g + 1) / 2])
    wmu = np.concatenate([w / 2, w / 2])
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - m * m)
    dirs = np.stack([s * np.cos(p), s * np.sin(p), m], axis=-1).reshape(-1, 3)
    return dirs, (wmu[:, None] * np.full_like(p, 2 * np.pi / n_phi)).reshape(-1)


def plane_visibility(dirs: np.ndarray, z_over_h: float) -> np.ndarray:
    with np.errstate(divide="ignore", over="ignore"):
        below = 1.0 - np.exp2(-z_over_h / np.abs(dirs[:, 2])) if math.isfinite(z_over_h) else 0.0
    return np.where(dirs[:, 2] >= 0, 1.0, below)


def ground_plane(directions: int) -> list[dict]:
    dirs, weight = _sphere_quadrature()
    normals = np.random.default_rng(0).normal(size=(2000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    cosines = np.maximum(normals @ dirs.T, 0.0)
    rows = []
    for zh in Z_OVER_H:
        v = plane_visibility(dirs, zh)
        exact = cosines @ (weight * v) / math.pi
        coeffs = sh.convolve_clamped_cosine((weight * v) @ sh.basis(dirs))
        row = {"z_over_h": zh if math.isfinite(zh) else "inf"}
        for name, count in (("linear", sh.LINEAR), ("quadratic", sh.QUADRATIC)):
            err = sh.evaluate(np.tile(coeffs[:count], (len(normals), 1)), normals) - exact
            row[f"{name}_max"] = float(np.abs(err).max())
            row[f"{name}_rms"] = float(np.sqrt(np.mean(err**2)))
        row["ao_range"] = [float(exact.min()), float(exact.max())]
        rows.append(row)
    # the traced pipeline at z / h = 1 (1024 jittered Fibonacci directions) against the same closed form
    plane = scene_from_arrays(
        np.array([[-1e3, -1e3, 0], [1e3, -1e3, 0], [1e3, 1e3, 0], [-1e3, 1e3, 0.0]]),
        np.array([[0, 1, 2], [0, 2, 3]]),
    )
    s = VolumeSettings(directions=directions)
    lab = make_labeller(plane, s)
    c, _ = spherical_ao(lab, np.array([[0.0, 0.0, 0.5]] * 16), np.arange(16), (0.5, 0.5), s)
    exact = cosines @ (weight * plane_visibility(dirs, 1.0)) / math.pi
    traced = {}
    for name, count in (("linear", sh.LINEAR), ("quadratic", sh.QUADRATIC)):
        err = np.stack([sh.evaluate(np.tile(ci[0, :count], (len(normals), 1)), normals) - exact for ci in c])
        traced[f"{name}_max"] = float(np.abs(err).max())
        traced[f"{name}_rms"] = float(np.sqrt(np.mean(err**2)))
    rows.append({"z_over_h": "1 (traced, 16 points)", **traced})
    return rows


# --------------------------------------------------------------------------- 2. the synthetic level


def _box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Closed axis-aligned box, outward normals: vertices (8, 3), faces (12, 3)."""
    import trimesh

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = trimesh.creation.box(extents=hi - lo)
    return np.asarray(m.vertices) + (lo + hi) / 2, np.asarray(m.faces)


def synthetic_level(seed: int) -> Scene:
    """A composed room (floor y = 0, 4 walls, ceiling) with objects, split at x = 0 by a wall 0.1 thick
    with a 1.0 x 1.6 doorway at z in [-0.5, 0.5]."""
    room = compose(
        ComposeSettings(
            seed=seed,
            objects=(8, 10),
            walls=(4, 4),
            ceiling=1.0,
            room=(5.0, 5.5),
            height=(2.2, 2.4),
            size=(0.3, 1.0),
        )
    )
    (x0, y0, z0), (x1, y1, z1) = room.bounds
    parts = [(room.vertices, room.faces)]
    t = 0.05
    for lo, hi in (
        ((-t, y0, z0), (t, y1, -0.5)),
        ((-t, y0, 0.5), (t, y1, z1)),
        ((-t, 1.6, -0.5), (t, y1, 0.5)),
    ):
        parts.append(_box(lo, hi))
    verts, faces, off = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + off)
        off += len(v)
    return scene_from_arrays(np.concatenate(verts), np.concatenate(faces), f"level-{seed}", "bench", False)


def random_probes(
    vol: Volumes, lab, s: VolumeSettings, count: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Valid points uniform over the union of the regions (by volume) and uniform random normals."""
    rng = np.random.default_rng(seed)
    vols = np.array([np.prod(r.size) for r in vol.regions])
    pts = []
    while sum(len(p) for p in pts) < count:
        k = rng.choice(len(vols), size=count, p=vols / vols.sum())
        lo = np.array([vol.regions[i].lo for i in k])
        hi = np.array([vol.regions[i].hi for i in k])
        p = rng.uniform(lo, hi)
        _, valid = spherical_ao(
            lab, p, np.arange(len(p)) + 10**7, vol.half_distances, replace(s, directions=256)
        )
        pts.append(p[valid])
    p = np.concatenate(pts)[:count]
    n = rng.normal(size=(count, 3))
    return p, n / np.linalg.norm(n, axis=1, keepdims=True)


def traced_ao(lab, vol: Volumes, points: np.ndarray, normals: np.ndarray, rays: int) -> np.ndarray:
    """Cosine-weighted obscurance at both half distances (labeller), blended like the models."""
    out = np.zeros(len(points))
    for k, half in enumerate(vol.half_distances):
        lab.settings = LabelSettings(
            rays=rays,
            kernel="obscurance",
            max_distance_rel=vol.settings.max_distance_rel,
            half_distance=half,
            backface_threshold=None,
            seed=11,
        )
        out += (vol.blend if k else 1.0 - vol.blend) * lab.ao_at_points(points, normals)[0]
    return out


def level_accuracy(
    scene: Scene, s: VolumeSettings, probes: int, ref_rays: int
) -> tuple[dict, Volumes, object]:
    t0 = time.perf_counter()
    vol, extra = bake_volumes(scene, s, progress=True)
    bake_s = time.perf_counter() - t0
    lab = make_labeller(scene, s)
    pts, n = random_probes(vol, lab, s, probes, seed=5)
    t1 = time.perf_counter()
    ref = traced_ao(lab, vol, pts, n, ref_rays)
    ref_s = time.perf_counter() - t1
    probe_regions = VolumeProbe(vol).region_of(pts)

    def rmse(models, order: str) -> float:
        v = Volumes(vol.regions, vol.edges, models, vol.half_distances, vol.blend, s)
        return float(
            np.sqrt(np.mean((VolumeProbe(v).ao(pts, n, order=order, regions=probe_regions) - ref) ** 2))
        )

    # SH of the probe point itself (no spatial model): what a model with a sample at every point would give
    lab_s = make_labeller(scene, s)
    own, _ = spherical_ao(lab_s, pts, np.arange(len(pts)) + 2 * 10**7, vol.half_distances, s)
    w = np.array([1.0 - vol.blend, vol.blend])
    floor = {}
    for order, count in (("linear", sh.LINEAR), ("quadratic", sh.QUADRATIC)):
        g = np.einsum("d,ndj->nj", w, own)[:, :count]
        floor[order] = float(np.sqrt(np.mean((np.clip(sh.evaluate(g, n), 0, 1) - ref) ** 2)))
    placeholder = [
        m if m is not None else replace(extra["models_unregularised"][i]) for i, m in enumerate(extra["fits"])
    ]
    rows = []
    for grid, beta in [(1, b) for b in BETAS] + [(3, b) for b in BETAS[1:]]:
        reg, _ = regularise_models(
            vol.regions, vol.edges, placeholder, extra["grams"], beta, s.iterations, grid
        )
        models = fill_fallbacks(
            vol.regions,
            vol.edges,
            [m if g is not None else None for m, g in zip(reg, extra["grams"], strict=True)],
        )
        area = np.array([e.area for e in vol.edges])
        row = {"beta": beta, "boundary_grid": grid}
        for order, count in (("quadratic", sh.QUADRATIC), ("linear", sh.LINEAR)):
            row[f"rmse_{order}"] = rmse(models, order)
            jc = boundary_jumps(vol.edges, models, vol.blend, count)
            jf = face_jumps(vol.regions, vol.edges, models, vol.blend, count)
            row[f"jump_centre_{order}"] = float((jc * area).sum() / area.sum())
            row[f"jump_face_{order}"] = float((jf * area).sum() / area.sum())
        rows.append(row)
    st = vol.stats
    nreg = st["regions"]
    result = {
        "scene": vol.scene,
        "regions": nreg,
        "edges": st["edges"],
        "valid_fraction": st["valid_samples"] / (nreg * st["samples_per_region"]),
        "fallback_regions": st["fallback_regions"],
        "probes": int(len(pts)),
        "ref_rays": ref_rays,
        "ref_seconds": ref_s,
        "sh_at_probe_rmse": floor,
        "ao_mean": float(ref.mean()),
        "ao_std": float(ref.std()),
        "betas": rows,
        "default_beta": s.beta,
        "bake_seconds": bake_s,
        "seconds": st["seconds"],
        "rays": st["rays"],
        "per_region_ms": {k: 1e3 * v / nreg for k, v in st["seconds"].items()},
        "bytes_per_region": {
            "json_model (3 + 7 x 18 float32)": 4 * (3 + 7 * 18),
            "glsl_linear (8 vec4)": 128,
            "glsl_quadratic (22 vec4)": 352,
        },
    }
    unregularised = Volumes(
        vol.regions, vol.edges, extra["models_unregularised"], vol.half_distances, vol.blend, s
    )
    return result, vol, lab, unregularised


def path_through(vol: Volumes) -> np.ndarray:
    """Positions (T, 3): a straight walk at 1.5 units/s, 30 fps, across the level through the doorway,
    at height 1.0 (y up), from x = -2.2 to 2.2 at z = 0.1."""
    x = np.arange(-2.2, 2.2, 1.5 / 30)
    return np.stack([x, np.full_like(x, 1.0), np.full_like(x, 0.1)], axis=1)


def path_study(vol: Volumes, lab, ref_rays: int, tau: float, unregularised: Volumes) -> dict:
    pos = path_through(vol)
    n = np.tile([0.0, 0.0, -1.0], (len(pos), 1))  # a face looking along -z (towards the partition's side)
    probe = VolumeProbe(vol)
    ref = traced_ao(lab, vol, pos, n, ref_rays)
    hard = blended_path(probe, pos, n, dt=1 / 30, tau=0.0, order="linear")
    soft = blended_path(probe, pos, n, dt=1 / 30, tau=tau, order="linear")
    params = blended_path(probe, pos, n, dt=1 / 30, tau=tau, order="linear", mode="parameters")
    quadratic = blended_path(probe, pos, n, dt=1 / 30, tau=0.0, order="quadratic")
    raw = VolumeProbe(unregularised)
    hard_raw = blended_path(raw, pos, n, dt=1 / 30, tau=0.0, order="linear")
    soft_raw = blended_path(raw, pos, n, dt=1 / 30, tau=tau, order="linear")
    regions = probe.region_of(pos)
    switch = np.diff(regions) != 0  # frame k -> k + 1 changes region

    def steps(a: np.ndarray) -> dict:
        d = np.abs(np.diff(a))
        return {
            "at_switches": float(d[switch].max(initial=0.0)),
            "elsewhere": float(d[~switch].max(initial=0.0)),
        }

    return {
        "x": pos[:, 0].tolist(),
        "traced": ref.tolist(),
        "no_blend": hard.tolist(),
        "blend": soft.tolist(),
        "blend_parameters": params.tolist(),
        "no_blend_quadratic": quadratic.tolist(),
        "steps": {
            "no_blend": steps(hard),
            "blend": steps(soft),
            "blend_parameters": steps(params),
            "unregularised_no_blend": steps(hard_raw),
            "unregularised_blend": steps(soft_raw),
        },
        "unregularised_no_blend": hard_raw.tolist(),
        "rmse_no_blend_quadratic": float(np.sqrt(np.mean((quadratic - ref) ** 2))),
        "ref_rays": ref_rays,
        "tau": tau,
        "regions": regions.tolist(),
        "switches": int((np.diff(regions) != 0).sum()),
        "max_step_no_blend": float(np.abs(np.diff(hard)).max()),
        "max_step_blend": float(np.abs(np.diff(soft)).max()),
        "max_step_blend_parameters": float(np.abs(np.diff(params)).max()),
        # how far the parameter blend leaves the range spanned by the two models it mixes
        "overshoot_parameters": float(np.maximum(np.minimum(hard[:-1], hard[1:]) - params[1:], 0).max()),
        "rmse_no_blend": float(np.sqrt(np.mean((hard - ref) ** 2))),
        "rmse_blend": float(np.sqrt(np.mean((soft - ref) ** 2))),
    }


def plot_path(path: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.asarray(path["x"])
    fig, ax = plt.subplots(figsize=(8, 4.0), dpi=120)
    r = np.asarray(path["regions"])
    for k in np.flatnonzero(np.diff(r) != 0):
        ax.axvline((x[k] + x[k + 1]) / 2, color="0.85", lw=0.8, zorder=0)
    ax.plot(x, path["traced"], color="k", lw=1.2, label=f"traced ({path['ref_rays']} rays)")
    ax.plot(x, path["no_blend_quadratic"], color="0.55", lw=1.0, label="model, quadratic SH, no blending")
    ax.plot(x, path["no_blend"], color="tab:red", lw=1.0, drawstyle="steps-mid", label="model, no blending")
    ax.plot(
        x,
        path["blend"],
        color="tab:blue",
        lw=1.4,
        label=f"model, temporal blend tau = {path['tau']} s (anchored)",
    )
    ax.plot(
        x,
        path["blend_parameters"],
        color="tab:orange",
        lw=1.0,
        ls="--",
        label="same, blending packed numbers",
    )
    ax.set_xlabel("x along the path (units; 30 fps at 1.5 units/s; grey lines: region switches)")
    ax.set_ylabel("AO (linear SH unless noted)")
    ax.legend(loc="lower center", fontsize=7, ncol=2)
    fig.tight_layout()
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


# --------------------------------------------------------------------------- report


def markdown(r: dict) -> str:
    lines = [
        "# Volume AO models (bench/bench_volumes.py)",
        "",
        "## Ground plane: SH error of AO at height z, half distance h",
        "",
    ]
    lines += [
        "| z / h | linear max | linear RMS | quadratic max | quadratic RMS |",
        "|---|---:|---:|---:|---:|",
    ]
    for row in r["ground_plane"]:
        lines.append(
            f"| {row['z_over_h']} | {row['linear_max']:.4f} | {row['linear_rms']:.4f} | "
            f"{row['quadratic_max']:.4f} | {row['quadratic_rms']:.4f} |"
        )
    lv = r["level"]
    lines += [
        "",
        f"## Synthetic level {lv['scene']['name']}: {lv['regions']} regions, "
        f"{lv['edges']} edges, {lv['probes']} probes vs {lv['ref_rays']}-ray traced AO (mean "
        f"{lv['ao_mean']:.3f}, sd {lv['ao_std']:.3f})",
        "",
    ]
    lines += [
        "| agreement points | beta | RMSE quadratic | RMSE linear | jump centre (quad) | jump face (quad) "
        "| jump face (linear) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for row in lv["betas"]:
        where = (
            "face centre"
            if row["boundary_grid"] == 1
            else f"{row['boundary_grid']}x{row['boundary_grid']} on the face"
        )
        lines.append(
            f"| {where} | {row['beta']:g} | {row['rmse_quadratic']:.4f} | "
            f"{row['rmse_linear']:.4f} | {row['jump_centre_quadratic']:.4f} | "
            f"{row['jump_face_quadratic']:.4f} | {row['jump_face_linear']:.4f} |"
        )
    f = lv["sh_at_probe_rmse"]
    lines += [
        "",
        f"SH of each probe point itself (no spatial model): RMSE quadratic {f['quadratic']:.4f}, "
        f"linear {f['linear']:.4f}.",
        "",
    ]
    sec = lv["seconds"]
    lines += [
        f"Bake: {lv['bake_seconds']:.1f} s total for {lv['regions']} regions "
        f"({lv['rays'] / 1e6:.1f} M rays): "
        + ", ".join(f"{k} {v:.2f} s" for k, v in sec.items())
        + "; per region "
        + ", ".join(f"{k} {v:.0f} ms" for k, v in lv["per_region_ms"].items())
        + ".",
        "Bytes per region: " + ", ".join(f"{k} {v} B" for k, v in lv["bytes_per_region"].items()) + ".",
    ]
    p = r["path"]
    st = p["steps"]
    lines += [
        "",
        "Largest frame-to-frame AO change along the path, at region switches / elsewhere: "
        + "; ".join(f"{k} {v['at_switches']:.4f} / {v['elsewhere']:.4f}" for k, v in st.items())
        + f". RMSE vs traced, quadratic SH without blending: {p['rmse_no_blend_quadratic']:.4f}.",
    ]
    lines += [
        "",
        f"Path: {len(p['x'])} frames, {p['switches']} region switches; largest frame-to-frame AO step "
        f"{p['max_step_no_blend']:.4f} without blending, {p['max_step_blend']:.4f} with tau = {p['tau']} s; "
        f"RMSE vs traced {p['rmse_no_blend']:.4f} / {p['rmse_blend']:.4f}; blending the packed numbers "
        f"(centre included) instead: step {p['max_step_blend_parameters']:.4f}, dips up to "
        f"{p['overshoot_parameters']:.4f} below both models.",
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("build/bench"))
    ap.add_argument(
        "--plot", type=Path, default=None, help="PNG of AO along the path (default OUT/volumes_path.png)"
    )
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--probes", type=int, default=1000)
    ap.add_argument("--ref-rays", type=int, default=1024)
    ap.add_argument("--directions", type=int, default=1024)
    ap.add_argument("--grid", type=int, default=16)
    ap.add_argument("--tau", type=float, default=0.15)
    args = ap.parse_args(argv)
    result = {"ground_plane": ground_plane(args.directions)}
    scene = synthetic_level(args.seed)
    s = VolumeSettings(directions=args.directions, grid=args.grid)
    result["level"], vol, lab, unregularised = level_accuracy(scene, s, args.probes, args.ref_rays)
    result["path"] = path_study(vol, lab, args.ref_rays, args.tau, unregularised)
    write_json(args.out / "volumes.json", result)
    write_text(args.out / "volumes.md", markdown(result))
    plot_path(result["path"], args.plot or args.out / "volumes_path.png")
    sys.stdout.write(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
