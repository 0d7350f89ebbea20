"""Dataset stage: render + label frames for many scenes into hashed, resumable shards.

Layout of a dataset folder::

    manifest.json        resolved config, one entry per shard (scene, views, split, sha256), dataset hash
    progress.json        shards finished so far (only while a run is incomplete)
    shards/<scene>-<k>.npz  stacked frames: every G-buffer channel (N, H, W[, 3]) + ao + valid + camera

Every shard is written atomically, and its hash recorded in ``progress.json`` (also atomic) before
the next one starts; a rerun skips shards whose file still matches its recorded hash (in
``progress.json``, or in the manifest of a finished dataset of the same config), so an interrupted run
resumes and ends with exactly the files an uninterrupted run writes. A folder another config made starts
over: its shards go. Every check of a config that needs no scene runs before anything is made. Every random
choice (orbit phase, interior cameras, labeller directions) is derived from ``seed``, the scene's
index and the view index, so the same config gives the same dataset hash.

Composed scenes (:mod:`neuralao.pipeline.geometry.compose`) are scenes too: a scene entry with ``compose``
settings instead of a ``mesh``, or a config-level ``composed`` generator that expands into ``count`` of them
(after the listed scenes, so their indices, and with them every seed, do not move). A composed scene draws
its meshes from its split's object meshes (:mod:`neuralao.pipeline.geometry.splits`), and no mesh of a train
scene may appear in a val or test scene: the splits are by mesh. With ``labels.radii_rel`` every frame also
stores ``ao_radii`` (H, W, k) and ``valid_radii`` (H, W, k), labelled at
``radii`` (k,) scene units from one trace; without it shards, hashes and manifests are unchanged.

Frames of several sizes and fields of view (a network's receptive field is fixed in pixels while
the AO radius on screen is not, so a corpus of one size and one field of view does not cover use):
``sizes`` draws each shard's frame size from a list (a shard stacks frames of one size), and
``yfov_range_deg`` draws each view's vertical field of view from a range, both seeded by ``seed``,
the scene's index and the view (the shard's first view for its size). Set on the dataset they apply
to every scene; a scene's or a generator's own setting wins. Orbits refit their distance to each
view's field of view. Without them, shards, hashes and manifests are unchanged; with them, every
shard entry of the manifest records its ``size`` [w, h].
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np
from tqdm import tqdm

from neuralao.pipeline.engines.engine import Context, LocalEngine, Task, content_key
from neuralao.pipeline.geometry.camera import Camera, closeup, interior, load_poses, orbit
from neuralao.pipeline.geometry.compose import ComposeSettings, compose
from neuralao.pipeline.geometry.scene import (
    Scene,
    load_scene,
    resolve_mesh_path,
    scene_from_arrays,
    slim_scene,
)
from neuralao.pipeline.geometry.splits import object_meshes
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import (
    read_npz,
    remove_stale_temporaries,
    sha256_file,
    write_json,
    write_npz,
)
from neuralao.runtime.foundation.limits import (
    MAX_CAP,
    PIXEL_BYTES,
    PIXEL_DISK_BYTES,
    check_count,
    check_disk,
    check_int_range,
    check_pixels,
    check_seed,
    format_bytes,
)
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.paths import check_plain_name
from neuralao.runtime.foundation.settings import apply_overrides, from_dict, load_settings, settings_to_dict
from neuralao.runtime.frame import Frame, FrameLike, check_yfov

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
# Per-frame keys stored in shards (stacked along a new first axis).
FRAME_KEYS = (
    "depth",
    "normal_cam",
    "normal_obj",
    "position",
    "mask",
    "tri_id",
    "ao",
    "valid",
    "pose",
    "yfov",
    "znear",
    "zfar",
)
# Extra per-frame keys when labels.radii_rel is set: AO and validity at each radius, the radii.
RADII_KEYS = ("ao_radii", "valid_radii", "radii")
# Per-frame keys of the back layer (``back_layer``), stored beside each shard as layers/<shard>.npz.
LAYER_KEYS = ("depth_back",)
# Pixels whose re-rendered visible triangle may differ from a shard's (another GL build rasterising an
# edge the other way) when the back layer is added to a built dataset; such pixels' layer reads thin.
LAYER_TRI_MISMATCH = 1e-3
# Composed scenes stand on a floor: their orbits stay this far above the horizon.
COMPOSED_MIN_ELEVATION_DEG = 10.0
CameraKind = Literal["orbit", "interior", "closeup", "file"]
# Streams of a view's generator (see view_look): one per kind of draw, so adding one moves no other.
_YFOV_STREAM, _SIZE_STREAM = 1, 2
# A frame size (width, height) and a range of vertical fields of view in degrees.
Size = tuple[int, int]
FovRange = tuple[float, float]


@dataclass
class SceneSpec:
    """One scene of a dataset."""

    name: str  # short unique name used in shard names and reports
    mesh: str = ""  # mesh file, glTF folder, or a bare name under the shared mesh folder (e.g. "spot")
    cameras: CameraKind = (
        "orbit"  # orbit around the bounding sphere, inside the box, close to contacts, or JSON poses
    )
    views: int = 16  # number of views (ignored for cameras="file")
    poses: str | None = None  # JSON camera file when cameras="file" (path relative to the config file)
    yfov_deg: float | None = None  # vertical field of view; None: 40 for orbits, 60 for interiors
    split: Literal["train", "val", "test"] = (
        "train"  # scene-level split: the U-Net never trains on val/test scenes
    )
    # A composed scene (instead of ``mesh``); see neuralao.pipeline.geometry.compose.
    compose: ComposeSettings | None = None
    sizes: list[Size] | None = None  # frame sizes drawn per shard; None: the dataset's (sizes, else size)
    # Vertical fields of view (degrees) drawn per view; None: yfov_deg if set, else the dataset's range,
    # else the camera kind's default. Not for cameras="file" (poses carry their own).
    yfov_range_deg: FovRange | None = None


@dataclass
class ComposedScenes:
    """A generator of ``count`` composed scenes named ``<prefix>-<seed + i:04d>`` (i < count)."""

    count: int = 0  # number of scenes
    seed: int = 0  # scene i is composed with seed + i
    prefix: str = "comp"  # scene name prefix (unique per generator)
    cameras: list[Literal["orbit", "interior", "closeup"]] = field(
        default_factory=lambda: ["orbit", "interior", "closeup"]
    )  # camera kind of scene i: cameras[i % len(cameras)]; orbits get <= 2 walls, no ceiling and a
    # 0.6x floor, interiors >= 3 walls (so a view from inside has a room around it)
    views: int = 12  # views per scene
    split: Literal["train", "val", "test"] = "train"  # split of every scene (and of the meshes drawn)
    yfov_deg: float | None = None  # field of view; None: the camera kind's default
    compose: ComposeSettings = field(default_factory=ComposeSettings)  # template (seed replaced)
    sizes: list[Size] | None = None  # every scene's SceneSpec.sizes (None: the dataset's)
    yfov_range_deg: FovRange | None = None  # every scene's SceneSpec.yfov_range_deg


@dataclass
class DatasetSettings:
    """Settings of `neuralao dataset`."""

    name: str = "dataset"  # dataset name (recorded in the manifest)
    scenes: list[SceneSpec] = field(default_factory=list)  # the scenes to render
    size: tuple[int, int] = (128, 128)  # frame width, height in pixels
    labels: LabelSettings = field(
        default_factory=LabelSettings
    )  # AO labeller settings (rays, max distance, kernel...)
    seed: int = 0  # master seed: cameras and labeller directions derive from it
    holdout_every: int = (
        8  # every k-th view of each scene is held back (never used for training; MLP evaluation)
    )
    frames_per_shard: int = 8  # frames per shard file (the unit of resumption)
    composed: list[ComposedScenes] = field(default_factory=list)  # generators, expanded after ``scenes``
    # Frame sizes (width, height) each shard draws one of (repeat an entry to weight it); None: ``size``.
    sizes: list[Size] | None = None
    # Vertical fields of view (degrees) drawn uniformly per view for scenes without yfov_deg or their own
    # range (cameras="file" keeps its poses' own); None: every scene's yfov_deg or its camera default.
    yfov_range_deg: FovRange | None = None
    # Also render the G-buffer's back layer (``depth_back``, what a version-4 U-Net reads) into
    # layers/<shard>.npz beside each shard. Turned on for a built dataset, it renders only the layer: the
    # shards, their labels and the dataset hash stay as they are.
    back_layer: bool = False


def frame_seed(seed: int, scene_index: int, view: int) -> int:
    """A 31-bit seed for one view, independent of run order (so resumption is exact)."""
    digest = hashlib.sha256(f"{seed}/{scene_index}/{view}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


# What a scene's view v is rendered at: (width, height, yfov_deg), yfov_deg None = the camera's own.
ViewLook = Callable[[int], tuple[int, int, float | None]]


def _view_rng(seed: int, scene_index: int, view: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([frame_seed(seed, scene_index, view), stream])


def view_look(settings: DatasetSettings, spec: SceneSpec, scene_index: int) -> ViewLook | None:
    """The size and field of view of each view of scene ``scene_index``, or None when it draws neither
    (its frames are then rendered exactly as before these settings existed).

    A view's field of view comes from its own generator; its size from its shard's first view, so a
    shard holds frames of one size.
    """
    sizes = spec.sizes if spec.sizes is not None else settings.sizes
    fovs = spec.yfov_range_deg
    if fovs is None and spec.yfov_deg is None and spec.cameras != "file":
        fovs = settings.yfov_range_deg
    if sizes is None and fovs is None:
        return None
    per_shard = settings.frames_per_shard

    def look(v: int) -> tuple[int, int, float | None]:
        w, h = settings.size
        if sizes is not None:
            shard_rng = _view_rng(settings.seed, scene_index, v - v % per_shard, _SIZE_STREAM)
            w, h = sizes[int(shard_rng.integers(len(sizes)))]
        if fovs is None:
            return int(w), int(h), None
        return int(w), int(h), float(_view_rng(settings.seed, scene_index, v, _YFOV_STREAM).uniform(*fovs))

    return look


def scene_cameras(
    spec: SceneSpec,
    scene: Scene,
    size: tuple[int, int],
    seed: int,
    config_dir: Path,
    look: ViewLook | None = None,
) -> list[Camera]:
    """The cameras of a scene at ``size``, or each at its own size and field of view with ``look``."""
    w, h = size
    if spec.cameras == "orbit":
        elevation = COMPOSED_MIN_ELEVATION_DEG if spec.compose is not None else None
        yfov = _yfov(spec, 40.0)
        frames = None if look is None else [(w_, h_, f or yfov) for w_, h_, f in map(look, range(spec.views))]
        return orbit(scene, spec.views, w, h, yfov, seed=seed, min_elevation_deg=elevation, frames=frames)
    if spec.cameras == "interior":
        cams = interior(scene, spec.views, w, h, _yfov(spec, 60.0), seed=seed)
    elif spec.cameras == "closeup":
        cams = closeup(scene, spec.views, w, h, _yfov(spec, 50.0), seed=seed)
    else:
        if not spec.poses:
            raise NeuralaoError(f"scene {spec.name}: cameras='file' needs 'poses'")
        cams = load_poses(_poses_path(spec, config_dir), scene, w, h)
    if look is None:
        return cams
    # Interior, close-up and file poses do not depend on the frame, so only the frame changes.
    return [_framed(cam, *look(v)) for v, cam in enumerate(cams)]


def _yfov(spec: SceneSpec, default: float) -> float:
    """The scene's field of view in degrees, or its camera kind's ``default`` when it sets none."""
    return default if spec.yfov_deg is None else spec.yfov_deg


def _framed(cam: Camera, width: int, height: int, yfov_deg: float | None) -> Camera:
    yfov = cam.yfov if yfov_deg is None else math.radians(yfov_deg)
    return replace(cam, width=width, height=height, yfov=yfov)


def expand_scenes(settings: DatasetSettings) -> list[SceneSpec]:
    """The listed scenes, then every generator's composed scenes (see :class:`ComposedScenes`)."""
    specs = list(settings.scenes)
    for gen in settings.composed:
        if gen.count < 0 or not gen.cameras:
            raise NeuralaoError(f"composed {gen.prefix!r}: count must be >= 0 and cameras non-empty")
        for i in range(gen.count):
            kind = gen.cameras[i % len(gen.cameras)]
            c = gen.compose
            if kind == "orbit":  # seen from outside: open on at least two sides, no lid, and a
                # smaller floor (the orbit frames all of it) so the objects fill the view
                walls = (min(c.walls[0], 2), min(c.walls[1], 2))
                c = replace(c, walls=walls, ceiling=0.0, room=(0.6 * c.room[0], 0.6 * c.room[1]))
            elif kind == "interior":
                c = replace(c, walls=(max(c.walls[0], 3), max(c.walls[1], 3)))
            spec = SceneSpec(
                f"{gen.prefix}-{gen.seed + i:04d}",
                cameras=kind,
                views=gen.views,
                yfov_deg=gen.yfov_deg,
                split=gen.split,
                compose=replace(c, seed=gen.seed + i),
                sizes=gen.sizes,
                yfov_range_deg=gen.yfov_range_deg,
            )
            specs.append(spec)
    return specs


