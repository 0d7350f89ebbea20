"""Scene composer: seeded and deterministic, objects resting and touching without interpenetrating,
train meshes only, split by mesh; close-up cameras; composed scenes in datasets.

Geometry checks use trimesh's proximity queries and raw Embree rays, independent of the
composer's own sweep code, on real meshes from the shared folder (small ones, for speed).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from neuralao.pipeline.datasets.dataset import (
    DatasetSettings,
    _validate,
    build_dataset,
    expand_scenes,
    scene_of,
)
from neuralao.pipeline.geometry.camera import _clearance, closeup, orbit
from neuralao.pipeline.geometry.compose import (
    PRIMITIVES,
    ComposeSettings,
    compose,
    compose_parts,
    normalized_mesh,
    plan,
)
from neuralao.pipeline.geometry.scene import mesh_root
from neuralao.pipeline.geometry.splits import ADDED, INTERIORS, OBJECTS, all_meshes, object_meshes
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import from_dict
from neuralao.runtime.foundation.tolerances import TOL

# Small train meshes (a few thousand faces at most) so the geometry checks stay fast.
SMALL = ["suzanne", "spot", "Fox", "beetle", "GlamVelvetSofa"]
SEEDS = range(6)


def _part(c, p) -> tuple[np.ndarray, np.ndarray]:
    s = c.scene
    v = s.vertices[p.vertices[0] : p.vertices[1]]
    return v, s.faces[p.faces[0] : p.faces[1]] - p.vertices[0]


def _probes(v: np.ndarray, f: np.ndarray, per_edge: int) -> np.ndarray:
    """Vertices plus points along every edge (denser than the composer's own probes)."""
    e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    s = (np.arange(1, per_edge + 1) / (per_edge + 1))[None, :, None]
    return np.concatenate([v, (v[e[:, 0], None] * (1 - s) + v[e[:, 1], None] * s).reshape(-1, 3)])


@pytest.fixture(scope="module")
def compositions():
    return [compose_parts(ComposeSettings(seed=s, meshes=SMALL, objects=(5, 9))) for s in SEEDS]


def test_same_seed_same_vertices_different_seeds_differ():
    a = compose_parts(ComposeSettings(seed=11, meshes=SMALL))
    normalized_mesh.cache_clear()  # a fresh load, not the cached arrays, must give the same bits
    b = compose_parts(ComposeSettings(seed=11, meshes=SMALL))
    assert np.array_equal(a.scene.vertices, b.scene.vertices) and np.array_equal(a.scene.faces, b.scene.faces)
    assert a.parts == b.parts and len(a.objects) >= 3
    c = compose(ComposeSettings(seed=12, meshes=SMALL))
    assert c.vertices.shape != a.scene.vertices.shape or not np.array_equal(c.vertices, a.scene.vertices)


def _vertical_gap(upper: tuple[np.ndarray, np.ndarray], lower: tuple[np.ndarray, np.ndarray]) -> float:
    """Smallest vertical distance between two parts: rays down from the upper one's probe points
    onto the lower one and up from the lower one's onto the upper one (raw Embree). Rays start
    ``back`` behind their probe (a ray starting exactly on a contact can round to t < 0 and miss)."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    best = np.inf
    for (v, _), (tv, tf), dy in ((upper, lower, -1.0), (lower, upper, 1.0)):
        es = rtcore_scene.EmbreeScene()
        TriangleMesh(es, tv.astype(np.float32), tf.astype(np.int32))
        back = 1e-3
        o = _probes(v, _, 49) - np.array([0, dy * back, 0])  # 49: includes the composer's 24 per edge
        d = np.tile(np.float32([0, dy, 0]), (len(o), 1))
        t = np.asarray(
            es.run(o.astype(np.float32), d, query="DISTANCE", dists=np.full(len(o), 1e30, np.float32))
        )
        best = min(best, float(t.min()) - back)
    return best


def _convex_depth(points: np.ndarray, v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(n,) signed depth of points inside a closed convex mesh with outward faces: the distance to
    the nearest face plane, > 0 inside, <= 0 outside (0 on the surface)."""
    t = v[f]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    offset = np.einsum("fk,fk->f", n, t[:, 0])
    out = np.empty(len(points))
    for lo in range(0, len(points), 2048):
        out[lo : lo + 2048] = (offset[None, :] - points[lo : lo + 2048] @ n.T).min(axis=1)
    return out


def test_objects_rest_on_the_floor_or_on_their_support(compositions):
    tol = TOL.compose_contact_rel
    stacked = 0
    for c in compositions:
        for p in c.objects:
            v, f = _part(c, p)
            low = v[:, 1].min()
            if p.support == 0:  # the floor, y = 0
                assert abs(low) <= tol * c.scene.diagonal, (p, low)
                continue
            stacked += 1
            assert low > tol * c.scene.diagonal  # above the floor, on another object
            gap = _vertical_gap((v, f), _part(c, c.parts[p.support]))
            assert gap <= tol * c.scene.diagonal, (p, gap)
    assert stacked >= 3  # the check above ran on stacks, not only on floor objects


def test_objects_do_not_interpenetrate_and_many_touch(compositions):
    # Primitives are closed and convex, so "inside" is exact: no point of any other object
    # (vertices plus dense edge samples) may lie deeper inside one than TOL.compose_penetration_rel.
    touching = total = checked = 0
    for c in compositions:
        diag = c.scene.diagonal
        idx = [c.parts.index(p) for p in c.objects]
        # 49 per edge includes the composer's own 24 (k / 25 = 2k / 50); the sphere's edges are short.
        probes = {i: _probes(*_part(c, c.parts[i]), 49 if c.parts[i].kind != "sphere" else 3) for i in idx}
        gap = dict.fromkeys(idx, np.inf)
        for i in idx:
            if c.parts[i].kind not in PRIMITIVES:
                continue
            v, f = _part(c, c.parts[i])
            assert _convex_depth(v.mean(0, keepdims=True), v, f)[0] > 0  # outward faces: centre inside
            lo, hi = v.min(0) - 1e-3, v.max(0) + 1e-3
            for j in idx:
                pts = probes[j][np.all((probes[j] >= lo) & (probes[j] <= hi), axis=1)]
                if j == i or not len(pts):
                    continue
                depth = _convex_depth(pts, v, f)
                assert depth.max() <= TOL.compose_penetration_rel * diag, (
                    c.parts[i],
                    c.parts[j],
                    depth.max(),
                )
                checked += 1
                touch = float(np.abs(depth).min())
                gap[i], gap[j] = min(gap[i], touch), min(gap[j], touch)
        walls = [p for p in c.parts if p.kind == "wall"]
        for i in idx:
            v, _ = _part(c, c.parts[i])
            flush = any(_touches_wall(v, w, c) for w in walls)
            total += 1
            touching += bool(flush or gap[i] <= TOL.compose_contact_rel * diag or c.parts[i].support > 0)
    assert checked >= 10
    # Contacts are the point of the composer: most objects touch a wall or another object.
    assert touching >= 0.5 * total, (touching, total)


def _touches_wall(v: np.ndarray, wall, c) -> bool:
    width, depth, _ = c.room
    axis, sign = (0, width / 2) if wall.source[1] == "x" else (2, depth / 2)
    extreme = v[:, axis].min() if wall.source[0] == "-" else v[:, axis].max()
    return abs(abs(extreme) - sign) <= TOL.compose_contact_rel * c.scene.diagonal


def test_wall_and_corner_objects_are_flush(compositions):
    checked = 0
    for c in compositions:
        walls = [p for p in c.parts if p.kind == "wall"]
        for p in c.objects:
            v, _ = _part(c, p)
            width, depth, _ = c.room
            assert np.all(np.abs(v[:, 0]) <= width / 2 + 1e-9) and np.all(np.abs(v[:, 2]) <= depth / 2 + 1e-9)
            if p.placement in ("wall", "corner"):
                n = sum(_touches_wall(v, w, c) for w in walls)
                assert n >= (2 if p.placement == "corner" else 1), p
                checked += 1
    assert checked >= 3


def test_composer_draws_only_train_meshes():
    for pool in (1, 2):
        used = set()
        for seed in range(300):
            used |= {
                o.source for o in plan(ComposeSettings(seed=seed, pool=pool)).objects if o.kind == "mesh"
            }
        train = set(object_meshes("train", pool))
        assert used and used <= train <= set(OBJECTS["train"])
        assert len(used) >= len(train) - 2  # the pool is actually drawn from, not one mesh
    # Revision 1 (the default) is the pool before meshes were added, so older configs keep their scenes.
    assert set(object_meshes("train", 1)) == set(OBJECTS["train"]) - set(ADDED[2])
    assert object_meshes("train") == OBJECTS["train"] and object_meshes("val", 1) == OBJECTS["val"]
    with pytest.raises(NeuralaoError, match="revision"):
        object_meshes("train", 3)
    val = {o.source for o in plan(ComposeSettings(seed=1, mesh_fraction=1.0), split="val").objects}
    assert val <= set(OBJECTS["val"])


def test_splits_are_by_mesh_disjoint_and_cover_the_shared_meshes():
    listed = [m for table in (OBJECTS, INTERIORS) for names in table.values() for m in names]
    assert len(listed) == len(set(listed))  # no mesh in two splits
    with open(mesh_root() / "SOURCES.tsv") as fh:
        shared = {Path(row["file"].rstrip("/")).stem for row in csv.DictReader(fh, delimiter="\t")}
    assert set(all_meshes()) == shared
    test = set(OBJECTS["test"]) | set(INTERIORS["test"])
    assert {"KnightArmor", "RetroUFO"} <= test  # glTF game assets
    assert "lucy" in test and "cornell_box" in test  # a dense scan, a low-poly interior
    with pytest.raises(NeuralaoError, match="split"):
        object_meshes("holdout")


def test_dataset_rejects_a_train_mesh_in_a_heldout_scene():
    config = {
        "scenes": [{"name": "spot", "mesh": "spot", "split": "val"}],
        "composed": [{"count": 2, "seed": 0, "views": 1}],
    }
    settings = from_dict(DatasetSettings, config)
    with pytest.raises(NeuralaoError, match="split by mesh"):
        _validate(settings, expand_scenes(settings), Path("."))
    settings.scenes[0].mesh = "fandisk"  # a val mesh: fine
    _validate(settings, expand_scenes(settings), Path("."))
    bad = from_dict(DatasetSettings, {"scenes": [{"name": "x", "mesh": "spot", "compose": {"seed": 1}}]})
    with pytest.raises(NeuralaoError, match="exactly one"):
        _validate(bad, expand_scenes(bad), Path("."))


def test_generator_expands_with_room_rules():
    settings = from_dict(
        DatasetSettings, {"composed": [{"count": 4, "seed": 7, "views": 3, "cameras": ["orbit", "interior"]}]}
    )
    specs = expand_scenes(settings)
    assert [s.name for s in specs] == ["comp-0007", "comp-0008", "comp-0009", "comp-0010"]
    assert [s.compose.seed for s in specs] == [7, 8, 9, 10]
    for s in specs:
        p = plan(s.compose)
        if s.cameras == "orbit":
            assert len(p.walls) <= 2 and not p.ceiling
        else:
            assert len(p.walls) >= 3


def test_closeups_are_clear_see_their_target_and_are_darker_than_orbits():
    from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
    from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings

    scene = compose(ComposeSettings(seed=3, meshes=SMALL, walls=(2, 2)))
    near = closeup(scene, 4, 32, 32, seed=5)
    assert len(near) == 4 and len({tuple(c.position) for c in near}) == 4
    assert np.all(_clearance(scene, np.array([c.position for c in near])) > 0.01 * scene.diagonal)
    far = orbit(scene, 4, 32, 32, seed=5, min_elevation_deg=10)
    assert all(c.position[1] > scene.center[1] for c in far)  # above the floor, never below it
    renderer, lab = GBufferRenderer(scene), Labeller(scene, LabelSettings(rays=16))
    means = {}
    for kind, cams in (("near", near), ("far", far)):
        aos = []
        for cam in cams:
            frame = renderer.render(cam)
            assert frame["mask"][16, 16] or kind == "far"  # a close-up looks straight at its target
            ao, _ = lab.label_frame(frame)
            aos.append(ao[frame["mask"]].mean())
        means[kind] = float(np.mean(aos))
    renderer.close()
    assert means["near"] < means["far"] - 0.1, means  # close-ups frame contact regions


def test_same_seed_same_dataset_hash(tmp_path):
    def settings(seed: int) -> DatasetSettings:
        config = {
            "name": "composed-tiny",
            "size": [32, 32],
            "labels": {"rays": 16},
            "composed": [{"count": 2, "seed": seed, "views": 2, "compose": {"meshes": SMALL}}],
        }
        return from_dict(DatasetSettings, config)

    def build(seed: int, out: str) -> str:
        return build_dataset(settings(seed), tmp_path / out, progress=False)["dataset_hash"]

    first = build(4, "a")
    normalized_mesh.cache_clear()
    assert build(4, "b") == first
    assert build(5, "c") != first
    # The manifest describes each composed scene well enough to rebuild it exactly.
    manifest = json.loads((tmp_path / "a" / "manifest.json").read_text())
    rebuilt = scene_of(manifest, "comp-0005")
    spec = expand_scenes(settings(4))[1]  # the second scene: an interior (>= 3 walls)
    assert spec.name == "comp-0005" and len(plan(spec.compose).walls) >= 3
    assert np.array_equal(rebuilt.vertices, compose(spec.compose).vertices)
    assert len(rebuilt.faces) == next(s["faces"] for s in manifest["shards"] if s["scene"] == "comp-0005")


def test_radii_in_the_dataset_leave_ao_unchanged(tmp_path):
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.runtime.foundation.io import read_npz

    def build(out: str, radii: list[float] | None) -> dict:
        labels = {"rays": 16} if radii is None else {"rays": 16, "radii_rel": radii}
        config = {
            "size": [32, 32],
            "labels": labels,
            "frames_per_shard": 4,
            "scenes": [{"name": "suz", "mesh": "suzanne", "views": 1}],
            "composed": [
                {"count": 1, "seed": 2, "views": 2, "cameras": ["closeup"], "compose": {"meshes": SMALL}}
            ],
        }
        return build_dataset(from_dict(DatasetSettings, config), tmp_path / out, progress=False)

    plain = build("plain", None)
    assert "ao_radii" not in plain["frame_keys"] and "radii" not in plain["scenes"]["comp-0002"]
    # 0.25 = max_distance_rel: ao comes from the radii trace itself; [0.1]: from its own trace.
    for out, radii in (("one-trace", [0.1, 0.25]), ("two-traces", [0.1])):
        m = build(out, radii)
        assert m["frame_keys"][-3:] == ["ao_radii", "valid_radii", "radii"]
        for a, b in zip(plain["shards"], m["shards"], strict=True):
            pa, pb = read_npz(tmp_path / "plain" / a["file"]), read_npz(tmp_path / out / b["file"])
            assert np.array_equal(pa["ao"], pb["ao"]) and np.array_equal(pa["valid"], pb["valid"])
            assert pb["ao_radii"].shape == (*pa["ao"].shape, len(radii)) and pb["radii"].shape == (
                len(pa["ao"]),
                len(radii),
            )
            assert np.all(np.diff(pb["ao_radii"], axis=-1) <= 0)
            if len(radii) == 2:
                assert np.array_equal(pb["ao_radii"][..., 1], pa["ao"])
        scene = m["scenes"]["comp-0002"]
        frame = next(f for f in open_dataset(tmp_path / out).frames(scene="comp-0002"))
        assert np.allclose(frame["radii"], scene["radii"], rtol=1e-6) and frame["ao_radii"].shape == (
            32,
            32,
            len(radii),
        )
