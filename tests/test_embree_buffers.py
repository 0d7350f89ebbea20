"""Triangles handed to Embree as whole buffers answer every ray as embreex's per-element TriangleMesh does."""

from __future__ import annotations

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from helpers import soup_scene

from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.tracing import embree_buffers
from neuralao.pipeline.tracing.embree_buffers import attach_triangles, scene_handle
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings


def _rays(rng, n, scale):
    origins = (rng.normal(size=(n, 3)) * scale).astype(np.float32)
    dirs = rng.normal(size=(n, 3))
    return origins, (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)


def _both(vertices, faces):
    ours, theirs = rtcore_scene.EmbreeScene(), rtcore_scene.EmbreeScene()
    assert attach_triangles(ours, vertices, faces)
    TriangleMesh(theirs, vertices, faces)
    return ours, theirs


def test_same_hits_as_the_binding_on_a_mesh_and_on_soup():
    rng = np.random.default_rng(3)
    bunny = load_scene("bunny")
    soup, _ = soup_scene(rng)
    for scene in (bunny, soup):
        v = ((scene.vertices - scene.center) / scene.diagonal).astype(np.float32)
        f = np.asarray(scene.faces, np.int32)
        ours, theirs = _both(v, f)
        origins, dirs = _rays(rng, 20_000, 0.3)
        a = ours.run(origins, dirs, query="INTERSECT", output=True)
        b = theirs.run(origins, dirs, query="INTERSECT", output=True)
        assert (a["geomID"] >= 0).mean() > 0.05  # the rays do hit
        for key in b:
            np.testing.assert_array_equal(a[key], b[key])
        occluded = [s.run(origins, dirs, query="OCCLUDED", dists=0.1) for s in (ours, theirs)]
        np.testing.assert_array_equal(*occluded)


def test_labels_unchanged_and_the_fallback(monkeypatch):
    scene = load_scene("bunny")
    rng = np.random.default_rng(0)
    idx = rng.choice(len(scene.faces), 300, replace=False)
    points = scene.vertices[scene.faces[idx]].mean(axis=1)
    normals = scene.unit_face_normals()[idx]
    settings = LabelSettings(rays=64, workers=1)
    fast = Labeller(scene, settings).ao_at_points(points, normals)
    # The binding's path, as taken where the scene's layout is not the one checked for.
    monkeypatch.setattr(embree_buffers, "attach_triangles", lambda *args: False)
    slow = Labeller(scene, settings).ao_at_points(points, normals)
    monkeypatch.undo()
    assert fast[1].all() and 0.05 < float(fast[0].mean()) < 0.99
    np.testing.assert_array_equal(fast[0], slow[0])
    np.testing.assert_array_equal(fast[1], slow[1])
    # A committed scene is left alone.
    committed = rtcore_scene.EmbreeScene()
    TriangleMesh(committed, np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.int32))
    committed.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED", dists=1.0)
    assert scene_handle(committed) is None
    assert not attach_triangles(committed, np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.int32))
