"""`neuralao level`: seeded synthetic game levels (glTF + bake config) for tests and benchmarks.

A level (Y up, metres) holds a terrain heightfield, buildings (shared test meshes placed as nodes
that reference one mesh, plus procedural houses made of overlapping boxes with split vertices:
triangle soup), a ring of blocker walls, and EXT_mesh_gpu_instancing nodes of trees, shrubs and
grass clumps standing on the terrain. Every random choice comes from one ``numpy`` generator seeded
by ``seed``, so a preset and a seed give the same bytes.

Presets: ``tiny`` (tests, ~3k faces), ``small`` (a demo, ~60k faces), ``table1`` (the scale of
Table 1 of Sloan et al. 2013: >= 1.5M vertices and >= 1.8M faces of baked geometry) and ``world10x``
(ten times Table 1, ~18M faces, the same mix over ten times the area).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from neuralao.pipeline.geometry.gltf import quat_to_matrix
from neuralao.pipeline.geometry.level_files import MIN_INSTANCE_REL, GltfWriter
from neuralao.pipeline.geometry.scene import Scene, load_scene
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json
from neuralao.runtime.foundation.limits import (
    available_memory,
    check_count,
    check_int_range,
    check_seed,
    format_bytes,
)
from neuralao.runtime.foundation.settings import apply_overrides, from_dict, parse_override, settings_to_dict


@dataclass
class BuildingSpec:
    # Shared test mesh name (resolved like every scene name: ../shared/assets/meshes/<name>).
    mesh: str = "cornell_box"
    # How many placements (nodes referencing the one mesh).
    count: int = 1
    # Uniform scale applied to the mesh.
    scale: float = 1.0


@dataclass
class LevelGenSettings:
    # Terrain side length (m) and cells per side (vertices = (cells + 1)^2, faces = 2 cells^2).
    terrain_size: float = 40.0
    terrain_cells: int = 24
    # Height amplitude of the terrain (m).
    terrain_height: float = 2.0
    # Procedural houses: count, boxes per house (split vertices: 24 per box).
    houses: int = 2
    house_boxes: int = 3
    # Buildings from the shared meshes.
    buildings: list[BuildingSpec] = field(default_factory=lambda: [BuildingSpec("cornell_box", 1, 2.0)])
    # Instanced decorators.
    trees: int = 3
    shrubs: int = 12
    grass: int = 20
    # Shrub media density (per metre inside the box) and tree transmission per hit.
    shrub_density: float = 0.8
    tree_transmission: float = 0.5
    # Sphere subdivisions of tree crowns and shrubs (1: 80 faces, 2: 320).
    crown_subdivisions: int = 1
    # Blocker walls around the terrain (height, m, >= 0; 0 = none).
    blocker_height: float = 6.0
    # Seed of every random choice.
    seed: int = 0


PRESETS: dict[str, dict] = {
    "tiny": {},
    "small": {
        "terrain_size": 120.0,
        "terrain_cells": 120,
        "houses": 40,
        "trees": 12,
        "shrubs": 200,
        "grass": 400,
        "buildings": [
            {"mesh": "cornell_box", "count": 4, "scale": 3.0},
            {"mesh": "sponza_partial", "count": 1, "scale": 0.01},
        ],
    },
    # Table 1 of Sloan et al.: 1.5M V / 1.8M F of geometry, 46 trees, 7856 shrub proxies.
    "table1": {
        "terrain_size": 600.0,
        "terrain_cells": 660,
        "terrain_height": 12.0,
        "houses": 6000,
        "house_boxes": 5,
        "trees": 46,
        "shrubs": 7856,
        "grass": 20000,
        "crown_subdivisions": 2,
        "buildings": [
            {"mesh": "Sponza", "count": 2, "scale": 1.0},
            {"mesh": "sponza_partial", "count": 2, "scale": 0.02},
        ],
    },
    # Ten times table1: ten times the area (600 m x sqrt(10)) and of every count. Faces: terrain
    # 2 x 2087^2 = 8.71M, 60,000 houses x 5 boxes x 12 = 3.6M, 20 + 20 Sponzas 5.92M: 18.2M
    # (table1: 0.87M + 0.36M + 0.59M = 1.82M).
    "world10x": {
        "terrain_size": 1897.0,
        "terrain_cells": 2087,
        "terrain_height": 12.0,
        "houses": 60000,
        "house_boxes": 5,
        "trees": 460,
        "shrubs": 78560,
        "grass": 200000,
        "crown_subdivisions": 2,
        "buildings": [
            {"mesh": "Sponza", "count": 20, "scale": 1.0},
            {"mesh": "sponza_partial", "count": 20, "scale": 0.02},
        ],
    },
}

# The bake config each preset is written with (neuralao.pipeline.bakes.level_settings.LevelBakeSettings keys).
BAKE_CONFIGS: dict[str, dict] = {
    "tiny": {
        "trace": {"rays": 64, "samples_per_vertex": 2.0, "samples_per_face_cap": 4},
        "decorators": {"samples_per_instance": 256, "holdout_samples": 256, "local_rays": 64},
        "lod": {"target_reduction": 0.5, "holdout_samples": 400},
    },
    "small": {"trace": {"rays": 128}},
    "table1": {
        "trace": {
            "rays": 256,
            "samples_per_vertex": 1.25,
            "samples_per_face_cap": 2,
            "min_samples_per_face": 0,
        }
    },
    # Table 1's settings at ten times the size (the solve is per piece and per connected component).
    "world10x": {
        "trace": {
            "rays": 256,
            "samples_per_vertex": 1.25,
            "samples_per_face_cap": 2,
            "min_samples_per_face": 0,
        }
    },
}


# --------------------------------------------------------------------------- geometry


def terrain_height(x: np.ndarray, z: np.ndarray, s: LevelGenSettings, phases: np.ndarray) -> np.ndarray:
    """Smooth seeded heightfield: a sum of 4 sinusoid pairs of decreasing wavelength."""
    h = np.zeros_like(np.asarray(x, np.float64))
    for k in range(4):
        w = 2 * math.pi * (k + 1) / s.terrain_size
        h += s.terrain_height / (k + 1) * np.sin(w * x + phases[k, 0]) * np.cos(w * z + phases[k, 1])
    return h


def terrain(s: LevelGenSettings, phases: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = s.terrain_cells
    t = np.linspace(-s.terrain_size / 2, s.terrain_size / 2, n + 1)
    xx, zz = np.meshgrid(t, t, indexing="ij")
    v = np.stack([xx.ravel(), terrain_height(xx, zz, s, phases).ravel(), zz.ravel()], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    # (a, d, c) / (a, c, b) winds counter-clockwise seen from +Y: normals point up.
    return v, np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)])


def box_soup(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box with split vertices (24 V, 12 F, outward normals): flat-shaded game geometry."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts, faces = [], []
    for axis in range(3):
        for side in (0, 1):
            u, w = [(axis + 1) % 3, (axis + 2) % 3]
            quad = []
            for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = lo.copy()
                p[axis] = (lo, hi)[side][axis]
                p[u] = (lo, hi)[a][u]
                p[w] = (lo, hi)[b][w]
                quad.append(p)
            base = len(verts)
            verts.extend(quad)
            f = [[base, base + 1, base + 2], [base, base + 2, base + 3]]
            faces.extend(f if side == 1 else [r[::-1] for r in f])
    return np.array(verts), np.array(faces, np.int64)


def ellipsoid(center, radii, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    import trimesh  # measured: ~1 s to import; only the file readers and writers need it

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return np.asarray(m.vertices) * np.asarray(radii) + np.asarray(center), np.asarray(m.faces, np.int64)


def prism(radius: float, height: float, sides: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Closed vertical prism (trunk), base at y = 0, outward normals."""
    a = np.linspace(0, 2 * math.pi, sides, endpoint=False)
    ring = np.stack([radius * np.cos(a), np.zeros(sides), -radius * np.sin(a)], 1)
    v = np.concatenate([ring, ring + [0, height, 0], [[0, 0, 0], [0, height, 0]]])
    f = []
    for i in range(sides):
        j = (i + 1) % sides
        f += [
            [i, j, sides + j],
            [i, sides + j, sides + i],
            [2 * sides, j, i],
            [2 * sides + 1, sides + i, sides + j],
        ]
    return v, np.array(f, np.int64)


