"""How close screen-space AO could get to the ray-traced labels from what the screen holds: one depth layer
against two.

    PYOPENGL_PLATFORM=osmesa .venv/bin/python bench/ao_visibility_bound.py --config configs/eval.json \
        [--size 256 256] [--frames build/bench/error_bands/frames/256x256] [--march-rays 64] [--steps 32] \
        [--models runtime/models/unet-gtao] [--categories scans gltf ...] [--out build/bench/visibility_bound]

The frames are `neuralao evaluate`'s, built or resumed as bench/ao_error_bands.py builds them (the config's
categories at ``--size``, its rays and views; held-aside categories left out unless named with
``--include-held-aside``), under ``OUT/frames/<W>x<H>``, or read from ``--frames``: a finished dataset of
exactly that config (checked against its manifest, never rebuilt there). GTAO and each U-Net export are
scored as evaluate scores them, over the valid foreground pixels of each (frame, radius) pair.

The AO estimator is the labels' (pipeline/tracing/labeller.py, the dataset's ``labels`` settings): binary
kernel, a ray is blocked when something lies within the radius (``radii_rel`` x the scene's diagonal, the
labels' ``radii``), ``ao = 1 - blocked / N``; rays from the labels' surface point of the pixel (the
pixel-centre camera ray on the plane of ``tri_id``, :meth:`Labeller.visible_points`) offset by
``offset_rel`` along the camera-facing geometric normal, directions the labeller's own cosine-weighted
Hammersley set with its per-pixel shifts (:meth:`Labeller.rays` with ``--march-rays`` rays and the frame's
label seed). Back-facing hits count as hits, as in the labels; the back-face rule decides only which
pixels are valid, and the labels' ``valid_radii`` mask is the one every method is scored on.

Instead of the mesh, a ray meets what the screen holds. Each ray is sampled at ``--steps`` points per
radius, one per stratum of [0, radius] (``t_k = radius (k + u) / S``, ``u`` one jitter per pixel and ray,
seeded); each sample is looked up in the pixel it projects to (nearest pixel; off screen or behind the
camera: unoccluded, and counted). A pixel's layers are planes in camera space: the *front* is the plane of
its visible triangle (exact for the flat facets a mesh is made of: a sample over a flat surface is never
behind it, so there is no self-occlusion bias to tune away), and is where the camera ray through the
sample meets it. Variants (``s_f`` < 0: the sample is behind the front layer along its camera ray):

* ``1L-inf``: one layer, infinite thickness (the height-field assumption): occluded when behind the front.
* ``1L-inf-px``: the same against the pixel-centre depth of the G-buffer (``depth``), the literal
  depth-buffer test with no bias: a sample near a surface seen at an angle lies behind the depth of the
  pixel centre it rounds to (self-occlusion); beyond the two pixels around the origin that no variant
  looks up (below) it comes within 0.01 of ``1L-inf``.
* ``1L-T=r``, ``1L-T=r/4``: one layer of thickness T (the radius, a quarter of it): behind the front by
  less than T in view depth (the front plane shifted by T along the pixel's camera ray).
* ``2L-thin``, ``2L-inf``: two layers: occluded between the front and the *back* layer (Embree on the
  labels' scene, camera rays through the pixel centres, from the front surface on): the plane of the first
  triangle behind the front that faces the camera ray the other way from the front triangle, i.e. the
  first back-facing one (``dot(ray, n) > 0``) behind a front-facing front, and the first front-facing one
  behind a back-facing front (a closed mesh wound inwards: the dataset's horse is): where the camera ray
  leaves the solid it entered. A pixel with none (an open, single-sided surface with nothing behind) is
  *open*: ``2L-thin`` gives it a back layer ``--open-eps`` x diagonal behind the front (a sheet),
  ``2L-inf`` infinite thickness (as ``1L-inf``).
* ``2L-next``: the back layer is the very next triangle behind the front if it faces the other way, else
  the pixel is open (thin): a sheet in front of another part stays a sheet instead of a slab reaching that
  part's far side, but a part inside another (intersecting shells) turns thin. The two rules bracket
  what a back-face layer can be on meshes that are not clean closed solids (glTF assets).

Near the origin the screen cannot resolve the surface: a pixel's facet plane extended across a pixel or
two misplaces it by more than a sample's height above it, and such false hits grew with the step count
(2L against the same rays on the mesh, lucy at the smallest radius: RMSE 0.046 / 0.062 / 0.074 / 0.080 at
16 / 32 / 64 / 128 steps). Samples within ``--near-px`` (2) pixel footprints of the origin (at its depth)
are therefore not looked up (0.036-0.037 at every step count); a ray that enters something there is caught by
the next sample looked up, inside it or by the crossing test with the origin as the previous sample.

Finite layers are also crossed between samples: a sample counts when the previous sample lies in front of
its pixel's front plane and it lies behind that pixel's back plane (the ray passed through the slab
between two samples), so a thin part is not missed for falling between steps. A sheet crossed while the
samples round to another pixel (a ray from a floor into the single-quad wall beside it, at the crease)
is still missed by ``2L-thin``; ``2L-inf`` keeps such walls solid.

Step choice: ``--steps 32`` per ray and radius (each radius marched on its own, so the smallest gets as
many as the largest: a step is radius / 32, under a pixel's footprint at the two smaller radii and a few
pixels at the largest on the interiors) and ``--march-rays 64``: a 256x256 interior frame (65k
foreground pixels, 4 radii, 0.5G samples) takes 25-40 s on one core, an orbit frame 4-15 s. With 64
steps the orbit categories' ratios move by at most 0.03.

``mesh@N`` is Embree with the very same N rays per pixel against the mesh (the labels' estimator at N
rays; the marched rays' own Embree hits are checked to give exactly :meth:`Labeller.ao_radii_at_points`):
its RMSE against the labels is the Monte Carlo floor of every variant, and a variant's RMSE against it
(``visibility error``) is what the screen alone gets wrong, free of ray noise. ``<variant>+os`` is the
off-screen oracle: a ray that leaves the screen (a sample off screen or behind the camera) before the
variant finds it blocked takes the mesh's answer for that very ray, so it separates what the screen
holds from what lies outside it. Validation: the front plane's depth must agree with the G-buffer's and
with Embree's first hit from the camera (reported on the foreground), and on the interior categories,
where little is hidden, the variants with the off-screen oracle must come close to ``mesh@N``.
tests/test_ao_visibility_bound.py checks the marcher against closed forms.

Reported per category and per group (``orbit cameras`` = the isolated objects, ``interior cameras``):
each method's RMSE against the labels as a ratio to GTAO's (pooled over pixels; in brackets as evaluate
averages, the mean over (frame, radius) pairs of each pair's RMSE), the same per radius, the visibility
error, the share of ray samples that land off screen and of rays that leave the screen before ``1L-inf``
finds them blocked, and the share of open pixels. Writes OUT/visibility_bound.json (every pair's sums,
the summary, the settings, per-frame checks and timings) and OUT/visibility_bound.md, and prints the
markdown.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import logging
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from neuralao.pipeline.datasets.dataset import (
    _config_dict,
    expand_scenes,
    frame_seed,
    open_dataset,
    scene_of,
)
from neuralao.pipeline.evaluation.categories import (
    EvalSettings,
    baseline_predictors,
    category_of,
    check_frames,
    dataset_settings,
    ensure_frames,
    unet_predictors,
)
from neuralao.pipeline.geometry.camera import Camera
from neuralao.pipeline.geometry.sequences import sample_shifts
from neuralao.pipeline.tracing.labeller import Labeller, pixel_directions
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json, write_text
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.settings import load_settings, settings_to_dict


def _sibling(name: str):
    """A script beside this one, as a module (bench/ is no package)."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parent / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_bands = _sibling("ao_error_bands")
