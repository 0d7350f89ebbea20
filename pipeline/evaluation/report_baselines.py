"""The report's baselines and the scenes they run in: the rows of the screen-space (SSAO, GTAO), baked
(vertex AO) and traced (Embree) methods (:func:`baseline_methods`), the per-scene context they read
(mesh, labeller, radii, cached bakes: :class:`SceneContext`), and :data:`BASELINES`, the table from
baseline family to how it computes a frame's AO and its time, with its place, colour and sides in the
report. The ``family_*`` functions answer those for any family, baselines and model kinds
(:mod:`neuralao.runtime.kinds`) alike."""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from neuralao.pipeline.bakes.vertex import BakeSettings, bake
from neuralao.pipeline.evaluation.report_settings import Method, ReportSettings
from neuralao.pipeline.evaluation.report_truth import frame_key_seed
from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.camera import Camera
from neuralao.pipeline.tracing.labeller import Labeller
from neuralao.runtime import kinds
from neuralao.runtime.baselines import (
    run_screen_space,
    time_screen_space,
    time_vertex_ao,
    traced_ao,
    vertex_ao_image,
)
from neuralao.runtime.foundation.io import read_npz, sha256_json, write_npz
from neuralao.runtime.foundation.settings import settings_to_dict
from neuralao.runtime.frame import FrameLike

log = logging.getLogger(__name__)

# The baseline rows in table order (the traced rows follow by ray count).
BASELINE_ORDER = ("ssao", "gtao", "vertex-sampled", "vertex-lsq", "vertex-lsq-8bit")


def baseline_methods(settings: ReportSettings) -> list[Method]:
    s = settings.ssao
    ssao_bytes = s.samples * 12 + s.noise_size**2 * 16
    gtao_bytes = settings.gtao.noise_size**2 * 16
    out = [
        Method(
            "ssao",
            "screen-space",
            f"Crytek-style normal-oriented hemisphere SSAO, {s.samples} samples + "
            f"{s.noise_size}x{s.noise_size} blur",
            "GL fragment shader",
            "GL fragment shader",
            bytes=ssao_bytes,
            bytes_note="kernel + noise tile",
        ),
        Method(
            "gtao",
            "screen-space",
            f"GTAO, {settings.gtao.slices} slices x {settings.gtao.steps} steps + blur",
            "GL fragment shader",
            "GL fragment shader",
            bytes=gtao_bytes,
            bytes_note="noise tile",
        ),
        Method(
            "vertex-sampled",
            "baked",
            f"per-vertex AO sampled at vertices ({settings.bake_rays} rays), vertex colours",
            "GL vertex-colour draw",
            "barycentric interpolation (= the draw)",
            bytes_note="4 B per vertex",
        ),
        Method(
            "vertex-lsq",
            "baked",
            f"least-squares vertex bake ({settings.bake_rays} rays/sample), vertex colours",
            "GL vertex-colour draw",
            "barycentric interpolation (= the draw)",
            bytes_note="4 B per vertex",
        ),
        Method(
            "vertex-lsq-8bit",
            "baked",
            "the least-squares bake stored as 8-bit UNORM vertex colours",
            "GL vertex-colour draw",
            "barycentric interpolation of the 8-bit values",
            bytes_note="1 B per vertex",
        ),
    ]
    for r in settings.trace_rays:
        out.append(
            Method(
                f"trace-{r}",
                "traced",
                f"Embree ray-traced AO, {r} rays per pixel",
                f"CPU Embree ({settings.workers} threads)",
                "CPU Embree",
                bytes_note="scene + BVH",
            )
        )
    return out