def load_spec_scene(spec: SceneSpec, config_dir: Path = Path(".")) -> Scene:
    """The scene of a config entry: its mesh (relative to the config file first), or its composition."""
    if spec.compose is not None:
        return compose(spec.compose, split=spec.split, name=spec.name)
    local = config_dir / spec.mesh  # a path relative to the config file wins over a bare mesh name
    return load_scene(local if local.exists() else spec.mesh, name=spec.name)


def _spec_meshes(spec: SceneSpec, config_dir: Path) -> set[str]:
    """Resolved paths of every mesh a scene may contain (a composed scene: its whole pool)."""
    if spec.compose is None:
        local = config_dir / spec.mesh
        names = [str(local) if local.exists() else spec.mesh]
    else:
        c = spec.compose
        names = c.meshes if c.meshes is not None else object_meshes(spec.split, c.pool)
    return {_resolved(n) for n in names}


@functools.lru_cache(maxsize=1024)
def _resolved(mesh: str) -> str:
    return str(resolve_mesh_path(mesh).resolve())


def scene_of(manifest: dict, name: str) -> Scene:
    """Rebuild scene ``name`` of a dataset manifest (its mesh, or its composition from the settings)."""
    entry = manifest["scenes"][name]
    if "compose" in entry:
        return compose(from_dict(ComposeSettings, entry["compose"]), split=entry["split"], name=name)
    return load_scene(entry["mesh"], name=name)


