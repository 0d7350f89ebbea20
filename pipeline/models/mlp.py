"""The baked MLP of Erra, Capece and Agatiello (2017): 16 object-space normals -> AO, one network per mesh.

Samples
-------
From every training view of a mesh, ``samples_per_view`` (512) random *valid* foreground pixels are
drawn (seeded per view). A sample's input is the object-space normal at 16 points on a circle of
``radius_px`` (10) pixels around the pixel, at angles ``k * 2 pi / 16``, each taken from the nearest
pixel: column ``j + rint(r cos a)``, row ``i - rint(r sin a)`` (counter-clockwise on screen, y up);
the 16 normals are interleaved ``x0 y0 z0 x1 y1 z1 ...`` (48 floats). Its target is the ray-traced AO
of the centre pixel.

A circle point that falls on background or off-screen has no normal; it gets the **centre pixel's
normal**. That is the network's deployed input at every one of the 16 positions (the shader repeats
the centre normal; see below), so such samples move towards the deployment distribution instead of
feeding the network a zero vector it never sees at run time.

Two sources:

* a dataset (``--data DIR --scene NAME``): the scene's non-held-back views; targets from the labelled
  frames (only pixels with ``valid`` labels are drawn);
* a mesh (``--mesh PATH_OR_NAME``): ``views`` orbit cameras are rendered (G-buffers are cheap) and
  ONLY the drawn centre pixels are labelled, with :meth:`Labeller.ao_at_points` on the float64 points
  and geometric normals of :meth:`Labeller.visible_points` and randomisation id = flat pixel index,
  so a label is bit-identical to what :meth:`Labeller.label_frame` gives that pixel (tested), at about
  ``512 / foreground pixels`` of the cost. Held-back views are a separate orbit (another phase, other
  cameras) at ``holdout_size``, fully labelled, used only for evaluation.

All samples are split 50/25/25 into train / validation / test with a seeded permutation (as MATLAB's
``dividerand`` in the paper). Held-back views are never sampled.

Model, training, metrics
------------------------
``48 -> X -> Y -> 1`` with tanh hidden units and a linear output (``nn.Linear`` layers only, so the
ONNX graph is Gemm / Tanh). Parameters: 929 / 2,113 / 5,249 for 16x8 / 32x16 / 64x32 (3,716 / 8,452
/ 20,996 bytes as float32). The output is *unclamped*; every consumer clamps to [0, 1] as a UNORM
render target would.

Optimiser: the paper used MATLAB's scaled conjugate gradient (full batch), a second-order-ish batch
method. Here it is full-batch L-BFGS with a strong-Wolfe line search (float32), measured against Adam
on bunny (65,536 samples of 128 views, 1 thread, same early stopping):

    size   optimiser              val RMSE   wall
    16x8   L-BFGS float32          0.0677    12 s
    16x8   L-BFGS float64          0.0680    18 s
    16x8   Adam lr 3e-3 batch 256  0.0680    11 s
    16x8   Adam lr 1e-2 batch 1024 0.0687     3 s
    64x32  L-BFGS float32          0.0601   156 s   (machine shared with other jobs)
    64x32  L-BFGS float64          0.0597   197 s
    64x32  Adam lr 3e-3 batch 256  0.0619    65 s   (mini-batch noise: plateaus higher)

L-BFGS reaches the lowest validation error at every size, needs no learning rate, and is
deterministic for a seed, so it is the default; Adam stays available (``--set optimizer=adam``).
Early stopping: the validation MSE is checked every ``check_every`` iterations; training stops after
``patience`` checks without improvement (MATLAB's ``max_fail`` idea) and the best weights are kept.

Evaluation, as deployed: on held-back views the network is applied at **radius zero** (each pixel's
own normal repeated 16 times), clamped to [0, 1], and compared with the ray-traced AO by masked SSIM
and RMSE (:mod:`neuralao.runtime.foundation.metrics`, Gaussian window 11, sigma 1.5) over the valid
foreground pixels. The same network applied with the radius-10 circle it was trained on is reported next to
it (``*_r10``), to show what the radius-zero deployment costs.
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

from neuralao.pipeline.datasets.dataset import frame_seed, open_dataset
from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.camera import orbit
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.models.checkpoint import (
    check_interval,
    check_lr,
    check_threads,
    count_parameters,
    per_mesh_checkpoint,
    restore_model,
    save_checkpoint,
)
from neuralao.pipeline.models.checkpoint import load_checkpoint as _load_checkpoint
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
from neuralao.runtime.foundation.metrics import image_ssim, masked_rmse, masked_ssim
from neuralao.runtime.foundation.settings import settings_to_dict
from neuralao.runtime.frame import FrameLike, check_yfov

# The deployed input layout is the consumer runtime's (CIRCLE_SAMPLES normals, radius-zero input).
from neuralao.runtime.predict import CIRCLE_SAMPLES, radius_zero_inputs
from neuralao.runtime.predict import MLP_INPUTS as INPUTS

log = logging.getLogger(__name__)

KIND = "mlp"
FORMAT_VERSION = 1
SPLIT_NAMES = ("train", "val", "test")
# The largest circle radius in pixels: the largest view side (check_pixels), past which every circle point
# is off-screen (the input is the centre normal repeated, as at radius 0).
MAX_RADIUS_PX = 8192.0


@dataclass
class MLPSettings:
    """Settings of `neuralao train mlp` (stored resolved in the checkpoint under "config")."""

    # Hidden widths X, Y (paper: 16x8, 32x16, 64x32); `--size XxY` on the command line.
    hidden: list[int] = field(default_factory=lambda: [16, 8])
    samples_per_view: int = 512  # random valid foreground pixels drawn per view (paper: 512)
    radius_px: float = 10.0  # circle radius in pixels for the training inputs (paper: 10)
    # What the network trains on: "circle" (the paper: 16 normals on the circle), "centre" (the deployed
    # radius-zero input: the centre normal repeated 16 times) or "both" (every sample in both forms).
    train_inputs: Literal["circle", "centre", "both"] = "circle"
    # Train / validation / test fractions of the samples (paper: 50/25/25).
    split: list[float] = field(default_factory=lambda: [0.5, 0.25, 0.25])
    # Full-batch L-BFGS (default, see the module docstring for the measurement) or mini-batch Adam.
    optimizer: Literal["lbfgs", "adam"] = "lbfgs"
    max_iterations: int = 3000  # L-BFGS iterations (or Adam epochs) at most
    check_every: int = 10  # L-BFGS iterations between validation checks (Adam: every epoch)
    patience: int = 8  # validation checks without improvement before stopping (early stopping)
    lbfgs_history: int = 50  # L-BFGS curvature pairs kept
    # Training arithmetic (weights are stored as float32). float64 L-BFGS reached the same validation error
    # (0.0597 vs 0.0601 on bunny 64x32) 25% slower, so float32.
    train_dtype: Literal["float32", "float64"] = "float32"
    adam_lr: float = 3e-3  # Adam learning rate
    adam_batch: int = 256  # Adam mini-batch size
    seed: int = 0  # seeds pixel draws, the split, weight initialisation and (mesh source) the labeller's rays
    # torch intra-op threads (0: torch's default). 1 by default: a 32k x 48 batch through a 16x8 network is
    # too small to split, and on 2 busy cores two threads ran 2-5x slower than one (spin-waiting).
    threads: int = 1
    # Mesh source only (--mesh):
    views: int = 128  # orbit views to draw samples from (paper: 128)
    size: tuple[int, int] = (256, 256)  # width, height of the sampled views in pixels (`--resolution W H`)
    yfov_deg: float = 40.0  # vertical field of view of the orbit cameras
    holdout_views: int = 8  # held-back evaluation views (a separate orbit, never sampled)
    holdout_size: tuple[int, int] = (256, 256)  # width, height of the held-back views
    # AO labeller settings (rays, max distance, kernel...); `--rays R` sets labels.rays.
    labels: LabelSettings = field(default_factory=LabelSettings)


# ----------------------------------------------------------------------------------------------- model


class BakedMLP(nn.Module):
    """``inputs -> hidden[0] -> ... -> 1``, tanh hidden units, linear output. (N, 48) f32 -> (N, 1) f32."""

    def __init__(self, hidden: list[int] | tuple[int, ...] = (16, 8), inputs: int = INPUTS):
        super().__init__()
        widths = [int(inputs), *[int(h) for h in hidden]]
        layers: list[nn.Module] = []
        for a, b in zip(widths[:-1], widths[1:], strict=True):
            layers += [nn.Linear(a, b), nn.Tanh()]
        layers.append(nn.Linear(widths[-1], 1))
        self.net = nn.Sequential(*layers)
        self.hidden = [int(h) for h in hidden]
        self.inputs = int(inputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


def parse_size(text: str) -> list[int]:
    """``"16x8"`` -> [16, 8] (any number of positive widths joined by ``x``)."""
    try:
        widths = [int(p) for p in str(text).lower().split("x")]
    except ValueError:
        widths = []
    if not widths or any(w < 1 for w in widths):
        raise NeuralaoError(
            f"--size (the network size) must look like 16x8 (positive hidden widths), got {text!r}"
        )
    return widths


def size_name(hidden: list[int] | tuple[int, ...]) -> str:
    return "x".join(str(int(h)) for h in hidden)


def build_model(model_args: dict) -> BakedMLP:
    """Rebuild from a checkpoint's ``model_args`` ({"inputs": 48, "hidden": [X, Y]})."""
    try:
        hidden = [int(h) for h in model_args["hidden"]]
        inputs = int(model_args.get("inputs", INPUTS))
    except (KeyError, TypeError, ValueError):
        raise NeuralaoError(f"bad MLP model_args {model_args!r}") from None
    if inputs != INPUTS or not hidden or min(hidden) < 1:
        raise NeuralaoError(f"bad MLP model_args {model_args!r} (inputs must be {INPUTS}, widths positive)")
    return BakedMLP(hidden, inputs)