select_categories = _bands.select_categories

log = logging.getLogger(__name__)

VARIANTS = ("1L-inf", "1L-inf-px", "1L-T=r", "1L-T=r/4", "2L-thin", "2L-inf", "2L-next")
ORACLE = "+os"  # suffix of a variant whose rays that leave the screen unresolved take the mesh's answer
DEFAULT_OPEN_EPS = 1e-4  # an open surface's back layer behind its front, x diagonal (2L-thin)
# Samples nearer the ray's origin than this many pixel footprints (at the origin's depth) are not looked up:
# the screen cannot resolve them (see the module doc).
DEFAULT_NEAR_PX = 2.0
PEEL_EPS = 1e-5  # a camera ray restarts this far (x diagonal) past a hit to find the next (labeller's offset)
MAX_PEELS = 64  # front-facing hits passed before a pixel with no exit yet counts as open
CHUNK_RAYS = 1 << 16  # rays marched together: arrays of a few hundred KB, numpy overhead < 1%
GOLDEN = 0.6180339887498949  # a pixel's rays' step jitters: its shift + i * GOLDEN (mod 1), stratified
JITTER_SALT = 0x5EED_0F_57E95  # the jitter's seed differs from the directions' (same frame seed)

# Columns of the per-pixel layer table (camera space, local units = scene units / diagonal): the front
# plane, the back plane of the exit rule and its open flag, the pixel-centre depth, the gain, and the back
# plane and open flag of the next-hit rule.
_FRONT, _BACK, _OPEN, _DEPTH, _GAIN, _NEXT, _NEXT_OPEN = slice(0, 4), slice(4, 8), 8, 9, 10, slice(11, 15), 15
_COLUMNS = 16


# ------------------------------------------------------------------------------------------ layers


@dataclass
class Screen:
    """What the screen holds, camera space (OpenGL: -z forward), local units (scene units / diagonal).

    table : (H * W + 1, 16) float32 per pixel (row-major, row 0 at the top), and a last row for "nothing"
    (background, off screen): front plane (n, c), back plane (n, c) and open flag of the exit rule,
    pixel-centre depth, gain, back plane and open flag of the next-hit rule (an open pixel's back plane is
    its front ``open_eps`` deeper). A plane's signed side is ``s(y) = n . y - c``, positive on the
    camera's side. ``gain`` = ``|n . q|`` with q the pixel-centre camera ray scaled to depth 1: the front
    plane shifted T deeper along that ray is ``s + T gain``. Background and the last row: ``n = 0,
    c = -1`` (everything in front), depth inf.
    """

    width: int
    height: int
    yfov: float  # radians
    table: np.ndarray

    @property
    def nothing(self) -> int:
        return self.width * self.height


def pixel_rays_cam(width: int, height: int, yfov: float, pix: np.ndarray) -> np.ndarray:
    """Camera-space pixel-centre rays scaled to depth 1, (k, 3) float64 ``(x, y, -1)``, of flat pixels."""
    row, col = np.divmod(np.asarray(pix, np.int64), width)
    t = math.tan(yfov / 2.0)
    x = ((col + 0.5) / width * 2.0 - 1.0) * t * (width / height)
    y = (1.0 - (row + 0.5) / height * 2.0) * t
    return np.stack([x, y, -np.ones_like(x)], axis=1)


