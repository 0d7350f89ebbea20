"""Outputs of a level bake: the baked glTF, the decorator shader and its manifest.

glTF layout (``OUT/level_baked.glb`` by default):

* one mesh per static instance, in world space: ``COLOR_0`` (RGBA8 normalised grey of the final
  AO), ``_AO`` (float, blended + remapped), ``_AO_SHORT`` and ``_AO_LONG`` (the two distances);
  node extras ``{"role": "static", "source_node": ...}``;
* one node per tree node: the shared model with ``_AO_LOCAL`` (local AO per model vertex) and
  EXT_mesh_gpu_instancing TRANSLATION / ROTATION / SCALE + ``_AO_GLOBAL`` (VEC4 per instance: the
  linear global function of equation 3, relative to the instance's translation);
* grass and shrub nodes: their model and instancing attributes + ``_AO`` (one scalar per instance);
* LOD 1 of the receivers: one mesh with ``COLOR_0`` / ``_AO``, extras ``{"lod": 1}``.

Blockers are not written (they receive no AO). glTF allows application attributes only with a
leading underscore, hence the names.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from export.glsl.decorator import decorator_shaders, manifest
from pipeline.foundation.io import write_json, write_text
from pipeline.foundation.settings import settings_to_dict
from pipeline.geometry.level_files import GltfWriter, decompose
from pipeline.geometry.surface import vertex_colours


def write_outputs(
    path: Path, out: Path, g, s, solved: dict, final: np.ndarray, deco: dict, small: dict, lod: dict | None
) -> None:
    w = GltfWriter("neuralao level bake")
    w.doc["extras"] = {
        "bake": {
            "blend": settings_to_dict(s.blend),
            "half_distances": [s.trace.half_distance_short, s.trace.half_distance_long],
            "rays": s.trace.rays,
        }
    }
    level = g.level
    rv = g.receivers.vertices
    for k, j, v0, f0 in g.static_spans:
        node = g.static_nodes[k]
        mesh = level.meshes[node.mesh]
        sl = slice(v0, v0 + len(mesh.vertices))
        attrs = {
            "COLOR_0": vertex_colours(final[sl]),
            "_AO": final[sl],
            "_AO_SHORT": solved["short"][sl],
            "_AO_LONG": solved["long"][sl],
        }
        mi = w.mesh(f"{node.name}_{j}", rv[sl], g.receivers.faces[f0 : f0 + len(mesh.faces)] - v0, attrs)
        w.node(
            f"{node.name}_{j}" if len(node.transforms) > 1 else node.name,
            mi,
            extras={"role": "static", "source_node": node.index, "instance": j},
        )
    rows = _coefficient_rows(g, deco)
    written: dict[int, int] = {}
    for node in g.trees:
        mesh = level.meshes[node.mesh]
        if node.mesh not in written:
            written[node.mesh] = w.mesh(
                mesh.name, mesh.vertices, mesh.faces, {"_AO_LOCAL": deco[f"local_{node.mesh}"]}
            )
        t, q, sc = decompose(node.transforms)
        w.node(
            node.name,
            written[node.mesh],
            extras={"role": "tree", **node.params},
            instances={"TRANSLATION": t, "ROTATION": q, "SCALE": sc, "_AO_GLOBAL": rows[node.index]},
        )
    for role, nodes in (("grass", g.grass), ("shrub", g.shrubs)):
        for kk, node in enumerate(nodes):
            mesh = level.meshes[node.mesh]
            t, q, sc = decompose(node.transforms)
            mi = w.mesh(mesh.name, mesh.vertices, mesh.faces)
            w.node(
                node.name,
                mi,
                extras={"role": role, **node.params},
                instances={"TRANSLATION": t, "ROTATION": q, "SCALE": sc, "_AO": small[f"{role}_{kk}"]},
            )
    if lod is not None:
        ao = np.asarray(lod["ao_least_squares"], np.float32)
        mi = w.mesh(
            "lod1",
            lod["vertices"],
            lod["faces"],
            {
                "COLOR_0": vertex_colours(ao),
                "_AO": ao,
                "_AO_RESAMPLED": np.asarray(lod["ao_vertex"], np.float32),
            },
        )
        w.node("lod1", mi, extras={"role": "static", "lod": 1})
    w.write(path)
    shaders = decorator_shaders()
    write_text(out / "shaders" / "decorator.vert", shaders["vertex"])
    write_text(out / "shaders" / "decorator.frag", shaders["fragment"])
    write_json(out / "shaders" / "manifest.json", manifest())


def _coefficient_rows(g, deco: dict) -> dict[int, np.ndarray]:
    """Per tree node index: (k, 4) float32 coefficients, in the order bake_decorators wrote them
    (models ascending, then the level's tree nodes of that model in order, instances in order)."""
    rows: dict[int, np.ndarray] = {}
    coeffs = np.asarray(deco.get("coefficients", np.zeros((0, 4))), np.float32)
    r = 0
    for mi in (int(m) for m in deco.get("models", [])):
        for node in (n for n in g.trees if n.mesh == mi):
            k = len(node.transforms)
            rows[node.index] = coeffs[r : r + k]
            r += k
    return rows
