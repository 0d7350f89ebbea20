"""Pinhole cameras: orbits around the bounding sphere, interior views, close-ups of contact regions,
explicit poses from JSON.

Convention (OpenGL, as pyrender): ``pose`` is camera-to-world, the camera looks down its -z axis
with +y up. Linear camera-space depth is the distance along the viewing axis, ``-z_cam``.
Pixel (row i, column j) has its centre at ``((j + 0.5) / W, (i + 0.5) / H)``; row 0 is the top.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from neuralao.pipeline.geometry.scene import MAX_COORDINATE, Scene
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame import check_yfov


@dataclass(frozen=True)
class Camera:
    """pose : (4, 4) float64 camera-to-world; yfov in radians; znear/zfar in scene units."""

    pose: np.ndarray
    width: int
    height: int
    yfov: float = math.radians(45.0)
    znear: float = 0.01
    zfar: float = 100.0

    @property
    def aspect(self) -> float:
        return self.width / self.height

    @property
    def position(self) -> np.ndarray:
        return self.pose[:3, 3]

    @property
    def view(self) -> np.ndarray:
        """(4, 4) float64 world-to-camera."""
        return np.linalg.inv(self.pose)

    @property
    def projection(self) -> np.ndarray:
        """(4, 4) float64 OpenGL perspective matrix (same as pyrender's PerspectiveCamera)."""
        f = 1.0 / math.tan(self.yfov / 2.0)
        n, fa = self.znear, self.zfar
        return np.array(
            [
                [f / self.aspect, 0, 0, 0],
                [0, f, 0, 0],
                [0, 0, (fa + n) / (n - fa), 2 * fa * n / (n - fa)],
                [0, 0, -1, 0],
            ]
        )

    def with_size(self, width: int, height: int) -> Camera:
        return Camera(self.pose, width, height, self.yfov, self.znear, self.zfar)

    def pixel_rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Primary rays through pixel centres.

        Returns origins (H*W, 3) float64 and unit directions (H*W, 3) float64, row-major, row 0 top.
        """
        h, w = self.height, self.width
        t = math.tan(self.yfov / 2.0)
        x = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) * t * self.aspect
        y = (1.0 - (np.arange(h) + 0.5) / h * 2.0) * t
        xx, yy = np.meshgrid(x, y)
        d_cam = np.stack([xx, yy, -np.ones_like(xx)], axis=-1).reshape(-1, 3)
        d = d_cam @ self.pose[:3, :3].T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = np.broadcast_to(self.position, d.shape).copy()
        return o, d

    def to_dict(self) -> dict:
        return {
            "pose": self.pose.tolist(),
            "width": self.width,
            "height": self.height,
            "yfov": self.yfov,
            "znear": self.znear,
            "zfar": self.zfar,
        }


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) camera-to-world pose looking from ``eye`` at ``target`` (``up`` defaults to +y)."""
    up = np.array([0.0, 1.0, 0.0]) if up is None else up
    eye = np.asarray(eye, dtype=np.float64)
    fwd = np.asarray(target, dtype=np.float64) - eye
    fwd /= np.linalg.norm(fwd)
    up = np.asarray(up, dtype=np.float64)
    if abs(float(np.dot(fwd, up / np.linalg.norm(up)))) > 0.999:  # looking along up: pick another up
        up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, fwd)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, true_up, -fwd, eye
    return pose


def _clip_planes(scene: Scene, eye: np.ndarray) -> tuple[float, float]:
    """Near/far planes enclosing the scene from ``eye``, relative to its size (scale invariant)."""
    radius = scene.diagonal / 2.0
    dist = float(np.linalg.norm(eye - scene.center))
    zfar = dist + radius * 1.05
    znear = max(dist - radius * 1.05, zfar * 1e-4)
    return znear, zfar


