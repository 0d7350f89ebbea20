"""`neuralao volumes LEVEL --out VOLUMES.json [--regions REGIONS.json] [--glsl DIR]`: bake per-region
volume AO models for dynamic objects (Sloan et al. 2013); the work is
:mod:`neuralao.pipeline.bakes.volumes`'s."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from neuralao.export.glsl.volume import write_volume_glsl
from neuralao.pipeline.bakes.volumes import bake_volumes, check_settings, load_level_scene, read_regions
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import publish_together, write_json
from neuralao.runtime.foundation.paths import FILE, FOLDER
from neuralao.runtime.foundation.settings import add_set_option, load_settings
from neuralao.runtime.volumes import VolumeSettings, to_json

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FILE, "glsl": FOLDER}
INPUTS = ("level", "regions", "config")
MESH_INPUTS = ("level",)  # mesh names: a file, a glTF folder or a bare name


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "level",
        help="glTF level (roles in node extras: static + blocker geometry) or any mesh file "
        "(.obj .ply .gltf .glb .stl .off), glTF folder or test-mesh name",
    )
    p.add_argument("--out", required=True, metavar="VOLUMES.json", help="output models (JSON)")
    p.add_argument(
        "--regions",
        metavar="REGIONS.json",
        help="regions {'regions': [{'name', 'min', 'max'}], 'edges': [[i, j]]} (default: from free space)",
    )
    p.add_argument("--config", metavar="JSON", help="VolumeSettings preset (JSON object)")
    p.add_argument(
        "--glsl", metavar="DIR", help="also write the vertex-shader GLSL function and packed models here"
    )
    p.add_argument(
        "--order",
        choices=("linear", "quadratic"),
        default="linear",
        help="SH order of the GLSL function (default linear, as the paper's engine)",
    )
    add_set_option(p, "grid=12 or beta=2")


def run(args: argparse.Namespace) -> int:
    settings = load_settings(VolumeSettings, args.config, args.set)
    check_settings(settings)
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise NeuralaoError(f"--out must end in .json, got {out.name!r}")
    if out.is_dir():
        raise NeuralaoError(f"--out {out} is a folder")
    regions, pairs = read_regions(args.regions) if args.regions else (None, None)
    scene = load_level_scene(args.level)
    vol, _ = bake_volumes(scene, settings, regions, pairs, progress=True)
    with publish_together():  # the JSON and the shader folder, both or neither
        write_json(out, to_json(vol))
        if args.glsl:
            write_volume_glsl(vol, args.glsl, args.order)
    st = vol.stats
    log.info(
        "%d regions (%d edges, %d fallback), %d rays in %.1f s; boundary jump %.4f -> %.4f -> %s",
        st["regions"],
        st["edges"],
        st["fallback_regions"],
        st["rays"],
        st["seconds"]["total"],
        st["jump_before"]["area_weighted"],
        st["jump_after"]["area_weighted"],
        out,
    )
    return 0