def camera_planes(normals: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(k, 4) float64 planes (n, c) through camera-space ``points`` with unit ``normals`` (k, 3), oriented
    so the camera (the origin) is on the positive side (``c <= 0``)."""
    c = np.sum(normals * points, axis=1)
    flip = np.where(c > 0, -1.0, 1.0)
    return np.concatenate([normals * flip[:, None], (c * flip)[:, None]], axis=1)


def screen_table(
    width: int,
    height: int,
    yfov: float,
    pix: np.ndarray,
    front: np.ndarray,
    depth: np.ndarray,
    back: np.ndarray | None,
    open_eps: float,
    next_back: np.ndarray | None = None,
) -> Screen:
    """The layer table of a frame: foreground pixels ``pix`` (k,), their front planes (k, 4) (camera side
    positive), pixel-centre depths (k,) and back planes (k, 4) of the exit rule and of the next-hit rule
    (``next_back``; None: the exit rule's), NaN rows where a pixel is open (``back`` None: all open)."""
    q = pixel_rays_cam(width, height, yfov, pix)
    gain = np.abs(np.sum(front[:, :3] * q, axis=1))
    sheet = front.copy()
    sheet[:, 3] -= open_eps * gain  # s_back = s_front + open_eps * gain
    table = np.zeros((width * height + 1, _COLUMNS), np.float64)
    table[:, [3, 7, 14]] = -1.0  # nothing: every point in front of every plane
    table[:, _DEPTH] = np.inf
    table[pix, _FRONT] = front
    table[pix, _DEPTH] = depth
    table[pix, _GAIN] = gain
    back = np.full_like(front, np.nan) if back is None else back
    for planes, col, flag in (
        (back, _BACK, _OPEN),
        (back if next_back is None else next_back, _NEXT, _NEXT_OPEN),
    ):
        is_open = ~np.isfinite(planes).all(axis=1)
        table[pix, col] = np.where(is_open[:, None], sheet, planes)
        table[pix, flag] = is_open
    return Screen(width, height, float(yfov), table.astype(np.float32))


@dataclass
class FrameLayers:
    """A dataset frame's screen (:class:`Screen`), the labels' surface points, and the checks."""

    screen: Screen
    points: np.ndarray  # (k, 3) world, the labels' points of the foreground pixels
    normals: np.ndarray  # (k, 3) unit, camera facing
    pix: np.ndarray  # (k,) flat pixel indices
    to_cam: np.ndarray  # (3, 3) local -> camera rotation (right-multiply row vectors)
    cam_local: np.ndarray  # (3,) camera position in local units
    checks: dict


def _cast(labeller: Labeller, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest hits of rays (local units): prim (n,) int (-1: none), t (n,) float64."""
    dists = np.full(len(origins), 1e6, np.float32)
    out = labeller.embree.run(
        np.ascontiguousarray(origins, np.float32),
        np.ascontiguousarray(dirs, np.float32),
        query="INTERSECT",
        dists=dists,
        output=1,
    )
    return np.asarray(out["primID"]).astype(np.int64), np.asarray(out["tfar"], np.float64)


def depth_planes(depth: np.ndarray, yfov: float, pix: np.ndarray, mode: str) -> np.ndarray:
    """(k, 4) camera-space front planes of the foreground pixels ``pix`` rebuilt from the depth buffer alone
    (``depth`` (H, W) local units, NaN on background), as a pass that reads only the depth could rebuild them.

    ``depth``: through the pixel-centre point, with the normal of the facet its neighbours show (in x and in
    y the neighbour whose depth is nearer the pixel's, the other one where that is background; a pixel with
    no foreground neighbour on an axis takes the camera-facing plane's axis); ``center``: the plane of
    constant depth through it (the depth test of a depth buffer, with a crossing test)."""
    h, w = depth.shape
    row, col = np.divmod(np.asarray(pix, np.int64), w)
    rays = pixel_rays_cam(w, h, yfov, np.arange(h * w)).reshape(h, w, 3)
    pos = rays * depth[..., None]  # camera space; NaN on background
    p = pos[row, col]
    if mode == "center":
        normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), p.shape).copy()
        return camera_planes(normals, p)

    def side(dr: int, dc: int) -> tuple[np.ndarray, np.ndarray]:
        r = np.clip(row + dr, 0, h - 1)
        c = np.clip(col + dc, 0, w - 1)
        inside = (row + dr >= 0) & (row + dr < h) & (col + dc >= 0) & (col + dc < w)
        q = pos[r, c]
        ok = inside & np.isfinite(q).all(axis=1)
        return q, ok

    def axis(plus, minus, sign):
        (qp, okp), (qm, okm) = plus, minus
        dp = np.where(okp, np.abs(qp[:, 2] - p[:, 2]), np.inf)
        dm = np.where(okm, np.abs(qm[:, 2] - p[:, 2]), np.inf)
        use_p = dp <= dm
        d = np.where(use_p[:, None], qp - p, p - qm)
        none = ~(okp | okm)
        return np.where(none[:, None], sign, d)

    dx = axis(side(0, 1), side(0, -1), np.array([1.0, 0.0, 0.0]))
    dy = axis(side(-1, 0), side(1, 0), np.array([0.0, 1.0, 0.0]))  # row - 1 is up (+y)
    n = np.cross(dx, dy)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1.0), np.array([0.0, 0.0, 1.0]))
    return camera_planes(n, p)


FRONTS = ("exact", "depth", "center")


def frame_layers(
    labeller: Labeller,
    face_normals: np.ndarray,
    frame,
    open_eps: float = DEFAULT_OPEN_EPS,
    front_mode: str = "exact",
) -> FrameLayers:
    """The front layer of a frame from its G-buffer (``tri_id``: the labels' surface, the plane of the
    visible triangle; ``depth``: the pixel-centre depths), the back layers from Embree (camera rays through
    the pixel centres, from the front surface on), and the agreement of the front with Embree's first hit
    from the camera and with the G-buffer depth.

    Exit rule: the back layer is the first triangle behind the front that faces the camera ray the other
    way from the front triangle (``dot(ray, n) > 0`` behind a front with ``dot(ray, n) < 0``: where the ray
    leaves the solid it entered, for a closed mesh of either winding); none: open. Next-hit rule: the very
    next triangle behind the front, if it faces the other way; else (it enters another surface first, as
    behind a sheet) open."""
    scene = labeller.scene
    tri_id = np.asarray(frame["tri_id"])
    h, w = tri_id.shape
    pose = np.asarray(frame["pose"], np.float64)
    yfov = float(frame["yfov"])
    points, normals, pix, exact = labeller.visible_points(frame)
    d = pixel_directions(Camera(pose, w, h, yfov), pix)  # world unit directions
    scale, center = labeller.scale, labeller.center
    cam_local = (pose[:3, 3] - center) / scale
    rot = pose[:3, :3]  # camera -> world; local -> camera of a row vector v: v @ rot
    tri = tri_id.reshape(-1)[pix].astype(np.int64)
    t_front = np.sum((points - pose[:3, 3]) * d, axis=1) / scale  # local units along the ray

    # Front: the visible triangle's plane, camera space.
    faces = np.asarray(scene.faces, np.int64)
    verts = np.asarray(scene.vertices, np.float64)

    def planes(prims: np.ndarray) -> np.ndarray:
        v0 = ((verts[faces[prims, 0]] - center) / scale - cam_local) @ rot
        return camera_planes(face_normals[prims] @ rot, v0)

    front = planes(tri)
    d_cam = d @ rot
    depth_gbuffer = np.asarray(frame["depth"], np.float64).reshape(-1)[pix] / scale
    depth_front = t_front * -d_cam[:, 2]

    # Embree's first hit from the camera: the front must agree.
    prim0, t0 = _cast(labeller, np.broadcast_to(cam_local, d.shape), d)
    hit0 = prim0 >= 0
    rel_embree = np.where(hit0, np.abs(t0 - t_front) / t_front, np.inf)
    rel_gbuffer = np.abs(depth_gbuffer - depth_front) / depth_front

    # Back: the first triangle behind the front facing the ray the other way (and the very next one).
    facing = lambda prims, dirs: np.sum(face_normals[prims] * dirs, axis=1) > 0  # noqa: E731
    front_back = facing(tri, d)  # the front seen from its back side (an inward-wound mesh, a sheet)
    exit_t = np.full(len(pix), np.nan)
    exit_prim = np.full(len(pix), -1, np.int64)
    next_prim = np.full(len(pix), -1, np.int64)
    active = np.ones(len(pix), bool)
    t_cur = t_front.copy()
    for peel in range(MAX_PEELS):
        idx = np.flatnonzero(active)
        if not len(idx):
            break
        start = t_cur[idx] + PEEL_EPS
        prim, t = _cast(labeller, cam_local + start[:, None] * d[idx], d[idx])
        miss = prim < 0
        active[idx[miss]] = False
        hit = np.flatnonzero(~miss)
        other = facing(prim[hit], d[idx[hit]]) != front_back[idx[hit]]
        done = idx[hit[other]]
        exit_t[done] = start[hit[other]] + t[hit[other]]
        exit_prim[done] = prim[hit[other]]
        if peel == 0:
            next_prim[done] = prim[hit[other]]
        active[done] = False
        t_cur[idx[hit[~other]]] = start[hit[~other]] + t[hit[~other]]
    closed = exit_prim >= 0
    back_planes = np.full((len(pix), 4), np.nan)
    back_planes[closed] = planes(exit_prim[closed])
    next_planes = np.full((len(pix), 4), np.nan)
    next_planes[next_prim >= 0] = planes(next_prim[next_prim >= 0])

    if front_mode != "exact":
        image = np.full(h * w, np.nan)
        image[pix] = depth_gbuffer
        front = depth_planes(image.reshape(h, w), yfov, pix, front_mode)
    screen = screen_table(w, h, yfov, pix, front, depth_gbuffer, back_planes, open_eps, next_planes)
    fg = exact & hit0
    checks = {
        "pixels": int(len(pix)),
        "inexact": int(np.count_nonzero(~exact)),
        "embree_same_triangle": float(np.mean(prim0 == tri)) if len(pix) else float("nan"),
        "embree_rel_depth_median": float(np.median(rel_embree[fg])) if fg.any() else float("nan"),
        "embree_rel_depth_p99": float(np.quantile(rel_embree[fg], 0.99)) if fg.any() else float("nan"),
        "embree_within_1e-4": float(np.mean(rel_embree <= 1e-4)) if len(pix) else float("nan"),
        "gbuffer_rel_depth_median": float(np.median(rel_gbuffer[exact])) if exact.any() else float("nan"),
        "gbuffer_rel_depth_p99": float(np.quantile(rel_gbuffer[exact], 0.99))
        if exact.any()
        else float("nan"),
        "gbuffer_within_1e-3": float(np.mean(rel_gbuffer <= 1e-3)) if len(pix) else float("nan"),
        "open": float(np.mean(~closed)) if len(pix) else float("nan"),
        "next_open": float(np.mean(next_prim < 0)) if len(pix) else float("nan"),
        "front_backfacing": float(np.mean(front_back)) if len(pix) else float("nan"),
        "thickness_median": float(np.median((exit_t - t_front)[closed])) if closed.any() else float("nan"),
    }
    return FrameLayers(screen, points, normals, pix, rot, cam_local, checks)


# ------------------------------------------------------------------------------------------ marcher


def step_jitter(seed: int, ids: np.ndarray, rays: int) -> np.ndarray:
    """(n, rays) float32 in [0, 1): the offset of each ray's samples within their strata, one shift per
    pixel (hashed from seed and id) spread over its rays by the golden ratio (stratified, seeded)."""
    shift, _ = sample_shifts((int(seed) ^ JITTER_SALT) & 0x7FFFFFFFFFFFFFFF, ids)
    return np.mod(shift[:, None] + np.arange(rays)[None, :] * GOLDEN, 1.0).astype(np.float32)


def march(
    screen: Screen,
    origins: np.ndarray,
    dirs: np.ndarray,
    jitter: np.ndarray,
    radius: float,
    steps: int,
    mesh_blocked: np.ndarray | None = None,
    near_px: float = DEFAULT_NEAR_PX,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """Binary AO of every variant of :data:`VARIANTS` from rays marched against a screen.

    origins : (n, 3) camera-space ray origins (local units); dirs : (n, R, 3) unit directions; jitter :
    (n, R) in [0, 1); radius : local units; steps : samples per ray, ``t_k = radius (k + u) / steps``;
    mesh_blocked : (n, R) bool, the same rays against the mesh (optional); near_px : samples within this
    many pixel footprints (at the origin's depth) of the origin are not looked up (the next one looked up
    has the origin as its previous sample for the crossing test).
    Returns ao (n, V) float64 (1 - blocked rays / R); with ``mesh_blocked`` the off-screen oracle (n, V):
    a ray that leaves the screen before the variant finds it blocked takes the mesh's answer, else None;
    offscreen (n,): samples that projected off screen or behind the camera; left (n,): rays with such a
    sample before 1L-inf found them blocked.
    """
    n, rays = dirs.shape[:2]
    w, h = screen.width, screen.height
    t = math.tan(screen.yfov / 2.0)
    kx, ky = np.float32(0.5 * w / (t * w / h)), np.float32(0.5 * h / t)
    table = screen.table
    blocked = np.zeros((len(VARIANTS), n), np.int64)
    oracle = np.zeros((len(VARIANTS), n), np.int64)
    offscreen = np.zeros(n, np.int64)
    left = np.zeros(n, np.int64)
    per = max(1, CHUNK_RAYS // rays)
    thick = (np.float32(radius), np.float32(radius / 4))
    for lo in range(0, n, per):
        hi = min(n, lo + per)
        m = (hi - lo) * rays
        o = np.repeat(origins[lo:hi].astype(np.float32), rays, axis=0)
        dv = dirs[lo:hi].reshape(m, 3).astype(np.float32)
        u = jitter[lo:hi].reshape(m).astype(np.float32)
        hit = np.zeros((len(VARIANTS), m), bool)
        off = np.zeros(m, np.int64)
        gone = np.zeros((len(VARIANTS), m), bool)
        prev = o.copy()
        inv = np.empty(m, np.float32)
        near = np.float32(near_px * 2.0 * t / h) * -o[:, 2]  # near_px pixel footprints at the origin
        for k in range(steps):
            tk = (np.float32(k) + u) * np.float32(radius / steps)
            x = o + tk[:, None] * dv
            far = tk >= near
            z = x[:, 2]
            ahead = z < 0
            inv.fill(0)
            np.divide(np.float32(-1), z, out=inv, where=ahead)
            colf = (x[:, 0] * inv) * kx + np.float32(0.5 * w)
            rowf = np.float32(0.5 * h) - (x[:, 1] * inv) * ky
            on = ahead & (colf >= 0) & (colf < w) & (rowf >= 0) & (rowf < h)
            tested = on & far
            idx = np.where(
                tested,
                np.clip(rowf, 0, h - 1).astype(np.int64) * w + np.clip(colf, 0, w - 1).astype(np.int64),
                screen.nothing,
            )
            lay = table[idx]
            s_f = lay[:, 0] * x[:, 0] + lay[:, 1] * x[:, 1] + lay[:, 2] * x[:, 2] - lay[:, 3]
            s_b = lay[:, 4] * x[:, 0] + lay[:, 5] * x[:, 1] + lay[:, 6] * x[:, 2] - lay[:, 7]
            s_n = lay[:, 11] * x[:, 0] + lay[:, 12] * x[:, 1] + lay[:, 13] * x[:, 2] - lay[:, 14]
            s_p = lay[:, 0] * prev[:, 0] + lay[:, 1] * prev[:, 1] + lay[:, 2] * prev[:, 2] - lay[:, 3]
            behind = s_f < 0
            crossed = s_p > 0  # the previous sample was in front of this pixel's front plane
            gain = lay[:, _GAIN]
            gone |= ~on[None, :] & ~hit
            hit[0] |= behind
            hit[1] |= tested & (-z > lay[:, _DEPTH])
            hit[2] |= behind & ((s_f > -thick[0] * gain) | crossed)
            hit[3] |= behind & ((s_f > -thick[1] * gain) | crossed)
            slab = behind & ((s_b > 0) | crossed)
            hit[4] |= slab
            hit[5] |= slab | (behind & (lay[:, _OPEN] > 0))
            hit[6] |= behind & ((s_n > 0) | crossed)
            off += ~on
            prev = np.where(far[:, None], x, prev)
        blocked[:, lo:hi] = hit.reshape(len(VARIANTS), hi - lo, rays).sum(axis=2)
        offscreen[lo:hi] = off.reshape(hi - lo, rays).sum(axis=1)
        left[lo:hi] = gone[0].reshape(hi - lo, rays).sum(axis=1)
        if mesh_blocked is not None:
            mesh = mesh_blocked[lo:hi].reshape(1, m)
            oracle[:, lo:hi] = np.where(gone, mesh, hit).reshape(len(VARIANTS), hi - lo, rays).sum(axis=2)
    ao_oracle = None if mesh_blocked is None else 1.0 - oracle.T / rays
    return 1.0 - blocked.T / rays, ao_oracle, offscreen, left


def frame_rays(
    labeller: Labeller, layers: FrameLayers, sel: np.ndarray, radii: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The labeller's rays of the foreground pixels ``sel`` (indices into ``layers.pix``) in camera space:
    origins (n, 3) (the surface point, offset along the normal) and directions (n, R, 3); with ``radii``
    (k,) scene units also whether each ray is blocked by the mesh within each radius, (n, R, k) bool,
    traced as :meth:`Labeller.ao_radii_at_points` traces them (one INTERSECT to the largest radius in
    float32 local units, blocked at r iff a hit at t <= r)."""
    rays = labeller.settings.rays
    org, dirs = labeller.rays(layers.points[sel], layers.normals[sel], ids=layers.pix[sel])
    blocked = None
    if radii is not None:
        r_local = np.array([np.float32(r / labeller.scale) for r in radii], np.float32)
        blocked = np.zeros((len(org), len(r_local)), bool)
        for lo in range(0, len(org), CHUNK_RAYS * 4):
            hi = min(len(org), lo + CHUNK_RAYS * 4)
            dists = np.full(hi - lo, r_local.max(), np.float32)
            out = labeller.embree.run(org[lo:hi], dirs[lo:hi], query="INTERSECT", dists=dists, output=1)
            hit = np.asarray(out["primID"]) >= 0
            blocked[lo:hi] = hit[:, None] & (np.asarray(out["tfar"], np.float32)[:, None] <= r_local[None, :])
        blocked = blocked.reshape(len(sel), rays, len(r_local))
    org = (org[::rays].astype(np.float64) - layers.cam_local) @ layers.to_cam
    dirs = dirs.astype(np.float64).reshape(len(sel), rays, 3) @ layers.to_cam
    return org, dirs, blocked


# ------------------------------------------------------------------------------------------ summary


def summarise(rows: list[dict], methods: list[str], groups: dict[str, list[str]], reference: str) -> dict:
    """pool (category, group of categories, ``all``) -> method -> pooled and per-pair RMSE, and their
    ratios to ``reference``'s (rows: category, method, se, n of one (frame, radius) pair)."""
    cats = sorted({r["category"] for r in rows})
    pools = {c: [c] for c in cats} | {g: cs for g, cs in groups.items() if len(cs) > 1}
    if len(cats) > 1:
        pools["all"] = cats
    out: dict[str, dict] = {}
    for pool, members in pools.items():
        out[pool] = {}
        for m in methods:
            sel = [r for r in rows if r["method"] == m and r["category"] in members]
            if not sel:
                continue
            se = float(sum(r["se"] for r in sel))
            n = int(sum(r["n"] for r in sel))
            out[pool][m] = {
                "pairs": len(sel),
                "pixels": n,
                "rmse": math.sqrt(se / n),
                "eval_rmse": float(np.mean([math.sqrt(r["se"] / r["n"]) for r in sel])),
            }
        ref = out[pool].get(reference)
        if ref is not None:
            for fig in out[pool].values():
                fig["ratio"] = fig["rmse"] / ref["rmse"]
                fig["eval_ratio"] = fig["eval_rmse"] / ref["eval_rmse"]
    return out


def pooled_shares(stats: list[dict], groups: dict[str, list[str]]) -> dict:
    """pool -> off-screen sample share, left-the-screen ray share, open-pixel share, front checks."""
    cats = sorted({s["category"] for s in stats})
    pools = {c: [c] for c in cats} | {g: cs for g, cs in groups.items() if len(cs) > 1}
    if len(cats) > 1:
        pools["all"] = cats
    out = {}
    for pool, members in pools.items():
        sel = [s for s in stats if s["category"] in members]
        samples = sum(s["samples"] for s in sel)
        rays = sum(s["rays"] for s in sel)
        px = [s for s in sel if s["radius"] == 0]
        checks = [s["checks"] for s in px]
        fg = sum(c["pixels"] for c in checks)

        def wmean(key, checks=checks, fg=fg):
            return float(sum(c[key] * c["pixels"] for c in checks if math.isfinite(c[key])) / max(fg, 1))

        out[pool] = {
            "offscreen_samples": sum(s["offscreen"] for s in sel) / max(samples, 1),
            "left_rays": sum(s["left"] for s in sel) / max(rays, 1),
            "open_pixels": wmean("open"),
            "next_open_pixels": wmean("next_open"),
            "mesh_per_ray_max_diff": max((c["mesh_per_ray_max_diff"] for c in checks), default=float("nan")),
            "front_backfacing": wmean("front_backfacing"),
            "embree_same_triangle": wmean("embree_same_triangle"),
            "embree_within_1e-4": wmean("embree_within_1e-4"),
            "gbuffer_within_1e-3": wmean("gbuffer_within_1e-3"),
            "embree_rel_depth_p99_max": max(
                (c["embree_rel_depth_p99"] for c in checks), default=float("nan")
            ),
            "gbuffer_rel_depth_p99_max": max(
                (c["gbuffer_rel_depth_p99"] for c in checks), default=float("nan")
            ),
            "per_radius_offscreen": {
                j: sum(s["offscreen"] for s in sel if s["radius"] == j)
                / max(sum(s["samples"] for s in sel if s["radius"] == j), 1)
                for j in sorted({s["radius"] for s in sel})
            },
        }
    return out


def markdown(summary: dict, vis: dict, per_radius: dict, shares: dict, methods: list[str], mesh: str) -> str:
    f3 = lambda v: f"{v:.3f}"  # noqa: E731
    pct = lambda v: f"{100 * v:.1f}%"  # noqa: E731
    pools = list(summary)

    def table(cols: list[str], cell) -> list[str]:
        out = ["| method | " + " | ".join(cols) + " |", "|---|" + "---:|" * len(cols)]
        for m in methods:
            cells = [cell(m, c) for c in cols]
            if any(cells):
                out.append(f"| {m} | " + " | ".join(cells) + " |")
        return out

    def fig(src: dict, key: str, m: str, c: str) -> str:
        v = src.get(c, {}).get(m, {}).get(key)
        return "" if v is None else f3(v)

    lines = [
        "### RMSE against the labels as a ratio to GTAO's",
        "",
        "Pooled over the valid foreground pixels of every (frame, radius) pair; in brackets as evaluate "
        "averages (mean over pairs of each pair's RMSE). 1L: one depth layer (inf: infinite thickness, "
        "px: against the pixel-centre depth, T: thickness); 2L: front and back layer (open surfaces thin / "
        f"infinite; next: the very next hit); {mesh}: the same rays against the mesh (the Monte Carlo "
        f"floor); {ORACLE}: rays that leave the screen before the variant resolves them take the mesh's "
        "answer (what the screen holds, with nothing off screen).",
        "",
        *table(
            pools,
            lambda m, c: (
                f"{fig(summary, 'ratio', m, c)} ({fig(summary, 'eval_ratio', m, c)})"
                if m in summary[c] and "ratio" in summary[c][m]
                else ""
            ),
        ),
        "",
        "### RMSE against the labels",
        "",
        *table(pools, lambda m, c: fig(summary, "rmse", m, c)),
    ]
    for pool in [p for p in ("orbit cameras", "interior cameras") if p in pools] or pools:
        radii = list(per_radius)
        lines += [
            "",
            f"### Ratio to GTAO per radius (x diagonal), {pool} (pooled)",
            "",
            *table(radii, lambda m, r, pool=pool: fig(per_radius[r], "ratio", m, pool)),
        ]
    lines += [
        "",
        f"### Visibility error: RMSE against {mesh} (the same rays against the mesh)",
        "",
        "What the screen alone gets wrong, free of ray noise (GTAO and the U-Net for scale).",
        "",
        *table(pools, lambda m, c: fig(vis, "rmse", m, c)),
        "",
        "### What the screen holds",
        "",
        "off screen: ray samples (all radii; per radius) that project off screen or behind the camera; "
        "left: rays that do so before 1L-inf finds them blocked; open: foreground pixels with no exit "
        "behind the front (exit rule / next-hit rule); backfacing: fronts seen from their back side; "
        "front checks: foreground pixels whose Embree first hit from the camera is the G-buffer's "
        "triangle / lies within 1e-4 (relative depth) of the front plane, and whose G-buffer depth lies "
        f"within 1e-3 of it; rays: largest difference between {mesh} from the marched rays' own Embree "
        "hits and the labeller's AO at those rays (0: the marched rays are the labeller's).",
        "",
        "| pool | off screen | per radius | left | open | next open | backfacing | Embree same tri "
        "| Embree depth | G-buffer depth | rays |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for pool, s in shares.items():
        per = " / ".join(pct(v) for v in s["per_radius_offscreen"].values())
        lines.append(
            f"| {pool} | {pct(s['offscreen_samples'])} | {per} | {pct(s['left_rays'])} "
            f"| {pct(s['open_pixels'])} | {pct(s['next_open_pixels'])} | {pct(s['front_backfacing'])} "
            f"| {pct(s['embree_same_triangle'])} | {pct(s['embree_within_1e-4'])} "
            f"| {pct(s['gbuffer_within_1e-3'])} | {s['mesh_per_ray_max_diff']:.2g} |"
        )
    lines.append("")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ run


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--config", default="configs/eval.json", help="evaluation config (as neuralao evaluate)")
    p.add_argument("--size", nargs=2, type=int, default=[256, 256], metavar=("W", "H"))
    p.add_argument("--models", nargs="+", default=["runtime/models/unet-gtao"], type=Path)
    p.add_argument("--out", default="build/bench/visibility_bound", type=Path)
    p.add_argument(
        "--frames",
        default=None,
        type=Path,
        help="a finished frames folder of this config (read, never built)",
    )
    p.add_argument("--categories", nargs="+", default=None, help="default: every category not held aside")
    p.add_argument(
        "--include-held-aside", action="store_true", help="allow a held-aside category named above"
    )
    p.add_argument("--rays", type=int, default=None, help="label rays per pixel (default: the config's)")
    p.add_argument("--views", type=int, default=None, help="views per scene (default: the config's)")
    p.add_argument("--march-rays", type=int, default=64, help="rays per pixel of the marcher (and mesh@N)")
    p.add_argument("--steps", type=int, default=32, help="samples per ray and radius")
    p.add_argument("--open-eps", type=float, default=DEFAULT_OPEN_EPS, help="open surface's thickness / diag")
    p.add_argument(
        "--near-px",
        type=float,
        default=DEFAULT_NEAR_PX,
        help="pixel footprints around the origin not looked up",
    )
    p.add_argument(
        "--seed-offset",
        type=int,
        default=0,
        help="> 0: rays independent of the labels' (their seed shifted), so the marcher's noise is its own",
    )
    p.add_argument(
        "--front",
        choices=FRONTS,
        default="exact",
        help="each pixel's front plane: its facet's (exact), rebuilt from the depth buffer (depth), or the "
        "plane of constant depth through its centre (center)",
    )
    p.add_argument(
        "--ray-normals",
        choices=("facet", "gbuffer"),
        default="facet",
        help="the hemisphere the rays leave: the facet's (the labels') or the G-buffer's smooth normal "
        "(mesh@N is then the mesh's answer about that normal)",
    )
    p.add_argument("--max-frames", type=int, default=0, help="> 0: only the first k frames of each category")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        return run(args)
    except NeuralaoError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1


def run(args: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    if args.march_rays < 1 or args.steps < 1 or not args.open_eps > 0 or not args.near_px >= 0:
        raise NeuralaoError("--march-rays and --steps must be >= 1, --open-eps > 0 and --near-px >= 0")
    settings = select_categories(
        load_settings(EvalSettings, args.config), args.categories, args.include_held_aside
    )
    w, h = args.size
    settings, res = _bands.at_size(settings, args.size, args.rays, args.views, args.config)
    ds = dataset_settings(settings, res)
    chosen = {c.name for c in settings.categories}
    if args.frames is None:
        check_frames(settings, args.out)
        folder = args.out / "frames" / f"{w}x{h}"
        ensure_frames(ds, folder, Path(args.config).resolve().parent, not args.no_progress)
    else:  # the frames of these categories, or of every category not held aside (then only these are read)
        folder = args.frames
        made = (
            read_json(folder / "manifest.json", "dataset manifest")
            if (folder / "manifest.json").is_file()
            else {}
        )
        everyday = select_categories(
            replace(load_settings(EvalSettings, args.config), resolutions=[res]), None, False
        )
        for candidate in (settings, everyday):
            cand_ds = dataset_settings(candidate, res)
            if made.get("config") == json.loads(json.dumps(_config_dict(cand_ds), default=str)):
                settings, ds = candidate, cand_ds
                break
        else:
            raise NeuralaoError(f"--frames {folder}: not a finished dataset of this config's {w}x{h} frames")
    dataset = open_dataset(folder)
    manifest = dataset.manifest
    scene_index = {spec.name: i for i, spec in enumerate(expand_scenes(ds))}

    methods = {}
    for model in args.models:
        methods.update(unet_predictors(Path(model), ["model"]))
    methods["gtao"] = baseline_predictors()["gtao"]
    mesh = f"mesh@{args.march_rays}"
    march_settings = replace(ds.labels, rays=args.march_rays)

    rows: list[dict] = []
    vis_rows: list[dict] = []
    stats: list[dict] = []
    seen: dict[str, int] = {}
    cache: dict[str, tuple[Labeller, np.ndarray]] = {}
    timings = []
    for frame in dataset.frames(split="test"):
        category = category_of(frame["scene"], settings)
        if category not in chosen:
            continue
        if args.max_frames and seen.get(category, 0) >= args.max_frames:
            continue
        seen[category] = seen.get(category, 0) + 1
        t0 = time.perf_counter()
        name = frame["scene"]
        if name not in cache:
            cache.clear()  # one scene at a time (its views are consecutive)
            scene = scene_of(manifest, name)
            labeller = Labeller(scene, march_settings)
            normals = np.nan_to_num(np.asarray(scene.unit_face_normals(), np.float64))
            cache[name] = (labeller, normals)
        labeller, face_normals = cache[name]
        labeller.settings = replace(
            march_settings, seed=frame_seed(ds.seed, scene_index[name], frame["view"]) + args.seed_offset
        )
        radii = np.asarray(manifest["scenes"][name].get("radii", frame["radii"]), np.float64)
        if not np.allclose(radii, np.asarray(frame["radii"], np.float64), rtol=1e-6):
            raise NeuralaoError(f"{name}: the manifest's radii differ from the frame's")
        layers = frame_layers(labeller, face_normals, frame, args.open_eps, args.front)
        if args.ray_normals == "gbuffer":  # the G-buffer's (smooth) normals, camera-facing, in world space
            smooth = np.asarray(frame["normal_cam"], np.float64).reshape(-1, 3)[layers.pix] @ layers.to_cam.T
            smooth /= np.maximum(np.linalg.norm(smooth, axis=1, keepdims=True), 1e-30)
            toward = np.sum(smooth * layers.normals, axis=1) < 0
            layers = replace(layers, normals=np.where(toward[:, None], -smooth, smooth))
        t_layers = time.perf_counter() - t0

        fg = np.asarray(frame["mask"], bool)
        valid = np.asarray(frame["valid_radii"], bool).reshape(-1, len(radii))[layers.pix]
        valid &= fg.reshape(-1)[layers.pix, None]
        sel = np.flatnonzero(valid.any(axis=1))
        org, dirs, ray_blocked = frame_rays(labeller, layers, sel, radii)
        jitter = step_jitter(labeller.settings.seed, layers.pix[sel], args.march_rays)
        mesh_ao, _ = labeller.ao_radii_at_points(
            layers.points[sel], layers.normals[sel], radii=radii, ids=layers.pix[sel]
        )
        # the rays marched are the labeller's: their mesh answers give its AO exactly
        per_ray = 1.0 - ray_blocked.sum(axis=1) / args.march_rays
        layers.checks["mesh_per_ray_max_diff"] = float(np.abs(per_ray - mesh_ao).max(initial=0.0))
        t1 = time.perf_counter()
        preds: dict[int, dict[str, np.ndarray]] = {}
        for j, radius in enumerate(radii):
            ao, ao_os, off, left = march(
                layers.screen,
                org,
                dirs,
                jitter,
                radius / labeller.scale,
                args.steps,
                ray_blocked[..., j],
                args.near_px,
            )
            keep = valid[sel, j]
            preds[j] = (
                {v: ao[:, i] for i, v in enumerate(VARIANTS)}
                | {f"{v}{ORACLE}": ao_os[:, i] for i, v in enumerate(VARIANTS)}
                | {mesh: mesh_ao[:, j]}
            )
            stats.append(
                {
                    "category": category,
                    "scene": name,
                    "view": frame["view"],
                    "radius": j,
                    "samples": int(keep.sum()) * args.march_rays * args.steps,
                    "offscreen": int(off[keep].sum()),
                    "rays": int(keep.sum()) * args.march_rays,
                    "left": int(left[keep].sum()),
                    "checks": layers.checks,
                }
            )
        t_march = time.perf_counter() - t1

        flat_pix = layers.pix[sel]
        for j, radius in enumerate(radii):
            mask = fg & np.asarray(frame["valid_radii"][..., j], bool)  # as score_frame masks a pair
            if not mask.any():
                continue
            gt = np.asarray(frame["ao_radii"][..., j], np.float32)
            images = {}
            for name_m, fn in methods.items():
                images[name_m] = np.asarray(fn(frame, float(radius)), np.float64)
            for v, ao in preds[j].items():
                img = np.ones(h * w)
                img[flat_pix] = ao
                images[v] = img.reshape(h, w)
            for name_m, img in images.items():
                if not np.isfinite(img[mask]).all():
                    raise NeuralaoError(f"{name_m} returned non-finite AO on {name}/{frame['view']}")
                base = {"category": category, "scene": name, "view": frame["view"], "radius": j}
                err = img[mask] - gt[mask]
                rows.append(base | {"method": name_m, "se": float(err @ err), "n": int(mask.sum())})
                if name_m != mesh:
                    e2 = img[mask] - images[mesh][mask]
                    vis_rows.append(base | {"method": name_m, "se": float(e2 @ e2), "n": int(mask.sum())})
        timings.append(
            {
                "scene": name,
                "view": frame["view"],
                "pixels": int(len(sel)),
                "layers_s": t_layers,
                "march_s": t_march,
                "total_s": time.perf_counter() - t0,
            }
        )
        log.info(
            "%s/%d: %d px, layers %.1f s, rays+mesh %.1f s, march %.1f s, total %.1f s (open %.0f%%, "
            "embree front %.1f%%)",
            name,
            frame["view"],
            len(sel),
            t_layers,
            t1 - t0 - t_layers,
            t_march,
            time.perf_counter() - t0,
            100 * layers.checks["open"],
            100 * layers.checks["embree_within_1e-4"],
        )
    if not rows:
        raise NeuralaoError("no (frame, radius) pair with valid foreground pixels")

    scored = [c for c in settings.categories if c.name in chosen]
    groups = _bands.camera_groups(replace(settings, categories=scored))
    order = [*(m for m in methods if m != "gtao"), *VARIANTS, mesh]
    table_methods = ["gtao", *order, *(f"{v}{ORACLE}" for v in VARIANTS)]
    summary = summarise(rows, table_methods, groups, "gtao")
    per_radius = {
        f"{settings.radii_rel[j]:g}": summarise(
            [r for r in rows if r["radius"] == j], table_methods, groups, "gtao"
        )
        for j in sorted({r["radius"] for r in rows})
    }
    vis = summarise(vis_rows, table_methods, groups, "gtao")
    shares = pooled_shares(stats, groups)
    text = markdown(summary, vis, per_radius, shares, table_methods, mesh)
    seconds = time.perf_counter() - t_start
    header = (
        f"## Screen-space ray-traced AO from one and two depth layers, {w}x{h}, labels {res.rays} rays, "
        f"{res.views} views\n\nMarcher: {args.march_rays} rays per pixel (the labeller's directions), "
        f"{args.steps} jittered samples per ray and radius, none within {args.near_px:g} pixel footprints of "
        f"the origin, nearest pixel, per-pixel front planes ({args.front}); open surfaces "
        f"{args.open_eps:g} x diagonal thick in 2L-thin. Categories: "
        f"{', '.join(c.name for c in scored)}. {len(timings)} frames in {seconds:.0f} s.\n\n"
    )
    result = {
        "config": settings_to_dict(settings),
        "frames": str(folder),
        "models": [str(m) for m in args.models],
        "methods": table_methods,
        "size": [w, h],
        "rays": res.rays,
        "views": res.views,
        "march": {
            "rays": args.march_rays,
            "steps": args.steps,
            "open_eps": args.open_eps,
            "near_px": args.near_px,
            "front": args.front,
            "ray_normals": args.ray_normals,
        },
        "summary": summary,
        "per_radius": per_radius,
        "visibility_error": vis,
        "screen": shares,
        "rows": rows,
        "visibility_rows": vis_rows,
        "stats": stats,
        "timings": timings,
        "seconds": seconds,
    }
    write_json(args.out / "visibility_bound.json", result)
    write_text(args.out / "visibility_bound.md", header + text)
    print(header + text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