def model_args_dict(model: BakedMLP) -> dict:
    return {"inputs": model.inputs, "hidden": list(model.hidden)}


def parameter_bytes(model: nn.Module) -> int:
    """Bytes of the weights as float32 (what the shader's uniform buffer holds)."""
    return 4 * count_parameters(model)


# ----------------------------------------------------------------------------------------------- inputs


def circle_offsets(radius: float = 10.0, count: int = CIRCLE_SAMPLES) -> np.ndarray:
    """(count, 2) int64 (row, column) offsets of the nearest pixels on the circle, angle k * 2 pi / count.

    Column ``rint(r cos a)``, row ``-rint(r sin a)`` (image rows grow downwards, so a = pi/2 is up).
    """
    a = np.arange(count) * (2.0 * math.pi / count)
    return np.stack([-np.rint(radius * np.sin(a)), np.rint(radius * np.cos(a))], axis=1).astype(np.int64)


def circle_inputs(
    normal_obj: np.ndarray,
    mask: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    radius: float = 10.0,
    count: int = CIRCLE_SAMPLES,
) -> tuple[np.ndarray, np.ndarray]:
    """Network inputs of centre pixels (rows[i], cols[i]).

    normal_obj : (H, W, 3) float object-space normals; mask : (H, W) bool foreground.
    rows, cols : (n,) int centre pixels (should be foreground).
    Returns inputs (n, 3 * count) float32 (xyz interleaved, angle-major) and substituted (n, count)
    bool: circle points on background or off-screen, which got the centre pixel's normal.
    """
    normal_obj = np.asarray(normal_obj, dtype=np.float32)
    mask = np.asarray(mask, dtype=bool)
    h, w = mask.shape
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    off = circle_offsets(radius, count)
    rr = rows[:, None] + off[None, :, 0]
    cc = cols[:, None] + off[None, :, 1]
    inside = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
    rr_c, cc_c = np.clip(rr, 0, h - 1), np.clip(cc, 0, w - 1)
    ok = inside & mask[rr_c, cc_c]
    centre = normal_obj[rows, cols]  # (n, 3)
    normals = np.where(ok[..., None], normal_obj[rr_c, cc_c], centre[:, None, :])
    return np.ascontiguousarray(normals.reshape(len(rows), 3 * count), dtype=np.float32), ~ok


