"""Outputs of a level bake: the baked glTF, the decorator shader and its manifest.

glTF layout (``OUT/level_baked.glb`` by default):

* one mesh per static instance, in world space: ``COLOR_0`` (RGBA8 normalised grey of the final
  AO), ``_AO`` (float, blended + remapped), ``_AO_SHORT`` and ``_AO_LONG`` (the two distances);
  node extras ``{"role": "static", "source_node": ...}``;
* one node per tree node: the shared model with ``_AO_LOCAL`` (local AO per model vertex) and
  EXT_mesh_gpu_instancing TRANSLATION / ROTATION / SCALE + ``_AO_GLOBAL`` (VEC4 per instance: the
  linear global function of equation 3, relative to the instance's translation);
* grass and shrub nodes: their model and instancing attributes + ``_AO`` (one scalar per instance);
* LOD 1 of the receivers: one mesh per piece (``lod1``, or ``lod1_<piece>`` with several) with
  ``COLOR_0`` / ``_AO`` / ``_AO_RESAMPLED``, extras ``{"lod": 1, "piece": <piece>}``.

Blockers are not written (they receive no AO). glTF allows application attributes only with a
leading underscore, hence the names.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from neuralao.export.glsl.decorator import decorator_shaders, manifest
from neuralao.pipeline.geometry.level_files import GltfWriter, decompose
from neuralao.pipeline.geometry.surface import vertex_colours
from neuralao.runtime.foundation.io import write_json, write_text
from neuralao.runtime.foundation.settings import settings_to_dict


def write_outputs(
    path: Path,
    out: Path,
    level,
    index,
    s,
    static_results,
    deco: dict,
    small: dict,
    lod_files,
    pieces,
) -> None:
    """Write the baked glTF, streamed: ``static_results`` yields each piece's glTF part (the output tasks'
    results, in piece order, as they arrive: its instances' meshes and nodes, made by the task) and the LOD
    comes piece by piece from ``lod_files`` (a pair: the LOD's results and its meshes, or None); the binary
    data goes to a file beside ``path`` as it is made, so memory holds one piece."""
    # Named as atomic_path names its temporaries, so a killed bake's rerun sweeps a stale one away.
    spill = path.with_name(f".{path.name}.spill.tmp")
    w = GltfWriter("neuralao level bake", spill=spill)
    try:  # an interrupted bake leaves no spill file behind
        w.doc["extras"] = {
            "bake": {
                "blend": settings_to_dict(s.blend),
                "half_distances": [s.trace.half_distance_short, s.trace.half_distance_long],
                "rays": s.trace.rays,
            }
        }
        for r in static_results:  # each piece's instances, written by its task for their place
            w.splice(r)
        trees = level.nodes_with("tree")
        rows = _coefficient_rows(trees, deco)
        written: dict[int, int] = {}
        for node in trees:
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
        for role, nodes in (("grass", level.nodes_with("grass")), ("shrub", level.nodes_with("shrub"))):
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
        if lod_files is not None:
            results, meshes = lod_files
            for piece in pieces:
                lod = results.get(f"p{piece.index:05d}")
                mesh = meshes.get(f"p{piece.index:05d}")
                if len(mesh["faces"]) == 0:
                    continue
                ao = np.asarray(lod["ao_least_squares"], np.float32)
                attrs = {
                    "COLOR_0": vertex_colours(ao),
                    "_AO": ao,
                    "_AO_RESAMPLED": np.asarray(lod["ao_vertex"], np.float32),
                }
                name = "lod1" if len(pieces) == 1 else f"lod1_{piece.index}"
                mi = w.mesh(name, mesh["vertices"], mesh["faces"], attrs)
                w.node(name, mi, extras={"role": "static", "lod": 1, "piece": piece.index})
        w.write(path)
    finally:
        w.close()
    shaders = decorator_shaders()
    write_text(out / "shaders" / "decorator.vert", shaders["vertex"])
    write_text(out / "shaders" / "decorator.frag", shaders["fragment"])
    write_json(out / "shaders" / "manifest.json", manifest())


def _coefficient_rows(trees, deco: dict) -> dict[int, np.ndarray]:
    """Per tree node index: (k, 4) float32 coefficients, in the order bake_decorators wrote them
    (models ascending, then the level's tree nodes of that model in order, instances in order)."""
    rows: dict[int, np.ndarray] = {}
    coeffs = np.asarray(deco.get("coefficients", np.zeros((0, 4))), np.float32)
    r = 0
    for mi in (int(m) for m in deco.get("models", [])):
        for node in (n for n in trees if n.mesh == mi):
            k = len(node.transforms)
            rows[node.index] = coeffs[r : r + k]
            r += k
    return rows