def orbit(
    scene: Scene,
    views: int,
    width: int,
    height: int,
    yfov_deg: float = 40.0,
    seed: int = 0,
    min_elevation_deg: float | None = None,
    frames: Sequence[tuple[int, int, float]] | None = None,
) -> list[Camera]:
    """``views`` cameras on a sphere around the bounding sphere, all looking at its centre.

    Directions follow a Fibonacci spiral (even coverage, deterministic), rotated by ``seed`` so
    different seeds give different but reproducible orbits. The distance fits the bounding sphere
    into the narrower field of view. ``min_elevation_deg`` keeps the spiral above that elevation
    (scenes standing on a ground plane, whose underside is no view at all); None: the whole sphere.
    ``frames``: per view (width, height, yfov_deg) instead of the three arguments (one orbit seen at
    several sizes and fields of view; each view's distance fits its own field of view).
    """
    if views < 1:
        raise NeuralaoError(f"views must be >= 1, got {views}")
    if frames is not None and len(frames) != views:
        raise NeuralaoError(f"orbit: {len(frames)} frame sizes for {views} views")
    frames = frames if frames is not None else [(width, height, yfov_deg)] * views
    # The tightest sphere about the box centre that holds every vertex (<= half the diagonal),
    # so objects fill the frame instead of their bounding box's circumsphere.
    radius = float(np.linalg.norm(scene.vertices - scene.center, axis=1).max())
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * math.pi) if seed else 0.0
    cams = []
    golden = math.pi * (3.0 - math.sqrt(5.0))
    y_low = -1.0 if min_elevation_deg is None else math.sin(math.radians(min_elevation_deg))
    for k, (w, h, fov_deg) in enumerate(frames):
        y = 1.0 - (1.0 - y_low) * (k + 0.5) / views
        r = math.sqrt(max(0.0, 1.0 - y * y))
        th = golden * k + phase
        d = np.array([r * math.cos(th), y, r * math.sin(th)])
        yfov = math.radians(fov_deg)
        half = min(yfov, 2 * math.atan(math.tan(yfov / 2) * (w / h))) / 2
        eye = scene.center + d * (radius / math.sin(half) * 1.02)
        znear, zfar = _clip_planes(scene, eye)
        cams.append(Camera(look_at(eye, scene.center), w, h, yfov, znear, zfar))
    return cams


def _clearance(scene: Scene, eyes: np.ndarray) -> np.ndarray:
    """(n,) distance from each eye to the nearest surface hit along 26 axis/diagonal directions."""
    from embreex import rtcore_scene  # measured: ~0.2 s to import; only the ray queries need it
    from embreex.mesh_construction import TriangleMesh

    es = rtcore_scene.EmbreeScene()
    TriangleMesh(es, (scene.triangles - scene.center).astype(np.float32))
    dirs = np.array(
        [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) != (0, 0, 0)],
        float,
    )
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    o = np.repeat(eyes - scene.center, len(dirs), axis=0).astype(np.float32)
    d = np.tile(dirs, (len(eyes), 1)).astype(np.float32)
    t = es.run(o, d, query="DISTANCE")
    return np.asarray(t, dtype=np.float64).reshape(len(eyes), len(dirs)).min(axis=1)


def interior(
    scene: Scene, views: int, width: int, height: int, yfov_deg: float = 60.0, seed: int = 0
) -> list[Camera]:
    """Cameras inside the bounding box (indoor scenes), seeded.

    Eyes are drawn in the central 60% of the box at 20-60% of its height and kept only if no
    surface is closer than 2% of the diagonal (else the near plane would clip a wall and the view
    would see through it); each looks at a point in the central 80% of the box with a downward bias.
    """
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds
    size = hi - lo
    yfov = math.radians(yfov_deg)
    znear, zfar = scene.diagonal * 1e-3, scene.diagonal * 1.5
    min_clearance = 0.02 * scene.diagonal
    eyes: list[np.ndarray] = []
    for _ in range(50):  # rejection sampling in batches; deterministic for a given seed
        cand = lo + size * np.stack(
            [
                rng.uniform(0.2, 0.8, 4 * views),
                rng.uniform(0.2, 0.6, 4 * views),
                rng.uniform(0.2, 0.8, 4 * views),
            ],
            axis=1,
        )
        eyes.extend(cand[_clearance(scene, cand) > min_clearance])
        if len(eyes) >= views:
            break
    if len(eyes) < views:
        raise NeuralaoError(
            f"scene {scene.name}: found only {len(eyes)} of {views} interior camera positions "
            "clear of geometry"
        )
    cams = []
    for eye in eyes[:views]:
        target = lo + size * rng.uniform(0.1, 0.9, size=3)
        target[1] = lo[1] + size[1] * rng.uniform(0.05, 0.6)
        cams.append(Camera(look_at(eye, target), width, height, yfov, znear, zfar))
    return cams


