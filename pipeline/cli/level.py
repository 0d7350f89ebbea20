"""`neuralao level`: write a seeded synthetic game level (glTF + bake config) for tests and benchmarks
(:mod:`neuralao.pipeline.geometry.level_gen`)."""

from __future__ import annotations

import argparse
import logging

from neuralao.pipeline.geometry.level_gen import PRESETS, settings_for, write_level
from neuralao.runtime.foundation.paths import FOLDER
from neuralao.runtime.foundation.settings import add_set_option

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", choices=sorted(PRESETS), default="tiny", help="level size (default tiny)")
    p.add_argument("--seed", type=int, help="seed of every random choice (default 0)")
    add_set_option(p, "houses=10")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for level.gltf, level.bin, bake.json")


def run(args: argparse.Namespace) -> int:
    s = settings_for(args.preset, args.seed, args.set)
    path, cfg = write_level(args.out, s, args.preset)
    log.info("wrote %s and %s", path, cfg)
    return 0