# ----------------------------------------------------------------------------------------------- samples


@dataclass
class Samples:
    """Training samples of one mesh and its held-back frames.

    inputs  : (n, 48) float32 circle normals; centre : (n, 3) float32 the centre pixel's normal
    targets : (n,) float32 centre AO
    view    : (n,) int32 view index; split : (n,) int8 (0 train, 1 val, 2 test)
    holdout : held-back frames (dicts with normal_obj (H,W,3), mask (H,W), valid (H,W), ao (H,W), view)
    info    : provenance (source, scene, mesh, label settings, counts)
    """

    inputs: np.ndarray
    centre: np.ndarray
    targets: np.ndarray
    view: np.ndarray
    split: np.ndarray
    holdout: list[dict]
    info: dict

    def part(self, name: str, inputs: str = "circle") -> tuple[np.ndarray, np.ndarray]:
        """(inputs (k, 48) float32, targets (k,) float32) of one split.

        inputs "circle": the training circle; "centre": the deployed radius-zero input; "both": each
        sample twice, once in each form.
        """
        sel = self.split == SPLIT_NAMES.index(name)
        y = self.targets[sel]
        if inputs == "circle":
            return self.inputs[sel], y
        zero = radius_zero_inputs(self.centre[sel])
        if inputs == "centre":
            return zero, y
        if inputs == "both":
            return np.concatenate([self.inputs[sel], zero]), np.concatenate([y, y])
        raise NeuralaoError(f"inputs must be circle, centre or both; got {inputs!r}")