def _check_looks(where: str, sizes: list[Size] | None, fovs: FovRange | None) -> None:
    """``where`` (``""`` or a key with its dot, ``scenes[0].``): sizes >= 1, fields of view a camera has."""
    if sizes is not None and (not sizes or any(w < 1 or h < 1 for w, h in sizes)):
        raise NeuralaoError(f"{where}sizes must be a non-empty list of [width, height] >= 1, got {sizes}")
    if fovs is not None:
        lo, hi = (check_yfov(f"{where}yfov_range_deg[{i}]", v) for i, v in enumerate(fovs))
        if lo > hi:
            raise NeuralaoError(f"{where}yfov_range_deg must be [lo, hi] with lo <= hi, got {list(fovs)}")


def _validate(settings: DatasetSettings, specs: list[SceneSpec], config_dir: Path) -> None:
    """Every rule of the config that needs no scene loaded, so a refused config has made nothing; each
    refusal names its key (``scenes[0].yfov_deg``, ``labels.radii_rel``)."""
    _check_looks("", settings.sizes, settings.yfov_range_deg)
    for j, gen in enumerate(settings.composed):
        check_plain_name(f"composed[{j}].prefix", gen.prefix)
        if gen.yfov_deg is not None:
            check_yfov(f"composed[{j}].yfov_deg", gen.yfov_deg)
        _check_looks(f"composed[{j}].", gen.sizes, gen.yfov_range_deg)
    names = set()
    for k, spec in enumerate(specs):
        listed = k < len(settings.scenes)  # the listed scenes come first; then the generated ones
        key = f"scenes[{k}]" if listed else f"composed scene {spec.name!r}"
        # a scene's name names its shard files: a '/' or '..' in it would write outside --out
        check_plain_name(f"{key}.name" if listed else "composed scene name", spec.name)
        if spec.name in names:
            raise NeuralaoError(f"scene name {spec.name!r} appears twice in the dataset config")
        names.add(spec.name)
        if spec.cameras != "file" and spec.views < 1:
            raise NeuralaoError(f"scene {spec.name}: views must be >= 1")
        if bool(spec.mesh) == (spec.compose is not None):
            raise NeuralaoError(f"scene {spec.name}: give exactly one of 'mesh' and 'compose'")
        if listed:
            if spec.yfov_deg is not None:
                check_yfov(f"{key}.yfov_deg", spec.yfov_deg)
            _check_looks(f"{key}.", spec.sizes, spec.yfov_range_deg)
        if spec.cameras == "file":
            if spec.yfov_range_deg is not None:
                raise NeuralaoError(
                    f"scene {spec.name}: cameras='file' takes its fields of view from the poses"
                )
            if not spec.poses:
                raise NeuralaoError(f"scene {spec.name}: cameras='file' needs 'poses'")
            poses = _poses_path(spec, config_dir)
            if not poses.is_file():
                raise NeuralaoError(f"{key}.poses: camera file not found: {poses}")
    _check_labels(settings.labels)
    train: set[str] = set()
    held: dict[str, str] = {}
    for spec in specs:
        meshes = _spec_meshes(spec, config_dir)
        if spec.split == "train":
            train |= meshes
        else:
            held.update(dict.fromkeys(meshes, spec.name))
    shared = sorted(train & set(held))
    if shared:
        raise NeuralaoError(
            f"mesh {Path(shared[0]).name} is in a train scene and in {held[shared[0]]!r} "
            f"({len(shared)} shared mesh(es)): val and test are split by mesh"
        )


