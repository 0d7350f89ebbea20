"""AO at points as engine tasks: the labeller of :mod:`neuralao.pipeline.tracing.labeller` split into chunks
of points mapped over an :class:`~neuralao.pipeline.engines.engine.Engine` (this process or a Ray cluster).

* :func:`labeller_context`: the :class:`~neuralao.pipeline.engines.engine.Context` a worker builds one
  Embree scene from (keyed by the scene's content and the label settings);
* :func:`trace_chunk`: the task body, one chunk of points -> ``{"ao", "valid"}``;
* :class:`EngineLabeller`: what the bakers use of a Labeller, with the tracing done as tasks.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from tqdm import tqdm

from neuralao.pipeline.engines.engine import Context, Engine, ResultStore, Task, content_key
from neuralao.pipeline.geometry.scene import Scene, slim_scene
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings, positive_distance


def _build_labeller(payload) -> Labeller:
    scene, settings = payload
    return Labeller(scene, settings)


def trace_chunk(labeller, args) -> dict[str, np.ndarray]:
    points, normals, ids = args
    ao, valid = labeller.ao_at_points(points, normals, ids=ids)
    return {"ao": ao, "valid": valid}


def labeller_context(scene: Scene, settings: LabelSettings, threads: int | None = None) -> Context:
    """A worker-side :class:`~neuralao.pipeline.tracing.labeller.Labeller` (one Embree scene) of ``scene``
    with
    ``threads`` threads (None: ``settings.workers``; labels never depend on it)."""
    if threads is not None:
        settings = replace(settings, workers=threads)
    slim = slim_scene(scene)
    key = content_key("labeller", slim.vertices, slim.faces, settings)
    return Context(key, _build_labeller, (slim, settings))


class EngineLabeller:
    """What the bakers use of a :class:`~neuralao.pipeline.tracing.labeller.Labeller` (``ao_at_points``,
    ``settings``,
    ``max_distance``), with the tracing split into chunks of points mapped over an engine.

    A point's rays depend only on (seed, id, normal), never on its chunk, so the result is bit-identical
    to ``Labeller(scene, settings).ao_at_points(points, normals)``. With ``store``, finished chunks
    are kept on disk (keyed by scene, settings and the chunk's points) and a rerun skips them.
    """

    def __init__(
        self,
        scene: Scene,
        settings: LabelSettings,
        engine: Engine,
        store: ResultStore | None = None,
        chunk_rays: int | None = None,
    ):
        self.scene, self.settings, self.engine, self.store = scene, settings, engine, store
        self.chunk_rays = chunk_rays or engine.task_rays  # rays per task
        self.max_distance = positive_distance(
            "max_distance", settings.max_distance, settings.max_distance_rel, scene.diagonal
        )
        self._context = labeller_context(scene, settings, engine.threads)

    def ao_at_points(self, points: np.ndarray, normals: np.ndarray, progress: bool = False):
        """points, normals (n, 3) float64 -> ao (n,) float32, valid (n,) bool (ids = arange(n))."""
        points = np.asarray(points, np.float64)
        normals = np.asarray(normals, np.float64)
        n = len(points)
        step = max(1, self.chunk_rays // self.settings.rays)
        bounds = [(lo, min(lo + step, n)) for lo in range(0, n, step)]
        ctx = self._context

        def tasks():
            for lo, hi in bounds:
                p, q = points[lo:hi], normals[lo:hi]
                key = content_key(ctx.key, p, q, lo) if self.store is not None else None
                yield Task(ctx, trace_chunk, (p, q, np.arange(lo, hi, dtype=np.int64)), key)

        ao = np.ones(n, np.float32)
        valid = np.zeros(n, bool)
        with tqdm(total=n, unit="pt", desc="AO labels", disable=not progress, leave=False) as bar:
            for i, result in self.engine.map(tasks(), self.store):
                lo, hi = bounds[i]
                ao[lo:hi], valid[lo:hi] = result["ao"], result["valid"]
                bar.update(hi - lo)
        return ao, valid
