"""Shared test helpers (trimesh's ``tests/generic.py`` habit): tiny analytic scenes and MC bounds.

Add helpers at the end; keep each one small, documented with shapes, and free of test logic.
"""

from __future__ import annotations

import math
import os
import signal
import threading
import time

import numpy as np
import onnx
import pytest
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.pipeline.geometry.scene import Scene, scene_from_arrays
from neuralao.runtime.chromium import chromium_paths
from neuralao.runtime.foundation.tolerances import TOL


def quad(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A planar quad from 4 corners (4, 3), counter-clockwise seen from the side its normal faces.

    Returns vertices (4, 3) float64 and faces (2, 3) int64 (right-handed winding keeps the normal).
    """
    return np.asarray(corners, dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)


def merge(*parts: tuple[np.ndarray, np.ndarray], name: str = "test") -> Scene:
    """Concatenate (vertices, faces) parts into one :class:`Scene`."""
    verts, faces, offset = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    return scene_from_arrays(np.concatenate(verts), np.concatenate(faces), name)


def floor_quad(half: float, z: float = 0.0, up: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Square [-half, half]^2 at height z, normal +z (``up``) or -z."""
    c = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return quad(c if up else c[::-1])


def wall_quad(
    x: float, half_width: float, height: float, facing_minus_x: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Wall in the plane X = x, y in [-half_width, half_width], z in [0, height]; normal -x or +x."""
    c = np.array(
        [[x, -half_width, 0.0], [x, -half_width, height], [x, half_width, height], [x, half_width, 0.0]]
    )
    return quad(c if facing_minus_x else c[::-1])


def box(half: float, inward: bool) -> tuple[np.ndarray, np.ndarray]:
    """Closed axis-aligned cube [-half, half]^3 (8 vertices, 12 faces), normals outward or inward."""
    v = np.array(
        [[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)], dtype=np.float64
    )
    # Outward, counter-clockwise seen from outside (index = 4x + 2y + z over {0,1}).
    f = np.array(
        [
            [0, 1, 3],
            [0, 3, 2],  # x = -half
            [4, 6, 7],
            [4, 7, 5],  # x = +half
            [0, 4, 5],
            [0, 5, 1],  # y = -half
            [2, 3, 7],
            [2, 7, 6],  # y = +half
            [0, 2, 6],
            [0, 6, 4],  # z = -half
            [1, 5, 7],
            [1, 7, 3],  # z = +half
        ],
        dtype=np.int64,
    )
    return v, (f[:, ::-1].copy() if inward else f)


def random_rotation(seed: int) -> np.ndarray:
    """(3, 3) float64 proper rotation, uniformly random (QR of a Gaussian matrix, sign-fixed)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def transformed(scene: Scene, rotation: np.ndarray, offset: np.ndarray | float = 0.0) -> Scene:
    """Scene with vertices @ rotation.T + offset (faces unchanged)."""
    return Scene(scene.vertices @ rotation.T + offset, scene.faces.copy(), scene.name)


def mc_bound(p: float | np.ndarray, samples: int | np.ndarray) -> float | np.ndarray:
    """Allowed |estimate - p| for a mean of ``samples`` values in [0, 1] with mean p.

    TOL.mc_sigmas standard errors, with the binomial variance p(1-p) (the largest variance any
    [0, 1]-valued variable with mean p can have, so also valid for obscurance and for stratified
    estimators, whose variance is lower), plus TOL.mc_abs_floor for p near 0 or 1.
    """
    p = np.clip(p, 0.0, 1.0)
    return TOL.mc_sigmas * np.sqrt(p * (1.0 - p) / samples) + TOL.mc_abs_floor


def segment_fraction(c: float) -> float:
    """Fraction of the unit disk's area with x > c (0 <= c <= 1): (acos c - c sqrt(1 - c^2)) / pi."""
    return (math.acos(c) - c * math.sqrt(1.0 - c * c)) / math.pi


def onnx_vs_torch_tol(ref: np.ndarray | float, model) -> float:
    """TOL.onnx_vs_torch's rule for reference values ``ref`` (any shape, or its max |value|) of ``model``:
    an ONNX ModelProto or .onnx path (depth: its Conv / ConvTranspose / Gemm / MatMul nodes), a torch
    module (its Conv2d / ConvTranspose2d / Linear modules) or the depth as an int."""
    if isinstance(model, int):
        depth = model
    elif hasattr(model, "modules"):  # a torch module, counted without importing torch here
        depth = sum(type(m).__name__ in ("Conv2d", "ConvTranspose2d", "Linear") for m in model.modules())
    else:
        from neuralao.export.onnx_io import weighted_layers

        depth = weighted_layers(model)
    return TOL.onnx_vs_torch(float(np.max(np.abs(ref))), depth)


# Skips a test (or, as ``pytestmark``, a module) where headless Chromium cannot start (runtime/chromium.py).
needs_chromium = pytest.mark.skipif(
    not all(chromium_paths()), reason="needs Debian's chromium and chromium-driver (make system-deps)"
)


def smooth_values(points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(k, 2) float64 in [0, 1] at ``points`` (k, 3), metres: two smooth signals of the position plus
    N(0, 0.05) noise, like the two AO distances' traced samples."""
    x, y, z = np.asarray(points, np.float64).T
    v = np.stack([0.5 + 0.4 * np.sin(x / 5) * np.cos(z / 7), 0.5 + 0.3 * np.sin(y / 3 + x / 11)], axis=1)
    return np.clip(v + rng.normal(0.0, 0.05, v.shape), 0.0, 1.0)


def under_footprints(points: np.ndarray, rng: np.random.Generator, count: int, half: float) -> np.ndarray:
    """(k,) bool: which of ``points`` (k, 3), Y up, lie under one of ``count`` yawed 4-9 m house footprints
    centred in [-half, half]^2 (x, z): the terrain inside the level generator's houses, which the back-face
    rule leaves without valid samples."""
    from scipy.spatial import cKDTree

    centres, sizes = rng.uniform(-half, half, (count, 2)), rng.uniform(4, 9, (count, 2))
    yaws = rng.uniform(0, math.pi, count)
    xz = np.asarray(points, np.float64)[:, [0, 2]]
    inside = np.zeros(len(xz), bool)
    for c, (w, d), yaw, near in zip(
        centres, sizes, yaws, cKDTree(xz).query_ball_point(centres, 6.5), strict=True
    ):
        near = np.asarray(near, np.int64)
        dx, dz = (xz[near] - c).T
        u, v = math.cos(yaw) * dx + math.sin(yaw) * dz, -math.sin(yaw) * dx + math.cos(yaw) * dz
        inside[near[(np.abs(u) < w / 2) & (np.abs(v) < d / 2)]] = True
    return inside


def ribbon(rng: np.random.Generator, quads: int, length: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """A wavy vertical strip of ``quads`` quads through the origin, ``length`` long: vertices (2 quads + 2,
    3) float64 and faces (2 quads, 3) int64; one connected part that crosses any cut of a soup."""
    t = np.linspace(-length / 2, length / 2, quads + 1)
    heading = rng.uniform(0, math.pi)
    along = np.array([math.cos(heading), 0.0, math.sin(heading)])
    side = np.array([-math.sin(heading), 0.0, math.cos(heading)])
    mid = t[:, None] * along + (3 * np.sin(t / 4 + rng.uniform(0, 6)))[:, None] * side + [0, 2, 0]
    i, j = np.arange(quads), np.arange(quads) + quads + 1
    faces = np.concatenate([np.stack([i, i + 1, j + 1], 1), np.stack([i, j + 1, j], 1)])
    return np.concatenate([mid, mid + [0, 1.5, 0]]), faces


def soup_scene(rng: np.random.Generator, houses: int = 30, half: float = 40.0) -> tuple[Scene, int]:
    """Triangle soup over [-half, half]^2: ``houses`` of the level generator's houses (overlapping boxes with
    split vertices), 300 interpenetrating random triangles, 100 of them duplicated (own vertices, same
    positions), 20 fans sharing a vertex, 8 closed ellipsoids through it all and 6 ribbons across it.
    Returns the scene and the index of the first ribbon's first face (its faces: the next 2 x 150)."""
    from neuralao.pipeline.geometry.level_gen import ellipsoid, house, merge_parts

    parts = []
    for _ in range(houses):
        v, f = house(rng, 5)
        parts.append((v + [rng.uniform(-half, half), 0.0, rng.uniform(-half, half)], f))
    tri = (rng.uniform(-half, half, (300, 3)) * [1, 0.2, 1])[:, None] + rng.normal(0, 2.0, (300, 3, 3))
    parts.append((tri.reshape(-1, 3), np.arange(900).reshape(-1, 3)))
    parts.append((tri[:100].reshape(-1, 3).copy(), np.arange(300).reshape(-1, 3)))
    for _ in range(20):
        centre = rng.uniform(-half, half, 3) * [1, 0.2, 1]
        ring = centre + rng.normal(0, 1.5, (8, 3))
        parts.append((np.r_[centre[None], ring], np.array([[0, 1 + i, 1 + (i + 1) % 8] for i in range(8)])))
    for _ in range(8):
        parts.append(
            ellipsoid(rng.uniform(-0.75 * half, 0.75 * half, 3) * [1, 0.1, 1], rng.uniform(3, 8, 3), 2)
        )
    first_ribbon = sum(len(f) for _, f in parts)
    parts += [ribbon(rng, 150, 1.5 * half) for _ in range(6)]
    return scene_from_arrays(*merge_parts(*parts), "soup", drop_degenerate=False), first_ribbon


# ------------------------------------------------------------------ small image graphs of the shader targets


def image_model(nodes, inits=(), in_shape=(1, 6, 5, 7), extra_inputs=(), opset=20) -> onnx.ModelProto:
    """A graph of ``nodes`` from input ``x`` (float, ``in_shape``) and ``extra_inputs`` to output ``y``,
    with the initializers ``inits`` ((name, array) pairs)."""
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, list(in_shape)), *extra_inputs],
        [oh.make_tensor_value_info("y", TensorProto.FLOAT, None)],
        [nh.from_array(np.asarray(v), k) for k, v in inits],
    )
    return oh.make_model(graph, opset_imports=[oh.make_opsetid("", opset)])


def seeded_weights(shape, seed=1) -> np.ndarray:
    """Normal weights of ``shape``, float32, from ``seed``."""
    return np.random.default_rng(seed).normal(size=shape).astype(np.float32)


def named_node(op, inputs=("x",), out="y", **attrs) -> onnx.NodeProto:
    """A node of ``op`` with a name holding spaces (names never reach shader text)."""
    return oh.make_node(op, list(inputs), [out], name=f"my {op.lower()} {out}", **attrs)


# ------------------------------------------------------------------ a G-buffer without a renderer


def analytic_gbuffer(width: int, height: int, yfov: float = 0.9) -> dict:
    """A G-buffer frame ray-cast in numpy (no GL): a floor (y = -1), a back wall (z = -6, up to y = 1.2, so
    the top rows are background), a sphere resting on the floor and a box against the wall, seen by an
    OpenGL camera at the origin looking down -z. Keys as a rendered frame's: depth (H, W) float32 (-z_cam,
    0 on background), normal_cam (H, W, 3) float32 (unit, facing the viewer), mask (H, W) bool, yfov."""
    t = math.tan(yfov / 2)
    x = ((np.arange(width) + 0.5) / width * 2 - 1) * t * width / height
    y = (1 - (np.arange(height) + 0.5) / height * 2) * t
    d = np.stack(np.broadcast_arrays(x[None, :], y[:, None], -np.ones((height, width))), -1)  # ray at depth 1
    best = np.full((height, width), np.inf)
    normal = np.zeros((height, width, 3))

    def hit(s, n, ok):
        better = ok & (s > 1e-6) & (s < best)
        best[better] = s[better]
        normal[better] = np.broadcast_to(n, normal.shape)[better]

    with np.errstate(divide="ignore", invalid="ignore"):
        s = -1.0 / d[..., 1]  # floor y = -1
        p = d * s[..., None]
        hit(s, np.array([0.0, 1.0, 0.0]), (p[..., 2] > -9) & (np.abs(p[..., 0]) < 4))
        s = np.full((height, width), 6.0)  # wall z = -6
        p = d * 6.0
        hit(s, np.array([0.0, 0.0, 1.0]), (p[..., 1] < 1.2) & (np.abs(p[..., 0]) < 3))
        c, r = np.array([0.4, -0.45, -3.6]), 0.55  # sphere on the floor
        b = np.einsum("hwc,c->hw", d, c)
        dd = np.einsum("hwc,hwc->hw", d, d)
        disc = b * b - dd * (c @ c - r * r)
        s = (b - np.sqrt(np.maximum(disc, 0))) / dd
        hit(s, (d * s[..., None] - c) / r, disc > 0)
        lo, hi = np.array([-1.9, -1.0, -5.9]), np.array([-0.9, 0.1, -4.8])  # box against the wall
        t0, t1 = (lo - 0.0) / d, (hi - 0.0) / d
        tn, tf = np.minimum(t0, t1), np.maximum(t0, t1)
        near, far = tn.max(-1), tf.min(-1)
        axis = tn.argmax(-1)
        n = np.zeros((height, width, 3))
        np.put_along_axis(n, axis[..., None], -np.sign(np.take_along_axis(d, axis[..., None], -1)), -1)
        hit(near, n, near < far)
    mask = np.isfinite(best)
    depth = np.where(mask, best, 0.0)  # the ray at depth 1 has z = -1: the parameter is the depth
    normal = np.where(mask[..., None], normal, 0.0)
    return {
        "depth": depth.astype(np.float32),
        "normal_cam": normal.astype(np.float32),
        "mask": mask,
        "yfov": float(yfov),
    }


def both_presets(model: onnx.ModelProto, ref: np.ndarray, run, tol: float, relative: bool = False, **options):
    """Generate ``model``'s compute GLSL under the ``gpu`` and the ``cpu`` preset (``options`` go to
    generate_compute), validate every shader, run each with ``run(program)`` and compare with ``ref``
    (absolute error, or relative to max(1, |ref|)). Returns the ``cpu`` program: its passes are unfused,
    one per layer or fused group, which is what structural assertions read."""
    from neuralao.export.glsl import generate_compute, validate_glsl

    programs = {preset: generate_compute(model, preset=preset, **options) for preset in ("gpu", "cpu")}
    for preset, program in programs.items():
        for src in program.sources.values():
            validate_glsl(src, "comp")
        got = run(program)
        assert got.shape == ref.shape and got.dtype == ref.dtype == np.float32, (preset, got.shape)
        diff = np.abs(got - ref) / (np.maximum(1.0, np.abs(ref)) if relative else 1.0)
        err = float(diff.max())
        assert err <= tol, f"{preset} preset: max abs err {err:.3g} > {tol}"
    return programs["cpu"]


def kill_a_worker_mid_run(engine, run, ready, what: str, worker: int = 1, timeout: float = 90):
    """``run()`` on a thread; once ``ready()`` (polled) the Ray ``engine``'s actor ``worker`` is SIGKILLed.
    Returns what ``run`` returned, after checking that it finished and that the actor was restarted (a new
    process)."""
    pid = engine.worker_info()[worker][0]
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(value=run()))
    thread.start()
    deadline = time.time() + timeout
    while not ready() and thread.is_alive():
        assert time.time() < deadline, f"no {what} within {timeout} s"
        time.sleep(0.002)
    assert thread.is_alive(), f"the run finished before a worker could be killed ({what})"
    os.kill(pid, signal.SIGKILL)
    thread.join(180)
    assert not thread.is_alive() and "value" in result
    assert engine.worker_info()[worker][0] != pid, "the killed actor was restarted"
    return result["value"]


def with_changes(doc: dict, changes: dict) -> dict:
    """``doc`` (nested dicts and lists) with each ``"a.0.b": value`` of ``changes`` set at its dotted path
    (list indices as digits), in place; returns ``doc``."""
    for path, value in changes.items():
        node = doc
        *parents, last = path.split(".")
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node[key]
        node[int(last) if isinstance(node, list) else last] = value
    return doc
