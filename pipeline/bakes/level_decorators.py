"""Decorators of a level bake (Sloan et al. 2013, section 2.2): trees (local AO per model times a linear
global function per instance, equation 3, fitted to each instance's in-place gold standard) and grass
clumps and shrubs (one scalar per instance, resampled from the baked level in a small sphere).

Every instance is a task of an engine; workers build the gold scene (the level with every tree opaque) from
the level's meshes and transforms, so the driver never flattens the level.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from neuralao.pipeline.bakes.level_pieces import instance_batches, level_bounds
from neuralao.pipeline.bakes.level_settings import (
    FoliageSettings,
    LevelBakeSettings,
    blend,
    halves,
    label_settings,
)
from neuralao.pipeline.bakes.level_stages import (
    LabellerFrame,
    PieceState,
    gold_scene,
    shared_level,
    worker_settings,
)
from neuralao.pipeline.engines.engine import Context, Shared, Task, content_key
from neuralao.pipeline.geometry.least_squares import fit_least_squares
from neuralao.pipeline.geometry.level_files import Level, LevelNode, flatten
from neuralao.pipeline.geometry.scene import Scene, scene_from_arrays, slim_scene
from neuralao.pipeline.geometry.surface import SurfaceSamples, interpolate, surface_samples
from neuralao.pipeline.tracing.foliage import Foliage, overlap_reduced
from neuralao.pipeline.tracing.level_tracer import LevelLabeller, resample_in_spheres, sphere_directions


def instance_boxes(level: Level, nodes: list[LevelNode]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World AABBs lo (b, 3), hi (b, 3) of every instance of ``nodes`` and each one's density (b,)."""
    lo, hi, dens = [], [], []
    for node in nodes:
        if len(level.meshes[node.mesh].vertices) == 0:
            continue  # no box
        for world in instance_batches(level.meshes[node.mesh].vertices, node.transforms):
            lo.append(world.min(axis=1))
            hi.append(world.max(axis=1))
        dens.append(np.full(len(node.transforms), node.params.get("density", 1.0)))
    if not lo:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(lo), np.concatenate(hi), np.concatenate(dens)