def _poses_path(spec: SceneSpec, config_dir: Path) -> Path:
    """A scene's camera file (``poses``, relative to the config file unless absolute)."""
    path = Path(spec.poses or "")
    return path if path.is_absolute() else config_dir / path


# A tetrahedron the labeller checks the label settings on before any scene is loaded (see _check_labels).
_PROBE_VERTICES = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64)
_PROBE_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)


def _check_labels(labels: LabelSettings) -> None:
    """``labels`` as the labeller will take them in every scene, before anything is made: the distances as
    given (the relative ones are fractions of each scene's diagonal), every radius within the max distance
    (the longest label ray), and the labeller's own rules (:attr:`Labeller.settings`, run on a tetrahedron,
    so whatever it would refuse in a scene is refused here)."""
    for key in ("max_distance", "max_distance_rel", "half_distance", "half_distance_rel"):
        v = getattr(labels, key)
        if v is None and not key.endswith("_rel"):
            continue
        if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v) and v > 0):
            raise NeuralaoError(f"labels.{key} must be a positive finite number, got {v!r}")
    radii = labels.radii_rel
    if radii is not None:
        if not isinstance(radii, list | tuple) or not radii:
            raise NeuralaoError(
                f"labels.radii_rel must be a non-empty list of positive numbers, got {radii!r}"
            )
        for r in radii:
            if isinstance(r, bool) or not isinstance(r, int | float) or not (math.isfinite(r) and r > 0):
                raise NeuralaoError(f"labels.radii_rel must hold positive finite numbers, got {r!r}")
        if labels.max_distance is None and max(radii) > labels.max_distance_rel:
            raise NeuralaoError(
                f"labels.radii_rel holds {max(radii):g}, beyond labels.max_distance_rel "
                f"{labels.max_distance_rel:g}: the longest label ray must reach every radius; raise "
                "max_distance_rel to the largest radius or drop the radius"
            )
    try:
        Labeller(scene_from_arrays(_PROBE_VERTICES, _PROBE_FACES, "labels"), labels)
    except NeuralaoError as e:
        raise NeuralaoError(f"labels: {e}") from None


def _check_radii_reach(spec: SceneSpec, labels: LabelSettings, radii: list[float]) -> None:
    """With ``labels.max_distance`` in scene units, a scene's radii (scene units) within it (the rule
    :func:`_check_labels` applies to the relative distances)."""
    if labels.max_distance is not None and max(radii) > labels.max_distance:
        raise NeuralaoError(
            f"scene {spec.name}: labels.radii_rel reach {max(radii):.6g} scene units, beyond "
            f"labels.max_distance {labels.max_distance:g}: the longest label ray must reach every radius"
        )


# Label distances a config gives either in scene units or relative to the diagonal, never both (the
# relative one would be silently ignored).
_DISTANCE_PAIRS = (("max_distance", "max_distance_rel"), ("half_distance", "half_distance_rel"))


