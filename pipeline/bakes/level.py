"""`neuralao bake LEVEL.gltf --config CONFIG --out DIR`: ambient obscurance for a game level.

The system of Sloan, Tranchida, Chen, Kavan 2013 ("Ambient Obscurance Baking on the GPU") on
Embree, stage by stage (the rows of their Table 1; the bake log times each one):

1. **geometry**: read and validate the level (:mod:`neuralao.pipeline.geometry.level_files`); cut its
   ``static`` instances into pieces (:mod:`neuralao.pipeline.bakes.level_pieces`) and find the opaque
   level's bounds, one instance at a time;
2. **samples**: stratified surface samples under a per-face cap, water-filled (two passes over the pieces:
   the density, then each piece's count);
3. **bvh**: the opaque Embree scene (here for a local bake; on every worker with an engine, started there
   as soon as the level is cut into pieces, before the foliage and the samples: the foliage is not in it,
   the tasks that trace it carry it);
4. **foliage**: shrub instances -> world boxes with overlap-reduced densities, tree instances ->
   triangles with their transmission (:mod:`neuralao.pipeline.tracing.foliage`);
5. **trace**: obscurance at the short and the long half distance from one trace, attenuated by the
   foliage, in blocks of samples (:mod:`neuralao.pipeline.bakes.level_stages`);
6. **decorators**: per tree model, local AO baked in isolation; per tree instance, the gold standard and
   the 4 coefficients of equation 3 (:mod:`neuralao.pipeline.bakes.level_decorators`);
7. **solve**: least-squares vertex values (Kavan et al. 2011) of both distances, one task per piece (with
   ``trace.subdomains`` > 1 a big component is cut into spatial subdomains, a task each per iteration);
8. **small decorators**: one scalar per grass clump and shrub, resampled from the baked level;
9. **lod**: per piece, a simplified LOD with AO by resampling at its vertices and by least squares over
   resampled surface samples, both measured against the gold standard;
10. **output**: glTF streamed to disk piece by piece (:mod:`neuralao.pipeline.bakes.level_output`), the
    decorator vertex shader, the bake log (JSON + a markdown table).

Every heavy stage is tasks of an engine (``engine``: None runs them here); the driver holds the level's
meshes and instance transforms, one piece's arrays at a time and one float per opaque vertex (the baked AO
the resampling reads), never the flattened level. Each task's result is written under ``OUT/stages/`` as it
arrives, stamped with its stage's key (:data:`STAGE_INPUTS`: the level's bytes, the settings the stage
reads and the keys of the stages it reads): a killed bake resumes where it stopped and ends with the same
bytes; a changed setting redoes the stages that read it and those after them, and reuses the others.

The workers build both BVHs in the background (``Engine.prepare``), each ahead of the stage that needs it:
the opaque one while the foliage and the samples' passes are made, the trees' gold one while the solve, the
LOD and the checks run (where a worker may hold it beside the opaque one: ``Engine.heavy_states``; else
from the trees' stage on). The log's rows ``prepare_opaque`` and ``prepare_gold`` mark where, and each
stage's row the states its tasks found prepared and the seconds they still waited for them.
"""

from __future__ import annotations

import functools
import logging
import os
import resource
import shutil
import time
import zipfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from neuralao.pipeline.bakes.level_decorators import (
    Resampler,
    bake_decorators,
    build_foliage,
    gold_stage_context,
    shrub_boxes,
    small_decorators,
)
from neuralao.pipeline.bakes.level_output import write_outputs
from neuralao.pipeline.bakes.level_pieces import index_level, sample_rule
from neuralao.pipeline.bakes.level_settings import (
    LevelBakeSettings,
    blend,
    check_settings,
    label_settings,
)
from neuralao.pipeline.bakes.level_stages import (
    LOD_HELD_OUT,
    LabellerFrame,
    TaskFiles,
    blend_piece,
    engine_each,
    join_tiles,
    lod_jobs,
    lod_mesh_files,
    lod_piece_errors,
    lod_reference_jobs,
    lod_reference_stems,
    lod_resample_jobs,
    lod_tiles,
    opaque_context,
    output_jobs,
    piece_resampled,
    piece_stem,
    piece_trace,
    pieces_context,
    plan_jobs,
    run_to_files,
    shared_foliage,
    simplify_level,
    simplify_piece,
    solve_stage,
    split_lod,
    task_rays,
    trace_jobs,
    unfinished,
    worker_settings,
)
from neuralao.pipeline.engines.engine import LocalEngine, ResultStore, Task, content_key
from neuralao.pipeline.geometry.least_squares import Whole
from neuralao.pipeline.geometry.level_files import read_level
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import (
    read_npz,
    remove_stale_temporaries,
    sha256_file,
    sha256_json,
    write_json,
    write_npz,
    write_text,
)
from neuralao.runtime.foundation.limits import release_free_memory
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.settings import settings_to_dict

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- bake log and stages