def _surface_samples(scene: Scene, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``count`` area-weighted random surface points (count, 3) and their face normals (count, 3)."""
    t = scene.triangles
    area = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    tri = rng.choice(len(t), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    c = t[tri]
    points = c[:, 0] + u[:, None] * (c[:, 1] - c[:, 0]) + v[:, None] * (c[:, 2] - c[:, 0])
    return points, scene.face_normals[tri]


def _openness(es, local: np.ndarray, normals: np.ndarray, radius: float, rays: int, rng) -> np.ndarray:
    """(n,) fraction of ``rays`` uniform hemisphere rays about each normal that escape within ``radius``."""
    d = rng.normal(size=(len(local), rays, 3))
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    d *= np.sign(np.einsum("nrk,nk->nr", d, normals))[..., None]
    o = np.repeat(local + normals * radius * 1e-3, rays, axis=0).astype(np.float32)
    hit = es.run(o, d.reshape(-1, 3).astype(np.float32), query="OCCLUDED", dists=np.float32(radius))
    return (np.asarray(hit).reshape(len(local), rays) < 0).mean(axis=1)


def closeup(
    scene: Scene, views: int, width: int, height: int, yfov_deg: float = 50.0, seed: int = 0
) -> list[Camera]:
    """Cameras close to contact regions (where AO varies most), seeded.

    Contacts are found without knowing how the scene was built: area-weighted surface samples get
    a 16-ray openness estimate within 5% of the diagonal along their authored normal; the most
    occluded quarter of those that are still visible from somewhere (openness >= 0.2, so not inside
    a closed part or under an object) are the targets. Each eye sits 5-15% of the diagonal from its
    target, off the normal by up to ~50 degrees, and is kept only if it passes the interior check
    (no surface closer than 1% of the diagonal along 26 directions) and sees its target unblocked.
    """
    from embreex import rtcore_scene  # measured: ~0.2 s to import; only the ray queries need it
    from embreex.mesh_construction import TriangleMesh

    if views < 1:
        raise NeuralaoError(f"views must be >= 1, got {views}")
    rng = np.random.default_rng(seed)
    diag = scene.diagonal
    es = rtcore_scene.EmbreeScene()
    TriangleMesh(es, (scene.triangles - scene.center).astype(np.float32))
    yfov = math.radians(yfov_deg)
    min_clearance = 0.01 * diag
    znear, zfar = min_clearance * 0.5, diag * 1.5
    cams: list[Camera] = []
    for _ in range(20):  # batches of candidates; deterministic for a given seed
        points, normals = _surface_samples(scene, 64 * views, rng)
        local = points - scene.center
        open_ = _openness(es, local, normals, 0.05 * diag, 16, rng)
        order = np.argsort(np.where(open_ >= 0.2, open_, np.inf), kind="stable")
        keep = order[: max(1, len(order) // 4)]
        keep = keep[np.isfinite(np.where(open_ >= 0.2, open_, np.inf)[keep])]
        if not len(keep):
            continue
        keep = rng.permutation(keep)
        tilt = rng.normal(size=(len(keep), 3)) * 0.6
        direction = normals[keep] + tilt - normals[keep] * np.einsum("nk,nk->n", tilt, normals[keep])[:, None]
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        dist = rng.uniform(0.05, 0.15, size=len(keep)) * diag
        eyes = points[keep] + direction * dist[:, None]
        ok = _clearance(scene, eyes) > min_clearance
        # Line of sight: the ray from the eye to its target must not stop short of it.
        to_target = (points[keep] - eyes) / dist[:, None]
        t = np.asarray(
            es.run((eyes - scene.center).astype(np.float32), to_target.astype(np.float32), query="DISTANCE"),
            np.float64,
        )
        ok &= t > dist * 0.98
        for e, target in zip(eyes[ok], points[keep][ok], strict=True):
            cams.append(Camera(look_at(e, target), width, height, yfov, znear, zfar))
            if len(cams) == views:
                return cams
    raise NeuralaoError(f"scene {scene.name}: found only {len(cams)} of {views} close-up camera positions")


# The keys of a camera in a camera file (anything else is refused: a misspelt "fov" would otherwise leave
# the default field of view without a word).
CAMERA_KEYS = ("eye", "target", "up", "pose", "yfov_deg", "znear", "zfar")


def load_poses(path: str | os.PathLike, scene: Scene, width: int, height: int) -> list[Camera]:
    """Explicit cameras from JSON: a list (or ``{"cameras": [...]}``) of objects with either

    ``{"eye": [x,y,z], "target": [x,y,z], "up": [0,1,0]?, "yfov_deg": 45?}`` or
    ``{"pose": 4x4 camera-to-world, "yfov_deg": 45?}``; optional ``znear``/``zfar``.

    Every camera is checked (:func:`camera_from_json`): known keys only, finite numbers, a rigid pose
    (rotation and translation: no scale, shear or mirror, within ``TOL.rigid_pose``), ``eye`` apart
    from ``target``, a field of view a camera has (:func:`~neuralao.runtime.frame.check_yfov`),
    0 < znear < zfar. Each refusal is one line naming the file, the camera and the key.
    """
    p = Path(path)
    data = read_json(p, "camera file")
    if isinstance(data, dict):
        unknown = sorted(set(data) - {"cameras"})
        if unknown:
            raise NeuralaoError(
                f"camera file {p}: unknown key {unknown[0]!r} (a camera file holds 'cameras')"
            )
        items = data.get("cameras")
    else:
        items = data
    if not isinstance(items, list) or not items:
        raise NeuralaoError(f"camera file {p} must hold a non-empty list of cameras")
    return [
        camera_from_json(c, scene, width, height, f"camera file {p}: camera {k}") for k, c in enumerate(items)
    ]


def _numbers_only(value: object) -> bool:
    """``value`` is a JSON number or a (nested) list of numbers: no string, no true/false (numpy would
    read "5" and true as numbers)."""
    if isinstance(value, list):
        return all(_numbers_only(v) for v in value)
    return isinstance(value, int | float) and not isinstance(value, bool)


def _vector(c: dict, key: str, n: int, where: str) -> np.ndarray:
    value = c[key]
    try:
        a = np.asarray(value, dtype=np.float64) if _numbers_only(value) else np.zeros(0)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != ((n,) if n != 16 else (4, 4)):
        want = "a 4x4 matrix (4 rows of 4 numbers)" if n == 16 else f"a list of {n} numbers"
        raise NeuralaoError(f"{where}: {key!r} must be {want}, got {value!r}"[:300])
    if not np.isfinite(a).all():
        raise NeuralaoError(f"{where}: {key!r} has NaN or inf")
    if np.abs(a).max() > MAX_COORDINATE:
        raise NeuralaoError(
            f"{where}: {key!r} reaches {np.abs(a).max():.3g}; coordinates lie within +-{MAX_COORDINATE:g}"
        )
    return a


def _number(c: dict, key: str, where: str) -> float | None:
    if key not in c:
        return None
    v = c[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise NeuralaoError(f"{where}: {key!r} must be a finite number, got {v!r}")
    return float(v)


def rigid_pose(pose: np.ndarray, where: str) -> np.ndarray:
    """``pose`` (4, 4) if it is a rigid camera-to-world transform: a rotation (orthonormal, det +1) and a
    translation, bottom row [0, 0, 0, 1], within ``TOL.rigid_pose``; else a one-line error saying what it
    holds instead (a scale, a shear or mirror, a singular matrix)."""
    r = pose[:3, :3]
    if np.abs(pose[3] - [0.0, 0.0, 0.0, 1.0]).max() > TOL.rigid_pose:
        raise NeuralaoError(f"{where}: 'pose' bottom row must be [0, 0, 0, 1], got {pose[3].tolist()}")
    scales = np.linalg.norm(r, axis=0)
    if scales.min() <= TOL.rigid_pose:
        raise NeuralaoError(f"{where}: 'pose' is singular (a zero column): a camera pose is a rotation")
    if np.abs(r.T @ r - np.eye(3)).max() > TOL.rigid_pose or np.linalg.det(r) < 0:
        if np.abs(scales - 1.0).max() > TOL.rigid_pose:
            what = f"scales its axes by {np.round(scales, 6).tolist()}"
        else:
            what = "shears or mirrors its axes"
        raise NeuralaoError(
            f"{where}: 'pose' {what}; a camera pose must be rigid (a rotation and a translation, "
            f"within {TOL.rigid_pose:g})"
        )
    return pose


def camera_from_json(c: object, scene: Scene, width: int, height: int, where: str) -> Camera:
    """One camera of a camera file (see :func:`load_poses`), checked; ``where`` names it in errors."""
    if not isinstance(c, dict):
        raise NeuralaoError(f"{where} must be a JSON object, got {type(c).__name__}")
    unknown = sorted(set(c) - set(CAMERA_KEYS))
    if unknown:
        raise NeuralaoError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(CAMERA_KEYS)})")
    if "pose" in c:
        clash = sorted(set(c) & {"eye", "target", "up"})
        if clash:
            raise NeuralaoError(f"{where}: give either 'pose' or 'eye' / 'target', not both ({clash[0]!r})")
        pose = rigid_pose(_vector(c, "pose", 16, where), where)
    else:
        missing = [k for k in ("eye", "target") if k not in c]
        if missing:
            raise NeuralaoError(f"{where}: needs 'pose', or 'eye' and 'target' (no {missing[0]!r})")
        eye, target = _vector(c, "eye", 3, where), _vector(c, "target", 3, where)
        up = _vector(c, "up", 3, where) if "up" in c else np.array([0.0, 1.0, 0.0])
        span = np.abs(np.concatenate([eye, target])).max()
        if not np.linalg.norm(target - eye) > 1e-9 * max(span, 1e-300):
            raise NeuralaoError(f"{where}: 'eye' and 'target' are the same point; a camera looks somewhere")
        if not np.abs(up).max() > 0:
            raise NeuralaoError(f"{where}: 'up' is the zero vector")
        pose = look_at(eye, target, up)
    yfov_deg = _number(c, "yfov_deg", where)
    if yfov_deg is not None:
        check_yfov(f"{where}: 'yfov_deg'", yfov_deg)
    yfov = math.radians(45.0 if yfov_deg is None else yfov_deg)
    znear, zfar = _clip_planes(scene, pose[:3, 3])
    if np.all(np.abs(pose[:3, 3] - scene.center) <= (scene.bounds[1] - scene.bounds[0]) / 2):
        znear, zfar = scene.diagonal * 1e-3, scene.diagonal * 1.5  # inside the scene
    given_near, given_far = _number(c, "znear", where), _number(c, "zfar", where)
    znear = znear if given_near is None else given_near
    zfar = zfar if given_far is None else given_far
    if not 0 < znear < zfar:
        raise NeuralaoError(f"{where}: clip planes need 0 < znear < zfar, got znear {znear:g}, zfar {zfar:g}")
    return Camera(pose, width, height, yfov, znear, zfar)