def load_dataset_settings(config: str | Path, overrides: list[str] | None = None) -> DatasetSettings:
    """The settings of a dataset config file with ``key=value`` overrides (``--set``), refusing a label
    distance given both in scene units and relative to the diagonal."""
    settings = load_settings(DatasetSettings, config, overrides)
    given = apply_overrides(read_json(config, "config file"), overrides).get("labels")
    for absolute, relative in _DISTANCE_PAIRS:
        if isinstance(given, dict) and given.get(absolute) is not None and relative in given:
            raise NeuralaoError(
                f"config file {config}: labels gives both {absolute} (scene units) and {relative} "
                "(a fraction of the diagonal); give one"
            )
    return settings


def check_config(settings: DatasetSettings, config_dir: Path = Path(".")) -> list[SceneSpec]:
    """Every check of a dataset config that needs no scene loaded (:func:`_validate`); its scenes."""
    specs = expand_scenes(settings)
    if not specs:
        raise NeuralaoError("the dataset config lists no scenes")
    if settings.frames_per_shard < 1 or settings.holdout_every < 0:
        raise NeuralaoError("frames_per_shard must be >= 1 and holdout_every >= 0")
    _validate(settings, specs, config_dir)
    return specs


def _config_dict(settings: DatasetSettings) -> dict:
    """The resolved config, without the options added since format 1 while they are unused, so a
    config that does not use them has the config hash (and manifest) it always had."""
    config = settings_to_dict(settings)
    del config["back_layer"]  # an add-on beside the shards (the manifest's "back_layer"), not their config
    if not config["composed"]:
        del config["composed"]
    if config["labels"]["radii_rel"] is None:
        del config["labels"]["radii_rel"]
    for scene in config["scenes"]:
        if scene["compose"] is None:
            del scene["compose"]
    for node in [config, *config["scenes"], *config.get("composed", [])]:
        for key in ("sizes", "yfov_range_deg"):
            if node[key] is None:
                del node[key]
        if node.get("compose") is not None:
            _drop_first_pool(node["compose"])
    return config


def _drop_first_pool(compose: dict) -> dict:
    """Compose settings without ``pool`` at revision 1 (the pool before the setting existed)."""
    if compose.get("pool") == 1:
        del compose["pool"]
    return compose


def build_dataset(
    settings: DatasetSettings,
    out: Path,
    config_dir: Path = Path("."),
    progress: bool = True,
    engine=None,
) -> dict:
    """Render and label every scene of ``settings`` into ``out``; resumable. Returns the manifest.

    ``engine`` (:mod:`neuralao.pipeline.engines.engine`; default: this process) runs the pending shards, one
    task each; this process writes every shard (and ``progress.json``) as results arrive, so the files and
    the dataset hash are the same on any engine.
    """
    specs = check_config(settings, config_dir)
    out = Path(out)
    config = _config_dict(settings)
    config_hash = hashlib.sha256(repr(sorted(config.items())).encode()).hexdigest()
    done, done_layers = _reusable_shards(out, config, config_hash)  # the last check; then the run works
    layers = bool(settings.back_layer)
    # a killed run (SIGKILL) leaves its half-written shard or layer behind
    for folder in (out, out / "shards", out / "layers"):
        for stale in remove_stale_temporaries(folder):
            log.info("removed %s left by an interrupted run", stale.name)
    own_engine = engine is None
    engine = engine or LocalEngine()
    progress_path = out / "progress.json"
    shards: list[dict] = []
    pending: list[dict] = []  # entries of the shards the engine renders, in task order
    frame_keys = FRAME_KEYS + (RADII_KEYS if settings.labels.radii_rel is not None else ())
    radii_of: dict[str, list[float]] = {}
    # Any scene drawing sizes or fields of view: every shard entry then records its frame size.
    looks = any(view_look(settings, spec, si) is not None for si, spec in enumerate(specs))
    counts = {"views": 0}
    bar = tqdm(total=0, desc="dataset", unit="view", disable=not progress)

    def shard_tasks():
        """Plan scene by scene (one scene in memory at a time); yield a task per shard not yet done."""
        for si, spec in enumerate(specs):
            scene = load_spec_scene(spec, config_dir)
            look = view_look(settings, spec, si)
            cams = scene_cameras(
                spec, scene, settings.size, frame_seed(settings.seed, si, -1), config_dir, look
            )
            counts["views"] += len(cams)
            bar.total += len(cams)
            bar.refresh()
            if settings.labels.radii_rel is not None:
                radii_of[spec.name] = [r * scene.diagonal for r in settings.labels.radii_rel]
                _check_radii_reach(spec, settings.labels, radii_of[spec.name])
            context = None
            views = list(range(len(cams)))
            chunks = [
                views[i : i + settings.frames_per_shard]
                for i in range(0, len(views), settings.frames_per_shard)
            ]
            for k, chunk in enumerate(chunks):
                rel = f"shards/{spec.name}-{k:04d}.npz"
                path = out / rel
                entry = {
                    "file": rel,
                    "scene": spec.name,
                    "split": spec.split,
                    "views": chunk,
                    "holdout": [
                        bool(
                            settings.holdout_every
                            and v % settings.holdout_every == settings.holdout_every - 1
                        )
                        for v in chunk
                    ],
                    "faces": int(len(scene.faces)),
                }
                if looks:
                    entry["size"] = [cams[chunk[0]].width, cams[chunk[0]].height]
                shards.append(entry)
                if rel in done and path.exists() and sha256_file(path) == done[rel]:
                    entry["sha256"] = done[rel]
                    if not layers or _layer_kept(out, entry, done_layers):
                        bar.update(len(chunk))
                        continue
                context = context or _shard_context(scene, settings.labels, engine.threads, layers)
                if "sha256" in entry:
                    # a shard of the dataset built before its back layer: only the layer is rendered
                    tri = read_npz(path, ["tri_id"])["tri_id"]
                    pending.append(entry)
                    yield Task(context, _render_layer, ([cams[v] for v in chunk], tri, rel))
                    continue
                seeds = [frame_seed(settings.seed, si, v) for v in chunk]
                pending.append(entry)
                keys = frame_keys + (LAYER_KEYS if layers else ())
                yield Task(context, _render_shard, ([cams[v] for v in chunk], seeds, keys))

    try:
        for i, arrays in engine.map(shard_tasks()):
            entry = pending[i]
            layer = {k: arrays.pop(k) for k in LAYER_KEYS if k in arrays}
            if "sha256" not in entry:  # a shard rendered and labelled (else only its layer was rendered)
                arrays["view"] = np.asarray(entry["views"], dtype=np.int32)
                arrays["holdout"] = np.asarray(entry["holdout"], dtype=bool)
                path = out / entry["file"]
                # the folder comes with the first shard: a run refused before it makes nothing
                path.parent.mkdir(parents=True, exist_ok=True)
                write_npz(path, **arrays)
                entry["sha256"] = done[entry["file"]] = sha256_file(path)
            if layer:
                rel = _layer_name(entry["file"])
                (out / rel).parent.mkdir(parents=True, exist_ok=True)
                write_npz(out / rel, **layer)
                entry["layer_file"], entry["layer_sha256"] = rel, sha256_file(out / rel)
                done_layers[rel] = entry["layer_sha256"]
            write_json(
                progress_path,
                {"config_hash": config_hash, "shards": done, **({"layers": done_layers} if layers else {})},
            )
            bar.update(len(entry["views"]))
    finally:
        bar.close()
        if own_engine:
            engine.close()
    dataset_hash = hashlib.sha256("".join(s["sha256"] for s in shards).encode()).hexdigest()
    manifest = {
        "format": "neuralao-dataset",
        "version": FORMAT_VERSION,
        "name": settings.name,
        "config": config,
        "dataset_hash": dataset_hash,
        "frames": counts["views"],
        "size": list(settings.size),
        **({"sizes": sorted({tuple(s["size"]) for s in shards})} if looks else {}),
        "scenes": {s.name: _scene_entry(s, radii_of.get(s.name)) for s in specs},
        "shards": shards,
        "frame_keys": list(frame_keys),
        **(
            {
                "back_layer": {
                    "keys": list(LAYER_KEYS),
                    "hash": hashlib.sha256("".join(s["layer_sha256"] for s in shards).encode()).hexdigest(),
                }
            }
            if layers
            else {}
        ),
        "conventions": {
            "ao": "accessibility in [0,1], 1 = open; 1 on background",
            "depth": "linear camera-space depth (-z_cam), 0 on background",
            "normals": "unit, flipped to face the viewer; camera space (OpenGL: -z forward) and object space",
            "rows": "row 0 at the top",
        },
    }
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "manifest.json", manifest)
    progress_path.unlink(missing_ok=True)
    return manifest


