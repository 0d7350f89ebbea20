"""The flags that choose where a command's work runs (``--engine``, ``--address``, ``--ray-workers``,
``--chunk-rays``) and the :class:`~pipeline.engines.engine.Engine` they describe."""

from __future__ import annotations

import argparse

from pipeline.engines.engine import CHUNK_RAYS, Engine, LocalEngine, RayEngine
from pipeline.foundation.errors import NeuralaoError


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
        help="Ray actors to start (default: one per CPU of the cluster)",
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
        if args.address is not None or args.ray_workers is not None or chunk_rays is not None:
            raise NeuralaoError("--address, --ray-workers and --chunk-rays need --engine ray")
        return LocalEngine()
    engine = RayEngine(args.address, args.ray_workers)
    engine.chunk_rays = chunk_rays
    return engine
