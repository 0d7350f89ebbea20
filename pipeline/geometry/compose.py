"""Seeded scene composer: rooms of meshes and primitives that rest on, lean on and touch each other.

AO lives in contact regions (an object's foot on the floor, a box against a wall, a vase on a
crate), so a corpus of isolated meshes on orbits teaches a network little of it. A composed scene
is a room (a floor, 0-4 walls, optionally a ceiling) holding objects: train-split meshes from
:mod:`neuralao.pipeline.geometry.splits` and primitives (boxes, cylinders, spheres, thin panels), each with
a random size and rotation, placed by one of five strategies:

* ``floor``: anywhere on the floor; ``wall`` / ``corner``: its bounding box flush against one wall
  / two adjacent walls; ``stack``: dropped onto an earlier object; ``beside``: slid along the
  floor until it touches an earlier object.

Contacts are exact, not bounding-box guesses: an object is moved along a straight line (down for
drops, horizontally for slides) by the largest distance before first contact, found with Embree
rays cast from its probe points (vertices, plus points along the edges of primitives, whose few
long edges would otherwise cross edges undetected) along the motion onto every static part, and
from their probe points backwards onto it. Vertex-face and (up to the edge sampling) edge-edge
contacts are caught, so objects touch without interpenetrating (tests/test_compose.py checks both).
Walls are planes at the room's edge, so flush is exact from the rotated bounding box.

Conventions: +y is up (as :mod:`neuralao.pipeline.geometry.camera`: interior eye heights are along y), the
floor is the plane y = 0 spanning the room, walls and ceiling face inwards. Every random choice comes from
``ComposeSettings.seed``: the plan (room, object kinds, meshes, sizes, rotations, strategies) from
one generator, each object's position from its own, so the same seed and mesh pool give identical
vertex arrays. Meshes are loaded once per process (:func:`normalized_mesh`).
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, field

import numpy as np

from neuralao.pipeline.geometry.scene import Scene, load_scene, scene_from_arrays
from neuralao.pipeline.geometry.splits import object_meshes
from neuralao.runtime.foundation.errors import NeuralaoError

log = logging.getLogger(__name__)

PRIMITIVES = ("box", "cylinder", "sphere", "panel")
STRATEGIES = ("floor", "wall", "corner", "stack", "beside")
_WALLS = ("-x", "+x", "-z", "+z")
_ADJACENT = (("-x", "-z"), ("-x", "+z"), ("+x", "-z"), ("+x", "+z"))
_MISS = 1e30  # Embree ray length meaning "no limit"
# Lift during horizontal slides so rays from an object's base never graze the floor plane.
_LIFT = 1e-4
# Start height above everything below an object before it is dropped.
_DROP_MARGIN = 1e-2
# Probe points per primitive edge (edge-edge contacts are caught to ~edge length / this).
_EDGE_PROBES = 24


@dataclass
class ComposeSettings:
    """One composed scene (all lengths in scene units)."""

    seed: int = 0  # every random choice derives from it: same seed + same mesh pool -> same vertices
    objects: tuple[int, int] = (4, 10)  # number of objects, inclusive range
    mesh_fraction: float = 0.6  # probability that an object is a mesh (else a primitive)
    walls: tuple[int, int] = (0, 4)  # number of walls, inclusive range within 0-4
    ceiling: float = 0.5  # probability of a ceiling when the room has 3 or 4 walls
    room: tuple[float, float] = (2.0, 3.5)  # range of the floor's side lengths
    height: tuple[float, float] = (1.2, 2.0)  # range of the wall / ceiling height (and the stack limit)
    size: tuple[float, float] = (0.25, 0.9)  # range of an object's largest bounding-box extent
    tumble: float = 0.25  # probability that a mesh gets a uniformly random rotation (else upright + yaw)
    meshes: list[str] | None = None  # mesh pool; None -> the object meshes of the scene's split
    # Revision of that split's pool (neuralao.pipeline.geometry.splits.ADDED): 1 = the meshes of the first
    # corpus, 2 adds the thin-part / shell props. Fixed per config, so adding meshes to a split never
    # changes a config's scenes.
    pool: int = 1


@dataclass(frozen=True)
class Placed:
    """One part of a composed scene: a room surface or an object."""

    kind: str  # "floor", "wall", "ceiling", "mesh" or a primitive (box, cylinder, sphere, panel)
    source: str  # mesh name, primitive name or wall side (-x, +x, -z, +z)
    vertices: tuple[int, int]  # [start, stop) rows of Scene.vertices
    faces: tuple[int, int]  # [start, stop) rows of Scene.faces
    placement: str = ""  # objects: floor | wall | corner | stack | beside
    support: int = -1  # index in Composition.parts of the part it rests on (0 = the floor)


@dataclass
class Composition:
    """A composed scene and what it is made of (room parts first, then objects)."""

    scene: Scene
    parts: list[Placed] = field(default_factory=list)
    room: tuple[float, float, float] = (0.0, 0.0, 0.0)  # floor width (x), depth (z), wall height
    walls: tuple[str, ...] = ()
    ceiling: bool = False

    @property
    def objects(self) -> list[Placed]:
        return [p for p in self.parts if p.kind not in ("floor", "wall", "ceiling")]


@dataclass(frozen=True)
class PlannedObject:
    kind: str  # "mesh" or a primitive
    source: str  # mesh name or primitive name
    size: float  # largest bounding-box extent before rotation
    rotation: np.ndarray  # (3, 3) float64
    strategy: str  # one of STRATEGIES
    aspect: tuple[float, float, float]  # primitive proportions


@dataclass(frozen=True)
class Plan:
    """Everything random about a composed scene except the positions, drawn before any mesh loads."""

    room: tuple[float, float, float]  # floor width (x), depth (z), wall height
    walls: tuple[str, ...]  # sides with a wall: -x, +x, -z, +z
    ceiling: bool
    objects: list[PlannedObject]


class _Part:
    """Geometry in world (or, while it moves, object) coordinates with a lazily built Embree scene."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, probes: np.ndarray | None = None):
        self.vertices = vertices  # (n, 3) float64
        self.faces = faces  # (m, 3) int64
        self.probes = vertices if probes is None else probes  # (p, 3) float64 contact probe points
        self.lo, self.hi = vertices.min(0), vertices.max(0)
        self._embree = None

    def moved(self, offset: np.ndarray) -> _Part:
        return _Part(self.vertices + offset, self.faces, self.probes + offset)

    def distances(self, origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """(n,) float64 distance along unit ``direction`` from each origin (n, 3) to this part; inf on a
        miss."""
        if len(origins) == 0:
            return np.full(0, np.inf)
        if self._embree is None:
            from embreex import rtcore_scene  # measured: ~0.2 s to import; only the ray queries need it
            from embreex.mesh_construction import TriangleMesh

            self._embree = rtcore_scene.EmbreeScene()
            TriangleMesh(self._embree, self.vertices.astype(np.float32), self.faces.astype(np.int32))
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(np.broadcast_to(direction, o.shape), dtype=np.float32)
        t = np.asarray(self._embree.run(o, d, query="DISTANCE", dists=np.full(len(o), _MISS, np.float32)))
        t = t.astype(np.float64)
        t[t >= _MISS * 0.5] = np.inf
        return t


# ---------------------------------------------------------------------------------- geometry


@functools.lru_cache(maxsize=64)
def normalized_mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    """A shared mesh centred on its bounding box and scaled to a largest extent of 1, cached per process.

    Returns vertices (n, 3) float64 and faces (m, 3) int64, both read-only (shared by every scene).
    """
    scene = load_scene(name)
    v = (scene.vertices - scene.center) / float((scene.bounds[1] - scene.bounds[0]).max())
    f = scene.faces.copy()
    v.flags.writeable = False
    f.flags.writeable = False
    return v, f


def _primitive(kind: str, aspect: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Closed primitive centred at the origin with largest extent 1: vertices (n, 3), faces (m, 3)."""
    import trimesh  # measured: ~1 s to import; only the file readers and writers need it

    a = np.asarray(aspect, dtype=np.float64)
    if kind in ("box", "panel"):
        m = trimesh.creation.box(extents=a / a.max())
    elif kind == "cylinder":  # axis along y; aspect = (diameter, height, -)
        d, h = a[0], a[1]
        k = max(d, h)
        m = trimesh.creation.cylinder(radius=d / k / 2, height=h / k, sections=32)
        m.apply_transform(trimesh.transformations.rotation_matrix(-math.pi / 2, [1, 0, 0]))
    elif kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=4, radius=0.5)  # 5120 faces: no facets in close-ups
    else:
        raise NeuralaoError(f"unknown primitive {kind!r}; use one of {', '.join(PRIMITIVES)}")
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def _edge_probes(vertices: np.ndarray, faces: np.ndarray, per_edge: int) -> np.ndarray:
    """Vertices plus ``per_edge`` evenly spaced points along every triangle edge (p, 3) float64."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    s = (np.arange(1, per_edge + 1) / (per_edge + 1))[None, :, None]
    pts = vertices[e[:, 0], None] * (1 - s) + vertices[e[:, 1], None] * s
    return np.concatenate([vertices, pts.reshape(-1, 3)])


def _quad(center, u, v) -> tuple[np.ndarray, np.ndarray]:
    """Rectangle center +- u +- v (4, 3) with normal along u x v, faces (2, 3)."""
    c, u, v = (np.asarray(x, np.float64) for x in (center, u, v))
    verts = np.stack([c - u - v, c + u - v, c + u + v, c - u + v])
    return verts, np.array([[0, 1, 2], [0, 2, 3]], np.int64)


def _room(width: float, depth: float, height: float, walls: tuple[str, ...], ceiling: bool):
    """(kind, side, vertices, faces) of the floor (y = 0, facing +y), walls and ceiling (facing in)."""
    w, d, h = width / 2, depth / 2, height / 2
    x, y, z = np.eye(3)
    parts = [("floor", "floor", *_quad((0, 0, 0), x * w, -z * d))]
    quads = {
        "-x": ((-w, h, 0), y * h, z * d),
        "+x": ((w, h, 0), z * d, y * h),
        "-z": ((0, h, -d), x * w, y * h),
        "+z": ((0, h, d), y * h, x * w),
    }
    parts += [("wall", side, *_quad(*quads[side])) for side in walls]
    if ceiling:
        parts.append(("ceiling", "ceiling", *_quad((0, height, 0), x * w, z * d)))
    return parts


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """(3, 3) float64 uniformly random proper rotation (QR of a Gaussian matrix, sign-fixed)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _axis_rotation(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


# ---------------------------------------------------------------------------------- planning


def plan(settings: ComposeSettings, split: str = "train") -> Plan:
    """The seeded :class:`Plan` of a composed scene, before any mesh is loaded. Meshes come from
    ``settings.meshes`` or else :func:`neuralao.pipeline.geometry.splits.object_meshes` of ``split`` at
    ``settings.pool``."""
    _check(settings)
    pool = tuple(settings.meshes) if settings.meshes is not None else object_meshes(split, settings.pool)
    rng = np.random.default_rng([int(settings.seed) & 0xFFFFFFFF, 0])
    width, depth = rng.uniform(*settings.room, size=2)
    height = float(rng.uniform(*settings.height))
    n_walls = int(rng.integers(settings.walls[0], settings.walls[1] + 1))
    walls = tuple(sorted(rng.choice(_WALLS, size=n_walls, replace=False).tolist(), key=_WALLS.index))
    ceiling = n_walls >= 3 and bool(rng.random() < settings.ceiling)
    corners = [c for c in _ADJACENT if c[0] in walls and c[1] in walls]
    objects = []
    largest = 0.45 * min(width, depth)
    for i in range(int(rng.integers(settings.objects[0], settings.objects[1] + 1))):
        is_mesh = bool(pool) and rng.random() < settings.mesh_fraction
        kind = "mesh" if is_mesh else str(rng.choice(PRIMITIVES))
        source = str(pool[int(rng.integers(len(pool)))]) if is_mesh else kind
        size = min(float(rng.uniform(*settings.size)), largest)
        aspect = tuple(float(a) for a in rng.uniform(0.3, 1.0, size=3))
        yaw = _axis_rotation(1, float(rng.uniform(0, 2 * math.pi)))
        if kind == "mesh":
            tumbled = rng.random() < settings.tumble
            rotation = _random_rotation(rng) if tumbled else yaw
        elif kind == "panel":  # a thin board: lying flat (a rug, a shelf) or leaning (60-85 degrees)
            aspect = (aspect[0], float(rng.uniform(0.02, 0.06)), aspect[2])
            lean = rng.random() < 0.6
            rotation = yaw @ _axis_rotation(
                0, float(rng.uniform(math.radians(60), math.radians(85))) if lean else 0.0
            )
        elif kind == "cylinder":  # standing or lying on its side
            rotation = yaw @ (_axis_rotation(0, math.pi / 2) if rng.random() < 0.4 else np.eye(3))
        else:
            rotation = yaw
        choices = ["floor", "floor"] + ["wall"] * (2 if walls else 0) + ["corner"] * (2 if corners else 0)
        if i > 0:
            choices += ["stack"] * 2 + ["beside"] * 3
        strategy = str(rng.choice(choices))
        objects.append(PlannedObject(kind, source, size, rotation, strategy, aspect))
    return Plan((float(width), float(depth), height), walls, ceiling, objects)


def _check(s: ComposeSettings) -> None:
    ranges = {"objects": s.objects, "walls": s.walls, "room": s.room, "height": s.height, "size": s.size}
    for name, (lo, hi) in ranges.items():
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
            raise NeuralaoError(f"compose.{name} must be a range [lo, hi] with 0 <= lo <= hi, got {[lo, hi]}")
    if s.walls[1] > 4:
        raise NeuralaoError(f"compose.walls must lie within [0, 4], got {list(s.walls)}")
    if s.room[0] <= 0 or s.height[0] <= 0 or s.size[0] <= 0:
        raise NeuralaoError("compose.room, compose.height and compose.size must be positive")
    for name in ("mesh_fraction", "ceiling", "tumble"):
        p = getattr(s, name)
        if not 0 <= p <= 1:
            raise NeuralaoError(f"compose.{name} is a probability in [0, 1], got {p!r}")


# ---------------------------------------------------------------------------------- placement


def _sweep(moving: _Part, offset: np.ndarray, statics: list[tuple[int, _Part]], direction: np.ndarray):
    """How far ``moving`` (its object coordinates + ``offset``) can travel along unit ``direction``
    before it touches one of ``statics``. Returns (distance, index of the part touched) or (inf, -1)."""
    best, who = math.inf, -1
    lo, hi = moving.lo + offset, moving.hi + offset
    reach = 1e3 * float(np.abs(hi - lo).max() + 1.0)
    swept_lo = np.minimum(lo, lo + direction * reach)
    swept_hi = np.maximum(hi, hi + direction * reach)
    for index, part in statics:
        if np.any(part.hi < swept_lo - 1e-9) or np.any(part.lo > swept_hi + 1e-9):
            continue
        t1 = part.distances(moving.probes + offset, direction)
        near = part.probes[
            np.all((part.probes >= swept_lo - 1e-9) & (part.probes <= swept_hi + 1e-9), axis=1)
        ]
        t2 = moving.distances(near - offset, -direction)
        t = min(t1.min(initial=math.inf), t2.min(initial=math.inf))
        if t < best:
            best, who = t, index
    return best, who


def _overlaps(lo: np.ndarray, hi: np.ndarray, part: _Part, axes=(0, 1, 2)) -> bool:
    return all(part.lo[a] < hi[a] and part.hi[a] > lo[a] for a in axes)


def _place(
    obj: _Part,
    strategy: str,
    placed: list[tuple[int, str, _Part]],
    room: tuple[float, float, float],
    walls: tuple[str, ...],
    rng: np.random.Generator,
) -> tuple[np.ndarray, int, str] | None:
    """Offset (3,) of ``obj`` into the room by ``strategy``, the index of the part it rests on and
    the strategy used (``beside`` becomes ``stack`` when its start is taken); None if it does not fit.
    ``placed`` holds (index, kind, part) of the room (floor first) and the objects placed so far."""
    width, depth, height = room
    lo, hi = obj.lo, obj.hi
    xr = (-width / 2 - lo[0], width / 2 - hi[0])
    zr = (-depth / 2 - lo[2], depth / 2 - hi[2])
    if xr[0] > xr[1] or zr[0] > zr[1]:
        return None
    floor = [(i, p) for i, k, p in placed if k == "floor"]
    objects = [(i, p) for i, k, p in placed if k not in ("floor", "wall", "ceiling")]
    x, z = rng.uniform(*xr), rng.uniform(*zr)
    if strategy == "wall":
        sides: tuple[str, ...] = (walls[int(rng.integers(len(walls)))],)
    elif strategy == "corner":
        corners = [c for c in _ADJACENT if c[0] in walls and c[1] in walls]
        sides = corners[int(rng.integers(len(corners)))]
    else:
        sides = ()
    for side in sides:  # flush: the rotated bounding box's extreme touches the wall plane exactly
        if side[1] == "x":
            x = xr[0] if side[0] == "-" else xr[1]
        else:
            z = zr[0] if side[0] == "-" else zr[1]
    if strategy in ("stack", "beside") and objects:
        _, target = objects[int(rng.integers(len(objects)))]
        centre = (target.lo + target.hi) / 2
        if strategy == "stack":
            jitter = rng.uniform(-0.3, 0.3, size=2) * (target.hi - target.lo)[[0, 2]]
            x, z = np.clip(centre[0] + jitter[0], *xr), np.clip(centre[2] + jitter[1], *zr)
        else:
            angle = rng.uniform(0, 2 * math.pi)
            direction = np.array([math.cos(angle), 0.0, math.sin(angle)])
            gap = np.linalg.norm((target.hi - target.lo)[[0, 2]]) / 2 + np.linalg.norm((hi - lo)[[0, 2]]) / 2
            start = centre + direction * (gap + 0.01)
            offset = np.array([np.clip(start[0], *xr), _LIFT - lo[1], np.clip(start[2], *zr)])
            if not any(_overlaps(lo + offset, hi + offset, p) for _, p in objects):
                statics = objects + [(i, p) for i, k, p in placed if k == "wall"]
                t, _ = _sweep(obj, offset, statics, -direction)
                if math.isfinite(t):
                    offset = offset - direction * t
                # Back onto the floor: sliding at _LIFT it stopped at anything taller, so nothing is under it.
                offset[1] = -lo[1]
                return offset, floor[0][0], "beside"
            strategy = "stack"  # start position taken: drop it from above there instead
            x, z = offset[0], offset[2]
    offset = np.array([x, 0.0, z])
    below = [p.hi[1] for _, p in objects if _overlaps(lo + offset, hi + offset, p, axes=(0, 2))]
    offset[1] = max([0.0, *below]) + _DROP_MARGIN - lo[1]
    # Walls are excluded: a drop runs parallel to them (and a flush object touches one exactly).
    t, who = _sweep(obj, offset, floor + objects, np.array([0.0, -1.0, 0.0]))
    if not math.isfinite(t):
        return None
    offset[1] -= t
    if offset[1] + hi[1] > 0.97 * height:  # under the ceiling (and no taller stacks without one)
        return None
    return offset, who, "floor" if strategy == "beside" else strategy


def compose_parts(settings: ComposeSettings, split: str = "train", name: str | None = None) -> Composition:
    """Compose the scene of ``settings`` (see the module doc) with its parts listed."""
    p = plan(settings, split)
    width, depth, height = p.room
    parts: list[tuple[int, str, _Part]] = []
    records: list[Placed] = []
    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    counts = [0, 0]

    def add(kind: str, source: str, part: _Part, placement: str = "", support: int = -1) -> None:
        index = len(records)
        parts.append((index, kind, part))
        records.append(
            Placed(
                kind,
                source,
                (counts[0], counts[0] + len(part.vertices)),
                (counts[1], counts[1] + len(part.faces)),
                placement,
                support,
            )
        )
        verts.append(part.vertices)
        faces.append(part.faces + counts[0])
        counts[0] += len(part.vertices)
        counts[1] += len(part.faces)

    for kind, side, v, f in _room(width, depth, height, p.walls, p.ceiling):
        add(kind, side, _Part(v, f))
    for i, item in enumerate(p.objects):
        if item.kind == "mesh":
            v, f = normalized_mesh(item.source)
            probes = None
        else:
            v, f = _primitive(item.kind, item.aspect)
            probes = _edge_probes(v, f, _EDGE_PROBES)
        v = (v * item.size) @ item.rotation.T
        probes = None if probes is None else (probes * item.size) @ item.rotation.T
        obj = _Part(v, f, probes)
        rng = np.random.default_rng([int(settings.seed) & 0xFFFFFFFF, 1, i])
        result = None
        for strategy in (item.strategy, "floor", "floor"):  # retries: a free spot on the floor
            result = _place(obj, strategy, parts, p.room, p.walls, rng)
            if result is not None:
                break
        if result is None:
            log.debug("compose seed %d: object %d (%s) does not fit; skipped", settings.seed, i, item.source)
            continue
        offset, support, used = result
        add(item.kind, item.source, obj.moved(offset), used, support)
    scene = scene_from_arrays(
        np.concatenate(verts),
        np.concatenate(faces),
        name or f"compose-{settings.seed}",
        f"compose:seed={settings.seed}",
        drop_degenerate=False,  # parts are clean; ranges must stay valid
    )
    return Composition(scene, records, p.room, p.walls, p.ceiling)


def compose(settings: ComposeSettings, split: str = "train", name: str | None = None) -> Scene:
    """A composed :class:`Scene` (see the module doc); meshes from ``settings.meshes`` or ``split``."""
    return compose_parts(settings, split, name).scene
