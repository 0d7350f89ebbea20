"""Dataset stage: render + label frames for many scenes into hashed, resumable shards.

Layout of a dataset folder::

    manifest.json        resolved config, one entry per shard (scene, views, split, sha256), dataset hash
    progress.json        shards finished so far (only while a run is incomplete)
    shards/<scene>-<k>.npz  stacked frames: every G-buffer channel (N, H, W[, 3]) + ao + valid + camera

Every shard is written atomically, and its hash recorded in ``progress.json`` (also atomic) before
the next one starts; a rerun skips shards whose file still matches its recorded hash, so an
interrupted run resumes and ends with exactly the files an uninterrupted run writes. Every random
choice (orbit phase, interior cameras, labeller directions) is derived from ``seed``, the scene's
index and the view index, so the same config gives the same dataset hash.
"""

from __future__ import annotations

import argparse
import hashlib
import logging
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from .camera import Camera, interior, load_poses, orbit
from .config import add_set_option, load_settings, settings_to_dict
from .errors import NeuralaoError
from .io import read_npz, remove_stale_temporaries, sha256_file, write_json, write_npz
from .labels import LabelSettings
from .scene import Scene, load_scene

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


@dataclass
class SceneSpec:
    """One scene of a dataset."""

    name: str  # short unique name used in shard names and reports
    mesh: str  # mesh file, glTF folder, or a bare name under the shared mesh folder (e.g. "spot")
    cameras: Literal["orbit", "interior", "file"] = (
        "orbit"  # orbit around the bounding sphere, inside the box, or JSON poses
    )
    views: int = 16  # number of views (ignored for cameras="file")
    poses: str | None = None  # JSON camera file when cameras="file" (path relative to the config file)
    yfov_deg: float | None = None  # vertical field of view; None: 40 for orbits, 60 for interiors
    split: Literal["train", "val", "test"] = (
        "train"  # scene-level split: the U-Net never trains on val/test scenes
    )


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


def frame_seed(seed: int, scene_index: int, view: int) -> int:
    """A 31-bit seed for one view, independent of run order (so resumption is exact)."""
    digest = hashlib.sha256(f"{seed}/{scene_index}/{view}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def scene_cameras(
    spec: SceneSpec, scene: Scene, size: tuple[int, int], seed: int, config_dir: Path
) -> list[Camera]:
    w, h = size
    if spec.cameras == "orbit":
        return orbit(scene, spec.views, w, h, spec.yfov_deg or 40.0, seed=seed)
    if spec.cameras == "interior":
        return interior(scene, spec.views, w, h, spec.yfov_deg or 60.0, seed=seed)
    if not spec.poses:
        raise NeuralaoError(f"scene {spec.name}: cameras='file' needs 'poses'")
    path = Path(spec.poses)
    return load_poses(path if path.is_absolute() else config_dir / path, scene, w, h)


def _validate(settings: DatasetSettings) -> None:
    names = set()
    for spec in settings.scenes:
        if spec.name in names:
            raise NeuralaoError(f"scene name {spec.name!r} appears twice in the dataset config")
        names.add(spec.name)
        if spec.cameras != "file" and spec.views < 1:
            raise NeuralaoError(f"scene {spec.name}: views must be >= 1")