class SceneContext:
    """The scene's mesh, labeller, radii, bakes and timing frame, built lazily.

    ``radius``: the labels' max distance (scene units), the radius of the main figures;
    ``radii``: (k,) scene units of the per-radius evaluation (``radii_rel`` x diagonal);
    ``trace_radii``: ``radii`` (columns 0..k-1) plus the max distance when it is not one of them, the
    radii of the one ground-truth trace; ``main``: the max distance's column.
    """

    def __init__(
        self,
        name: str,
        scene,
        label_settings,
        settings: ReportSettings,
        cache: Path | None,
        progress: bool,
        radii_rel: list[float] | None = None,
    ):
        self.name = name
        self.scene = scene
        self.labeller = Labeller(self.scene, label_settings)
        self.radius = self.labeller.max_distance
        diag = float(scene.diagonal)
        self.radii_rel = list(radii_rel or [])
        # rel * diag, as Labeller resolves radii_rel; the max distance itself where they agree, so its
        # column is exactly the single-radius label (bit for bit)
        self.radii = tuple(
            self.radius if math.isclose(float(r) * diag, self.radius, rel_tol=1e-9) else float(r) * diag
            for r in self.radii_rel
        )
        self.trace_radii = self.radii if self.radius in self.radii else (*self.radii, self.radius)
        self.main = self.trace_radii.index(self.radius)
        self.settings = settings
        self.cache = cache
        self.progress = progress
        self.bakes: dict[str, np.ndarray] = {}
        self.bake_info: dict[str, dict] = {}

    def baked(self, method: str) -> np.ndarray:
        """Per-vertex AO (n,) float32 of 'vertex-sampled' / 'vertex-lsq' (cached under OUT/bake/)."""
        if method in self.bakes:
            return self.bakes[method]
        if method == "vertex-lsq-8bit":  # what an RGBA8 vertex-colour attribute stores
            lsq = self.baked("vertex-lsq")
            self.bakes[method] = (np.rint(np.clip(lsq, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)
            return self.bakes[method]
        ls = self.labeller.settings
        bs = BakeSettings(
            rays=self.settings.bake_rays,
            max_distance=self.labeller.max_distance,
            kernel=ls.kernel,
            half_distance=self.labeller.half_distance,
            method="vertex" if method == "vertex-sampled" else "least-squares",
            samples_per_vertex=self.settings.bake_samples_per_vertex,
            backface_threshold=ls.backface_threshold,
            seed=frame_key_seed(self.settings.seed, "bake", self.name),
            workers=ls.workers,
        )
        key = {
            "scene": self.name,
            "vertices": len(self.scene.vertices),
            "faces": len(self.scene.faces),
            "source": self.scene.source,
            "bake": settings_to_dict(bs),
        }
        path = self.cache / f"{self.name}-{method}-{sha256_json(key)[:16]}.npz" if self.cache else None
        if path is not None and path.is_file():
            z = read_npz(path)
            self.bakes[method] = z["ao"]
            self.bake_info[method] = json.loads(str(z["info"]))
        else:
            log.info(
                "baking %s (%s, %d vertices) for the vertex-AO baselines",
                self.name,
                method,
                len(self.scene.vertices),
            )
            r = bake(self.scene, bs, progress=self.progress)
            self.bakes[method], self.bake_info[method] = r.ao, r.info
            if path is not None:
                write_npz(path, ao=r.ao, info=np.array(json.dumps(r.info, default=str)))
        return self.bakes[method]

    def timing_frame(self, frame: FrameLike) -> tuple[dict, Camera]:
        """A ``time_size`` G-buffer from the pose of ``frame`` and its camera."""
        return timing_frame(self.scene, frame, self.settings.time_size)


def timing_frame(scene, frame: FrameLike, size: tuple[int, int]) -> tuple[dict, Camera]:
    """A G-buffer of ``scene`` at ``size`` (W, H) from the pose of ``frame``, and its camera."""
    w, h = size
    cam = Camera(
        np.asarray(frame["pose"], np.float64),
        int(w),
        int(h),
        float(frame["yfov"]),
        float(frame["znear"]),
        float(frame["zfar"]),
    )
    with GBufferRenderer(scene) as r:
        return r.render(cam), cam


# --------------------------------------------------------------------------- the baseline families


def _screen_space_ao(m: Method, ctx: SceneContext, frame: FrameLike, radius: float) -> np.ndarray:
    s = ctx.settings
    return run_screen_space(frame, m.name, radius, s.ssao if m.name == "ssao" else s.gtao)


def _screen_space_seconds(m: Method, ctx: SceneContext, frame: FrameLike, camera: Camera) -> float:
    s = ctx.settings
    return time_screen_space(
        frame, m.name, ctx.radius, s.ssao if m.name == "ssao" else s.gtao, repeats=s.repeats
    )


def _baked_ao(m: Method, ctx: SceneContext, frame: FrameLike, radius: float) -> np.ndarray:
    return vertex_ao_image(ctx.scene, ctx.baked(m.name), frame)


def _baked_seconds(m: Method, ctx: SceneContext, frame: FrameLike, camera: Camera) -> float:
    return time_vertex_ao(ctx.scene, camera, ctx.baked(m.name), repeats=ctx.settings.repeats)


def _traced_ao(m: Method, ctx: SceneContext, frame: FrameLike, radius: float) -> np.ndarray:
    rays = int(m.name.split("-")[1])
    ao, _, _ = traced_ao(
        ctx.labeller, frame, rays, seed=frame_key_seed(ctx.settings.seed, m.name, ctx.name, frame["view"])
    )
    return ao


def _traced_seconds(m: Method, ctx: SceneContext, frame: FrameLike, camera: Camera) -> float:
    return traced_ao(ctx.labeller, frame, int(m.name.split("-")[1]), seed=1)[2]


@dataclass(frozen=True)
class BaselineFamily:
    # (method, scene context, frame, AO radius in scene units) -> AO (H, W) float32 of the frame.
    ao: Callable[[Method, SceneContext, dict, float], np.ndarray]
    # (method, scene context, time_size G-buffer frame, its camera) -> seconds per frame.
    seconds: Callable[[Method, SceneContext, dict, Camera], float]
    # Position of its rows in the report's tables (the model kinds' report_order follow).
    order: int
    # Scatter-plot colour of its rows.
    colour: str
    # Can show the two sides of a single-sided surface differently: per-vertex bakes store one value per
    # vertex, so both sides of an open sheet show the same AO.
    two_sided: bool
    # Takes the AO radius at run time (evaluated at every ReportSettings.radii_rel).
    radius_input: bool


BASELINES: dict[str, BaselineFamily] = {
    "screen-space": BaselineFamily(
        _screen_space_ao, _screen_space_seconds, order=0, colour="tab:blue", two_sided=True, radius_input=True
    ),
    "baked": BaselineFamily(
        _baked_ao, _baked_seconds, order=1, colour="tab:green", two_sided=False, radius_input=False
    ),
    "traced": BaselineFamily(
        _traced_ao, _traced_seconds, order=2, colour="tab:gray", two_sided=True, radius_input=False
    ),
}


# --------------------------------------------------------------------------- any family


def _family(family: str) -> BaselineFamily | kinds.ModelKind | None:
    return BASELINES.get(family) or kinds.reported().get(family)


def family_order(family: str) -> int:
    """Position of a family's rows in the report's tables (9: unknown, last)."""
    if family in BASELINES:
        return BASELINES[family].order
    kind = kinds.reported().get(family)
    return 9 if kind is None else kind.report_order


def family_colour(family: str) -> str:
    """Scatter-plot colour of a family's rows ("k": unknown)."""
    f = _family(family)
    return "k" if f is None else f.colour


def family_two_sided(family: str) -> bool:
    """Whether a family can show the two sides of a single-sided surface differently (the G-buffer turns
    the normal towards the viewer; True when unknown)."""
    f = _family(family)
    return True if f is None else f.two_sided


def radius_families() -> tuple[str, ...]:
    """Families that take the AO radius at run time, baselines first, then model kinds in report order."""
    return (
        *(n for n, f in BASELINES.items() if f.radius_input),
        *(n for n, k in kinds.reported().items() if k.radius_input),
    )