def _layer_name(shard: str) -> str:
    """The back layer's file of shard ``shards/NAME.npz``: ``layers/NAME.npz``."""
    return "layers/" + Path(shard).name


def _layer_kept(out: Path, entry: dict, done_layers: dict[str, str]) -> bool:
    """Whether shard ``entry``'s back layer is on disk as a run recorded it (then the entry names it)."""
    rel = _layer_name(entry["file"])
    if rel in done_layers and (out / rel).is_file() and sha256_file(out / rel) == done_layers[rel]:
        entry["layer_file"], entry["layer_sha256"] = rel, done_layers[rel]
        return True
    return False


def _reusable_shards(out: Path, config: dict, config_hash: str) -> tuple[dict[str, str], dict[str, str]]:
    """The shards (file -> sha256) a run of ``config`` in ``out`` keeps, and their back layers' files (file
    -> sha256): those of a finished dataset of this config (its manifest) and of an interrupted run of it
    (``progress.json``). A folder that holds a dataset of another config starts over: its shards, layers,
    manifest and progress file go, so it never ends with another config's shards beside the new manifest.
    A ``manifest.json`` that is not a dataset's is refused (it is not this command's to replace)."""
    manifest_path, progress_path = out / "manifest.json", out / "progress.json"
    done: dict[str, str] = {}
    layers: dict[str, str] = {}
    same = True
    if manifest_path.is_file():
        made = read_json(manifest_path, "dataset manifest")
        if not isinstance(made, dict) or made.get("format") != "neuralao-dataset":
            raise NeuralaoError(
                f"--out {out} holds a manifest.json that is not a dataset's; give another folder"
            )
        same = made.get("config") == json.loads(json.dumps(config, default=str))
        if same and isinstance(made.get("shards"), list):
            entries = [e for e in made["shards"] if isinstance(e, dict)]
            for files, name, sha in ((done, "file", "sha256"), (layers, "layer_file", "layer_sha256")):
                files.update(
                    (e[name], e[sha])
                    for e in entries
                    if isinstance(e.get(name), str) and isinstance(e.get(sha), str)
                )
    if progress_path.is_file():
        state = read_json(progress_path, "dataset progress file")
        if isinstance(state, dict) and state.get("config_hash") == config_hash:
            shards, kept = state.get("shards"), state.get("layers")
            done |= shards if isinstance(shards, dict) else {}
            layers |= kept if isinstance(kept, dict) else {}
        else:
            same = False
    if not same:
        old = sorted((out / "shards").glob("*.npz"))
        log.warning("%s: holds a dataset of another config; starting over (%d shards removed)", out, len(old))
        for path in [*old, *sorted((out / "layers").glob("*.npz")), manifest_path, progress_path]:
            path.unlink(missing_ok=True)
        return {}, {}
    return done, layers