def build_dataset(
    settings: DatasetSettings, out: Path, config_dir: Path = Path("."), progress: bool = True
) -> dict:
    """Render and label every scene of ``settings`` into ``out``; resumable. Returns the manifest."""
    from tqdm import tqdm

    from .gbuffer import GBufferRenderer
    from .labels import Labeller

    if not settings.scenes:
        raise NeuralaoError("the dataset config lists no scenes")
    if settings.frames_per_shard < 1 or settings.holdout_every < 0:
        raise NeuralaoError("frames_per_shard must be >= 1 and holdout_every >= 0")
    _validate(settings)
    out = Path(out)
    (out / "shards").mkdir(parents=True, exist_ok=True)
    for folder in (out, out / "shards"):  # a killed run (SIGKILL) leaves its half-written shard behind
        for stale in remove_stale_temporaries(folder):
            log.info("removed %s left by an interrupted run", stale.name)
    config = settings_to_dict(settings)
    config_hash = hashlib.sha256(repr(sorted(config.items())).encode()).hexdigest()
    progress_path = out / "progress.json"
    done: dict[str, str] = {}
    if progress_path.exists():
        import json

        state = json.loads(progress_path.read_text())
        if state.get("config_hash") == config_hash:
            done = state.get("shards", {})
        else:
            log.warning("%s: config changed since the interrupted run; starting over", out)
    shards = []
    total_views = 0
    for si, spec in enumerate(settings.scenes):
        local = config_dir / spec.mesh  # a path relative to the config file wins over a bare mesh name
        scene = load_scene(local if local.exists() else spec.mesh, name=spec.name)
        cams = scene_cameras(spec, scene, settings.size, frame_seed(settings.seed, si, -1), config_dir)
        total_views += len(cams)
        renderer = labeller = None
        views = list(range(len(cams)))
        chunks = [
            views[i : i + settings.frames_per_shard] for i in range(0, len(views), settings.frames_per_shard)
        ]
        bar = tqdm(total=len(views), desc=f"{spec.name}", unit="view", disable=not progress, leave=False)
        for k, chunk in enumerate(chunks):
            rel = f"shards/{spec.name}-{k:04d}.npz"
            path = out / rel
            entry = {
                "file": rel,
                "scene": spec.name,
                "split": spec.split,
                "views": chunk,
                "holdout": [
                    bool(settings.holdout_every and v % settings.holdout_every == settings.holdout_every - 1)
                    for v in chunk
                ],
                "faces": int(len(scene.faces)),
            }
            if rel in done and path.exists() and sha256_file(path) == done[rel]:
                entry["sha256"] = done[rel]
                shards.append(entry)
                bar.update(len(chunk))
                continue
            if renderer is None:
                renderer = GBufferRenderer(scene)
                labeller = Labeller(scene, settings.labels)
            frames = []
            for v in chunk:
                frame = renderer.render(cams[v])
                labeller.settings = replace(settings.labels, seed=frame_seed(settings.seed, si, v))
                frame["ao"], frame["valid"] = labeller.label_frame(frame)
                frames.append(frame)
                bar.update(1)
            arrays = {key: np.stack([np.asarray(f[key]) for f in frames]) for key in FRAME_KEYS}
            arrays["view"] = np.asarray(chunk, dtype=np.int32)
            arrays["holdout"] = np.asarray(entry["holdout"], dtype=bool)
            write_npz(path, **arrays)
            entry["sha256"] = done[rel] = sha256_file(path)
            write_json(progress_path, {"config_hash": config_hash, "shards": done})
            shards.append(entry)
        bar.close()
    dataset_hash = hashlib.sha256("".join(s["sha256"] for s in shards).encode()).hexdigest()
    manifest = {
        "format": "neuralao-dataset",
        "version": FORMAT_VERSION,
        "name": settings.name,
        "config": config,
        "dataset_hash": dataset_hash,
        "frames": total_views,
        "size": list(settings.size),
        "scenes": {s.name: {"split": s.split, "mesh": s.mesh, "cameras": s.cameras} for s in settings.scenes},
        "shards": shards,
        "frame_keys": list(FRAME_KEYS),
        "conventions": {
            "ao": "accessibility in [0,1], 1 = open; 1 on background",
            "depth": "linear camera-space depth (-z_cam), 0 on background",
            "normals": "unit, flipped to face the viewer; camera space (OpenGL: -z forward) and object space",
            "rows": "row 0 at the top",
        },
    }
    write_json(out / "manifest.json", manifest)
    progress_path.unlink(missing_ok=True)
    return manifest


class Dataset:
    """A finished dataset folder. Shards are verified against the manifest's hashes on first read."""

    def __init__(self, root: str | Path, verify: bool = True):
        import json

        self.root = Path(root)
        mpath = self.root / "manifest.json"
        if not mpath.is_file():
            hint = (
                " (an interrupted run: rerun `neuralao dataset` to resume)"
                if (self.root / "progress.json").exists()
                else ""
            )
            raise NeuralaoError(f"no dataset manifest at {mpath}{hint}")
        try:
            self.manifest = json.loads(mpath.read_text())
        except json.JSONDecodeError:
            raise NeuralaoError(f"dataset manifest {mpath} is corrupt") from None
        if self.manifest.get("format") != "neuralao-dataset":
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

    def load_shard(self, entry: dict) -> dict[str, np.ndarray]:
        path = self.root / entry["file"]
        if not path.is_file():
            raise NeuralaoError(f"dataset shard missing: {path}")
        if self.verify and entry["file"] not in self._verified:
            if sha256_file(path) != entry["sha256"]:
                raise NeuralaoError(
                    f"dataset shard {path} is corrupt (sha256 differs from the manifest); rerun `neuralao dataset`"
                )
            self._verified.add(entry["file"])
        return read_npz(path)

    def frames(
        self, split: str | None = None, scene: str | None = None, holdout: bool | None = None
    ) -> Iterator[dict]:
        """Yield frame dicts (COMMON G-buffer keys + ao, valid, pose...) with 'scene', 'view', 'split', 'holdout'."""
        for entry in self.manifest["shards"]:
            if split is not None and entry["split"] != split:
                continue
            if scene is not None and entry["scene"] != scene:
                continue
            if holdout is not None and not any(h == holdout for h in entry["holdout"]):
                continue
            arrays = self.load_shard(entry)
            for i in range(len(arrays["view"])):
                if holdout is not None and bool(arrays["holdout"][i]) != holdout:
                    continue
                frame = {k: arrays[k][i] for k in FRAME_KEYS}
                for k in ("yfov", "znear", "zfar"):
                    frame[k] = float(frame[k])
                frame.update(
                    scene=entry["scene"],
                    view=int(arrays["view"][i]),
                    split=entry["split"],
                    holdout=bool(arrays["holdout"][i]),
                )
                yield frame


def open_dataset(root: str | Path, verify: bool = True) -> Dataset:
    return Dataset(root, verify)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", help="dataset config (JSON); see configs/demo.json")
    p.add_argument("--out", required=True, help="output folder (resumes if an interrupted run is there)")
    add_set_option(p, "--set labels.rays=64")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    settings = load_settings(DatasetSettings, args.config, args.set)
    manifest = build_dataset(
        settings, Path(args.out), Path(args.config).resolve().parent, progress=not args.no_progress
    )
    log.info(
        "dataset %s: %d frames, %d shards, hash %s",
        args.out,
        manifest["frames"],
        len(manifest["shards"]),
        manifest["dataset_hash"][:16],
    )
    return 0