def view_rng(seed: int, view: int) -> np.random.Generator:
    """The pixel-drawing generator of one view (independent of view order)."""
    return np.random.default_rng([int(seed), int(view), 0x4D4C50])


def draw_pixels(candidates: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``min(count, len(candidates))`` of the flat pixel indices ``candidates``, without replacement."""
    count = min(int(count), len(candidates))
    return np.sort(rng.choice(candidates, size=count, replace=False)) if count else candidates[:0]


def check_split(fractions: list[float]) -> np.ndarray:
    """The train / validation / test fractions as a (3,) float64 array: they sum to 1, train and val > 0."""
    f = np.asarray(fractions, dtype=np.float64)
    if f.shape != (3,) or (f < 0).any() or abs(f.sum() - 1.0) > 1e-6 or f[0] <= 0 or f[1] <= 0:
        raise NeuralaoError(
            f"split must be three fractions summing to 1 with train, val > 0; got {fractions}"
        )
    return f


def split_samples(n: int, fractions: list[float], seed: int) -> np.ndarray:
    """(n,) int8 split labels (0/1/2) from a seeded permutation, sizes floor(f * n) (test gets the rest)."""
    f = check_split(fractions)
    perm = np.random.default_rng([int(seed), 0x53504C]).permutation(n)
    n_train, n_val = int(f[0] * n), int(f[1] * n)
    out = np.full(n, 2, dtype=np.int8)
    out[perm[:n_train]] = 0
    out[perm[n_train : n_train + n_val]] = 1
    return out


def _eval_frame(frame: FrameLike, view: int) -> dict:
    """The channels evaluation needs (and what relabelling needs: tri_id, pose, yfov, depth), compact."""
    out = {
        "normal_obj": np.asarray(frame["normal_obj"], dtype=np.float32),
        "mask": np.asarray(frame["mask"], dtype=bool),
        "valid": np.asarray(frame["valid"], dtype=bool),
        "ao": np.asarray(frame["ao"], dtype=np.float32),
        "view": int(view),
    }
    for key in ("tri_id", "pose", "yfov", "depth", "normal_cam"):
        if key in frame:
            out[key] = frame[key]
    return out


def _finish(
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]],
    holdout: list[dict],
    settings: MLPSettings,
    info: dict,
) -> Samples:
    if not parts:
        raise NeuralaoError(f"no valid foreground pixel to sample in {info.get('scene')}")
    inputs = np.concatenate([p[0] for p in parts])
    centre = np.concatenate([p[1] for p in parts]).astype(np.float32)
    targets = np.concatenate([p[2] for p in parts]).astype(np.float32)
    view = np.concatenate([np.full(len(p[2]), p[3], dtype=np.int32) for p in parts])
    if len(targets) < 8:
        raise NeuralaoError(f"only {len(targets)} samples in {info.get('scene')}: too few to train")
    info = {**info, "samples": int(len(targets)), "sampled_views": len(parts), "holdout_views": len(holdout)}
    return Samples(
        inputs,
        centre,
        targets,
        view,
        split_samples(len(targets), settings.split, settings.seed),
        holdout,
        info,
    )


def samples_from_dataset(
    data: str | Path, scene: str, settings: MLPSettings, progress: bool = False
) -> Samples:
    """Samples from the non-held-back views of ``scene`` in a dataset; its held-back views for evaluation."""
    ds = open_dataset(data)
    if scene not in ds.scenes:
        raise NeuralaoError(f"scene {scene!r} is not in dataset {data} (it has: {', '.join(ds.scenes)})")
    parts, holdout, substituted = [], [], []
    for frame in tqdm(
        ds.frames(scene=scene), desc=f"samples {scene}", unit="view", disable=not progress, leave=False
    ):
        v = int(frame["view"])
        if frame["holdout"]:
            holdout.append(_eval_frame(frame, v))
            continue
        valid = np.asarray(frame["valid"], dtype=bool) & np.asarray(frame["mask"], dtype=bool)
        pix = draw_pixels(np.flatnonzero(valid), settings.samples_per_view, view_rng(settings.seed, v))
        if len(pix) == 0:
            continue
        rows, cols = np.divmod(pix, valid.shape[1])
        x, sub = circle_inputs(frame["normal_obj"], frame["mask"], rows, cols, settings.radius_px)
        centre = np.asarray(frame["normal_obj"], np.float32)[rows, cols]
        parts.append((x, centre, np.asarray(frame["ao"], np.float32).reshape(-1)[pix], v))
        substituted.append(sub.mean())
    info = {
        "source": "dataset",
        "dataset": str(data),
        "dataset_hash": ds.manifest.get("dataset_hash"),
        "scene": scene,
        "mesh": ds.manifest["scenes"][scene].get("mesh", scene),
        "size": list(ds.manifest.get("size", [])),
        "labels": ds.label_settings,
        "substituted_fraction": float(np.mean(substituted)) if substituted else 0.0,
    }
    return _finish(parts, holdout, settings, info)


def label_pixels(labeller, frame: FrameLike, pix: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """AO of some foreground pixels of a frame, exactly as ``label_frame`` (same seed) would label them.

    pix : (k,) int64 flat pixel indices (foreground). Points and normals come from
    :meth:`Labeller.visible_points` (float64, from ``tri_id`` and the pixel ray), randomisation ids are the
    flat pixel indices. Returns ao (k,) float32 and valid (k,) bool (False where the point is not exact).
    """
    points, normals, fg_pix, exact = labeller.visible_points(frame)
    where = np.searchsorted(fg_pix, pix)
    if len(pix) and (where.max() >= len(fg_pix) or (fg_pix[where] != pix).any()):
        raise NeuralaoError("label_pixels: a pixel is not foreground")
    labeller.settings = replace(labeller.settings, seed=int(seed))
    ao, valid = labeller.ao_at_points(points[where], normals[where], ids=pix)
    return ao, valid & exact[where]


def samples_from_mesh(mesh: str | Path, settings: MLPSettings, progress: bool = False) -> Samples:
    """Render ``settings.views`` orbit views of a mesh, label only the drawn pixels; fully label held-back
    views."""
    scene = load_scene(mesh)
    w, h = settings.size
    hw, hh = settings.holdout_size
    if settings.views < 1 or settings.holdout_views < 0:
        raise NeuralaoError("views must be >= 1 and holdout_views >= 0")
    cams = orbit(scene, settings.views, w, h, settings.yfov_deg, seed=0)
    # A different phase (seed 1) and count: held-back cameras are never training cameras.
    hold_cams = (
        orbit(scene, settings.holdout_views, hw, hh, settings.yfov_deg, seed=1)
        if settings.holdout_views
        else []
    )
    labeller = Labeller(scene, settings.labels)
    parts, holdout, substituted = [], [], []
    t0 = time.perf_counter()
    with GBufferRenderer(scene) as renderer:
        for v, cam in enumerate(
            tqdm(cams, desc=f"samples {scene.name}", unit="view", disable=not progress, leave=False)
        ):
            frame = renderer.render(cam)
            rng = view_rng(settings.seed, v)
            candidates = rng.permutation(np.flatnonzero(frame["mask"].reshape(-1)))
            # Draw in order of a seeded permutation, labelling batches until samples_per_view are valid
            # (the back-face rule invalidates a few pixels on triangle soup; closed meshes: one batch).
            chosen, ao_parts, start = [], [], 0
            need = settings.samples_per_view
            while need > 0 and start < len(candidates):
                batch = np.sort(candidates[start : start + need])
                start += len(batch)
                ao, ok = label_pixels(labeller, frame, batch, frame_seed(settings.seed, 0, v))
                chosen.append(batch[ok])
                ao_parts.append(ao[ok])
                need -= int(ok.sum())
            pix = np.concatenate(chosen) if chosen else np.zeros(0, np.int64)
            if len(pix) == 0:
                continue
            rows, cols = np.divmod(pix, w)
            x, sub = circle_inputs(frame["normal_obj"], frame["mask"], rows, cols, settings.radius_px)
            centre = np.asarray(frame["normal_obj"], np.float32)[rows, cols]
            parts.append((x, centre, np.concatenate(ao_parts), v))
            substituted.append(sub.mean())
        t_samples = time.perf_counter() - t0
        for k, cam in enumerate(
            tqdm(hold_cams, desc=f"held-back {scene.name}", unit="view", disable=not progress, leave=False)
        ):
            frame = renderer.render(cam)
            labeller.settings = replace(settings.labels, seed=frame_seed(settings.seed, 1, k))
            frame["ao"], frame["valid"] = labeller.label_frame(frame)
            holdout.append(_eval_frame(frame, k))
    info = {
        "source": "mesh",
        "scene": scene.name,
        "mesh": str(mesh),
        "faces": int(len(scene.faces)),
        "size": [w, h],
        "holdout_size": [hw, hh],
        "labels": settings_to_dict(settings.labels),
        "substituted_fraction": float(np.mean(substituted)) if substituted else 0.0,
        "sampling_seconds": t_samples,
        "holdout_seconds": time.perf_counter() - t0 - t_samples,
    }
    return _finish(parts, holdout, settings, info)


# ----------------------------------------------------------------------------------------------- training


def _mse(model: nn.Module, x: torch.Tensor, y: torch.Tensor) -> float:
    with torch.no_grad():
        return float(torch.mean((model(x)[:, 0] - y) ** 2))


def train_model(samples: Samples, settings: MLPSettings, progress: bool = False) -> tuple[BakedMLP, dict]:
    """Train a fresh network on the train split with early stopping on the val split.

    Runs on ``settings.threads`` torch threads (restored afterwards). Returns the model (float32, eval
    mode, best-validation weights) and a history dict.
    """
    previous = torch.get_num_threads()
    if settings.threads > 0:
        torch.set_num_threads(settings.threads)
    try:
        return _train_model(samples, settings, progress)
    finally:
        torch.set_num_threads(previous)


def _train_model(samples: Samples, settings: MLPSettings, progress: bool) -> tuple[BakedMLP, dict]:
    if settings.max_iterations < 1 or settings.check_every < 1 or settings.patience < 1:
        raise NeuralaoError("max_iterations, check_every and patience must be >= 1")
    torch.manual_seed(settings.seed)
    model = BakedMLP(settings.hidden)
    dtype = torch.float64 if settings.train_dtype == "float64" else torch.float32
    xt, yt = (torch.from_numpy(a).to(dtype) for a in samples.part("train", settings.train_inputs))
    xv, yv = (torch.from_numpy(a).to(dtype) for a in samples.part("val", settings.train_inputs))
    if len(yt) == 0 or len(yv) == 0:
        raise NeuralaoError("the train and validation splits must both be non-empty")
    model = model.to(dtype)
    with torch.no_grad():  # start at the constant predictor: output bias = mean target
        model.net[-1].bias.fill_(float(yt.mean()))
    best = {
        "val_mse": _mse(model, xv, yv),
        "iteration": 0,
        "state": {k: v.clone() for k, v in model.state_dict().items()},
    }
    history: list[dict] = []
    fails = 0
    t0 = time.perf_counter()
    bar = tqdm(
        total=settings.max_iterations,
        desc=f"train {size_name(settings.hidden)}",
        unit="it",
        disable=not progress,
        leave=False,
    )

    def check(iteration: int, train_mse: float) -> bool:
        nonlocal fails
        val = _mse(model, xv, yv)
        history.append(
            {
                "iteration": iteration,
                "train_mse": train_mse,
                "val_mse": val,
                "seconds": time.perf_counter() - t0,
            }
        )
        bar.set_postfix(train=f"{math.sqrt(train_mse):.4f}", val=f"{math.sqrt(val):.4f}")
        if val < best["val_mse"] * (1 - 1e-6):
            best.update(
                val_mse=val, iteration=iteration, state={k: v.clone() for k, v in model.state_dict().items()}
            )
            fails = 0
        else:
            fails += 1
        return fails >= settings.patience

    iteration = 0
    if settings.optimizer == "lbfgs":
        opt = torch.optim.LBFGS(
            model.parameters(),
            lr=1.0,
            max_iter=settings.check_every,
            history_size=settings.lbfgs_history,
            line_search_fn="strong_wolfe",
            tolerance_grad=1e-12,
            tolerance_change=1e-15,
        )

        def closure() -> torch.Tensor:
            opt.zero_grad()
            loss = torch.mean((model(xt)[:, 0] - yt) ** 2)
            loss.backward()
            return loss

        first = opt.param_groups[0]["params"][0]  # L-BFGS keeps its global state on the first parameter
        while iteration < settings.max_iterations:
            before = opt.state[first].get("n_iter", 0)
            loss = float(opt.step(closure).detach())
            done = opt.state[first].get("n_iter", 0) - before
            iteration += max(done, 1)
            bar.update(max(done, 1))
            if check(iteration, loss) or done == 0:
                break
    else:
        opt = torch.optim.Adam(model.parameters(), lr=settings.adam_lr)
        gen = torch.Generator().manual_seed(settings.seed)
        n = len(yt)
        while iteration < settings.max_iterations:
            perm = torch.randperm(n, generator=gen)
            total = 0.0
            for lo in range(0, n, settings.adam_batch):
                idx = perm[lo : lo + settings.adam_batch]
                opt.zero_grad()
                loss = torch.mean((model(xt[idx])[:, 0] - yt[idx]) ** 2)
                loss.backward()
                opt.step()
                total += float(loss.detach()) * len(idx)
            iteration += 1
            bar.update(1)
            if check(iteration, total / n):
                break
    bar.close()
    model.load_state_dict(best["state"])
    model = model.to(torch.float32).eval()
    info = {
        "optimizer": settings.optimizer,
        "iterations": iteration,
        "best_iteration": best["iteration"],
        "stopped_early": fails >= settings.patience,
        "seconds": time.perf_counter() - t0,
        "history": history,
    }
    return model, info


# ----------------------------------------------------------------------------------------------- evaluation


def predict(model: BakedMLP, inputs: np.ndarray, batch: int = 1 << 16) -> np.ndarray:
    """Raw (unclamped) network output (n,) float32 for inputs (n, 48) float32."""
    model = model.eval()
    out = []
    with torch.no_grad():
        for lo in range(0, len(inputs), batch):
            out.append(
                model(torch.from_numpy(np.ascontiguousarray(inputs[lo : lo + batch], np.float32)))[
                    :, 0
                ].numpy()
            )
    return np.concatenate(out) if out else np.zeros(0, np.float32)


def predict_frame(
    model: BakedMLP, normal_obj: np.ndarray, mask: np.ndarray, radius: float = 0.0
) -> np.ndarray:
    """AO image of a frame: (H, W) float32 in [0, 1], 1 on background.

    radius 0 is the deployed input (centre normal repeated 16 times); radius > 0 the training circle.
    """
    mask = np.asarray(mask, dtype=bool)
    rows, cols = np.nonzero(mask)
    if radius > 0:
        x, _ = circle_inputs(normal_obj, mask, rows, cols, radius)
    else:
        x = radius_zero_inputs(np.asarray(normal_obj, np.float32)[rows, cols])
    ao = np.ones(mask.shape, dtype=np.float32)
    ao[rows, cols] = np.clip(predict(model, x), 0.0, 1.0)
    return ao


def evaluate_frames(model: BakedMLP | float, frames: list[FrameLike], radius: float = 0.0) -> dict:
    """Masked SSIM / RMSE (and whole-image SSIM) against ray-traced AO over valid foreground pixels,
    per frame and mean. ``model`` may be a number: the constant predictor (baseline)."""
    rows = []
    for f in frames:
        valid = np.asarray(f["valid"], dtype=bool) & np.asarray(f["mask"], dtype=bool)
        if not valid.any():
            continue
        if isinstance(model, BakedMLP):
            pred = predict_frame(model, f["normal_obj"], f["mask"], radius)
        else:
            pred = np.where(f["mask"], np.float32(model), np.float32(1.0))
        ref = np.asarray(f["ao"], dtype=np.float32)
        rows.append(
            {
                "view": int(f.get("view", -1)),
                "ssim": masked_ssim(pred, ref, valid),
                "rmse": masked_rmse(pred, ref, valid),
                "ssim_full": image_ssim(pred, ref),
            }
        )
    if not rows:
        return {"frames": 0, "ssim": None, "rmse": None, "ssim_full": None, "per_view": []}
    return {
        "frames": len(rows),
        **{k: float(np.mean([r[k] for r in rows])) for k in ("ssim", "rmse", "ssim_full")},
        "per_view": rows,
    }


def compute_metrics(model: BakedMLP, samples: Samples) -> dict:
    """Sample RMSE per split (training inputs), a constant predictor's test RMSE, held-back SSIM / RMSE."""
    out: dict = {}
    for name in SPLIT_NAMES:
        x, y = samples.part(name)
        out[f"{name}_rmse"] = float(np.sqrt(np.mean((predict(model, x) - y) ** 2))) if len(y) else None
        out[f"{name}_samples"] = int(len(y))
    x_test, y_test = samples.part("test")
    mean_train = float(samples.part("train")[1].mean())
    out["constant_test_rmse"] = float(np.sqrt(np.mean((y_test - mean_train) ** 2))) if len(y_test) else None
    zero = evaluate_frames(model, samples.holdout, 0.0)
    circle = evaluate_frames(model, samples.holdout, float(samples.info.get("radius_px", 10.0)))
    constant = evaluate_frames(mean_train, samples.holdout)
    out.update(
        holdout_frames=zero["frames"],
        holdout_ssim=zero["ssim"],
        holdout_rmse=zero["rmse"],
        holdout_ssim_full=zero["ssim_full"],
        holdout_per_view=zero["per_view"],
        holdout_ssim_r10=circle["ssim"],
        holdout_rmse_r10=circle["rmse"],
        holdout_constant_ssim=constant["ssim"],
        holdout_constant_rmse=constant["rmse"],
        ssim_window="gaussian 11, sigma 1.5, C1=1e-4, C2=9e-4, masked to valid foreground "
        "(holdout_ssim_full: whole image with background, for comparison with the paper only)",
        deployed_input=(
            "radius zero: the pixel's object-space normal repeated 16 times, output clamped to [0, 1]"
        ),
    )
    return out


# ----------------------------------------------------------------------------------------------- checkpoints


def make_checkpoint(
    model: BakedMLP, settings: MLPSettings, samples: Samples, metrics: dict, train_info: dict
) -> dict:
    return per_mesh_checkpoint(
        KIND,
        FORMAT_VERSION,
        model,
        model_args_dict(model),
        settings_to_dict(settings),
        samples.info,
        metrics,
        train_info,
        parameter_bytes(model),
    )


def load_checkpoint(path: str | Path) -> dict:
    """Load an MLP checkpoint with ``weights_only=True``; another kind or a corrupt file is a one-line
    error."""
    return _load_checkpoint(path, KIND, "an MLP", FORMAT_VERSION)


def model_from_checkpoint(ckpt: dict) -> BakedMLP:
    return restore_model(build_model, ckpt)


# ----------------------------------------------------------------------------------------------- driver


def check_counts(s: MLPSettings) -> None:
    """Every setting in its range and every count within what the machine can hold, before anything is
    rendered or allocated (neuralao.runtime.foundation.limits): the orbit's views and their samples, the
    view and held-back sizes, the batch, the network and the validation history; the circle, the field of
    view, the split, the optimiser's settings, seed and threads."""
    if not s.hidden or min(s.hidden) < 1:
        raise NeuralaoError(f"hidden must list positive widths, got {list(s.hidden)}")
    check_int_range("lbfgs_history", s.lbfgs_history, 1, MAX_CAP)
    for name in ("max_iterations", "check_every", "patience"):
        check_int_range(name, getattr(s, name), 1, MAX_CAP)
    check_int_range("holdout_views", s.holdout_views, 0, MAX_CAP)
    check_interval("radius_px", s.radius_px, 0.0, MAX_RADIUS_PX)
    check_yfov("yfov_deg", s.yfov_deg)
    check_lr("adam_lr", s.adam_lr)
    check_split(s.split)
    check_count(
        "views", s.views, bytes_each=4096 + SAMPLE_BYTES * max(s.samples_per_view, 1), each="a view's samples"
    )
    check_count(
        "samples_per_view",
        s.views * s.samples_per_view,
        bytes_each=SAMPLE_BYTES,
        each="per sample",
        shown=f"{s.samples_per_view} on {s.views} views",
    )
    check_pixels("size", *s.size)
    if s.holdout_views:
        check_pixels("holdout_size", *s.holdout_size, frames=s.holdout_views)
    check_count(
        "adam_batch", s.adam_batch, bytes_each=64 * (INPUTS + sum(s.hidden or [1])), each="per batch row"
    )
    check_count(
        "hidden",
        max(s.hidden or [1]) ** 2 * len(s.hidden or [1]) * max(s.lbfgs_history, 1),
        bytes_each=64,
        each="per weight and L-BFGS pair",
        shown=str(list(s.hidden)),
    )
    check_count(
        "max_iterations",
        s.max_iterations // max(s.check_every, 1) + 1,
        bytes_each=512,
        each="a validation record of the history",
        shown=str(s.max_iterations),
    )
    check_threads("threads", s.threads)
    check_seed("seed", s.seed)


def train(
    settings: MLPSettings,
    out: str | Path | None,
    data: str | Path | None = None,
    scene: str | None = None,
    mesh: str | Path | None = None,
    progress: bool = False,
    samples: Samples | None = None,
) -> dict:
    """Samples (dataset scene or mesh) -> trained network -> metrics -> checkpoint at ``out`` (atomic).

    ``samples`` may be passed in to train several sizes on the same samples. Returns the checkpoint dict.
    """
    check_counts(settings)
    if samples is None:
        if mesh is not None:
            samples = samples_from_mesh(mesh, settings, progress)
        elif data is not None and scene is not None:
            samples = samples_from_dataset(data, scene, settings, progress)
        else:
            raise NeuralaoError("give --data DIR --scene NAME, or --mesh PATH_OR_NAME")
    samples.info["radius_px"] = settings.radius_px
    model, train_info = train_model(samples, settings, progress)
    metrics = compute_metrics(model, samples)
    ckpt = make_checkpoint(model, settings, samples, metrics, train_info)
    if out is not None:
        save_checkpoint(out, ckpt)
    return ckpt