def merge_parts(*parts) -> tuple[np.ndarray, np.ndarray]:
    verts, faces, off = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + off)
        off += len(v)
    return np.concatenate(verts), np.concatenate(faces)


def house(rng: np.random.Generator, boxes: int) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping boxes (body, wings, chimney...), base at y = -0.3 (sunk into the terrain)."""
    parts = []
    w, d, h = rng.uniform(4, 9), rng.uniform(4, 9), rng.uniform(3, 7)
    parts.append(box_soup([-w / 2, -0.3, -d / 2], [w / 2, h, d / 2]))
    for _ in range(boxes - 1):
        cx, cz = rng.uniform(-w / 2, w / 2), rng.uniform(-d / 2, d / 2)
        bw, bd, bh = rng.uniform(1, w / 1.5), rng.uniform(1, d / 1.5), rng.uniform(1, h * 1.3)
        parts.append(box_soup([cx - bw / 2, -0.3, cz - bd / 2], [cx + bw / 2, bh, cz + bd / 2]))
    return merge_parts(*parts)


def tree_model(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Trunk + a crown of five overlapping leaf clusters (interpenetrating closed parts: the crown
    shades itself, which is what the per-model local AO captures)."""
    clusters = [
        ellipsoid(c, r, subdivisions)
        for c, r in (
            ([0, 6.2, 0], [1.6, 1.5, 1.6]),
            ([1.3, 5.0, 0.2], [1.3, 1.1, 1.2]),
            ([-1.2, 5.1, -0.4], [1.2, 1.1, 1.3]),
            ([0.2, 4.9, 1.3], [1.2, 1.0, 1.1]),
            ([-0.1, 5.0, -1.4], [1.1, 1.0, 1.2]),
        )
    ]
    return merge_parts(prism(0.3, 5.0), *clusters)