class BakeLog:
    """Timed stages, each stored (or not) under OUT/stages/ with its own key (:func:`stage_keys`)."""

    def __init__(self, out: Path, keys: dict[str, str]):
        self.out, self.keys = out, keys
        self.stages: list[dict[str, Any]] = []
        self.runner = None  # the engine whose task seconds each stage's row takes (Engine.task_seconds)
        self.task_seconds: dict[str, list[float]] = {}
        # per stage, the wave (0, 1, ...: the engine's map calls in order) each of its tasks ran in
        self.task_waves: dict[str, list[int]] = {}
        # per stage whose wave ran another stage's tasks (Task.aside: the solve's plans beside the trace),
        # the positions of those tasks in its task seconds
        self.task_aside: dict[str, list[int]] = {}
        # per stage, the seconds of each state its tasks were the first to use (built there or prepared
        # ahead), the seconds the first task waited for it and whether it was prepared (Engine.prepare)
        self.state_seconds: dict[str, list[float]] = {}
        self.state_waits: dict[str, list[float]] = {}
        self.state_prepared: dict[str, list[bool]] = {}
        self.dir = out / "stages"
        self._waited0 = 0.0  # the local runner's waiting seconds when the current stage began
        self._thread0 = 0.0  # this thread's CPU seconds then
        self.dir.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(self.dir)
        remove_stale_temporaries(out)

    def _begin(self) -> None:
        self._waited0 = getattr(self.runner, "waited", 0.0)
        self._thread0 = time.thread_time()

    def timed(self, name: str, description: str, fn, **counts):
        _reset_peak_rss()
        t0, c0 = time.perf_counter(), _cpu_seconds()
        self._begin()
        result = fn()
        self._record(name, description, t0, c0, False, counts)
        return result

    def stored(self, name: str, description: str, fn, **counts) -> dict[str, np.ndarray]:
        """``fn() -> dict of arrays``, stored as stages/NAME.npz with the stage's key; reused when the key
        matches. One of another key goes before ``fn`` runs: the stage's task files change from then on,
        and a run killed midway must leave no stored stage that would vouch for them."""
        path, key = self.dir / f"{name}.npz", self.keys[name]
        _reset_peak_rss()
        t0, c0 = time.perf_counter(), _cpu_seconds()
        self._begin()
        if path.is_file():
            try:
                data = read_npz(path)
            except NeuralaoError:
                data = {}  # unreadable: made again
            if str(data.pop("_key", "")) == key:
                self._record(name, description, t0, c0, True, counts)
                return data
            path.unlink()
        data = fn()
        write_npz(path, _key=np.array(key), **data)
        self._record(name, description, t0, c0, False, counts)

        shutil.rmtree(self.dir / f"{name}.parts", ignore_errors=True)  # its task results (parts)
        return data

    def will_make(self, name: str) -> bool:
        """Whether this run makes stage ``name`` (no stored result of its key is there)."""
        try:
            with np.load(self.dir / f"{name}.npz", allow_pickle=False) as z:
                return str(z["_key"]) != self.keys[name]
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return True

    def prepare(self, name: str, stage: str, make, users: tuple[str, ...] = ()) -> None:
        """Have the runner's workers start building the state of the context ``make()`` returns (None:
        none) ahead of ``stage`` (:meth:`neuralao.pipeline.engines.engine.Engine.prepare`), unless this run
        makes none of the stages ``users`` (default: ``stage``) that read it. A row ``name`` of its own:
        the driver's seconds to make the context and send it, and ``prepares``, the stage it is for, so a
        projection knows which stages' work runs beside the build."""
        if not any(self.will_make(u) for u in users or (stage,)):
            return

        def start() -> None:
            if (ctx := make()) is not None:
                self.runner.prepare(ctx)

        self.timed(name, f"State of the {stage} stage started on the workers", start, prepares=stage)

    def parts(self, name: str):
        """The :class:`neuralao.pipeline.engines.engine.ResultStore` of stage ``name``'s task results: each
        is written
        as it arrives, so a killed bake's rerun skips them; removed once the stage's own file is written."""

        return ResultStore(self.dir / f"{name}.parts")

    def _record(self, name, description, t0, c0, reused, counts) -> None:
        release_free_memory()  # the stage's temporaries: the next stage's peak is its own
        self.stages.append(
            {
                "stage": name,
                "description": description,
                "seconds": time.perf_counter() - t0,
                "cpu_seconds": _cpu_seconds() - c0,
                "reused": reused,
                **counts,
            }
        )
        if (peak := _peak_rss()) is not None:
            self.stages[-1]["peak_rss_bytes"] = peak
        done: list[float] = []
        built: list[float] = []
        if self.runner is not None and self.runner.task_seconds:
            done, self.runner.task_seconds = self.runner.task_seconds, []
            waves, self.runner.task_waves = self.runner.task_waves, []
            self.task_seconds[name] = done
            _, waves = np.unique(waves, return_inverse=True)  # numbered from 0 in the stage
            self.task_waves[name] = waves.reshape(-1).tolist()
            aside, self.runner.task_aside = self.runner.task_aside, []
            if any(aside):
                self.task_aside[name] = [i for i, a in enumerate(aside) if a]
            self.stages[-1].update(tasks=len(done), task_seconds_max=max(done))
        if self.runner is not None and self.runner.state_seconds:
            built, self.runner.state_seconds = self.runner.state_seconds, []
            waits, self.runner.state_waits = self.runner.state_waits, []
            prepared, self.runner.state_prepared = self.runner.state_prepared, []
            self.state_seconds[name], self.state_waits[name] = built, waits
            self.state_prepared[name] = prepared
            self.stages[-1].update(states_built=len(built))
            if any(prepared):  # built ahead: what their first tasks still waited for them
                ahead = [w for w, p in zip(waits, prepared, strict=True) if p]
                self.stages[-1].update(states_prepared=len(ahead), state_wait_seconds_max=max(ahead))
        # The driver's own seconds: what no task did. Here, one task at a time, the tasks ran in this thread,
        # so the stage's wall time less theirs; with several at once they ran on other threads, so this
        # thread's CPU seconds (not the stage's wall time less the time it waited for them: that counts
        # the time it waited for the interpreter lock the tasks held, which a driver in its own process
        # does not); on a cluster the driver waits for them, so its CPU time (Ray's client work included).
        row = self.stages[-1]
        if self.runner is not None and self.runner.name == "local" and self.runner.workers > 1:
            waited = self.runner.waited - self._waited0
            row["driver_seconds"] = time.thread_time() - self._thread0  # states are built by the tasks
            row["driver_wall_seconds"] = max(0.0, row["seconds"] - waited)
        elif self.runner is None or self.runner.name == "local":  # (a local engine prepares nothing)
            row["driver_seconds"] = max(0.0, row["seconds"] - sum(done) - sum(built))
        else:
            row["driver_seconds"] = row["cpu_seconds"]

    def note(self, name: str, **counts) -> None:
        for st in self.stages:
            if st["stage"] == name:
                st.update(counts)