def shrub_boxes(level: Level, s: FoliageSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The shrubs' media boxes: every shrub instance's world AABB lo (b, 3), hi (b, 3) and density (b,),
    overlaps reduced where ``s.reduce_overlaps`` (the 10x world's 78,560 shrubs: 1.4 s, made once a bake)."""
    lo, hi, dens = instance_boxes(level, level.nodes_with("shrub"))
    if s.reduce_overlaps:
        dens = overlap_reduced(lo, hi, dens)
    return lo, hi, dens


def build_foliage(
    level: Level, frame, s: FoliageSettings, include_trees: bool = True, shrubs: tuple | None = None
) -> Foliage:
    """Shrub instances as media boxes and tree instances as semi-transparent triangles, in the local frame
    (``frame.center``, ``frame.scale``) of the opaque labeller. ``shrubs``: :func:`shrub_boxes` of the
    level, if made already."""
    trees = level.nodes_with("tree")
    lo, hi, dens = shrub_boxes(level, s) if shrubs is None else shrubs
    tv, tf, trans = np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0)
    if include_trees and trees:
        tv, tf, spans = flatten(level, trees)
        per_face = [
            np.full(len(level.meshes[trees[k].mesh].faces), trees[k].params["transmission"])
            for k, _, _, _ in spans
        ]
        trans = np.concatenate(per_face)
    return Foliage(lo, hi, dens, tv, tf, trans, frame.center, frame.scale, s.max_hits)


def linear_basis(points: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(k, 4) rows [1, x - ox, y - oy, z - oz]: the 3-D linear global function's basis."""
    return np.c_[np.ones(len(points)), np.asarray(points) - np.asarray(origin)]


def fit_global(
    points: np.ndarray, origin: np.ndarray, local: np.ndarray, target: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Equation 3: y (4,) minimising sum_i w_i (f_i - G_y(s_i) L_i)^2, G_y(p) = y . [1, p - origin]."""
    a = linear_basis(points, origin) * np.asarray(local, np.float64)[:, None]
    sw = np.sqrt(np.asarray(weights, np.float64))
    y, *_ = np.linalg.lstsq(a * sw[:, None], np.asarray(target, np.float64) * sw, rcond=None)
    return y


def transform_samples(samples: SurfaceSamples, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Object-space samples -> world points (k, 3) and unit normals (k, 3) under the 4x4 ``m``."""
    p = samples.points @ m[:3, :3].T + m[:3, 3]
    n = samples.normals @ np.linalg.inv(m[:3, :3])
    return p, n / np.linalg.norm(n, axis=1, keepdims=True)


_DECORATOR_ERRORS = ("local_x_global", "global_only", "in_place", "local_only", "local_x_global_vs_in_place")


@dataclass
class _TreeModel:
    """What every in-place task of one tree model reads (a :class:`neuralao.pipeline.engines.engine.Shared`
    value)."""

    model: Scene  # the model's mesh (object space)
    train: SurfaceSamples  # fit samples (object space)
    hold: SurfaceSamples  # held-out samples (object space)
    local: np.ndarray  # (v,) float32 local AO per model vertex (blended)
    l_train: np.ndarray  # (train,) float64 local AO at the fit samples


def _tree_model(state, args) -> _TreeModel:
    """Engine task: the local AO of one tree model baked in isolation (both distances, least squares,
    blended). args: (its mesh, the level's diagonal, settings); ``state`` is not read."""
    mesh, diagonal, s = args
    d = s.decorators
    model = scene_from_arrays(mesh.vertices, mesh.faces, mesh.name, drop_degenerate=False)
    loc_lab = LevelLabeller(
        model,
        replace(
            label_settings(s, diagonal, d.local_rays),
            max_distance=s.trace.max_distance or diagonal,
        ),
        s.trace.bvh,
    )
    loc_samples = surface_samples(model, d.local_samples_per_vertex * len(model.vertices), 32, s.seed)
    a, v = loc_lab.obscurance(loc_samples.points, loc_samples.normals, halves(s))
    local_two = fit_least_squares(model, loc_samples, a, v, s.trace.alpha)
    local = blend(local_two[:, 0], local_two[:, 1], s.blend)
    train = surface_samples(model, d.samples_per_instance, 64, s.seed + 1)
    hold = surface_samples(model, d.holdout_samples, 64, s.seed + 2)
    return _TreeModel(
        slim_scene(model), train, hold, local, interpolate(model, local, train.face, train.bary)
    )


def _tree_instance(state, args) -> dict[str, np.ndarray]:
    """Engine task: one tree instance traced in place (gold labeller + foliage without trees) and its
    equation-3 fits and errors. args: (_TreeModel (Shared), 4x4 transform, instance number, settings)."""
    gold_labeller, gold_foliage = state
    tm, m, uid, s = args
    model, train, hold, local, l_train = tm.model, tm.train, tm.hold, tm.local, tm.l_train
    pt, nt = transform_samples(train, m)
    ph, nh = transform_samples(hold, m)
    ids = np.arange(len(pt) + len(ph), dtype=np.int64) + uid * (1 << 24)
    ao, valid = gold_labeller.obscurance(np.r_[pt, ph], np.r_[nt, nh], halves(s), gold_foliage, ids=ids)
    f = blend(ao[:, 0], ao[:, 1], s.blend).astype(np.float64)
    ft, vt, fh, vh = f[: len(pt)], valid[: len(pt)], f[len(pt) :], valid[len(pt) :]
    origin = m[:3, 3]
    y = fit_global(pt[vt], origin, l_train[vt], ft[vt], train.weights[vt])
    y1 = fit_global(pt[vt], origin, np.ones(vt.sum()), ft[vt], train.weights[vt])
    # In place: the instance's own least-squares vertex bake (what per-vertex storage buys).
    inplace = fit_least_squares(model, train, ft, vt, s.trace.alpha)
    world_v = model.vertices @ m[:3, :3].T + m[:3, 3]
    # What the shader shows: the per-vertex product, interpolated by the rasteriser.
    prod = np.clip(local * (linear_basis(world_v, origin) @ y), 0, 1)
    w = hold.weights[vh] / hold.weights[vh].sum()
    preds = {
        "local_x_global": interpolate(model, prod, hold.face, hold.bary),
        "global_only": np.clip(linear_basis(ph, origin) @ y1, 0, 1),
        "in_place": interpolate(model, inplace, hold.face, hold.bary),
        "local_only": interpolate(model, local, hold.face, hold.bary),
    }
    err = {k: float(np.sqrt(np.sum(w * (p[vh] - fh[vh]) ** 2))) for k, p in preds.items()}
    err["local_x_global_vs_in_place"] = float(
        np.sqrt(np.sum(w * (preds["local_x_global"][vh] - preds["in_place"][vh]) ** 2))
    )
    return {"y": y, "y1": y1, "errors": np.array([err[k] for k in _DECORATOR_ERRORS])}


def gold_stage_context(
    level: Level,
    diagonal: float,
    s: LevelBakeSettings,
    runner,
    keys: dict[str, str] | None = None,
    shrubs: tuple | None = None,
) -> Context | None:
    """The engine context of the trees' gold standard (the level with every tree opaque, and the foliage
    without the trees in its frame), or None for a level without trees. Arguments as
    :func:`bake_decorators`'. Its state is built where its tasks run (:func:`_gold_state`), foliage
    included: the driver only names it."""
    if not level.nodes_with("tree"):
        return None
    settings = worker_settings(label_settings(s, diagonal), runner)
    keys = keys or {}
    key, bvh = keys.get("geometry", ""), s.trace.bvh
    foliage = (s.foliage, shrubs) if s.foliage.enabled else None
    payload = (shared_level(key, level, None)[0], settings, bvh, foliage)
    name = content_key(key, settings, bvh, keys.get("foliage", ""))
    return Context(f"level-gold/{name}", _gold_state, payload, heavy=True)


def _gold_state(payload) -> tuple[LevelLabeller, Foliage | None]:
    """The gold labeller (:func:`gold_scene`) and the foliage without the trees, in the frame of the
    level's static, blocker and tree instances (found one instance batch at a time); ``payload``: the
    level, label settings, BVH quality and (foliage settings, the shrubs' boxes or None), or None."""
    level, settings, bvh, foliage = payload
    gold_foliage = None
    if foliage is not None:
        foliage_settings, shrubs = foliage
        bounds = level_bounds(level, level.nodes_with("static", "blocker", "tree"))
        frame = LabellerFrame(bounds.mean(0), float(np.linalg.norm(bounds[1] - bounds[0])), settings)
        gold_foliage = build_foliage(level, frame, foliage_settings, include_trees=False, shrubs=shrubs)
    return LevelLabeller(gold_scene(level), settings, bvh), gold_foliage


def bake_decorators(
    level: Level,
    diagonal: float,
    s: LevelBakeSettings,
    runner,
    local: bool,
    store=None,
    keys: dict[str, str] | None = None,
    shrubs: tuple | None = None,
    ctx: Context | None = None,
) -> dict[str, np.ndarray]:
    """Local AO per tree model, gold standard per instance, equation-3 coefficients, errors.

    The local AO of each model is a task of ``runner``, then every instance's in-place trace and fits is one
    (``local``: a LocalEngine, lent the gold labeller built here for the stage), results kept in
    ``store`` (:class:`neuralao.pipeline.engines.engine.ResultStore`) as they arrive. Instances are numbered
    (and traced with ray ids) in a fixed order, so the result is the same bytes wherever the tasks run.
    ``diagonal``: the opaque level's (the rays' length). ``keys``: the bake's stage keys
    (:func:`neuralao.pipeline.bakes.level.stage_keys`: the stage's own names its results, the geometry's
    the level its workers hold). ``shrubs``: :func:`shrub_boxes`, if made already. ``ctx``: the gold
    context (:func:`gold_stage_context`), if made already (its state prepared on the workers)."""

    trees = level.nodes_with("tree")
    if not trees:
        return {"models": np.zeros(0, np.int64)}
    ctx = ctx or gold_stage_context(level, diagonal, s, runner, keys, shrubs)
    keys = keys or {}
    key = keys.get("decorators", "")
    t0 = time.perf_counter()
    if local:  # the gold standard sees the trees as opaque geometry (every instance baked in place)
        runner.hold(ctx.key, ctx.build(ctx.value()))
    gold_s = time.perf_counter() - t0
    ctx_key = ctx.key
    models = sorted({n.mesh for n in trees})
    out: dict[str, Any] = {}
    jobs = []  # (shared model, transform, uid) in the order of the result rows
    # Each model's local AO is a task (a wave before its instances', which read it), under the gold context
    # its instances use: a worker holds no other state for it.
    made = runner.ordered(Task(ctx, _tree_model, (level.meshes[mi], diagonal, s)) for mi in models)
    for mi, tm in zip(models, made, strict=True):
        out[f"local_{mi}"] = tm.local
        shared = Shared(content_key(key, "tree-model", mi), tm)
        for node in (n for n in trees if n.mesh == mi):
            for m in node.transforms:
                jobs.append((shared, np.asarray(m, np.float64), len(jobs)))

    def tasks():
        for shared, m, uid in jobs:
            yield Task(ctx, _tree_instance, (shared, m, uid, s), content_key(ctx_key, shared.key, m, uid))

    rows: list[dict | None] = [None] * len(jobs)
    for i, r in runner.map(tasks(), store):
        rows[i] = r
    if local:
        runner.release(ctx.key)
    out["models"] = np.array(models, np.int64)
    out["seconds_gold_state"] = np.array(gold_s)  # the gold BVH built here (a local bake), 0 on an engine
    out["coefficients"] = np.array([r["y"] for r in rows])
    out["coefficients_global_only"] = np.array([r["y1"] for r in rows])
    errors = np.array([r["errors"] for r in rows]).reshape(len(rows), len(_DECORATOR_ERRORS))
    for j, k in enumerate(_DECORATOR_ERRORS):
        out[f"rmse_{k}"] = errors[:, j]
    return out


def small_decorators(
    level: Level, resample: Resampler, values: Shared, s: LevelBakeSettings
) -> dict[str, np.ndarray]:
    """One scalar per grass clump and shrub: ``values`` (per opaque vertex, NaN on blockers) resampled in
    a sphere of ``grass.radius`` around its base."""
    out: dict[str, np.ndarray] = {}
    for role in ("grass", "shrub"):
        for k, node in enumerate(level.nodes_with(role)):
            centres = node.transforms[:, :3, 3]
            v = resample(values, centres, s.grass.radius, s.grass.rays, f"{role}-{k}")
            missing = ~np.isfinite(v)
            out[f"{role}_{k}"] = np.where(missing, 1.0, v).astype(np.float32)
            out[f"{role}_{k}_missing"] = np.array(int(missing.sum()))
    return out


def _resample_task(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: :func:`resample_in_spheres` of one block of centres on the opaque labeller."""
    values, centers, radius, rays = args
    v, total = resample_in_spheres(state.labeller, values, centers, radius, rays)
    return {"values": v, "total": total}


class Resampler:
    """:func:`resample_in_spheres` with the centres split into blocks of ``task_rays`` rays,
    each a task of ``engine`` on the opaque labeller's context (the trace's, so workers reuse its state);
    a centre's value depends only on its own rays, so the bytes never depend on where blocks run.
    ``store``: finished blocks kept on disk (a killed bake's rerun skips them)."""

    def __init__(self, engine, context, store=None, task_rays: int = 1 << 20):
        self.engine, self.context, self.store, self.task_rays = engine, context, store, task_rays

    @staticmethod
    def share(values: np.ndarray) -> Shared:
        """Per-vertex values of the opaque scene (float32, NaN on blockers) as a
        :class:`neuralao.pipeline.engines.engine.Shared`: put in the object store once, read by every task."""

        values = np.asarray(values, np.float32)
        return Shared(content_key("opaque-values", values), values)

    def __call__(self, values, centers: np.ndarray, radius: float, rays: int, tag: str) -> np.ndarray:
        """values: :meth:`share` of (n,) vertex values; centers (p, 3) -> (p,) float64 (NaN: no hit)."""

        centers = np.asarray(centers, np.float64).reshape(-1, 3)
        step = max(1, self.task_rays // len(sphere_directions(rays)))
        bounds = [(lo, min(lo + step, len(centers))) for lo in range(0, len(centers), step)]
        tasks = (
            Task(
                self.context,
                _resample_task,
                (values, centers[lo:hi], radius, rays),
                content_key(self.context.key, values.key, tag, lo, hi, radius, rays),
            )
            for lo, hi in bounds
        )
        out = np.full(len(centers), np.nan)
        for i, r in self.engine.map(tasks, self.store):
            lo, hi = bounds[i]
            out[lo:hi] = r["values"]
        return out
