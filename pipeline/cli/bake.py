"""`neuralao bake`: per-vertex AO of a mesh (:mod:`neuralao.pipeline.bakes.vertex`), an AO texture map
(``--to texture``, :mod:`neuralao.pipeline.bakes.texture`), a glTF scene with its nodes and materials kept
(:mod:`neuralao.pipeline.bakes.gltf_scene`), or a game level (``--config``,
:mod:`neuralao.pipeline.bakes.level`).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.pipeline.bakes.gltf_scene import (
    bake_texture_scene,
    bakes_as_scene,
    read_gltf_scene,
    write_texture_scene,
    write_vertex_scene,
)
from neuralao.pipeline.bakes.level import bake_level
from neuralao.pipeline.bakes.level_settings import load_level_settings
from neuralao.pipeline.bakes.texture import (
    TextureBakeSettings,
    bake_texture,
    load_uv_mesh,
    png_path_for,
    quantise,
    texture_glb_bytes,
)
from neuralao.pipeline.bakes.texture import check_settings as check_texture_settings
from neuralao.pipeline.bakes.vertex import (
    OUTPUT_SUFFIXES,
    BakeSettings,
    bake,
    check_settings,
    write_baked_mesh,
)
from neuralao.pipeline.cli.engine_options import add_engine_arguments, engine_from_args
from neuralao.pipeline.engines.engine import ResultStore
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.tracing.labeller import check_label_args, label_fields
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import publish_together, write_bytes, write_png
from neuralao.runtime.foundation.paths import FILE, FOLDER

log = logging.getLogger(__name__)

# What the command reads, checked with its outputs before it runs (cli.main.check_arguments).
INPUTS = ("mesh", "config")
MESH_INPUTS = ("mesh",)  # mesh names: a file, a glTF folder or a bare name


def OUTPUTS(args: argparse.Namespace) -> dict:  # noqa: N802 (the name every command module uses)
    """--out is a mesh file, or with --config a level bake's folder (what is checked before any work); a
    texture bake of a mesh that is not a glTF scene also writes its map beside it, OUT.ao.png."""
    if args.config is not None:
        return {"out": FOLDER}
    try:
        glb = args.to == "texture" and Path(args.out).suffix.lower() == ".glb"
        map_beside = glb and not bakes_as_scene(args.mesh, args.out)
    except (NeuralaoError, OSError):  # no mesh there: run refuses it, in its own words
        map_beside = False
    return {"out": FILE, **({"the map beside --out": (png_path_for(args.out), FILE)} if map_beside else {})}


# Single-mesh flags that have no meaning for a level (its settings come from --config and --set).
_MESH_ONLY_FLAGS = (
    "rays",
    "max_distance",
    "kernel",
    "half_distance",
    "method",
    "alpha",
    "samples_per_vertex",
    "samples_per_face_cap",
    "seed",
    "workers",
    "to",
    "resolution",
    "margin",
    "uv",
)
# Flags of the vertex bake only, and of the texture bake only (refused with the other --to).
_VERTEX_ONLY_FLAGS = ("method", "alpha", "samples_per_vertex", "samples_per_face_cap")
_TEXTURE_ONLY_FLAGS = ("resolution", "margin", "uv")
# Flags of the least-squares fit (refused with --method vertex, which samples at the vertices).
_LEAST_SQUARES_FLAGS = ("alpha", "samples_per_vertex", "samples_per_face_cap")


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = BakeSettings()
    p.add_argument(
        "mesh", help="mesh file (.obj .ply .gltf .glb .stl .off), glTF folder, or a bare test-mesh name"
    )
    p.add_argument("--rays", type=int, default=None, help=f"AO rays per sample (default {d.rays})")
    p.add_argument(
        "--max-distance",
        type=float,
        default=None,
        help="longest AO ray, scene units (default 0.25 x diagonal)",
    )
    p.add_argument(
        "--kernel", choices=("binary", "obscurance"), default=None, help="AO kernel (default binary)"
    )
    p.add_argument(
        "--half-distance",
        type=float,
        default=None,
        help="obscurance: distance at which a hit counts half, scene units (default 0.05 x diagonal)",
    )
    p.add_argument(
        "--method",
        choices=("vertex", "least-squares"),
        default=None,
        help="sample at vertices, or fit vertex values to surface samples (default least-squares)",
    )
    p.add_argument(
        "--alpha", type=float, default=None, help="least-squares edge regulariser weight (default 1)"
    )
    p.add_argument(
        "--samples-per-vertex",
        type=float,
        default=None,
        help=f"least-squares surface sample budget per vertex (default {d.samples_per_vertex:g})",
    )
    p.add_argument(
        "--samples-per-face-cap",
        type=int,
        default=None,
        help=f"least-squares: at most this many samples on one face (default {d.samples_per_face_cap})",
    )
    p.add_argument(
        "--seed", type=int, default=None, help="seed of sample positions and ray directions (default 0)"
    )
    p.add_argument("--workers", type=int, default=None, help="tracing threads (default 2)")
    p.add_argument(
        "--config",
        default=None,
        metavar="CONFIG.json",
        help="bake a game level (.gltf/.glb with roles in node extras) with these level settings "
        "(neuralao.pipeline.bakes.level_settings.LevelBakeSettings); --out is then a folder",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="with --config: override a level setting, e.g. trace.rays=64 (repeatable)",
    )
    p.add_argument(
        "--to",
        choices=("vertex", "texture"),
        default=None,
        help="per-vertex AO, or an AO texture map (occlusionTexture of OUT.glb + OUT.ao.png; "
        "neuralao.pipeline.bakes.texture) (default vertex)",
    )
    _add_texture_arguments(p)
    p.add_argument(
        "--out",
        required=True,
        metavar="OUT.ply|OUT.glb|DIR",
        help="output mesh with per-vertex AO (a folder with --config)",
    )
    add_engine_arguments(p, chunks=True)


def _add_texture_arguments(p: argparse.ArgumentParser) -> None:
    """Texture-only flags (the tracing flags are the vertex bake's)."""
    d = TextureBakeSettings()
    p.add_argument(
        "--resolution",
        type=int,
        default=None,
        help=f"--to texture: texture size in texels (default {d.resolution})",
    )
    p.add_argument(
        "--margin",
        type=int,
        default=None,
        help=f"--to texture: gutter dilated around the UV charts, texels (default {d.margin})",
    )
    p.add_argument(
        "--uv",
        choices=("auto", "mesh", "xatlas"),
        default=None,
        help="--to texture: the mesh's UVs, an xatlas atlas, or the mesh's when usable (default auto)",
    )


def settings_from_args(args: argparse.Namespace) -> BakeSettings:
    check_label_args(args)
    settings = BakeSettings(
        **label_fields(args),
        method=args.method,
        alpha=args.alpha,
        samples_per_vertex=args.samples_per_vertex,
        samples_per_face_cap=args.samples_per_face_cap,
    )
    check_settings(settings)
    return settings


def texture_settings_from_args(args: argparse.Namespace) -> TextureBakeSettings:
    d = TextureBakeSettings()
    check_label_args(args)
    s = TextureBakeSettings(
        resolution=d.resolution if args.resolution is None else args.resolution,
        # The default gutter shrinks with a small texture (it may be at most a quarter of it).
        margin=min(d.margin, (args.resolution or d.resolution) // 4) if args.margin is None else args.margin,
        uv=args.uv or d.uv,
        **label_fields(args),
    )
    check_texture_settings(s)
    return s


def _given(args: argparse.Namespace, flags: tuple[str, ...]) -> list[str]:
    """The flags of ``flags`` given on the command line (each defaults to None: given means set)."""
    return [f for f in flags if getattr(args, f) is not None]


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _fill_defaults(args: argparse.Namespace) -> None:
    """Every mesh flag left out takes its default (one place for them: the settings classes)."""
    d = BakeSettings()
    defaults = {
        "rays": d.rays,
        "kernel": d.kernel,
        "method": d.method,
        "alpha": d.alpha,
        "samples_per_vertex": d.samples_per_vertex,
        "samples_per_face_cap": d.samples_per_face_cap,
        "seed": 0,
        "workers": 2,
        "to": "vertex",
    }
    for name, value in defaults.items():
        if getattr(args, name) is None:
            setattr(args, name, value)


def run(args: argparse.Namespace) -> int:
    """One parser for the four bakes: the mode follows from the input (a level with ``--config``, a glTF
    scene, a mesh) and ``--to``; a flag of another mode is refused in one line before any work."""
    if args.config is not None:
        if Path(args.mesh).suffix.lower() not in (".gltf", ".glb"):
            raise NeuralaoError(f"--config bakes a level: expected a .gltf or .glb file, got {args.mesh!r}")
        given = _given(args, _MESH_ONLY_FLAGS)
        if given:
            raise NeuralaoError(f"{_flag(given[0])} does not apply to a level; use --set trace.KEY=VALUE")
        # --engine ray: every heavy stage runs as tasks (neuralao.pipeline.bakes.level)
        return run_level(args)
    if args.set:
        raise NeuralaoError("--set needs --config (level bakes only)")
    to = args.to or "vertex"
    refused = _given(args, _VERTEX_ONLY_FLAGS if to == "texture" else _TEXTURE_ONLY_FLAGS)
    if refused:
        raise NeuralaoError(f"{_flag(refused[0])} does not apply to --to {to}")
    if args.method == "vertex" and (fitted := _given(args, _LEAST_SQUARES_FLAGS)):
        raise NeuralaoError(f"{_flag(fitted[0])} applies to --method least-squares only")
    _fill_defaults(args)
    if args.to == "texture":
        if getattr(args, "engine", "local") != "local":
            raise NeuralaoError("texture bakes run locally (--engine ray is for vertex bakes and datasets)")
        return run_texture(args)
    return run_vertex(args)


def run_vertex(args: argparse.Namespace) -> int:
    settings = settings_from_args(args)
    out = Path(args.out)
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise NeuralaoError(f"--out must end in .ply or .glb, got {out.name!r}")
    if out.exists() and out.is_dir():
        raise NeuralaoError(f"--out {out} is a folder")
    engine = engine_from_args(args)
    # a glTF to a .glb is baked as a scene (neuralao.pipeline.bakes.gltf_scene): nodes, materials and
    # textures kept
    gltf = read_gltf_scene(args.mesh) if bakes_as_scene(args.mesh, out) else None
    scene = load_scene(args.mesh) if gltf is None else gltf.world
    # On a cluster, finished chunks are kept beside OUT until it is written (a rerun resumes).
    store = None if engine.name == "local" else ResultStore(out.parent / f".{out.name}.chunks")
    with engine:
        result = bake(scene, settings, progress=True, engine=engine, store=store)
    if gltf is None:
        write_baked_mesh(out, scene, result.ao)
    else:
        write_vertex_scene(out, gltf, result.ao, {"settings": result.info["settings"]})
    if store is not None:
        store.clear()
    i = result.info
    log.info(
        "baked %s (%d vertices, %s, %d samples, %d invalid) in %.1f s -> %s",
        scene.name,
        i["vertices"],
        i["method"],
        i["samples"],
        i["invalid_samples"],
        i["seconds"],
        out,
    )
    return 0


def run_texture(args: argparse.Namespace) -> int:
    settings = texture_settings_from_args(args)
    out = Path(args.out)
    if out.suffix.lower() != ".glb":
        raise NeuralaoError(f"--to texture writes a .glb, got --out {out.name!r}")
    if out.exists() and out.is_dir():
        raise NeuralaoError(f"--out {out} is a folder")
    if bakes_as_scene(
        args.mesh, out
    ):  # nodes, materials and textures kept (neuralao.pipeline.bakes.gltf_scene)
        return run_texture_scene(args.mesh, out, settings)
    mesh = load_uv_mesh(args.mesh, settings)
    result = bake_texture(mesh, settings, progress=True)
    data = texture_glb_bytes(mesh, result.ao)
    with publish_together():  # both files or neither (a full disk on the second)
        write_png(png_path_for(out), quantise(result.ao))
        write_bytes(out, data)
    i = result.info
    log.info(
        "baked %s (%d faces, %s UVs, %dx%d, %d texels, %d invalid) in %.1f s -> %s + %s",
        mesh.name,
        i["faces"],
        i["uv_source"],
        i["resolution"],
        i["resolution"],
        i["texels_covered"],
        i["invalid_texels"],
        i["seconds"],
        out,
        png_path_for(out).name,
    )
    return 0


def run_texture_scene(mesh: str, out: Path, settings: TextureBakeSettings) -> int:
    """``neuralao bake SCENE.gltf --to texture --out OUT.glb``."""
    gs = read_gltf_scene(mesh)
    images, layouts, info = bake_texture_scene(gs, settings, progress=True)
    write_texture_scene(
        out, gs, images, layouts, {"settings": info["settings"], "uv_sources": info["uv_sources"]}
    )
    log.info(
        "baked %s (%d primitives in %d nodes, %d maps %dx%d, %d texels, %d invalid) in %.1f s -> %s",
        gs.path.name,
        sum(p.written for p in gs.pieces),
        len({p.node for p in gs.pieces if p.written}),
        info["maps"],
        info["resolution"],
        info["resolution"],
        info["texels_covered"],
        info["invalid_texels"],
        info["seconds"],
        out,
    )
    return 0


def run_level(args: argparse.Namespace) -> int:
    """The level branch (``--config``)."""
    settings = load_level_settings(args.config, getattr(args, "set", None))
    if getattr(args, "chunk_rays", None) is not None:
        raise NeuralaoError("--chunk-rays does not apply to a level; use --set trace.block_samples=N")
    with engine_from_args(args) as engine:
        info = bake_level(
            args.mesh, settings, args.out, progress=True, engine=None if engine.name == "local" else engine
        )
    c = info["counts"]
    log.info(
        "baked level %s (%d vertices, %d faces, %d samples) in %.1f s -> %s",
        args.mesh,
        c["receiver_vertices"],
        c["receiver_faces"],
        c["samples"],
        info["seconds_total"],
        args.out,
    )
    return 0
