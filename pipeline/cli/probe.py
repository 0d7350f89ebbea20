"""`neuralao probe VOLUMES.json --points P.npy --normals N.npy --out AO.npy`: evaluate volume AO models
at points and normals (:class:`neuralao.runtime.probe.VolumeProbe`)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path, read_npy
from neuralao.runtime.foundation.limits import FLOAT32_MAX, check_count
from neuralao.runtime.foundation.normals import normalize_normals
from neuralao.runtime.foundation.paths import FILE
from neuralao.runtime.probe import ORDERS, POINT_BYTES, VolumeProbe
from neuralao.runtime.volumes import read_volumes

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FILE}
INPUTS = ("volumes", "points", "normals")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("volumes", metavar="VOLUMES.json", help="models written by neuralao volumes")
    p.add_argument("--points", required=True, metavar="P.npy", help="(n, 3) world positions")
    p.add_argument("--normals", required=True, metavar="N.npy", help="(n, 3) normals (normalised here)")
    p.add_argument("--out", required=True, metavar="AO.npy", help="(n,) float32 AO in [0, 1]")
    p.add_argument(
        "--distance",
        choices=("blend", "short", "long"),
        default="blend",
        help="which AO: the file's blend of the two distances (default), or one of them",
    )
    p.add_argument("--order", choices=tuple(ORDERS), default="quadratic", help="SH order (default quadratic)")


def _load_rows(path: str, what: str, flag: str) -> np.ndarray:
    """(n, 3) float64 rows of an .npy of real numbers, every value finite and within float32's range (NaN,
    inf or a larger value refused, naming ``flag``: the probe's models are float32)."""
    a = read_npy(path, what)
    if a.ndim != 2 or a.shape[1] != 3:
        raise NeuralaoError(f"{what} {path} must be an (n, 3) numeric array, got {a.shape}")
    a = a.astype(np.float64)
    bad = int((~np.isfinite(a).all(axis=1)).sum())
    if bad:
        raise NeuralaoError(f"{flag} {path} has {bad} row(s) with NaN or inf")
    far = int((np.abs(a) > FLOAT32_MAX).any(axis=1).sum())
    if far:
        raise NeuralaoError(
            f"{flag} {path} has {far} row(s) with values past float32's largest, {FLOAT32_MAX:.4g}"
        )
    return a


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".npy":
        raise NeuralaoError(f"--out must end in .npy, got {out.name!r}")
    vol = read_volumes(args.volumes)
    points = _load_rows(args.points, "points", "--points")
    normals = _load_rows(args.normals, "normals", "--normals")
    if len(points) != len(normals):
        raise NeuralaoError(
            f"--points {args.points} has {len(points)} rows and --normals {args.normals} has {len(normals)}"
        )
    check_count(
        "--points",
        len(points),
        low=0,
        bytes_each=POINT_BYTES * len(vol.regions),
        each=f"per point and region, {len(vol.regions)} regions",
    )
    unit, ok = normalize_normals(normals)
    if not ok.all():
        log.warning("%d zero normals evaluated as +z", int((~ok).sum()))
    ao = VolumeProbe(vol).ao(points, unit, args.distance, args.order)
    with atomic_path(out) as tmp:
        np.save(tmp, ao)
    log.info("probed %d points in %d regions -> %s", len(ao), len(vol.regions), out)
    return 0