def shrub_model(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    return ellipsoid([0, 0.35, 0], [0.8, 0.55, 0.8], subdivisions)


def grass_model() -> tuple[np.ndarray, np.ndarray]:
    """Three crossed blades (thin quads), 0.4 m tall."""
    parts = []
    for k in range(3):
        a = k * math.pi / 3
        c, s = 0.15 * math.cos(a), 0.15 * math.sin(a)
        v = np.array([[-c, 0, -s], [c, 0, s], [c, 0.4, s], [-c, 0.4, -s]])
        parts.append((v, np.array([[0, 1, 2], [0, 2, 3]], np.int64)))
    return merge_parts(*parts)


def _yaw_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    yaw = rng.uniform(0, 2 * math.pi, n)
    return np.stack([np.zeros(n), np.sin(yaw / 2), np.zeros(n), np.cos(yaw / 2)], 1)


def _scatter(
    rng: np.random.Generator, n: int, s: LevelGenSettings, phases: np.ndarray, margin: float, sink: float
):
    half = max(s.terrain_size / 2 - margin, 0.0)  # a terrain narrower than the margins: at its centre
    x, z = rng.uniform(-half, half, n), rng.uniform(-half, half, n)
    return np.stack([x, terrain_height(x, z, s, phases) - sink, z], 1)


# --------------------------------------------------------------------------- level


def generate(s: LevelGenSettings) -> GltfWriter:
    """The glTF of a synthetic level for settings ``s`` (deterministic for ``s.seed``)."""
    check(s)
    buildings = _building_meshes(s)  # checked before anything else is made
    rng = np.random.default_rng(s.seed)
    phases = rng.uniform(0, 2 * math.pi, (4, 2))
    g = GltfWriter("neuralao level generator")
    g.doc["extras"] = {"generator": settings_to_dict(s)}
    tv, tf = terrain(s, phases)
    g.node("terrain", g.mesh("terrain", tv, tf), extras={"role": "static"})
    for k, b in enumerate(s.buildings):
        sc, v = buildings[k]
        mesh = g.mesh(f"building_{b.mesh}", v, sc.faces)
        half = np.abs(v).max(axis=0)[[0, 2]].max()
        pos = _scatter(rng, b.count, s, phases, min(half, s.terrain_size / 3), 0.5)
        for j, p in enumerate(pos):
            m = np.eye(4)
            yaw = rng.choice([0.0, 0.5, 1.0, 1.5]) * math.pi
            m[:3, :3] = [[math.cos(yaw), 0, math.sin(yaw)], [0, 1, 0], [-math.sin(yaw), 0, math.cos(yaw)]]
            m[:3, 3] = p
            g.node(f"building_{k}_{j}", mesh, matrix=np.round(m, 12), extras={"role": "static"})
    if s.houses:
        # A handful of house models, each placed several times (shared meshes, as in a game).
        models = [g.mesh(f"house{i}", *house(rng, s.house_boxes)) for i in range(min(s.houses, 16))]
        pos = _scatter(rng, s.houses, s, phases, 8.0, 0.0)
        quats = _yaw_quats(rng, s.houses)
        for i, (p, q) in enumerate(zip(pos, quats, strict=True)):
            m = np.eye(4)
            m[:3, :3] = quat_to_matrix(q)[0]
            m[:3, 3] = p
            g.node(f"house_{i}", models[i % len(models)], matrix=m, extras={"role": "static"})
    if s.blocker_height > 0:
        h, t = s.terrain_size / 2, 2.0
        walls = [
            box_soup([-h - t, -s.terrain_height * 2, -h - t], [h + t, s.blocker_height, -h]),
            box_soup([-h - t, -s.terrain_height * 2, h], [h + t, s.blocker_height, h + t]),
            box_soup([-h - t, -s.terrain_height * 2, -h], [-h, s.blocker_height, h]),
            box_soup([h, -s.terrain_height * 2, -h], [h + t, s.blocker_height, h]),
        ]
        g.node("blocker_walls", g.mesh("walls", *merge_parts(*walls)), extras={"role": "blocker"})
    for role, count, model, extras, margin, sink in (
        ("tree", s.trees, tree_model(s.crown_subdivisions), {"transmission": s.tree_transmission}, 6.0, 0.1),
        ("shrub", s.shrubs, shrub_model(s.crown_subdivisions), {"density": s.shrub_density}, 3.0, 0.1),
        ("grass", s.grass, grass_model(), {}, 2.0, 0.05),
    ):
        if count == 0:
            continue
        pos = _scatter(rng, count, s, phases, margin, sink)
        inst = {
            "TRANSLATION": pos,
            "ROTATION": _yaw_quats(rng, count),
            "SCALE": np.repeat(rng.uniform(0.8, 1.25, (count, 1)), 3, axis=1),
        }
        g.node(f"{role}s", g.mesh(role, *model), extras={"role": role, **extras}, instances=inst)
    return g


# Bytes the generator allocates per unit of each count (generous: the numpy arrays, their float32 copies in
# the glTF writer, its binary buffer and the JSON of nodes), so a count the machine cannot hold is refused
# before anything is allocated, naming the setting and its bound.
TERRAIN_VERTEX_BYTES = 512  # (terrain_cells + 1)^2 vertices, two faces per cell, height temporaries
HOUSE_BYTES = 4096  # a node: its matrix, name and extras in the document, and its JSON text
HOUSE_BOX_BYTES = 16 * 4096  # one box in each of the (up to 16) house models
INSTANCE_BYTES = 512  # a tree, shrub or grass instance: TRS arrays, float32 copies, buffer bytes
CROWN_FACE_BYTES = 6 * 256  # an icosphere face in each of the tree's 5 crown clusters and the shrub
# Icosphere subdivisions: 20 x 4^k faces; past 10 (21M faces a sphere) no level needs them.
MAX_CROWN_SUBDIVISIONS = 10
# Largest terrain_size, |terrain_height|, blocker_height and building size (m). A bake refuses an instance
# spanning less than MIN_INSTANCE_REL (2^-36) of the level's reach (its float64 coordinates could not
# resolve it): the smallest instance placed here, a 0.45 m grass clump, allows a reach of 3e10 m, 10x what
# these bounds let a level reach (the terrain reaches 25/12 terrain_height, a building on it its own size).
MAX_LEVEL_SIZE = 1e9
# Above the terrain (and beyond its edge), what the generator places reaches at most this far (m): trees
# 7.7 m at scale 1.25, houses 9.1 m, the 2 m walls.
DECORATION_REACH = 10.0


def _memory(s: LevelGenSettings) -> dict[str, float]:
    """Bytes each count of ``s`` makes the generator allocate (see the constants above)."""
    return {
        "terrain_cells": (s.terrain_cells + 1) ** 2 * TERRAIN_VERTEX_BYTES,
        "houses": s.houses * HOUSE_BYTES,
        "house_boxes": s.house_boxes * HOUSE_BOX_BYTES,
        "trees": s.trees * INSTANCE_BYTES,
        "shrubs": s.shrubs * INSTANCE_BYTES,
        "grass": s.grass * INSTANCE_BYTES,
        "crown_subdivisions": 20 * 4**s.crown_subdivisions * CROWN_FACE_BYTES,
        "buildings": sum(b.count for b in s.buildings) * HOUSE_BYTES,
    }


def check(s: LevelGenSettings) -> None:
    """Every setting in its range, and every count within what this machine can hold, before anything is
    allocated; each refusal is one line naming the setting (and the bound)."""
    check_seed("seed", s.seed)
    for name in ("terrain_cells", "house_boxes", "houses", "trees", "shrubs", "grass"):
        low = 1 if name in ("terrain_cells", "house_boxes") else 0
        check_count(name, getattr(s, name), low=low, bytes_each=1)  # an integer >= low; memory below
    check_int_range("crown_subdivisions", s.crown_subdivisions, 0, MAX_CROWN_SUBDIVISIONS)
    # past MAX_LEVEL_SIZE the level's small decorators fall below what its bake resolves, and is refused
    past = "; a level's grass clumps (0.45 m) would be below what its bake resolves"
    if not 0 < s.terrain_size <= MAX_LEVEL_SIZE:
        raise NeuralaoError(f"terrain_size must be in (0, {MAX_LEVEL_SIZE:g}] m, got {s.terrain_size}{past}")
    if not abs(s.terrain_height) <= MAX_LEVEL_SIZE:
        raise NeuralaoError(
            f"terrain_height must be within +-{MAX_LEVEL_SIZE:g} m, got {s.terrain_height}{past}"
        )
    if not 0 <= s.blocker_height <= MAX_LEVEL_SIZE:
        raise NeuralaoError(
            f"blocker_height must be in [0, {MAX_LEVEL_SIZE:g}] m (0: no walls), got {s.blocker_height}"
        )
    if not s.shrub_density >= 0:
        raise NeuralaoError(f"shrub_density must be >= 0, got {s.shrub_density}")
    if not 0 <= s.tree_transmission <= 1:
        raise NeuralaoError(f"tree_transmission must be in [0, 1], got {s.tree_transmission}")
    for b in s.buildings:
        if b.count < 0 or not 0 < b.scale <= MAX_LEVEL_SIZE:
            raise NeuralaoError(
                f"building {b.mesh!r}: count must be >= 0 and scale in (0, {MAX_LEVEL_SIZE:g}], "
                f"got count {b.count}, scale {b.scale}"
            )
    need = _memory(s)
    avail = available_memory()
    for name, nbytes in need.items():
        if nbytes > avail:
            raise NeuralaoError(
                f"{name} {_shown(s, name)} is more than this machine can hold: about {format_bytes(nbytes)} "
                f"of memory, {format_bytes(avail)} available (at most {_largest(name, s, avail)})"
            )
    if sum(need.values()) > avail:
        top = sorted(need, key=need.get, reverse=True)[:3]
        raise NeuralaoError(
            f"the level's counts together need about {format_bytes(sum(need.values()))} of memory, "
            f"{format_bytes(avail)} available (most: {', '.join(f'{n} {_shown(s, n)}' for n in top)})"
        )


def _building_meshes(s: LevelGenSettings) -> list[tuple[Scene, np.ndarray]]:
    """Each building's scene and its vertices (n, 3) float64 as placed (based on y = 0, centred in x / z,
    scaled), checked so that the bake takes the level: at most ``MAX_LEVEL_SIZE`` from its base, and
    spanning at least ``MIN_INSTANCE_REL`` of the level's reach (bounded from the settings: a building
    stands on the terrain, within ``terrain_size / 2`` across and 25/12 ``terrain_height`` up or down)."""
    ground = max(s.terrain_size / 2, 25 / 12 * abs(s.terrain_height))
    reach = max(
        ground + DECORATION_REACH, 2 * abs(s.terrain_height), s.blocker_height
    )  # what the terrain, the walls and the decorators reach
    out = []
    for b in s.buildings:
        sc = load_scene(b.mesh)
        # Base on y = 0, centred in x / z (Y up), so a placement sits on the terrain.
        v = (sc.vertices - [sc.center[0], sc.bounds[0, 1], sc.center[2]]) * b.scale
        out.append((sc, v))
        if b.count and not np.abs(v).max() <= MAX_LEVEL_SIZE:
            raise NeuralaoError(
                f"building {b.mesh!r}: scale {b.scale:g} makes it reach {np.abs(v).max():.3g} m from its "
                f"base; a building reaches at most {MAX_LEVEL_SIZE:g} m (lower the scale)"
            )
        reach = max(reach, ground + np.abs(v).max()) if b.count else reach
    for b, (_, v) in zip(s.buildings, out, strict=True):
        extent = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
        if b.count and extent < MIN_INSTANCE_REL * reach:
            raise NeuralaoError(
                f"building {b.mesh!r}: scale {b.scale:g} makes it {extent:.3g} m across, less than 2^-36 of "
                f"the level's reach ({reach:.3g} m): its bake could not resolve it (raise the scale)"
            )
    return out


def _shown(s: LevelGenSettings, name: str) -> str:
    if name == "buildings":
        return f"({sum(b.count for b in s.buildings)} placements)"
    return str(getattr(s, name))


def _largest(name: str, s: LevelGenSettings, avail: int) -> str:
    """The largest value of count ``name`` that fits ``avail`` bytes alone (for the message)."""
    per = {
        "houses": HOUSE_BYTES,
        "house_boxes": HOUSE_BOX_BYTES,
        "trees": INSTANCE_BYTES,
        "shrubs": INSTANCE_BYTES,
        "grass": INSTANCE_BYTES,
        "buildings": HOUSE_BYTES,
    }
    if name == "terrain_cells":
        return f"{max(math.isqrt(avail // TERRAIN_VERTEX_BYTES) - 1, 0)} cells per side"
    if name == "crown_subdivisions":
        k = 0
        while 20 * 4 ** (k + 1) * CROWN_FACE_BYTES <= avail:
            k += 1
        return f"{k} subdivisions"
    return f"{avail // per[name]}"


def write_level(out: str | Path, s: LevelGenSettings, preset: str = "tiny") -> tuple[Path, Path]:
    """Write OUT/level.gltf (+ level.bin) and OUT/bake.json (the preset's bake config)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NeuralaoError(f"--out {out} is a file, expected a folder")
    writer = generate(s)
    cfg = out / "bake.json"
    write_json(cfg, BAKE_CONFIGS.get(preset, {}))
    # level.gltf last (after its .bin): its presence marks a complete level, even after an interrupt
    return writer.write(out / "level.gltf"), cfg


def settings_for(
    preset: str, seed: int | None = None, overrides: list[str] | None = None
) -> LevelGenSettings:
    """A preset's settings with ``seed`` (None: 0) and ``key=value`` overrides (unknown keys rejected); a
    seed given both ways is refused (neither would silently win)."""
    if preset not in PRESETS:
        raise NeuralaoError(f"unknown preset {preset!r} (one of {', '.join(sorted(PRESETS))})")
    if seed is not None and any(parse_override(o)[0] == "seed" for o in overrides or []):
        raise NeuralaoError("the seed is given twice, by --seed and by --set seed=...; give one")
    data = json.loads(json.dumps({**PRESETS[preset], "seed": 0 if seed is None else seed}))
    return from_dict(LevelGenSettings, apply_overrides(data, overrides))
