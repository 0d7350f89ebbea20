"""A per-mesh neural AO field: object-space position + viewer-facing normal -> AO, one network per mesh.

Why
---
Erra's baked MLP, deployed at radius zero, sees only the pixel's normal, and AO is not a function of
the normal. Vertex baking sees position, but only at the mesh's own vertices, so it fails on low-poly
meshes (a room of 4.7k vertices cannot hold a contact shadow along a wall). The field sees *where* the
point is, at any resolution, in a few KiB of weights, and runs as one fragment shader over the
G-buffer (position + normal textures), like Erra's MLP.

Model (``FieldNet``; ONNX ops Sub, Mul, MatMul, Sin, Cos, Concat, Gemm, Tanh)
---------------------------------------------------------------------------
* ``q = (position - centre) * inv_half``: the position normalised by the mesh's bounding box to
  [-1, 1] per axis (``centre``, ``inv_half`` are constants of the graph, stored in its metadata).
* Encoding: ``octaves`` axis-aligned frequency bands (NeRF's positional encoding), ``z[3k + a] =
  q[a] * pi 2^k``, then ``sin(z)`` and ``cos(z)``. Axis-aligned bands keep the encoding's arguments
  *bit-identical* between onnxruntime and the generated GLSL (one correctly rounded product per
  feature; the rest of the MatMul row is exact zeros), so the shader matches to ~1e-7 although
  ``|z|`` reaches ``pi 2^(octaves-1)``. Random Gaussian Fourier features would sum three rounded
  products per feature and lose that. The measured choice of ``octaves`` is in the README.
* ``features = [q, normal, sin(z), cos(z)]`` (6 + 6 octaves floats) -> ``hidden`` tanh layers ->
  one linear output (unclamped; consumers clamp to [0, 1]).

Samples
-------
``samples`` points drawn area-proportionally over the surface (stratified per face,
:func:`neuralao.pipeline.geometry.surface.surface_samples`, seeded), each on *both sides*: the front with
the smooth normal the G-buffer interpolates (corner normals turned to the face's side, barycentric blend,
renormalised) and the label of the geometric normal, the back with both negated. The labeller's back-face
rule marks the back side of a closed surface invalid (its rays start inside) and those samples are dropped,
so closed meshes train on their outside only, while an open, single-sided surface trains on both sides and
the field, whose normal input tells the sides apart, represents both (a vertex bake holds one value per
vertex and cannot). Split 80/20 train / validation by a seeded permutation; held-back orbit views (another
phase) are fully labelled for evaluation only.

Training: Adam (seeded, full determinism on the CPU: one thread, fixed batch order), cosine learning
rate decay, MSE loss, the weights of the best validation RMSE kept.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from neuralao.pipeline.datasets.dataset import frame_seed, open_dataset, scene_of
from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.camera import interior, orbit
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.geometry.surface import surface_samples
from neuralao.pipeline.models.checkpoint import (
    check_interval,
    check_lr,
    check_threads,
    per_mesh_checkpoint,
    restore_model,
    save_checkpoint,
)
from neuralao.pipeline.models.checkpoint import load_checkpoint as _load_checkpoint
from neuralao.pipeline.models.mlp import (  # count_parameters: trainable weights only
    count_parameters,
    size_name,
)
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import (
    MAX_CAP,
    SAMPLE_BYTES,
    check_count,
    check_int_range,
    check_pixels,
    check_seed,
)
from neuralao.runtime.foundation.metrics import masked_rmse, masked_ssim
from neuralao.runtime.foundation.settings import from_dict, settings_to_dict
from neuralao.runtime.frame import FrameLike, check_yfov

log = logging.getLogger(__name__)

KIND = "field"
FORMAT_VERSION = 1
INPUTS = ("position", "normal")  # ONNX input names, each (N, 3) float32
# What a held-back frame keeps: the network's inputs, the labels, and what relabelling and the vertex
# draw need (pose, camera, triangle ids).
HOLDOUT_KEYS = (
    "position",
    "normal_obj",
    "mask",
    "valid",
    "ao",
    "view",
    "pose",
    "tri_id",
    "yfov",
    "znear",
    "zfar",
)


@dataclass
class FieldSettings:
    """Settings of `neuralao train field` (stored resolved in the checkpoint under "config")."""

    # Hidden tanh widths (`--size 32x16`).
    hidden: list[int] = field(default_factory=lambda: [32, 16])
    # Frequency bands of the position encoding: pi * 2^k for k < octaves (0: raw position only).
    # 4 measured best on bunny at 64x32 (held-back RMSE 0.0305 / 0.0189 / 0.0178 / 0.0182 / 0.0183 for
    # 0 / 2 / 4 / 6 / 8 octaves; bench/bench_field.py repeats the sweep on a low-poly mesh).
    octaves: int = 4
    # Surface points (each labelled on both sides; invalid sides dropped).
    samples: int = 1 << 17
    # Most samples on one face (stratified area sampling; every face gets at least one). Effectively no cap:
    # a low-poly mesh (a room of 36 faces) needs thousands of samples per face to show its contact shadows.
    samples_per_face_cap: int = 1 << 30
    # Fraction of the valid samples held out for validation (early stopping / best weights).
    val_fraction: float = 0.2
    # Adam: steps, batch, peak learning rate (cosine decay to lr_final_fraction of it). Measured on
    # GlamVelvetSofa, 32x16, held-back RMSE: 6k steps lr 5e-3 0.0202, 20k 0.0159, 40k at lr 1e-2 0.0135
    # (vertex-lsq 0.0186); the field is under-fitted at short schedules, so 20k at 1e-2 (about 50 s on one
    # core for 32x16; the demo passes fewer).
    steps: int = 20000
    batch: int = 4096
    lr: float = 1e-2
    lr_final_fraction: float = 0.02
    # Validation every this many steps.
    check_every: int = 250
    # Seeds the surface samples, the split, the initialisation, the batches and the labeller's rays.
    seed: int = 0
    # torch intra-op threads (1: deterministic and fastest for batches this small on 2 busy cores).
    threads: int = 1
    # Held-back evaluation views (never sampled): "orbit" (another phase) or "interior" (rooms), and size.
    cameras: Literal["orbit", "interior"] = "orbit"
    holdout_views: int = 4
    holdout_size: tuple[int, int] = (192, 192)
    yfov_deg: float = 40.0
    # AO labeller settings (rays, max distance, kernel...); `--rays R` sets labels.rays.
    labels: LabelSettings = field(default_factory=LabelSettings)


# ----------------------------------------------------------------------------------------------- model


def frequency_matrix(octaves: int) -> np.ndarray:
    """(3, 3 * octaves) float32: column 3k + a is pi 2^k on axis a, zero elsewhere."""
    m = np.zeros((3, 3 * octaves), np.float32)
    for k in range(octaves):
        for a in range(3):
            m[a, 3 * k + a] = np.float32(math.pi * 2.0**k)
    return m


class FieldNet(nn.Module):
    """(position (N, 3), normal (N, 3)) float32 -> (N, 1) float32 AO (unclamped)."""

    def __init__(self, hidden, octaves: int, centre, inv_half):
        super().__init__()
        self.hidden = [int(h) for h in hidden]
        self.octaves = int(octaves)
        self.register_buffer("centre", torch.as_tensor(np.asarray(centre, np.float32)).reshape(1, 3))
        self.register_buffer("inv_half", torch.as_tensor(np.asarray(inv_half, np.float32)).reshape(1, 3))
        self.register_buffer("freqs", torch.as_tensor(frequency_matrix(self.octaves)))
        widths = [self.features, *self.hidden]
        layers: list[nn.Module] = []
        for a, b in zip(widths[:-1], widths[1:], strict=True):
            layers += [nn.Linear(a, b), nn.Tanh()]
        layers.append(nn.Linear(widths[-1], 1))
        self.net = nn.Sequential(*layers)

    @property
    def features(self) -> int:
        return 6 + 6 * self.octaves

    def encode(self, position: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
        q = (position - self.centre) * self.inv_half
        if self.octaves == 0:
            return torch.cat([q, normal], dim=1)
        z = q @ self.freqs
        return torch.cat([q, normal, torch.sin(z), torch.cos(z)], dim=1)

    def forward(self, position: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
        return self.net(self.encode(position, normal))


def bounding_box(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """centre (3,) and inverse half extent (3,) float32 mapping the box to [-1, 1]; flat axes -> 1."""
    lo, hi = np.min(vertices, axis=0), np.max(vertices, axis=0)
    half = (hi - lo) / 2.0
    scale = max(float(half.max()), 1e-30)
    half = np.where(half > 1e-6 * scale, half, scale)  # a flat axis (a plane) maps to [~0, ~0]
    return ((lo + hi) / 2.0).astype(np.float32), (1.0 / half).astype(np.float32)


def build_model(model_args: dict) -> FieldNet:
    try:
        hidden = [int(h) for h in model_args["hidden"]]
        octaves = int(model_args["octaves"])
        centre = np.asarray(model_args["centre"], np.float32)
        inv_half = np.asarray(model_args["inv_half"], np.float32)
    except (KeyError, TypeError, ValueError):
        raise NeuralaoError(f"bad field model_args {model_args!r}") from None
    if (
        not hidden
        or min(hidden) < 1
        or not 0 <= octaves <= 16
        or centre.shape != (3,)
        or inv_half.shape != (3,)
    ):
        raise NeuralaoError(f"bad field model_args {model_args!r}")
    return FieldNet(hidden, octaves, centre, inv_half)


def model_args_dict(model: FieldNet) -> dict:
    return {
        "hidden": list(model.hidden),
        "octaves": model.octaves,
        "centre": model.centre.reshape(-1).tolist(),
        "inv_half": model.inv_half.reshape(-1).tolist(),
    }


def parameter_bytes(model: FieldNet) -> int:
    """float32 bytes of everything the shader stores: weights + the 6 normalisation constants + the
    non-zero frequencies (the shader's frequency matrix is padded, see the export manifest)."""
    return 4 * (count_parameters(model) + 6 + 3 * model.octaves)


# ----------------------------------------------------------------------------------------------- samples


@dataclass
class FieldSamples:
    """position (n, 3), normal (n, 3) float32 network inputs, ao (n,) float32,
    split (n,) int8 (0 train, 1 val)."""

    position: np.ndarray
    normal: np.ndarray
    ao: np.ndarray
    split: np.ndarray
    holdout: list[dict]
    info: dict

    def part(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sel = self.split == k
        return self.position[sel], self.normal[sel], self.ao[sel]


def smooth_normals_at(scene, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(k, 3) float64 unit normals as the G-buffer interpolates them (pipeline/gbuffers/rasterizer.py):
    each corner's vertex normal turned to its face's side, barycentric blend, renormalised; zero -> the
    face normal."""
    fn = scene.face_normals[face]
    corners = scene.vertex_normals[scene.faces[face]]  # (k, 3, 3)
    flip = np.einsum("kcd,kd->kc", corners, fn) < 0
    corners = np.where(flip[..., None], -corners, corners)
    n = np.einsum("kc,kcd->kd", bary, corners)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-12, n / np.maximum(length, 1e-300), fn)


def two_sided_samples(scene, settings: FieldSettings, progress: bool = False) -> tuple[np.ndarray, ...]:
    """Surface samples on both sides, labelled. Returns position (m, 3), normal (m, 3) float32 and ao (m,)
    float32 of the valid ones, and counts (front valid, back valid, total per side)."""
    s = surface_samples(scene, settings.samples, settings.samples_per_face_cap, seed=settings.seed)
    smooth = smooth_normals_at(scene, s.face, s.bary)
    labeller = Labeller(scene, replace(settings.labels, seed=settings.seed))
    n = len(s)
    points = np.concatenate([s.points, s.points])
    geometric = np.concatenate([s.normals, -s.normals])
    ids = np.arange(2 * n, dtype=np.int64)  # the back side's rays are independent of the front's
    ao, valid = labeller.ao_at_points(points, geometric, progress=progress, ids=ids)
    inputs_n = np.concatenate([smooth, -smooth]).astype(np.float32)
    counts = (int(valid[:n].sum()), int(valid[n:].sum()), n)
    return points[valid].astype(np.float32), inputs_n[valid], ao[valid].astype(np.float32), counts


def holdout_frames(scene, settings: FieldSettings) -> list[dict]:
    """Fully labelled orbit views of another phase than any sampling (evaluation only)."""
    if settings.holdout_views < 1:
        return []
    w, h = settings.holdout_size
    if settings.cameras == "interior":
        cams = interior(scene, settings.holdout_views, w, h, seed=1)
    else:
        cams = orbit(scene, settings.holdout_views, w, h, settings.yfov_deg, seed=1)
    labeller = Labeller(scene, settings.labels)
    frames = []
    with GBufferRenderer(scene) as renderer:
        for k, cam in enumerate(cams):
            f = renderer.render(cam)
            labeller.settings = replace(settings.labels, seed=frame_seed(settings.seed, 1, k))
            f["ao"], f["valid"] = labeller.label_frame(f)
            f["view"] = k
            frames.append({key: f[key] for key in HOLDOUT_KEYS})
    return frames


def check_settings(s: FieldSettings) -> None:
    if not 0 <= s.octaves <= 16:
        raise NeuralaoError(
            f"octaves must be in 0..16 (pi 2^15 is the largest float32-safe band), got {s.octaves}"
        )
    if not s.hidden or min(s.hidden) < 1:
        raise NeuralaoError(f"hidden widths must be positive, got {s.hidden}")
    for name in ("steps", "batch", "check_every", "samples", "samples_per_face_cap", "holdout_views"):
        check_int_range(name, getattr(s, name), 0 if name == "holdout_views" else 1, MAX_CAP)
    check_threads("threads", s.threads)
    # Every check_every-th step keeps a validation record in the history (and the checkpoint).
    check_count(
        "steps",
        s.steps // s.check_every + 1,
        bytes_each=512,
        each="a validation record of the history",
        shown=f"{s.steps} (checked every {s.check_every})",
    )
    # What the counts allocate, before any of it is (neuralao.runtime.foundation.limits): every surface
    # sample twice (both sides), a batch of activations per layer, the held-back frames, a network of hidden
    # widths.
    check_count(
        "samples", 2 * s.samples, bytes_each=SAMPLE_BYTES, each="per surface sample", shown=str(s.samples)
    )
    check_count(
        "batch",
        s.batch,
        bytes_each=64 * (sum(s.hidden) + 6 + 6 * max(s.octaves, 0)) + 64,
        each="per batch row",
    )
    if s.holdout_views:
        check_pixels("holdout_size", *s.holdout_size, frames=s.holdout_views)
    check_count(
        "hidden",
        max(s.hidden or [1]) ** 2 * len(s.hidden or [1]),
        bytes_each=64,
        each="per weight",
        shown=str(list(s.hidden)),
    )
    check_seed("seed", s.seed)
    check_lr("lr", s.lr)
    check_interval("lr_final_fraction", s.lr_final_fraction, 0.0, 1.0)
    # 0: every sample trains, and the best weights are those of the lowest training-batch error.
    check_interval("val_fraction", s.val_fraction, 0.0, 1.0, open_high=True)
    check_yfov("yfov_deg", s.yfov_deg)
    if s.samples < 16:
        raise NeuralaoError(f"samples must be >= 16, got {s.samples}")


def collect_samples(scene, settings: FieldSettings, progress: bool = False) -> FieldSamples:
    check_settings(settings)
    t0 = time.perf_counter()
    position, normal, ao, (front, back, per_side) = two_sided_samples(scene, settings, progress)
    if len(ao) < 16:
        raise NeuralaoError(f"only {len(ao)} valid surface samples on {scene.name}: too few to train")
    rng = np.random.default_rng(settings.seed)
    split = np.zeros(len(ao), np.int8)
    split[rng.permutation(len(ao))[: int(round(settings.val_fraction * len(ao)))]] = 1
    t_samples = time.perf_counter() - t0
    holdout = holdout_frames(scene, settings)
    info = {
        "scene": scene.name,
        "mesh": str(scene.source),
        "vertices": int(len(scene.vertices)),
        "faces": int(len(scene.faces)),
        "surface_points": per_side,
        "valid_front": front,
        "valid_back": back,
        "samples": int(len(ao)),
        "labels": settings_to_dict(settings.labels),
        "sampling_seconds": t_samples,
        "holdout_seconds": time.perf_counter() - t0 - t_samples,
    }
    return FieldSamples(position, normal, ao, split, holdout, info)


# ----------------------------------------------------------------------------------------------- training


def predict(model: FieldNet, position: np.ndarray, normal: np.ndarray, batch: int = 1 << 16) -> np.ndarray:
    """(n,) float32 raw network output (unclamped)."""
    out = np.empty(len(position), np.float32)
    with torch.no_grad():
        for i in range(0, len(position), batch):
            p = torch.from_numpy(np.ascontiguousarray(position[i : i + batch], np.float32))
            n = torch.from_numpy(np.ascontiguousarray(normal[i : i + batch], np.float32))
            out[i : i + batch] = model(p, n).reshape(-1).numpy()
    return out


def predict_frame(model: FieldNet, frame: FrameLike) -> np.ndarray:
    """(H, W) float32 AO of a G-buffer frame (position, normal_obj, mask), clamped; background 1."""
    mask = np.asarray(frame["mask"], bool)
    ao = np.ones(mask.shape, np.float32)
    ao[mask] = np.clip(predict(model, frame["position"][mask], frame["normal_obj"][mask]), 0.0, 1.0)
    return ao


def train_model(samples: FieldSamples, scene, settings: FieldSettings, progress: bool = False):
    """Adam with cosine decay; returns (model with the best validation weights, info)."""
    if settings.threads > 0:
        torch.set_num_threads(settings.threads)
    check_settings(settings)
    torch.manual_seed(settings.seed)
    centre, inv_half = bounding_box(scene.vertices)
    model = FieldNet(settings.hidden, settings.octaves, centre, inv_half)
    tp, tn, ty = (torch.from_numpy(a) for a in samples.part(0))
    vp, vn, vy = (torch.from_numpy(a) for a in samples.part(1))
    opt = torch.optim.Adam(model.parameters(), lr=settings.lr)
    gen = torch.Generator().manual_seed(settings.seed)
    best = (math.inf, None, 0)
    history = []
    t0 = time.perf_counter()
    perm, cursor = torch.randperm(len(ty), generator=gen), 0
    for step in tqdm(
        range(1, settings.steps + 1),
        desc=f"field {size_name(settings.hidden)}",
        disable=not progress,
        leave=False,
        unit="step",
    ):
        frac = (step - 1) / max(1, settings.steps - 1)
        scale = settings.lr_final_fraction + (1 - settings.lr_final_fraction) * 0.5 * (
            1 + math.cos(math.pi * frac)
        )
        for g in opt.param_groups:
            g["lr"] = settings.lr * scale
        if cursor + settings.batch > len(ty):
            perm, cursor = torch.randperm(len(ty), generator=gen), 0
        idx = perm[cursor : cursor + settings.batch]
        cursor += settings.batch
        pred = model(tp[idx], tn[idx]).reshape(-1)
        loss = torch.mean((pred - ty[idx]) ** 2)
        if not torch.isfinite(loss):
            raise NeuralaoError(
                f"training diverged at step {step} (loss {float(loss.detach())}); "
                f"try a smaller lr than {settings.lr:g}"
            )
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if step % settings.check_every == 0 or step == settings.steps:
            with torch.no_grad():
                val = (
                    float(torch.sqrt(torch.mean((model(vp, vn).reshape(-1) - vy) ** 2)))
                    if len(vy)
                    else math.sqrt(float(loss.detach()))  # no validation split: the batch's RMSE
                )
            history.append({"step": step, "val_rmse": val, "seconds": time.perf_counter() - t0})
            if not math.isfinite(val):  # the weights are gone (NaN or inf): no best model to keep
                raise NeuralaoError(
                    f"training diverged at step {step} (validation RMSE {val}); "
                    f"try a smaller lr than {settings.lr:g}"
                )
            if val < best[0]:
                best = (val, {k: v.detach().clone() for k, v in model.state_dict().items()}, step)
    model.load_state_dict(best[1])
    info = {
        "best_step": best[2],
        "best_val_rmse": best[0],
        "history": history,
        "seconds": time.perf_counter() - t0,
        "optimizer": "adam, cosine decay",
    }
    return model.eval(), info


def evaluate_frames(model: FieldNet | float, frames: list[FrameLike]) -> dict:
    """Masked SSIM / RMSE over valid foreground pixels of held-back frames (``model`` a number: constant)."""
    rows = []
    for f in frames:
        valid = np.asarray(f["valid"], bool) & np.asarray(f["mask"], bool)
        if not valid.any():
            continue
        if isinstance(model, FieldNet):
            pred = predict_frame(model, f)
        else:
            pred = np.where(f["mask"], np.float32(model), np.float32(1.0))
        ref = np.asarray(f["ao"], np.float32)
        rows.append(
            {
                "view": int(f["view"]),
                "ssim": masked_ssim(pred, ref, valid),
                "rmse": masked_rmse(pred, ref, valid),
            }
        )
    if not rows:
        return {"frames": 0, "ssim": None, "rmse": None}
    return {
        "frames": len(rows),
        "ssim": float(np.mean([r["ssim"] for r in rows])),
        "rmse": float(np.mean([r["rmse"] for r in rows])),
    }


def compute_metrics(model: FieldNet, samples: FieldSamples) -> dict:
    out: dict = {}
    for k, name in ((0, "train"), (1, "val")):
        p, n, y = samples.part(k)
        out[f"{name}_rmse"] = float(np.sqrt(np.mean((predict(model, p, n) - y) ** 2))) if len(y) else None
        out[f"{name}_samples"] = int(len(y))
    mean_train = float(samples.part(0)[2].mean())
    vy = samples.part(1)[2]
    out["constant_val_rmse"] = float(np.sqrt(np.mean((vy - mean_train) ** 2))) if len(vy) else None
    held, constant = evaluate_frames(model, samples.holdout), evaluate_frames(mean_train, samples.holdout)
    out.update(
        holdout_frames=held["frames"],
        holdout_ssim=held["ssim"],
        holdout_rmse=held["rmse"],
        holdout_constant_ssim=constant["ssim"],
        holdout_constant_rmse=constant["rmse"],
    )
    return out


# ----------------------------------------------------------------------------------------------- checkpoints


def make_checkpoint(
    model: FieldNet, settings: FieldSettings, samples: FieldSamples, metrics: dict, info: dict
) -> dict:
    return per_mesh_checkpoint(
        KIND,
        FORMAT_VERSION,
        model,
        model_args_dict(model),
        settings_to_dict(settings),
        samples.info,
        metrics,
        info,
        parameter_bytes(model),
    )


def load_checkpoint(path: str | Path) -> dict:
    return _load_checkpoint(path, KIND, "a field", FORMAT_VERSION)


def model_from_checkpoint(ckpt: dict) -> FieldNet:
    return restore_model(build_model, ckpt)


# ----------------------------------------------------------------------------------------------- driver


def resolve_source(data, scene_name, mesh, settings: FieldSettings):
    """The Scene to train on, the settings and the held-back frames (None: render them): a dataset scene
    takes the dataset's label settings and its held-back views of that scene."""
    if mesh is not None:
        return load_scene(mesh), settings, None

    ds = open_dataset(data)
    if scene_name not in ds.scenes:
        raise NeuralaoError(f"scene {scene_name!r} is not in {data} (has {sorted(ds.scenes)})")
    labels = from_dict(LabelSettings, dict(ds.label_settings))
    labels = replace(labels, workers=settings.labels.workers)
    frames = [{k: f[k] for k in HOLDOUT_KEYS} for f in ds.frames(scene=scene_name, holdout=True)]
    return scene_of(ds.manifest, scene_name), replace(settings, labels=labels, holdout_views=0), frames


def train(
    settings: FieldSettings, out, data=None, scene=None, mesh=None, progress=False, samples=None
) -> dict:
    """Mesh (or dataset scene) -> two-sided surface samples -> field -> metrics -> checkpoint at ``out``."""
    check_settings(settings)  # before the mesh or dataset is read
    scene_obj, settings, frames = resolve_source(data, scene, mesh, settings)
    if samples is None:
        samples = collect_samples(scene_obj, settings, progress)
        if frames is not None:
            samples.holdout = frames
            samples.info["holdout_source"] = f"dataset {data}: held-back views of {scene}"
    model, info = train_model(samples, scene_obj, settings, progress)
    ckpt = make_checkpoint(model, settings, samples, compute_metrics(model, samples), info)
    if out is not None:
        save_checkpoint(out, ckpt)
    return ckpt
