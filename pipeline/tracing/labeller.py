"""Exact AO labels from Embree: cosine-weighted hemisphere rays, binary or obscurance kernel.

How a label is made
-------------------
For a surface point ``p`` with unit normal ``n`` the labeller casts ``rays`` directions drawn from
the cosine-weighted hemisphere around ``n``, from ``p + offset * n``, up to ``max_distance``:

* ``binary``: ao = fraction of rays that reach ``max_distance`` without a hit.
* ``obscurance`` (Sloan et al. 2013): each ray contributes ``rho(d) = 1 - exp(a d)`` with
  ``a = ln(0.5) / half_distance`` (``rho = 0.5`` at ``d = half_distance``) for a hit at distance
  ``d``, and 1 when it escapes within ``max_distance``; ao = mean of rho. Cosine weighting is in the
  sampling, so a plain mean is the estimator of ``1/pi * integral rho cos(theta) dw``.

Back-face rule (Sloan et al. 2013, for triangle soup): a ray whose first hit is a triangle whose
geometric normal points along the ray (``dot(ray_dir, n_tri) > 0``, i.e. the inside of a closed
part) is a back-face hit; a sample with more than ``backface_threshold`` of its rays hitting back
faces lies inside geometry and gets ``valid = False`` (its ao is still computed, finite, in [0, 1]).

Directions (deterministic, independent of how points are split across workers)
------------------------------------------------------------------------------
One Hammersley set of ``rays`` points ``(u1_i, u2_i) = (i / N, radical_inverse_2(i))`` is shared by
every sample. Each sample gets two uniforms ``(s1, s2)`` hashed (splitmix64) from ``(seed, id)``,
where ``id`` is the point's index (the flat pixel index in :meth:`Labeller.label_frame`):

* ``u1_i = (i + s1) / N``: every elevation stratum jittered by the same amount;
* ``phi_i = 2 pi (u2_i + s2)``: a per-sample rotation about the normal (a Cranley-Patterson shift
  of the azimuth), folded into the tangent frame so no trigonometry runs per ray.

Each ray is then marginally exactly cosine-distributed (unbiased), the set keeps the Hammersley
stratification (error well below the i.i.d. binomial sigma, which the tests use as a bound), and a
sample's rays depend only on ``(seed, id, normal)``. Direction ``(sqrt(u1) cos phi, sqrt(u1) sin phi,
sqrt(1 - u1))`` in the tangent frame of Duff et al. 2017 ("Building an orthonormal basis,
revisited": branchless, ``sign = copysign(1, n.z)`` keeps ``|sign + n.z| >= 1``, so no unit normal,
not even -z or -0.0, divides by zero).

Precision and scale
-------------------
The Embree scene is built in *local* coordinates ``(x - scene.center) / scene.diagonal`` computed in
float64 before the cast to float32, so an offset of 1e6 or a scale of 1e-3 / 1e4 changes neither
the float32 rounding of the geometry nor that of the ray origins. Visible points in
:meth:`Labeller.label_frame` are recomputed in float64 from the triangle id and the pixel ray.

Ray offset (``offset_rel = 1e-5``): in local units the coordinates are <= ~0.5, so float32 rounding
of an origin or of a triangle vertex is <= 2^-25 ~ 3e-8 and Embree's watertight test adds a few
ulps: an origin may sit ~1e-7 below its own (float32) triangle. Measured on a tilted open plane
(at scale 1 and at scale 1e4 + offset 1e6 alike): offset 0 gives self-hits on 54% of points, 1e-8
already gives none. 1e-5 keeps a 100x margin over the worst-case rounding and 1000x over the
measured threshold, so no ray re-hits its own surface (the tests check open planes give exactly
ao = 1 at every scale), yet it is 400x below a pixel footprint at 256 px (~diagonal/256) and
biases labels negligibly: on spot the mean ao moves by 3e-6 from offset 1e-7 to 1e-5 (3e-4 at
1e-4, 2e-3 at 1e-3, where contact shadows start to leak).

Zero / NaN normals: the sample is marked ``valid = False`` and traced with the fallback normal +z
(finite ao). Unnormalised normals are normalised (scale-safe, any finite non-zero length). A
non-finite point gets ``ao = 1, valid = False`` (nothing to trace).

Parallelism: embreex's ``EmbreeScene.run`` releases the GIL (two threads on one committed scene
trace 1.8-1.9x faster than one on an idle 2-core machine), and numpy's ufuncs release it as well,
so ``workers`` threads share one Embree scene; no processes, no ray copying between them. Rays are
built per chunk of 2^16 into per-thread planar float32 buffers that Embree reads through transposed
(n, 3) views (no interleaving copy).

Query per configuration (what it costs is in bench/bench_labeller.py): binary without the back-face
rule uses OCCLUDED (any hit, the fastest); binary with it uses INTERSECT (closest primitive id);
obscurance uses DISTANCE, or INTERSECT with ``output`` (distance + primitive id) with the rule.
Several radii (:meth:`Labeller.ao_radii_at_points`, :meth:`Labeller.label_frame_radii`) use one
INTERSECT with ``output`` to the largest radius and derive every radius from the hit distances.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, fields
from functools import cached_property
from typing import Literal

import numpy as np
from tqdm import tqdm

from neuralao.pipeline.geometry.camera import Camera
from neuralao.pipeline.geometry.scene import Scene
from neuralao.pipeline.geometry.sequences import hammersley, sample_shifts
from neuralao.pipeline.tracing.embree_buffers import add_triangles, high_quality
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import (
    RAY_BYTES,
    RAY_TABLE_BYTES,
    THREAD_BYTES,
    check_count,
    check_seed,
)
from neuralao.runtime.foundation.normals import normalize_normals
from neuralao.runtime.frame import FrameLike

# Rays per work item: big enough that Python overhead per chunk (~50 us) is < 1% of the trace,
# small enough that two workers stay balanced and the float32 ray buffers stay in L2/L3.
_CHUNK_RAYS = 1 << 16


@dataclass
class LabelSettings:
    # Rays per sample, cosine-weighted over the hemisphere of the normal.
    rays: int = 256
    # Longest ray, scene units; None -> max_distance_rel * scene.diagonal.
    max_distance: float | None = None
    # Default max distance as a fraction of the bounding-box diagonal (scale invariant).
    max_distance_rel: float = 0.25
    # "binary": fraction of rays escaping within max_distance; "obscurance": Sloan et al. 2013 rho(d).
    kernel: Literal["binary", "obscurance"] = "binary"
    # Obscurance: distance at which a hit counts half, scene units; None -> half_distance_rel * diagonal.
    half_distance: float | None = None
    # Default half distance as a fraction of the diagonal.
    half_distance_rel: float = 0.05
    # Ray-origin offset along the normal as a fraction of the diagonal: 100x the float32 error of a
    # local-coordinate origin (no self-hit speckle), 400x below a 256-px pixel (see module doc).
    offset_rel: float = 1e-5
    # A sample whose rays hit back faces more than this fraction of the time is invalid (Sloan et al.:
    # 0.25); None or a negative value disables the rule (and lets the binary kernel use OCCLUDED rays).
    backface_threshold: float | None = 0.25
    # Seed of the per-sample direction randomisation; the same seed gives identical labels.
    seed: int = 0
    # Threads tracing in parallel (embreex releases the GIL); results do not depend on it.
    workers: int = 2
    # Extra AO radii (max distances) as fractions of the diagonal, all from one trace to the largest
    # (Labeller.radii, label_frame_radii; the dataset's ao_radii); None: none, only ``ao``.
    radii_rel: list[float] | None = None

    @classmethod
    def shared_with(cls, settings: object) -> LabelSettings:
        """The labelling settings of a stage whose settings repeat some of these fields by name (a vertex
        or texture bake's); the fields it does not have keep their defaults."""
        return cls(**{f.name: getattr(settings, f.name) for f in fields(cls) if hasattr(settings, f.name)})


def onb(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent and bitangent (n, 3) float64 for unit normals (n, 3) float64 (Duff et al. 2017).

    Right-handed: ``cross(t, b) == n``; continuous except across n.z = 0 sign changes, no division
    by zero for any unit normal (``sign + n.z`` has magnitude >= 1).
    """
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    bt = np.stack([b, sign + y * y * a, -y], axis=1)
    return t, bt


class Labeller:
    """AO labels for points and G-buffer frames of one scene.

    Attributes (resolved, scene units): ``max_distance``, ``half_distance``, ``offset``.
    """

    # The Embree scene: "robust" (watertight triangle tests and conservative traversal, the default BVH) or
    # "fast" (Embree's high-quality BVH without the robust flag: 1.4x the rays per second on a level; the
    # same closest hits but for about one ray in ten million grazing an edge, distances within float
    # rounding; a tie between coincident faces may name the other face). Labels and datasets use "robust";
    # level bakes (LevelLabeller) "fast".
    bvh: Literal["robust", "fast"] = "robust"

    def __init__(self, scene: Scene, settings: LabelSettings | None = None, bvh: str | None = None):
        from embreex import rtcore_scene  # measured: ~0.2 s to import; only the ray queries need it

        diag = float(scene.diagonal)
        if not (math.isfinite(diag) and diag > 0):
            raise NeuralaoError(f"scene {scene.name} has no extent (diagonal {diag})")
        self.scene = scene
        # Local frame: float64 centring and scaling before the float32 cast (see module doc):
        # local = (world - center) / scale; center (3,) float64, scale the diagonal (scene units).
        self.center = np.asarray(scene.center, dtype=np.float64)
        self.scale = diag
        # float32 unit face normals for the hot path; the float64 ones (frames only) are made on demand,
        # so a level's labeller holds no (m, 3) float64 copy.
        with np.errstate(invalid="ignore", divide="ignore"):
            self._face_normals32 = np.nan_to_num(scene.unit_face_normals()).astype(np.float32)
        # The committed Embree scene of the local-frame triangles (shared by every tracing thread).
        self.bvh = bvh or self.bvh
        if self.bvh not in ("robust", "fast"):
            raise NeuralaoError(f"bvh must be 'robust' or 'fast', got {self.bvh!r}")
        self.embree = rtcore_scene.EmbreeScene(robust=self.bvh == "robust")
        if self.bvh == "fast":
            high_quality(self.embree)
        add_triangles(self.embree, self._verts_local, scene.faces)
        del self.__dict__["_verts_local"]  # only frames need it again: a level's labeller keeps no copy
        # EmbreeScene.run commits lazily on the first call; do it now, before threads share it.
        self.embree.run(
            np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED", dists=1.0
        )
        self._tls = threading.local()  # per-worker scratch buffers
        self.settings = settings or LabelSettings()

    @cached_property
    def _face_normals(self) -> np.ndarray:
        """(m, 3) float64 unit face normals (frames only)."""
        return np.asarray(self.scene.face_normals, dtype=np.float64)

    @cached_property
    def _verts_local(self) -> np.ndarray:
        """(n, 3) float64 vertices in the local frame (module doc)."""
        return (np.asarray(self.scene.vertices, np.float64) - self.center) / self.scale

    @property
    def settings(self) -> LabelSettings:
        """The settings in use. Assigning new settings (e.g. another seed per frame) validates and
        re-resolves them (cheap: the Embree scene is kept). ``seed`` and ``workers`` are read on every
        call; other fields only on assignment, so change them with ``dataclasses.replace``."""
        return self._settings

    @settings.setter
    def settings(self, s: LabelSettings) -> None:
        if s.kernel not in ("binary", "obscurance"):
            raise NeuralaoError(f"kernel must be 'binary' or 'obscurance', got {s.kernel!r}")
        for name in ("rays", "workers", "seed"):
            value = getattr(s, name)
            if isinstance(value, bool) or not isinstance(value, int) or (name != "seed" and value < 1):
                raise NeuralaoError(
                    f"{name} must be a{' positive' if name != 'seed' else 'n'} integer, got {value!r}"
                )
        # Before the ray tables and buffers are allocated: what they take must fit
        # (neuralao.runtime.foundation.limits).
        check_count("workers", s.workers, bytes_each=THREAD_BYTES, each="per tracing thread")
        check_rays("rays", s.rays, s.workers)
        diag = self.scale
        self.max_distance = positive_distance("max_distance", s.max_distance, s.max_distance_rel, diag)
        self.half_distance = positive_distance("half_distance", s.half_distance, s.half_distance_rel, diag)
        if not (math.isfinite(s.offset_rel) and 0 <= s.offset_rel < 0.01):
            raise NeuralaoError(f"offset_rel must be in [0, 0.01), got {s.offset_rel!r}")
        thr = s.backface_threshold
        if thr is not None and not math.isfinite(thr):
            raise NeuralaoError(f"backface_threshold must be finite or None, got {thr!r}")
        self.offset = s.offset_rel * diag
        self.radii = None if s.radii_rel is None else _radii(s.radii_rel, diag)
        self.backface_rule = thr is not None and thr >= 0
        self.r_local = np.float32(self.max_distance / diag)  # max_distance in local units, cast once
        self._h_local = self.half_distance / diag
        self._offset_local = float(s.offset_rel)
        i, radinv = hammersley(s.rays)
        self._stratum = i.astype(np.float32)
        phi = 2.0 * np.pi * radinv
        self._cos = np.cos(phi).astype(np.float32)
        self._sin = np.sin(phi).astype(np.float32)
        self._chunk_points = max(1, _CHUNK_RAYS // s.rays)
        # Resolved copies used by the hot path, so an in-place edit of the dataclass cannot
        # desynchronise them from the tables above (seed and workers are read on every call).
        self._rays, self._kernel, self._threshold = s.rays, s.kernel, thr
        self._settings = s

    # ------------------------------------------------------------------ public API

    def ao_at_points(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        progress: bool = False,
        ids: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """AO at surface points.

        points  : (n, 3) float64 world positions (scene units)
        normals : (n, 3) float64 normals, any length (normalised here; zero/NaN -> invalid)
        ids     : (n,) int64 randomisation ids, default ``arange(n)``: a point's rays depend only on
                  (seed, id, normal), never on the batch it is in.
        Returns ao (n,) float32 in [0, 1] and valid (n,) bool.
        """
        local, normals, ids = self._local_points(points, normals, ids)
        return self._ao_local(local, normals, ids, progress)

    def hits_along(
        self, points: np.ndarray, directions: np.ndarray, progress: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """Closest hits of caller-chosen rays (spherical samples of volume models, pipeline/bakes/volumes.py).

        points     : (n, 3) float64 world positions; rays start exactly there (no offset: these are
                     points in free space, not on a surface)
        directions : (n, k, 3) unit directions, k rays per point
        Returns dist (n, k) float32, scene units, ``inf`` where nothing is hit within
        :attr:`max_distance`; back (n, k) bool, True where the first hit is a back face
        (``dot(direction, n_tri) > 0``, the back-face rule's test).
        """
        points = np.asarray(points, dtype=np.float64)
        directions = np.asarray(directions, dtype=np.float32)
        n = len(points)
        if points.shape[1:] != (3,) or directions.ndim != 3 or directions.shape[::2] != (n, 3):
            raise NeuralaoError(
                f"points must be (n, 3) and directions (n, k, 3); got {points.shape} and {directions.shape}"
            )
        k = directions.shape[1]
        local = ((points - self.center) / self.scale).astype(np.float32)
        dist = np.full((n, k), np.inf, dtype=np.float32)
        back = np.zeros((n, k), dtype=bool)

        def trace(lo: int, hi: int) -> None:
            orig = np.ascontiguousarray(np.repeat(local[lo:hi], k, axis=0))
            dirs = np.ascontiguousarray(directions[lo:hi].reshape(-1, 3))
            dists = np.full(len(dirs), self.r_local, dtype=np.float32)
            out = self.embree.run(orig, dirs, query="INTERSECT", dists=dists, output=1)
            prim, tfar = out["primID"], out["tfar"]
            hit = prim >= 0
            fn = self._face_normals32[np.where(hit, prim, 0)]
            facing = dirs[:, 0] * fn[:, 0] + dirs[:, 1] * fn[:, 1] + dirs[:, 2] * fn[:, 2]
            dist[lo:hi] = np.where(hit, tfar * np.float32(self.scale), np.inf).reshape(hi - lo, k)
            back[lo:hi] = (hit & (facing > 0)).reshape(hi - lo, k)

        if n and k:
            run_chunks(trace, n, max(1, _CHUNK_RAYS // k), self.settings.workers, progress)
        return dist, back

    def _local_points(self, points, normals, ids) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Checked float64 points in local units, float64 normals and int64 ids (default arange(n))."""
        points = np.asarray(points, dtype=np.float64)
        normals = np.asarray(normals, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
            raise NeuralaoError(
                f"points and normals must both be (n, 3); got {points.shape} and {normals.shape}"
            )
        ids = np.arange(len(points), dtype=np.int64) if ids is None else np.asarray(ids, dtype=np.int64)
        if ids.shape != (len(points),):
            raise NeuralaoError(f"ids must be ({len(points)},), got {ids.shape}")
        return (points - self.center) / self.scale, normals, ids

    def label_frame(self, frame: FrameLike, progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """AO labels of a G-buffer frame.

        Uses ``frame['tri_id']`` (H, W) int (-1 on background), ``frame['pose']`` (4, 4) and
        ``frame['yfov']`` (and ``frame['depth']`` only as a fallback, see :meth:`visible_points`);
        each pixel's randomisation id is its flat index ``row * W + col``.
        Returns ao (H, W) float32 (1 on background) and valid (H, W) bool (False on background).
        """
        # Exactly visible_points -> ao_at_points(ids=pix) (the world round trip costs ~1e-16 relative),
        # so labelling a subset of pixels that way is bit-identical to labelling the whole frame.
        points, normals, pix, exact = self.visible_points(frame)
        h, w = np.shape(frame["tri_id"])
        ao = np.ones(h * w, dtype=np.float32)
        valid = np.zeros(h * w, dtype=bool)
        ao[pix], v = self.ao_at_points(points, normals, progress, ids=pix)
        valid[pix] = v & exact
        return ao.reshape(h, w), valid.reshape(h, w)

    def ao_radii_at_points(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        radii: list[float] | np.ndarray | None = None,
        progress: bool = False,
        ids: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """AO at several max distances from one trace: :meth:`ao_at_points` once per radius, in one pass.

        Every ray is traced once (INTERSECT, closest hit) to the largest radius; at radius r a ray
        counts as blocked iff its closest hit is at distance <= r (binary), or contributes rho of
        that distance iff it is < r (obscurance, same half distance), and the back-face rule counts
        only the hits within r. With the same settings and seed this equals separate traces with
        ``max_distance = r`` (tests/test_labels.py checks it bit for bit).

        radii : (k,) scene units, positive; default :attr:`radii` (from ``settings.radii_rel``)
        Returns ao (n, k) float32 in [0, 1] and valid (n, k) bool (the back-face rule per radius).
        """
        radii_local = self._radii_local(radii)
        local, normals, ids = self._local_points(points, normals, ids)
        return self._ao_local(local, normals, ids, progress, radii_local)

    def label_frame_radii(
        self, frame: FrameLike, radii: list[float] | np.ndarray | None = None, progress: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`label_frame` at several radii from one trace (see :meth:`ao_radii_at_points`).

        Returns ao (H, W, k) float32 (1 on background) and valid (H, W, k) bool (False on background).
        """
        radii_local = self._radii_local(radii)
        local, normals, pix, exact = self._frame_points_local(frame)
        h, w = np.shape(frame["tri_id"])
        k = len(radii_local)
        ao = np.ones((h * w, k), dtype=np.float32)
        valid = np.zeros((h * w, k), dtype=bool)
        ao[pix], v = self._ao_local(local, normals, pix, progress, radii_local)
        valid[pix] = v & exact[:, None]
        return ao.reshape(h, w, k), valid.reshape(h, w, k)

    def _radii_local(self, radii: list[float] | np.ndarray | None) -> np.ndarray:
        """(k,) float32 radii in local units (as ``r_local``: scene units / diagonal, cast once)."""
        if radii is None:
            if self.radii is None:
                raise NeuralaoError("no radii given and settings.radii_rel is None")
            radii = self.radii
        else:
            radii = _radii(list(np.asarray(radii, dtype=np.float64).reshape(-1)), 1.0)
        return np.array([np.float32(r / self.scale) for r in radii], dtype=np.float32)

    def visible_points(self, frame: FrameLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The float64 surface points :meth:`label_frame` labels.

        Each foreground pixel's point is the intersection of its pixel-centre ray
        (:meth:`Camera.pixel_rays` convention) with the plane of triangle ``tri_id``, computed in
        float64 in the labeller's centred frame, so a scene offset by 1e6 carries no float32 error;
        its normal is that triangle's geometric normal flipped to face the camera.
        Where the ray is (nearly) parallel to the plane the point comes from ``frame['depth']``
        (float32) if present, else it is NaN; such pixels have ``exact = False`` (labelled invalid).

        Returns points (k, 3) float64 world, normals (k, 3) float64 unit, pix (k,) int64 flat pixel
        indices of the foreground, exact (k,) bool.
        """
        local, normal, pix, exact = self._frame_points_local(frame)
        return local * self.scale + self.center, normal, pix, exact

    def _frame_points_local(self, frame: FrameLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`visible_points` in local units ``(x - center) / diagonal``."""
        for key in ("tri_id", "pose", "yfov"):
            if key not in frame:
                raise NeuralaoError(f"frame has no {key!r} channel")
        tri_id = np.asarray(frame["tri_id"])
        if tri_id.ndim != 2:
            raise NeuralaoError(f"frame tri_id must be (H, W), got {tri_id.shape}")
        h, w = tri_id.shape
        pose = np.asarray(frame["pose"], dtype=np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise NeuralaoError("frame pose must be a finite 4x4 matrix")
        flat = tri_id.reshape(-1).astype(np.int64)
        if flat.max(initial=-1) >= len(self.scene.faces):
            raise NeuralaoError(
                f"frame tri_id {int(flat.max())} is outside this scene's {len(self.scene.faces)} faces"
            )
        pix = np.flatnonzero(flat >= 0)
        d = pixel_directions(Camera(pose, w, h, float(frame["yfov"])), pix)
        tri = flat[pix]
        origin = (pose[:3, 3] - self.center) / self.scale
        v0 = self._verts_local[self.scene.faces[tri, 0]]
        n = self._face_normals[tri]
        denom = _dot(n, d)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = _dot(n, v0 - origin) / denom
        exact = np.isfinite(t) & (t > 0) & (np.abs(denom) > 1e-12)
        if not exact.all():
            t = np.where(exact, t, np.nan)
            if "depth" in frame:
                # Ray (nearly) in the triangle's plane: fall back to the rasterised depth.
                fwd = -pose[:3, 2] / np.linalg.norm(pose[:3, 2])
                depth = np.asarray(frame["depth"], np.float64).reshape(-1)[pix]
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = np.where(exact, t, depth / self.scale / (d @ fwd))
        normal = np.where((denom > 0)[:, None], -n, n)
        return origin + t[:, None] * d, normal, pix, exact

    # ------------------------------------------------------------------ internals

    def _ao_local(
        self,
        local: np.ndarray,
        normals: np.ndarray,
        ids: np.ndarray,
        progress: bool,
        radii: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Core: points (n, 3) float64 in local units, normals (n, 3), ids (n,) -> ao (n,) f32, valid (n,)
        bool; with ``radii`` (k,) float32 local: ao (n, k) f32 and valid (n, k) bool
        (:meth:`_trace_radii`)."""
        count = len(local)
        shape = (count,) if radii is None else (count, len(radii))
        ao = np.ones(shape, dtype=np.float32)
        valid = np.zeros(shape, dtype=bool)
        if count == 0:
            return ao, valid
        origins, frames, jitter, ok = self._prepare_all(local, normals, ids)

        def trace(lo: int, hi: int) -> None:
            if radii is None:
                ao[lo:hi], valid[lo:hi] = self._trace(origins[lo:hi], frames[:, :, lo:hi], jitter[lo:hi])
            else:
                ao[lo:hi], valid[lo:hi] = self._trace_radii(
                    origins[lo:hi], frames[:, :, lo:hi], jitter[lo:hi], radii
                )

        run_chunks(trace, count, self._chunk_points, self.settings.workers, progress)
        ao[~np.isfinite(local).all(axis=1)] = 1.0
        valid &= ok if radii is None else ok[:, None]
        return ao, valid

    def _prepare_all(
        self, local: np.ndarray, normals: np.ndarray, ids: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_prepare` of every point (n of them), in blocks on the workers: numpy call overhead
        (~1-10 us a call) makes it too slow per trace chunk and too slow serially. Elementwise, so a
        point's rays never depend on its block, batch or worker. Returns origins (n, 3), frames
        (3, 3, n, 1), jitter (n,) float32 and ok (n,) bool."""
        count = len(local)
        origins = np.empty((count, 3), np.float32)
        frames = np.empty((3, 3, count, 1), np.float32)
        jitter = np.empty(count, np.float32)
        ok = np.empty(count, bool)

        def prepare(lo: int, hi: int) -> None:
            o, f, j, k = self._prepare(local[lo:hi], normals[lo:hi], ids[lo:hi])
            origins[lo:hi], frames[:, :, lo:hi], jitter[lo:hi], ok[lo:hi] = o, f, j, k

        workers = self.settings.workers
        run_chunks(prepare, count, max(1024, -(-count // workers)), workers, False)
        return origins, frames, jitter, ok

    def _prepare(
        self, local: np.ndarray, normals: np.ndarray, ids: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-point ray set-up: origins (m, 3) f32 local, frames (3, 3, m, 1) f32, jitter (m,) f32,
        ok (m,) bool (finite point and usable normal)."""
        unit, normal_ok = normalize_normals(normals)
        finite = np.isfinite(local).all(axis=1)
        local = np.where(finite[:, None], local, 0.0)
        origins = (local + self._offset_local * unit).astype(np.float32)
        s1, s2 = sample_shifts(self.settings.seed, ids)
        t, b = onb(unit)
        c, s = np.cos(2.0 * np.pi * s2)[:, None], np.sin(2.0 * np.pi * s2)[:, None]
        # Rotating the frame by phi0 about n == adding phi0 to every ray's azimuth (a Cranley-Patterson
        # shift of u2); (row, component, point, 1) layout so each broadcast below reads contiguously.
        frames = np.stack([c * t + s * b, c * b - s * t, unit]).astype(np.float32)
        frames = np.ascontiguousarray(frames.transpose(0, 2, 1))[..., None]
        return origins, frames, s1.astype(np.float32), normal_ok & finite

    def rays(
        self, points: np.ndarray, normals: np.ndarray, ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The exact rays :meth:`ao_at_points` traces, in the Embree scene's local frame
        ``(x - scene.center) / scene.diagonal`` (for benchmarks and tests).

        Returns origins (n * rays, 3) float32 and unit directions (n * rays, 3) float32, point-major;
        each ray's maximum length is ``max_distance / scene.diagonal``.
        """
        points = np.asarray(points, dtype=np.float64)
        ids = np.arange(len(points), dtype=np.int64) if ids is None else np.asarray(ids, dtype=np.int64)
        origins, frames, jitter, _ = self._prepare((points - self.center) / self.scale, normals, ids)
        m, n_rays = len(points), self._rays
        dirs = np.empty((3, m, n_rays), np.float32)
        self._directions(frames, jitter, dirs, np.empty((m, n_rays), np.float32))
        return np.repeat(origins, n_rays, axis=0), np.ascontiguousarray(dirs.reshape(3, -1).T)

    def _buffers(self, rays: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-thread scratch: dirs (3, rays), origins (3, rays), tmp (rays,), dists (rays,) float32.

        Reused across chunks: fresh 1 MB arrays cost a page fault per 4 KB on every call.
        Components are planar; Embree reads them through the (rays, 3) transposed views.
        """
        tls = self._tls
        if getattr(tls, "capacity", 0) < rays:
            tls.capacity = rays
            tls.dirs = np.empty((3, rays), np.float32)
            tls.origins = np.empty((3, rays), np.float32)
            tls.tmp = np.empty(rays, np.float32)
            tls.dists = np.empty(rays, np.float32)
        return tls.dirs[:, :rays], tls.origins[:, :rays], tls.tmp[:rays], tls.dists[:rays]

    def _trace(
        self, origins: np.ndarray, frames: np.ndarray, jitter: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """origins (m, 3) f32, frames (3, 3, m, 1) f32 [row t/b/n, component], jitter (m,) f32
        -> ao (m,) float32 in [0, 1], back_ok (m,) bool (back-face fraction within the threshold)."""
        m, n_rays = len(origins), self._rays
        dirs_p, orig_p, tmp, dists = self._buffers(m * n_rays)
        self._directions(frames, jitter, dirs_p.reshape(3, m, n_rays), tmp.reshape(m, n_rays))
        for k in range(3):
            orig_p[k].reshape(m, n_rays)[:] = origins[:, k, None]
        dirs, orig = dirs_p.T, orig_p.T  # (m * N, 3) views, no copy
        kernel, r = self._kernel, self.r_local
        back_ok = np.ones(m, dtype=bool)
        if kernel == "binary" and not self.backface_rule:
            # embreex OCCLUDED returns the hit geometry's id, 0 (our only mesh), or -1 for a miss.
            hit_geom = self.embree.run(orig, dirs, query="OCCLUDED", dists=r)
            escaped = np.count_nonzero(hit_geom.reshape(m, n_rays), axis=1)
            return (escaped / n_rays).astype(np.float32), back_ok
        prim = tfar = None
        if kernel == "binary":
            prim = self.embree.run(orig, dirs, query="INTERSECT", dists=r)
        elif self.backface_rule:
            dists.fill(r)  # run() writes hit distances into this array
            out = self.embree.run(orig, dirs, query="INTERSECT", dists=dists, output=1)
            prim, tfar = out["primID"], out["tfar"]
        else:
            dists.fill(r)
            tfar = self.embree.run(orig, dirs, query="DISTANCE", dists=dists)
        if prim is not None:
            # Work on the hits only (usually a minority): their indices, and each one's point.
            hit_idx = np.flatnonzero(prim >= 0)
            hit_point = hit_idx // n_rays
        if tfar is None:
            ao = (1.0 - np.bincount(hit_point, minlength=m) / n_rays).astype(np.float32)
        else:
            # rho(d) = 1 - exp(a d), a = ln(0.5) / d_half  ==  1 - 2^(-d / d_half); escaped rays: 1.
            rho = np.where(tfar < r, 1.0 - np.exp2(-tfar / np.float32(self._h_local)), np.float32(1.0))
            ao = rho.reshape(m, n_rays).mean(axis=1, dtype=np.float64).astype(np.float32)
        if self.backface_rule:
            fn = self._face_normals32[prim[hit_idx]]
            facing = dirs_p[0, hit_idx] * fn[:, 0]
            facing += dirs_p[1, hit_idx] * fn[:, 1]
            facing += dirs_p[2, hit_idx] * fn[:, 2]
            back = np.bincount(hit_point[facing > 0], minlength=m)
            back_ok = back / n_rays <= self._threshold
        return np.clip(ao, 0.0, 1.0), back_ok

    def _trace_radii(
        self, origins: np.ndarray, frames: np.ndarray, jitter: np.ndarray, radii: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_trace` at every radius of ``radii`` (k,) float32 local from one INTERSECT to the
        largest -> ao (m, k) float32, back_ok (m, k) bool. Each radius repeats the single-radius
        arithmetic of :meth:`_trace` for this configuration, so the results agree bit for bit."""
        m, n_rays = len(origins), self._rays
        dirs_p, orig_p, tmp, dists = self._buffers(m * n_rays)
        self._directions(frames, jitter, dirs_p.reshape(3, m, n_rays), tmp.reshape(m, n_rays))
        for k in range(3):
            orig_p[k].reshape(m, n_rays)[:] = origins[:, k, None]
        dirs, orig = dirs_p.T, orig_p.T
        dists.fill(radii.max())
        out = self.embree.run(orig, dirs, query="INTERSECT", dists=dists, output=1)
        prim, tfar = out["primID"], out["tfar"]
        hit_idx = np.flatnonzero(prim >= 0)
        hit_point, hit_t = hit_idx // n_rays, tfar[hit_idx]
        if self.backface_rule:
            fn = self._face_normals32[prim[hit_idx]]
            facing = dirs_p[0, hit_idx] * fn[:, 0]
            facing += dirs_p[1, hit_idx] * fn[:, 1]
            facing += dirs_p[2, hit_idx] * fn[:, 2]
            back_hit = facing > 0
        ao = np.empty((m, len(radii)), np.float32)
        back_ok = np.ones((m, len(radii)), dtype=bool)
        for j, r in enumerate(radii):
            within = hit_t <= r  # what a trace with tfar = r reports as a hit
            if self._kernel == "binary":
                hits = np.bincount(hit_point[within], minlength=m)
                if self.backface_rule:
                    ao[:, j] = np.clip((1.0 - hits / n_rays).astype(np.float32), 0.0, 1.0)
                else:  # OCCLUDED path of _trace: escaped / N
                    ao[:, j] = ((n_rays - hits) / n_rays).astype(np.float32)
            else:
                rho = np.where(tfar < r, 1.0 - np.exp2(-tfar / np.float32(self._h_local)), np.float32(1.0))
                mean = rho.reshape(m, n_rays).mean(axis=1, dtype=np.float64).astype(np.float32)
                ao[:, j] = np.clip(mean, 0.0, 1.0)
            if self.backface_rule:
                back = np.bincount(hit_point[within & back_hit], minlength=m)
                back_ok[:, j] = back / n_rays <= self._threshold
        return ao, back_ok

    def _directions(
        self, frames: np.ndarray, jitter: np.ndarray, out: np.ndarray, tmp: np.ndarray, rays=slice(None)
    ) -> None:
        """Fill out (3, m, N) float32 with unit world directions; frames (3, 3, m, 1), jitter (m,) f32.
        ``rays``: only these of each point's N rays (out (3, m, len) then).

        Elementwise float32 only (no BLAS, no per-ray trigonometry), so a ray's bits depend only on
        its own point, never on the chunk it is computed in.
        """
        n_rays = self._rays
        u1 = np.add(self._stratum[None, rays], jitter[:, None])
        # Divide (correctly rounded, monotone): (N - 1 + s1) / N <= N / N = 1 exactly, so 1 - u1 >= 0;
        # multiplying by a rounded 1/N could give 1 + ulp and a NaN z.
        u1 /= np.float32(n_rays)
        z = np.subtract(np.float32(1.0), u1)
        np.sqrt(z, out=z)
        r = np.sqrt(u1, out=u1)
        x = r * self._cos[rays]
        y = np.multiply(r, self._sin[rays], out=r)
        for k in range(3):
            o = out[k]
            np.multiply(x, frames[0, k], out=o)
            o += np.multiply(y, frames[1, k], out=tmp)
            o += np.multiply(z, frames[2, k], out=tmp)


def pixel_directions(camera: Camera, pix: np.ndarray) -> np.ndarray:
    """Unit world directions (k, 3) float64 of the pixel-centre rays of flat pixel indices ``pix``
    (k,): :meth:`Camera.pixel_rays` for just those pixels (a frame is mostly background)."""
    h, w = camera.height, camera.width
    row, col = np.divmod(np.asarray(pix, dtype=np.int64), w)
    t = math.tan(camera.yfov / 2.0)
    x = ((col + 0.5) / w * 2.0 - 1.0) * t * camera.aspect
    y = (1.0 - (row + 0.5) / h * 2.0) * t
    rot = camera.pose[:3, :3]
    d = x[:, None] * rot[:, 0] + y[:, None] * rot[:, 1] - rot[:, 2]  # rot @ (x, y, -1)
    return d / np.sqrt(_dot(d, d))[:, None]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (n, 3) arrays, (n,), as an explicit elementwise sum."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def positive_distance(name: str, value: float | None, rel: float, diag: float) -> float:
    """``value``, or ``rel * diag`` when it is None; refused unless a positive finite number."""
    v = rel * diag if value is None else value
    if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
        raise NeuralaoError(f"{name} must be a positive finite distance, got {v!r}")
    return float(v)


def _radii(values: list[float], diag: float) -> tuple[float, ...]:
    """Resolve relative radii (``values * diag``), each positive and finite; at least one."""
    if not isinstance(values, list | tuple) or not values:
        raise NeuralaoError(f"radii must be a non-empty list of positive distances, got {values!r}")
    return tuple(positive_distance("radius", None, float(v), diag) for v in values)


def run_chunks(
    work: Callable[[int, int], None], count: int, chunk: int, workers: int, progress: bool
) -> None:
    """Call ``work(lo, hi)`` over [0, count) in chunks on ``workers`` threads (tqdm if ``progress``)."""
    bounds = [(lo, min(lo + chunk, count)) for lo in range(0, count, chunk)]
    bar = tqdm(total=count, unit="pt", desc="AO labels", disable=not progress, leave=False)
    try:
        if workers == 1 or len(bounds) == 1:
            for lo, hi in bounds:
                work(lo, hi)
                bar.update(hi - lo)
            return
        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(work, lo, hi): hi - lo for lo, hi in bounds}
            for f in as_completed(futures):
                f.result()
                bar.update(futures[f])
    finally:
        bar.close()


def check_rays(name: str, rays: int, workers: int) -> int:
    """Rays per sample within what the labeller's buffers can hold: ``max(rays, chunk)`` rays per
    tracing thread plus the ray tables (neuralao.runtime.foundation.limits)."""
    return check_count(
        name,
        rays,
        bytes_each=RAY_BYTES * max(int(workers), 1) + RAY_TABLE_BYTES,
        each=f"per ray on {workers} tracing thread(s)",
    )


def check_label_args(args) -> None:
    """The labelling flags every tracing command shares (--rays, --workers, --max-distance,
    --half-distance, --kernel): a bad value is a one-line error."""
    check_count("--workers", args.workers, bytes_each=THREAD_BYTES, each="per tracing thread")
    check_rays("--rays", args.rays, args.workers)
    if getattr(args, "seed", None) is not None:
        check_seed("--seed", args.seed)
    for flag, value in (("--max-distance", args.max_distance), ("--half-distance", args.half_distance)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise NeuralaoError(f"{flag} must be a positive finite distance, got {value}")
    if args.half_distance is not None and args.kernel != "obscurance":
        raise NeuralaoError("--half-distance only applies to --kernel obscurance")


def label_fields(args) -> dict:
    """The :class:`LabelSettings` fields those flags (and --seed) give, by name, for any settings that
    extend them (a bake's, a render's)."""
    names = ("rays", "max_distance", "kernel", "half_distance", "seed", "workers")
    return {k: getattr(args, k) for k in names}
