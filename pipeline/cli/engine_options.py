"""The flags that choose where a command's work runs (``--engine``, ``--address``, ``--ray-workers``,
``--ray-threads``, ``--ray-heavy-states``, ``--chunk-rays``) and the
:class:`~neuralao.pipeline.engines.engine.Engine` they describe."""

from __future__ import annotations

import argparse

from neuralao.pipeline.engines.engine import CHUNK_RAYS, Engine, LocalEngine, RayEngine
from neuralao.runtime.foundation.errors import NeuralaoError


def add_engine_arguments(p: argparse.ArgumentParser, chunks: bool = False) -> None:
    """--engine, --address, --ray-workers (and --chunk-rays for commands that trace point chunks)."""
    p.add_argument(
        "--engine",
        choices=("local", "ray"),
        default="local",
        help="where the work runs: this process (default) or a Ray cluster",
    )
    p.add_argument(
        "--address",
        default=None,
        metavar="HOST:PORT",
        help="Ray cluster address (`ray start --head` prints it); 'auto': the cluster on this "
        "machine; default: a private local Ray instance",
    )
    p.add_argument(
        "--ray-workers",
        type=int,
        default=None,
        metavar="N",
        help="Ray actors to start (default: as many as the cluster's CPUs hold)",
    )
    p.add_argument(
        "--ray-threads",
        type=int,
        default=None,
        metavar="T",
        help="CPUs and tracing threads per Ray actor (default 1; a machine's cores: one actor, one copy "
        "of a level's BVH per machine)",
    )
    p.add_argument(
        "--ray-heavy-states",
        type=int,
        default=None,
        metavar="H",
        help="BVHs a Ray actor may hold at once, so the next one is built while the current one is in use "
        "(default 2 with --ray-threads above 1, else 1)",
    )
    if chunks:
        p.add_argument(
            "--chunk-rays",
            type=int,
            default=None,
            metavar="N",
            help=f"rays per task (default {CHUNK_RAYS}); changes scheduling, never results",
        )


def engine_from_args(args: argparse.Namespace) -> Engine:
    chunk_rays = getattr(args, "chunk_rays", None)
    if chunk_rays is not None and chunk_rays < 1:
        raise NeuralaoError(f"--chunk-rays must be >= 1, got {chunk_rays}")
    if args.engine == "local":
        heavy = getattr(args, "ray_heavy_states", None)
        ray_flags = (args.address, args.ray_workers, getattr(args, "ray_threads", None), heavy, chunk_rays)
        if any(f is not None for f in ray_flags):
            raise NeuralaoError(
                "--address, --ray-workers, --ray-threads, --ray-heavy-states and --chunk-rays need "
                "--engine ray"
            )
        return LocalEngine()
    engine = RayEngine(
        args.address,
        args.ray_workers,
        1 if args.ray_threads is None else args.ray_threads,
        getattr(args, "ray_heavy_states", None),
    )
    engine.chunk_rays = chunk_rays
    return engine