class _ShardWorker:
    """A worker's state for one scene: its G-buffer renderer and labeller (built where it runs)."""

    def __init__(self, payload: tuple[Scene, LabelSettings, bool]):
        # Lazy: PyOpenGL (0.16 s measured, and a GL library) is needed only where a shard renders; a
        # Ray driver and U-Net training read datasets without it.
        from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer

        scene, labels, back_layer = payload
        self.scene, self.labels = scene, labels
        self.renderer = GBufferRenderer(scene, back_layer=back_layer)
        self._labeller: Labeller | None = None

    @property
    def labeller(self) -> Labeller:
        """Built by the first shard that labels (a run that adds only back layers builds no BVH)."""
        if self._labeller is None:
            self._labeller = Labeller(self.scene, self.labels)
        return self._labeller

    def close(self) -> None:
        self.renderer.close()


def _shard_context(scene: Scene, labels: LabelSettings, threads: int | None, back_layer: bool = False):
    """Scene + label settings (``threads`` labelling threads per task; None: the settings' own), and
    whether the renderer draws the back layer."""
    labels = labels if threads is None else replace(labels, workers=threads)
    slim = slim_scene(scene)
    key = content_key("shard", slim.vertices, slim.faces, labels, *(("back_layer",) if back_layer else ()))
    return Context(key, _ShardWorker, (slim, labels, back_layer))


def _render_shard(state: _ShardWorker, args: tuple) -> dict[str, np.ndarray]:
    """Render and label the frames of one shard: cameras, per-view label seeds, the keys to stack."""
    cams, seeds, frame_keys = args
    frames = []
    for cam, seed in zip(cams, seeds, strict=True):
        frame = state.renderer.render(cam)
        state.labeller.settings = replace(state.labels, seed=seed)
        if state.labeller.radii is None:
            frame["ao"], frame["valid"] = state.labeller.label_frame(frame)
        else:
            _label_with_radii(state.labeller, frame)
        frames.append(frame)
    return {key: np.stack([np.asarray(f[key]) for f in frames]) for key in frame_keys}


def _render_layer(state: _ShardWorker, args: tuple) -> dict[str, np.ndarray]:
    """The back layer of a built shard's frames: its cameras rendered again, their visible triangles
    checked against the shard's (``tri``); where another GL rasterised an edge the other way the layer
    reads thin (0), beyond :data:`LAYER_TRI_MISMATCH` of the pixels the shard is not this GL's."""
    cams, tri, name = args
    out = []
    for cam, stored in zip(cams, tri, strict=True):
        frame = state.renderer.render(cam)
        moved = frame["tri_id"] != stored
        if moved.mean() > LAYER_TRI_MISMATCH:
            raise NeuralaoError(
                f"{name}: rendered again, {int(moved.sum())} of {moved.size} pixels show another triangle "
                "than the shard holds; this GL does not reproduce the dataset's G-buffers: build it again "
                "(remove its folder) to add the back layer"
            )
        out.append(np.where(moved, np.float32(0.0), frame["depth_back"]))
    return {"depth_back": np.stack(out)}


def _label_with_radii(labeller: Labeller, frame: FrameLike) -> None:
    """Set ``ao``, ``valid``, ``ao_radii``, ``valid_radii`` and ``radii`` of a frame from one trace
    when the max distance is one of the radii (bit-identical to :meth:`Labeller.label_frame`, which
    tests/test_labels.py checks), else from that trace plus the usual one."""
    frame["ao_radii"], frame["valid_radii"] = labeller.label_frame_radii(frame)
    frame["radii"] = np.asarray(labeller.radii, dtype=np.float32)
    if labeller.max_distance in labeller.radii:
        j = labeller.radii.index(labeller.max_distance)
        frame["ao"], frame["valid"] = frame["ao_radii"][..., j].copy(), frame["valid_radii"][..., j].copy()
    else:
        frame["ao"], frame["valid"] = labeller.label_frame(frame)


def _scene_entry(spec: SceneSpec, radii: list[float] | None) -> dict:
    """A scene's manifest entry; composed scenes add their compose settings, radii their radii."""
    entry = {"split": spec.split, "mesh": spec.mesh, "cameras": spec.cameras}
    if spec.compose is not None:
        entry["compose"] = _drop_first_pool(settings_to_dict(spec.compose))
    if radii is not None:
        entry["radii"] = radii  # scene units, one per labels.radii_rel
    return entry