def _peak_rss() -> int | None:
    """This process's peak resident memory (bytes) since the last :func:`_reset_peak_rss` (Linux's
    VmHWM); None where /proc does not tell it."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _reset_peak_rss() -> None:
    """Start a new peak (Linux: writing 5 to clear_refs resets VmHWM), so each stage reports its own."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _cpu_seconds() -> float:
    """User + system CPU seconds of this process, all threads (on a shared machine, CPU time / cores
    estimates the wall time the same work would take with the cores to itself)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


# The stage keys' version: a folder baked with keys of another version is baked again, never misread.
KEY_VERSION = 2

# The settings of the trace's rays (the opaque level's and the trees' gold standard's).
_RAYS = (
    "trace.rays",
    "trace.half_distance_short",
    "trace.half_distance_long",
    "trace.max_distance",
    "trace.backface_threshold",
    "trace.bvh",
)

# What each stage's result is made from besides the level's bytes: the settings it reads that the stages
# it reads have not keyed already (dotted names; a section's name stands for all of its keys), and those
# stages. A stage's key hashes the level's bytes, these settings and those stages' keys, so a changed
# setting redoes the stages that read it and every stage after them, and a stored stage whose key is
# unchanged is reused. The geometry, samples and foliage are made again by every run: their keys only chain.
STAGE_INPUTS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "geometry": (("piece_faces",), ()),
    "samples": (
        ("trace.samples_per_vertex", "trace.min_samples_per_face", "trace.samples_per_face_cap", "seed"),
        ("geometry",),
    ),
    "foliage": (("foliage",), ()),
    "trace": ((*_RAYS, "trace.block_samples"), ("samples", "foliage")),
    "solve": (("trace.alpha", "trace.solver", "trace.component_vertices", "trace.subdomains"), ("trace",)),
    "small_decorators": (("blend", "grass"), ("solve",)),
    "lod": (("blend", "lod"), ("samples", "solve")),
    "lod_check": ((), ("trace", "lod")),
    # the blend's remap is not checked: the check compares the blend before it
    "blend_check": (("blend.long_weight",), ("trace", "solve")),
    # the trees are traced on their own (their gold scene, their samples), the level's stages unread
    "decorators": ((*_RAYS, "trace.alpha", "seed", "blend", "decorators"), ("foliage",)),
}

# Settings no stage's result depends on (each tested: two values bake the same bytes): tasks at once and
# rays per resampling task (scheduling), the baked level's file name (the output is written by every run)
# and whether the checks run (each check is a stage of its own).
UNKEYED = ("workers", "task_rays", "output", "error_tables")


def stage_keys(path: Path, settings: LevelBakeSettings) -> dict[str, str]:
    """Each stage's key (:data:`STAGE_INPUTS`): a hash of the level's bytes (the .gltf / .glb and every
    external buffer), the settings the stage reads and the keys of the stages whose results it reads."""

    files = [sha256_file(path)]
    if path.suffix.lower() == ".gltf":
        try:
            doc = read_json(path, "glTF JSON")
            for b in doc.get("buffers", []):
                uri = b.get("uri", "")
                if uri and not uri.startswith("data:") and (path.parent / uri).is_file():
                    files.append(sha256_file(path.parent / uri))
        except (NeuralaoError, AttributeError, TypeError):
            pass  # read_level reports it
    values = settings_to_dict(settings)
    keys: dict[str, str] = {}
    for stage, (reads, after) in STAGE_INPUTS.items():
        keyed = {name: setting_value(values, name) for name in reads}
        keys[stage] = sha256_json(
            {
                "stage": stage,
                "files": files,
                "settings": keyed,
                "after": [keys[a] for a in after],
                "version": KEY_VERSION,
            }
        )
    return keys


def setting_value(values: dict[str, Any], name: str) -> Any:
    """The value of the dotted setting ``name`` (a section: all of it) in ``values`` (settings_to_dict's)."""
    for part in name.split("."):
        values = values[part]
    return values


# --------------------------------------------------------------------------- the bake


def bake_level(
    path: str | Path, settings: LevelBakeSettings, out: str | Path, progress: bool = False, engine=None
) -> dict:
    """Bake the level at ``path`` into the folder ``out``; returns the bake log (also OUT/bake_log.json).

    ``engine`` (:mod:`neuralao.pipeline.engines.engine`): runs every heavy stage's tasks (None: here, with
    threads)."""

    check_settings(settings)
    path, out = Path(path), Path(out)
    if out.exists() and not out.is_dir():
        raise NeuralaoError(f"--out {out} is a file; a level bake writes a folder")
    t_start, c_start = time.perf_counter(), _cpu_seconds()
    keys = stage_keys(path, settings) if path.is_file() else dict.fromkeys(STAGE_INPUTS, "")
    level = read_level(path)
    out.mkdir(parents=True, exist_ok=True)
    blog = BakeLog(out, keys)
    s = settings
    index = blog.timed("geometry", "Process geometry", lambda: index_level(level, s.piece_faces))
    blog.note(
        "geometry",
        vertices=index.vertices,
        faces=index.faces,
        occluder_faces=index.faces + level.counts().get("blocker_faces", 0),
        pieces=len(index.pieces),
    )
    t = s.trace
    light = pieces_context(keys["geometry"], level, index)
    # Locally, s.workers tasks at a time on threads, each tracing on one (as Ray's single-CPU actors): no
    # task's numpy waits for its own tracing threads, and the stages' tasks fill the cores.
    local = None if engine is not None else LocalEngine(workers=s.workers, threads=1)
    settings_here = worker_settings(label_settings(s, index.diagonal), engine or local)
    frame = LabellerFrame(index.center, index.diagonal, settings_here)
    ctx = opaque_context(keys["geometry"], level, index, settings_here, t.bvh)
    blog.runner = engine or local
    # The opaque BVH built on the workers while the foliage and the samples' passes are made (the foliage
    # is not in its state: the tasks that trace it carry it); the trace, the resampling and the blend
    # check read it.
    blog.prepare("prepare_opaque", "trace", lambda: ctx, ("trace", "small_decorators", "lod", "blend_check"))
    blog.runner = None
    foliage = shrubs = None
    if s.foliage.enabled:
        # the shrubs' boxes made once: the trees' gold foliage has the same
        shrubs, foliage = blog.timed(
            "foliage",
            "Flatten trees, shrub 'fog' boxes + foliage BVH",
            lambda: _shrubs_and_foliage(level, frame, s),
        )
        blog.note("foliage", trees=level.counts().get("tree_instances", 0), shrub_boxes=foliage.n_boxes)
    shared = shared_foliage(foliage, settings_here, keys["foliage"])
    blog.runner = engine or local
    # The samples' two passes over the pieces' sample ranges are a task per range each.
    rule, pieces = blog.timed(
        "samples",
        "Sample mesh",
        lambda: sample_rule(
            level,
            index,
            t.samples_per_vertex,
            t.min_samples_per_face,
            t.samples_per_face_cap,
            s.seed,
            engine_each(blog.runner, light),
        ),
    )
    blog.runner = None
    total_samples = sum(p.ns for p in pieces)
    blog.note("samples", samples=total_samples)
    # With an engine every trace runs on the workers: the driver builds no Embree scene (a few GiB for a
    # world of tens of millions of faces).
    if engine is None:
        state = blog.timed("bvh", "Embree BVH build (opaque)", lambda: ctx.build(ctx.value()))
        local.hold(ctx.key, state)
        runner = local
    else:
        runner = engine
    blog.runner = runner  # each stage's row counts its tasks' seconds
    trace_files = TaskFiles(blog.dir / "trace", keys["trace"])
    # The solve's plans of its pieces in subdomains (a connected component check and the subdomains, from
    # the mesh alone) are made in the trace's wave, beside its blocks.
    plan_files = TaskFiles(blog.dir / "solve_plan", keys["solve"])
    plans = unfinished(plan_files, plan_jobs(light, pieces, t)) if blog.will_make("solve") else []
    traced = blog.stored(
        "trace",
        "Ray trace samples (2 distances, foliage)",
        lambda: _summary(
            run_to_files(
                trace_files,
                runner,
                trace_jobs(ctx, pieces, rule, s, shared),
                "trace blocks",
                progress,
                keys=("valid", "weight", "weighted"),
                aside=(plan_files, plans),
            ),
            invalid=lambda r: int((~r["valid"]).sum()),
            valid_weight=lambda r: float(r["weight"]),
            valid_weighted=lambda r: r["weighted"],
        ),
        samples=total_samples,
        rays=total_samples * s.trace.rays,
    )
    # The trees' gold BVH built on the workers from here on, while the solve's and the LOD's drivers leave
    # them mostly idle, where a worker may hold it beside the opaque one the resampling still reads (a
    # local bake holds its own: its log places the call as on such machines); else once the opaque is done.
    gold = functools.cache(lambda: gold_stage_context(level, index.diagonal, s, runner, keys, shrubs))

    def prepare_gold() -> None:
        blog.prepare("prepare_gold", "decorators", gold)

    ahead = engine is None or engine.heavy_states >= 2
    if ahead:
        prepare_gold()
    solve_files = TaskFiles(blog.dir / "solve", keys["solve"])
    # What every piece's least squares takes from the whole level (it is one block of the level's).
    weight = float(traced["valid_weight"])
    prior = traced["valid_weighted"] / weight if weight > 0 else np.ones(2)
    whole = Whole(weight, rule.area_all, prior)
    lod_files = TaskFiles(blog.dir / "lod", keys["lod"]) if s.lod.enabled else None
    # The per-piece LOD's simplifications need no solved value: they run in the solve's first wave, beside
    # its own tasks (on many machines they then take no wave of their own).
    solved = blog.stored(
        "solve",
        "Least squares solve (both distances)",
        lambda: _summary(
            solve_stage(
                solve_files,
                runner,
                light,
                pieces,
                rule,
                trace_files,
                s,
                whole,
                progress,
                plan_files,
                SOLVE_TIMES,
                aside=_lod_ahead(lod_files, light, pieces, s),
            ),
            **{k: lambda r, k=k: float(r[k]) for k in SOLVE_TIMES},
        ),
        vertices=index.vertices,
    )
    blog.note("solve", **{k: float(v) for k, v in solved.items() if k.startswith("seconds_")})
    shutil.rmtree(plan_files.folder, ignore_errors=True)  # the plans' subdomains are in the solve's results
    # The baked AO of every opaque vertex (NaN on blockers): what the resampling of grass, shrubs and the
    # LOD reads, one float each.
    values = Resampler.share(_final_values(solve_files, pieces, index, level, s))
    small = blog.stored(
        "small_decorators",
        "Resample grass clumps and shrubs",
        lambda: small_decorators(
            level, Resampler(runner, ctx, blog.parts("small_decorators"), task_rays(s, runner)), values, s
        ),
    )
    lod = None
    if lod_files is not None:
        lod = blog.stored(
            "lod",
            "LOD: simplify, resample, least squares solve",
            lambda: _lod_stage(
                runner,
                (ctx, light, pieces_context(keys["geometry"], level, index, heavy=True)),
                level,
                index,
                pieces,
                rule,
                values,
                lod_files,
                s,
                progress,
            ),
        )
        blog.note(
            "lod",
            lod_vertices=int(lod["lod_vertices"]),
            lod_faces=int(lod["lod_faces"]),
            resample_points=int(lod["resample_points"]),
            simplify_tasks=int(lod.get("simplify_tasks", 1)),
            simplified_beside=int(lod.get("simplified_beside", 0)),
            **({"resample_tasks": int(lod["resample_tasks"])} if "resample_tasks" in lod else {}),
            **{
                k: float(lod[k])
                for k in ("seconds_simplify", "seconds_resample", "seconds_solve", "seconds_reference")
            },
        )
    values = None  # the driver keeps no per-vertex array past the resampling stages
    lod_err = blend_err = None
    if lod is not None and s.error_tables:
        lod_err = blog.stored(
            "lod_check",
            "LOD vs traced samples at held-out points (error table)",
            lambda: _lod_check(
                runner,
                light,
                pieces,
                rule,
                (lod_files, trace_files, TaskFiles(blog.dir / "lod_reference", keys["lod_check"])),
                float(lod["radius"]),
                s,
                progress,
            ),
        )
    if s.error_tables:
        blend_err = blog.stored(
            "blend_check",
            "Two-distance blend vs blended-kernel traces (error table)",
            lambda: _blend_check(
                runner, ctx, pieces, rule, trace_files, solve_files, index, s, total_samples, whole, shared
            ),
        )
    # The trees last: their gold BVH (the level with every tree opaque) replaces the opaque one on the
    # workers (and here), which need it no more.
    if engine is None:
        runner.release(ctx.key)
        state = None
    if not ahead:
        prepare_gold()
    deco = blog.stored(
        "decorators",
        "Trees: local AO, in-place gold standard, eq. 3 fits",
        lambda: bake_decorators(
            level,
            index.diagonal,
            s,
            runner,
            engine is None,
            blog.parts("decorators"),
            keys,
            shrubs,
            gold(),
        ),
        instances=level.counts().get("tree_instances", 0),
    )
    if "seconds_gold_state" in deco:
        blog.note("decorators", seconds_gold_state=float(deco["seconds_gold_state"]))
    # A kept output folder of an older bake (whose parts went through files) is not read.
    shutil.rmtree(blog.dir / "output", ignore_errors=True)
    blog.timed(
        "output",
        "Write glTF, shader, log",
        lambda: write_outputs(
            out / s.output,
            out,
            level,
            index,
            s,
            runner.ordered(output_jobs(light, pieces, index, solve_files, s)),
            deco,
            small,
            None if lod_files is None else (lod_files, lod_mesh_files(lod_files)),
            pieces,
        ),
    )
    # ru_maxrss is the whole run's peak (the stages' own peaks are in their rows: VmHWM is reset per stage).
    peak = max(
        [resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024]
        + [st.get("peak_rss_bytes", 0) for st in blog.stages]
    )
    counts = level.counts()
    info = {
        "level": str(path),
        "keys": keys,
        "settings": settings_to_dict(s),
        "stages": blog.stages,
        "seconds_total": time.perf_counter() - t_start,
        "cpu_seconds_total": _cpu_seconds() - c_start,
        "peak_rss_bytes": int(peak),
        "counts": {
            **counts,
            "receiver_vertices": index.vertices,
            "receiver_faces": index.faces,
            "pieces": len(pieces),
            "samples": total_samples,
            "invalid_samples": int(traced["invalid"]),
        },
        "errors": _error_tables(deco, lod_err, blend_err),
        # Every task's own seconds per stage (as it ran, on whichever worker): what bench/bench_level.py
        # projects onto N machines.
        "task_seconds": blog.task_seconds,
        "task_waves": blog.task_waves,
        "task_aside": blog.task_aside,
        "state_seconds": blog.state_seconds,
        "state_waits": blog.state_waits,
        "state_prepared": blog.state_prepared,
        "engine": runner.name,
        # Threads each task traced with (this process's for a local bake; an actor's on Ray).
        "task_threads": runner.threads or s.workers,
        "tasks_at_once": runner.workers,
        # How task seconds were taken: the wall clock, or each task's thread CPU seconds
        "task_clock": runner.task_clock,
        "output_bytes": _bytes_written(out / s.output),
        "load_average": list(os.getloadavg()),
        "cpu_count": os.cpu_count(),
    }
    write_json(out / "bake_log.json", info)
    write_text(out / "bake_log.md", bake_log_markdown(info))
    return info


def _shrubs_and_foliage(level, frame, s: LevelBakeSettings) -> tuple:
    """The shrubs' boxes (:func:`shrub_boxes`) and the opaque labeller's foliage made from them."""
    shrubs = shrub_boxes(level, s.foliage)
    return shrubs, build_foliage(level, frame, s.foliage, shrubs=shrubs)


def _bytes_written(path: Path) -> int:
    """Bytes of the baked glTF (and its .bin beside a .gltf)."""
    total = path.stat().st_size
    if path.suffix.lower() == ".gltf" and path.with_suffix(".bin").is_file():
        total += path.with_suffix(".bin").stat().st_size
    return total


def _summary(results, **fields) -> dict[str, np.ndarray]:
    """Consume ``run_to_files``' results one at a time: the number of tasks, those an earlier run did, and
    the sum of each field (a function of one result)."""
    sums = {k: 0.0 for k in fields}
    tasks = reused = 0
    for _, r, was_reused in results:
        tasks += 1
        reused += was_reused
        for k, f in fields.items():
            sums[k] += f(r)
    return {
        "tasks": np.array(tasks),
        "reused_tasks": np.array(reused),
        **{k: np.array(v) for k, v in sums.items()},
    }


# The solve's seconds each piece's result carries (what the stage's row sums; its values are not read).
SOLVE_TIMES = ("seconds_assembly", "seconds_blocks", "seconds_largest_block", "seconds_driver")


def _final_values(solve_files: TaskFiles, pieces, index, level, s: LevelBakeSettings) -> np.ndarray:
    """(opaque vertices,) float32: the blended AO of every static vertex, NaN on blockers."""
    blockers = level.counts().get("blocker_vertices", 0)
    values = np.full(index.vertices + blockers, np.nan, np.float32)
    for p in pieces:
        r = solve_files.get(piece_stem(p))
        values[p.v0 : p.v0 + p.nv] = blend(r["short"], r["long"], s.blend)
    return values


def _lod_stage(runner, contexts, level, index, pieces, rule, values, lod_files, s, progress):
    """LOD 1 of the level's static instances: one task, one simplification of them all, split by piece as
    it arrives; or with ``lod.max_error`` a task per piece, each simplified alone to that shared error.
    Then per piece its LOD resampled and solved, and its held-out points for the error table (a task
    each). The resampling radius is 1.5 x the LOD's median edge unless ``lod.radius`` sets it.
    ``contexts``: the opaque labeller's, the level's pieces' and the one simplification's."""
    ctx, light, simplify_ctx = contexts
    t0 = time.perf_counter()
    mesh_files = lod_mesh_files(lod_files)
    mesh_files.keep_only({piece_stem(p) for p in pieces} | {"radius"})
    have_meshes = _lod_meshes_made(lod_files, pieces)
    simplified = beside = 0
    if s.lod.max_error is not None and not have_meshes:
        # Per piece (a big one in tiles), a task each, at one shared error (those not done beside the solve);
        # the pieces' meshes joined from their tiles here, the radius from the level's median LOD edge.
        tile_files, jobs = _lod_tile_jobs(lod_files, light, pieces, s)
        simplified = len(unfinished(tile_files, jobs))
        beside = len(jobs) - simplified  # made in the solve's first wave
        edges, tiles = [], []
        for stem, r, _ in run_to_files(tile_files, runner, jobs, "lod simplify", progress):
            edges.append(r["edges"])
            tiles.append(r)
            p = pieces[int(stem[1:6])]
            if len(tiles) == lod_tiles(p, s.lod.tile_faces):
                mesh_files.put(piece_stem(p), join_tiles(tiles))
                tiles = []
        edges = np.concatenate(edges)
        median = float(np.median(edges.astype(np.float64))) if len(edges) else 1.0
        del edges
        mesh_files.put("radius", {"median_edge": np.array(median)})
        shutil.rmtree(tile_files.folder, ignore_errors=True)  # joined into the pieces' meshes
    elif not have_meshes:
        # A heavy context: its worker drops the opaque BVH while it simplifies the flattened level.
        ((_, result),) = list(runner.map([Task(simplify_ctx, simplify_level, (s.lod.target_reduction,))]))
        for stem, part in split_lod(result, pieces):
            mesh_files.put(stem, part)
        mesh_files.put("radius", {"median_edge": result["median_edge"]})
        del result
    radius = s.lod.radius or 1.5 * float(mesh_files.get("radius")["median_edge"])
    t1 = time.perf_counter()
    per_block = max(1, task_rays(s, runner) // s.lod.rays)
    # the blocks' files are numbered by this size: a rerun with another (another engine) redoes them
    resample_files = TaskFiles(
        lod_files.folder.parent / "lod_resample", content_key(lod_files.key, per_block)
    )
    jobs, counts = lod_resample_jobs(ctx, pieces, values, mesh_files, radius, s, per_block)
    resample_tasks = len(jobs)
    for _ in run_to_files(resample_files, runner, jobs, "lod resampling", progress, keys=()):
        pass  # every block's values are there (read by the pieces' tasks below)
    t2 = time.perf_counter()

    def resampled(p):
        return piece_resampled(resample_files, p, counts[p.index], per_block)

    jobs = lod_jobs(light, pieces, rule, mesh_files, resampled, radius, s)
    for _ in run_to_files(lod_files, runner, jobs, "lod", progress, keys=LOD_SUMMED):
        pass  # read again, piece by piece, by the summary
    out = _lod_summary(lod_files, pieces)
    out["seconds_simplify"] = np.array(t1 - t0)
    # The stage's tasks in order: its simplifications (one of the whole level, or those of the pieces and
    # tiles not made beside the solve), its resampling, then a task per piece.
    out["simplify_tasks"] = np.array(simplified if s.lod.max_error is not None else int(not have_meshes))
    out["simplified_beside"] = np.array(beside)
    out["resample_tasks"] = np.array(resample_tasks)
    out["seconds_resample"] = np.array(t2 - t1)
    out["radius"] = np.array(radius)
    return out


def _lod_tile_jobs(lod_files: TaskFiles, light, pieces, s: LevelBakeSettings) -> tuple[TaskFiles, list]:
    """The per-piece LOD's simplifications (``lod.max_error``): their files and (stem, task maker) per piece,
    or per tile of a piece of more than ``lod.tile_faces`` faces (:func:`simplify_piece`)."""
    jobs = [
        (
            f"{piece_stem(p)}_{t:04d}",
            lambda p=p, t=t, n=n: Task(light, simplify_piece, (p, n, t, s.lod.max_error)),
        )
        for p in pieces
        for n in [lod_tiles(p, s.lod.tile_faces)]
        for t in range(n)
    ]
    return TaskFiles(lod_files.folder.parent / "lod_tiles", lod_files.key), jobs


def _lod_meshes_made(lod_files: TaskFiles, pieces) -> bool:
    """Whether every piece's LOD mesh and the resampling radius are stored (no simplification is left)."""
    mesh_files = lod_mesh_files(lod_files)
    return all(mesh_files.has(stem) for stem in [*(piece_stem(p) for p in pieces), "radius"])


def _lod_ahead(lod_files: TaskFiles | None, light, pieces, s: LevelBakeSettings):
    """What the solve's first wave runs beside its own tasks: the per-piece LOD's simplifications that
    are not done yet (they need no solved value), as (their files, their jobs); None when there are none
    (no LOD, one global simplification, or the LOD's meshes already made)."""
    if lod_files is None or s.lod.max_error is None or _lod_meshes_made(lod_files, pieces):
        return None
    files, jobs = _lod_tile_jobs(lod_files, light, pieces, s)
    todo = unfinished(files, jobs)
    return (files, todo) if todo else None


# What the LOD stage's summary reads of each piece's result (not its meshes and values).
LOD_SUMMED = ("sizes", "resample_points", "seconds_solve", "seconds_reference", *LOD_HELD_OUT)


def _lod_summary(lod_files: TaskFiles, pieces) -> dict[str, np.ndarray]:
    """The LOD pieces' counts and times."""
    times = ("seconds_solve", "seconds_reference")
    out = dict.fromkeys(("lod_vertices", "lod_faces", "resample_points", *times), 0.0)
    for p in pieces:
        r = _lod_result(lod_files, p, LOD_SUMMED)
        out["lod_vertices"] += int(r["sizes"][0])
        out["lod_faces"] += int(r["sizes"][1])
        out["resample_points"] += float(r["resample_points"])
        for k in times:
            out[k] += float(r[k])
    return {k: np.array(v) for k, v in out.items()}


def _lod_result(lod_files: TaskFiles, piece, keys) -> dict[str, np.ndarray]:
    r = lod_files.get(piece_stem(piece), keys)
    if r is None:
        raise NeuralaoError(f"{lod_files.path(piece_stem(piece))} could not be read back: is the disk full?")
    return r


def _lod_check(runner, light, pieces, rule, files, radius: float, s, progress) -> dict[str, np.ndarray]:
    """The LOD's error table: at each piece's held-out LOD points, its two AOs (resampled at the LOD's
    vertices, least squares over resampled samples) against the gold standard there, the traced samples
    within the resampling sphere (a task per trace block of a piece with held-out points); each piece's
    error sums (:func:`lod_piece_errors`) added in piece order. Writes nothing into the baked level.
    ``files``: the LOD's results, the trace's blocks and this stage's own (the gold standard's sums)."""
    lod_files, trace_files, reference_files = files
    jobs = lod_reference_jobs(light, pieces, rule, lod_files, trace_files, radius, s)
    for _ in run_to_files(reference_files, runner, jobs, "lod reference", progress, keys=()):
        pass  # read piece by piece below
    sums = np.zeros(6)
    for p in pieces:
        r = _lod_result(lod_files, p, LOD_HELD_OUT)
        sums += lod_piece_errors(r, reference_files, lod_reference_stems(p, s.trace.block_samples))
    sw = max(sums[0], 1e-300)
    mean = sums[3] / sw
    return {
        "radius": np.array(radius),
        "rmse_vertex": np.array(np.sqrt(sums[1] / sw)),
        "rmse_least_squares": np.array(np.sqrt(sums[2] / sw)),
        "rmse_constant": np.array(np.sqrt(max(sums[4] / sw - mean**2, 0.0))),
        "holdout": np.array(int(sums[5])),
    }


# Largest level on which the blend check also fits the blended samples by least squares.
_BLEND_LSQ_CHECK_VERTICES = 300_000


def _blend_check(
    runner,
    ctx,
    pieces,
    rule,
    trace_files,
    solve_files,
    index,
    s: LevelBakeSettings,
    total: int,
    whole: Whole,
    foliage=None,
    count: int = 2000,
) -> dict:
    """The error table of the two-distance blend: (a) same rays (valid samples): blend of the two columns vs
    one trace whose kernel is the blend (rho_b = w rho_long + (1 - w) rho_short: the mean is linear, so any
    difference is float rounding); (b) the stored per-vertex blend vs a 4x-ray blended-kernel reference
    at held-out samples (the bake's error); (c) per-vertex blend vs least squares of blended samples (levels
    of at most 300k vertices). Each piece's picked samples are a task."""
    rng = np.random.default_rng(s.seed + 7)
    pick = np.sort(rng.choice(total, size=min(count, total), replace=False))
    starts = np.array([p.s0 for p in pieces])
    owner = np.searchsorted(starts, pick, side="right") - 1
    gap = index.vertices <= _BLEND_LSQ_CHECK_VERTICES
    w = s.blend.long_weight
    # The blend is linear, so the blended samples' mean is the blend of the two means.
    blended = replace(whole, prior=w * whole.prior[1] + (1 - w) * whole.prior[0])
    # The reference: 4x the rays, its own seed.
    ref_settings = replace(label_settings(s, index.diagonal, 4 * s.trace.rays), seed=s.seed + 1000)
    jobs, parts = [], []
    for p in pieces:
        mine = np.flatnonzero(owner == p.index)
        if not len(mine) and not gap:
            continue
        local = pick[mine] - p.s0

        def make(p=p, local=local, mine=mine) -> Task:
            ao, valid = piece_trace(trace_files, p, s.trace.block_samples)
            r = solve_files.get(piece_stem(p))
            two_ao, two_valid = ao[local], valid[local]
            parts.append((mine, two_ao, two_valid))
            args = (p, rule, local, mine.astype(np.int64), r["short"], r["long"])
            if gap:
                args += (ao, valid, s, ref_settings, True, blended, foliage)
            else:
                args += (None, None, s, ref_settings, False, blended, foliage)
            return Task(ctx, blend_piece, args)

        jobs.append(make)
    n = len(pick)
    kern, ref_two, ref_valid, pred = np.zeros(n), np.zeros((n, 2)), np.zeros(n, bool), np.zeros(n)
    two_ao, two_valid = np.zeros((n, 2)), np.zeros(n, bool)
    worst = np.nan
    # Made as the engine takes them (each ``make`` notes its picks, in order): one piece's arrays at a time.
    for i, r in runner.map(make() for make in jobs):
        mine, a, v = parts[i]
        kern[mine], ref_two[mine], ref_valid[mine], pred[mine] = (
            r["kern"],
            r["ref_two"],
            r["ref_valid"],
            r["pred"],
        )
        two_ao[mine], two_valid[mine] = a, v
        if gap:
            worst = float(r["gap"]) if np.isnan(worst) else max(worst, float(r["gap"]))
    w = s.blend.long_weight
    plain = replace(s.blend, remap=None)
    two = blend(two_ao[:, 0], two_ao[:, 1], plain)
    ref = w * ref_two[:, 1].astype(np.float64) + (1 - w) * ref_two[:, 0]
    m = ref_valid & two_valid
    return {
        # over valid samples: the trace stops early on samples the back-face rule rejects
        "same_rays_max_abs": np.array(float(np.abs(two - kern)[two_valid].max(initial=0.0))),
        "bake_rmse_vs_reference": np.array(float(np.sqrt(np.mean((pred[m] - ref[m]) ** 2)))),
        "samples_rmse_vs_reference": np.array(float(np.sqrt(np.mean((two[m] - ref[m]) ** 2)))),
        "per_vertex_blend_vs_lsq_of_blend_max_abs": np.array(worst),
        "count": np.array(int(m.sum())),
    }


def _error_tables(deco: dict, lod: dict | None, blend_err: dict | None) -> dict:
    """The bake's error tables: the trees' fits always, the LOD's and the blend's where they were made."""
    out: dict[str, Any] = {}
    if blend_err is not None:
        out["blend"] = {k: float(v) for k, v in blend_err.items()}
    if len(deco.get("models", [])):
        out["decorators"] = {
            k[5:]: {"mean": float(np.mean(v)), "max": float(np.max(v))}
            for k, v in deco.items()
            if k.startswith("rmse_")
        }
        out["decorators"]["instances"] = int(len(deco["coefficients"]))
    if lod is not None:
        out["lod"] = {
            "rmse_vertex": float(lod["rmse_vertex"]),
            "rmse_least_squares": float(lod["rmse_least_squares"]),
            "rmse_constant": float(lod["rmse_constant"]),
            "holdout": int(lod["holdout"]),
            "radius": float(lod["radius"]),
        }
    return out


def bake_log_markdown(info: dict) -> str:
    """A table like Table 1 of Sloan et al. 2013 (stage, counts, seconds) plus totals and errors."""
    c = info["counts"]
    lines = [
        f"Bake of {Path(info['level']).name}: {c['receiver_vertices']:,} V {c['receiver_faces']:,} F, "
        f"{c['samples']:,} samples, {info['settings']['trace']['rays']} rays",
        "",
        "| Description | Time (s) | CPU (s) | peak RSS (MiB) | reused |",
        "|---|---:|---:|---:|:---:|",
    ]
    skip = ("stage", "description", "seconds", "cpu_seconds", "reused", "peak_rss_bytes")
    for st in info["stages"]:
        extra = {k: v for k, v in st.items() if k not in skip}
        detail = ", ".join(
            f"{k} {v:,}" if isinstance(v, int) else f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}"
            for k, v in extra.items()
        )
        rss = f"{st['peak_rss_bytes'] / 2**20:,.0f}" if "peak_rss_bytes" in st else ""
        lines.append(
            f"| {st['description']}{' (' + detail + ')' if detail else ''} | {st['seconds']:.2f} | "
            f"{st['cpu_seconds']:.1f} | {rss} | {'yes' if st['reused'] else ''} |"
        )
    lines += [
        f"| **Total** | **{info['seconds_total']:.1f}** | **{info['cpu_seconds_total']:.1f}** | "
        f"**{info['peak_rss_bytes'] / 2**20:,.0f}** | |",
        "",
        f"Peak memory (RSS): {info['peak_rss_bytes'] / 2**30:.2f} GiB; "
        f"load average {info['load_average'][0]:.2f} "
        f"on {info['cpu_count']} cores (CPU s: all threads of this process).",
        "",
    ]
    e = info["errors"]
    if "decorators" in e:
        d = e["decorators"]
        lines += ["| decorators (trees, RMSE vs traced gold standard) | mean | max |", "|---|---:|---:|"]
        for k in ("in_place", "local_x_global", "global_only", "local_only", "local_x_global_vs_in_place"):
            lines.append(f"| {k.replace('_', ' ')} | {d[k]['mean']:.4f} | {d[k]['max']:.4f} |")
        lines.append("")
    if "lod" in e:
        lines += [
            "| LOD transfer (RMSE vs gold standard) | RMSE |",
            "|---|---:|",
            f"| resampled at LOD vertices | {e['lod']['rmse_vertex']:.4f} |",
            f"| least squares over resampled samples | {e['lod']['rmse_least_squares']:.4f} |",
            f"| (baseline: one constant) | {e['lod']['rmse_constant']:.4f} |",
            "",
        ]
    if "blend" not in e:
        return "\n".join(lines)
    b = e["blend"]
    lines += [
        "| two-distance blend | value |",
        "|---|---:|",
        "| same rays: blend of two columns vs blended-kernel trace, max abs | "
        f"{b['same_rays_max_abs']:.2e} |",
        "| per-vertex blend vs least squares of blended samples, max abs | "
        f"{b['per_vertex_blend_vs_lsq_of_blend_max_abs']:.2e} |",
        f"| samples (blend) vs 4x-ray blended reference, RMSE | {b['samples_rmse_vs_reference']:.4f} |",
        f"| baked vertices (blend) vs 4x-ray blended reference, RMSE | {b['bake_rmse_vs_reference']:.4f} |",
        "",
    ]
    return "\n".join(lines)