class Dataset:
    """A finished dataset folder. Shards are verified against the manifest's hashes on first read."""

    def __init__(self, root: str | Path, verify: bool = True):
        self.root = Path(root)
        mpath = self.root / "manifest.json"
        if not mpath.is_file():
            hint = (
                " (an interrupted run: rerun `neuralao dataset` to resume)"
                if (self.root / "progress.json").exists()
                else ""
            )
            raise NeuralaoError(f"no dataset manifest at {mpath}{hint}")
        self.manifest = read_json(mpath, "dataset manifest")
        if not isinstance(self.manifest, dict) or self.manifest.get("format") != "neuralao-dataset":
            raise NeuralaoError(f"{mpath} is not a neuralao dataset manifest")
        self.verify = verify
        self._verified: set[str] = set()

    @property
    def scenes(self) -> list[str]:
        return list(self.manifest["scenes"])

    def split_of(self, scene: str) -> str:
        return self.manifest["scenes"][scene]["split"]

    @property
    def label_settings(self) -> dict:
        return self.manifest["config"]["labels"]

    @property
    def back_layer(self) -> dict | None:
        """The manifest's back layer (``keys`` and ``hash`` of its files), None without one."""
        return self.manifest.get("back_layer")

    def load_shard(self, entry: dict) -> dict[str, np.ndarray]:
        """A shard's arrays, with its back layer's where the dataset has one."""
        arrays = self._read(entry["file"], entry["sha256"])
        if self.back_layer is not None and "layer_file" in entry:
            arrays |= self._read(entry["layer_file"], entry["layer_sha256"])
        return arrays

    def _read(self, rel: str, sha: str) -> dict[str, np.ndarray]:
        path = self.root / rel
        if not path.is_file():
            raise NeuralaoError(f"dataset shard missing: {path}")
        if self.verify and rel not in self._verified:
            if sha256_file(path) != sha:
                raise NeuralaoError(
                    f"dataset shard {path} is corrupt (sha256 differs from the manifest); "
                    "rerun `neuralao dataset`"
                )
            self._verified.add(rel)
        return read_npz(path)

    def frames(
        self, split: str | None = None, scene: str | None = None, holdout: bool | None = None
    ) -> Iterator[Frame]:
        """Yield the frames (G-buffer keys + ao, valid, pose..., and RADII_KEYS where stored) with their
        scene, view, split and holdout, checked as :class:`~neuralao.runtime.frame.Frame` checks them."""
        for entry in self.manifest["shards"]:
            if split is not None and entry["split"] != split:
                continue
            if scene is not None and entry["scene"] != scene:
                continue
            if holdout is not None and not any(h == holdout for h in entry["holdout"]):
                continue
            for frame in self.shard_frames(entry):
                if holdout is None or frame["holdout"] == holdout:
                    yield frame

    def shard_frames(self, entry: dict) -> Iterator[Frame]:
        """Every frame of one shard (an entry of the manifest's ``shards``), in order."""
        arrays = self.load_shard(entry)
        keys = [k for k in (*self.manifest.get("frame_keys", FRAME_KEYS), *LAYER_KEYS) if k in arrays]
        for i in range(len(arrays["view"])):
            yield Frame.from_arrays(
                {k: arrays[k][i] for k in keys}
                | {
                    "scene": entry["scene"],
                    "view": int(arrays["view"][i]),
                    "split": entry["split"],
                    "holdout": bool(arrays["holdout"][i]),
                },
                f"{entry['file']} frame {i}",
            )


def open_dataset(root: str | Path, verify: bool = True) -> Dataset:
    return Dataset(root, verify)


def check_counts(settings: DatasetSettings, out: Path) -> None:
    """Every count of the config within what the machine can hold, before anything is expanded or
    allocated (neuralao.runtime.foundation.limits): scenes and views (a camera each), frame sizes (a shard's
    frames
    are in memory together), the frames on disk, seeds."""
    scene_bytes = 4096  # a scene entry or a camera, before anything is rendered
    check_seed("seed", settings.seed)
    check_count("frames_per_shard", settings.frames_per_shard)
    check_int_range("holdout_every", settings.holdout_every, 0, MAX_CAP)
    check_count(
        "composed count",
        sum(max(g.count, 0) for g in settings.composed) + 1,
        bytes_each=scene_bytes,
        each="a scene entry",
    )
    sizes = [tuple(settings.size), *(settings.sizes or [])]
    views, pixels = 0, 0.0
    for item in [*settings.scenes, *settings.composed]:
        where = f"scene {item.name}" if isinstance(item, SceneSpec) else f"composed {item.prefix!r}"
        check_count(f"{where}: views", item.views, low=0, bytes_each=scene_bytes, each="a camera")
        sizes += list(item.sizes or [])
        n = item.views * (item.count if isinstance(item, ComposedScenes) else 1)
        # each shard draws its size from the list (an entry repeated weighs more): the expected pixels
        drawn = item.sizes if item.sizes is not None else settings.sizes or [settings.size]
        views, pixels = views + n, pixels + n * sum(a * b for a, b in drawn) / max(len(drawn), 1)
    for w, h in sizes:
        check_pixels("size", w, h)
    w, h = max(w for w, _ in sizes), max(h for _, h in sizes)
    # a shard's frames are in memory together: a count past that is named as itself, not as the size
    check_count(
        "frames_per_shard",
        settings.frames_per_shard,
        bytes_each=PIXEL_BYTES * w * h,
        each=f"a frame of up to {w}x{h} pixels",
    )
    # a rerun keeps (or replaces) the shards already written: only the rest needs free space
    written = sum(f.stat().st_size for f in (Path(out) / "shards").glob("*.npz")) if Path(out).is_dir() else 0
    check_disk(
        "views",
        max(pixels * PIXEL_DISK_BYTES - written, 0),
        out,
        f"{views} at up to {w} {h}"
        + (f", beyond the {format_bytes(written)} already written" if written else ""),
    )
