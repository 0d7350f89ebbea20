"""CLI fuzz: hypothesis-generated ``neuralao`` invocations with bad and absurd numbers, shapes, paths and
hostile files (truncated and lying glTF / OBJ / PLY / NPZ / NPY / ONNX / JSON), run in-process through
:func:`neuralao.pipeline.cli.main.main` (stderr and ``SystemExit`` captured), so hundreds of cases fit in a
test run.

The contract every case is held to:

* exit 0 and a valid output (each command's output is read back and checked: finite, in range, the
  right shape), or
* exit 2 and exactly one line on stderr (progress bars aside), ``neuralao COMMAND: error: ...``, that
  names the flag, setting or file that was bad (one of the case's culprits);
* never a traceback or another exit status, never a Python warning (a real process prints it on stderr),
  never a temporary file left in the output folder, never the output itself after a refusal;
* an input holding NaN or inf that the command reads is refused (never a finite-looking result), and so
  is every hostile input marked as one that must be refused (a glTF breaking the specification's rules, a
  camera with a misspelt key or a scaled pose, a complex-valued array, a float past float32...);
* an output that cannot be written (below a file, inside /proc, an existing folder where a file is wanted,
  the same path as an input or as another output) is refused before any work, and an input given as the
  output is left as it was; every file written has the umask's permissions;
* an export folder written over an earlier export holds nothing of it afterwards (replaced whole), and a
  folder of other files is refused without ``--force``;
* SIGINT or SIGTERM at a random moment ends the command in one line with 130 / 143, leaving no temporary
  and no partial output (what is there is complete and valid).

Values are drawn from small pools: cheap valid ones (a 4-triangle mesh, 1-3 rays, 8-pixel frames) and
absurd ones (0, -1, 2^63, 1e12, nan, inf, words), so a case that legitimately succeeds stays cheap.
``make test`` runs FUZZ_EXAMPLES seeded cases (derandomised: the same cases every run);
``make fuzz`` runs more (``NEURALAO_FUZZ_EXAMPLES``). ``NEURALAO_FUZZ_REPORT=FILE`` writes the counts.
"""

from __future__ import annotations

import contextlib
import gc
import io
import json
import os
import re
import shutil
import signal
import struct
import time
import warnings
import zipfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from neuralao.pipeline.cli.main import main

FUZZ_EXAMPLES = int(os.environ.get("NEURALAO_FUZZ_EXAMPLES", "500"))
# None: derandomised (the same cases every run, as CI needs); a number: that seed (`make fuzz`).
FUZZ_SEED = int(os.environ["NEURALAO_FUZZ_SEED"]) if os.environ.get("NEURALAO_FUZZ_SEED") else None
STATS: Counter = Counter()

# ----------------------------------------------------------------------------- value pools

INT_ABSURD = [
    "0",
    "-1",
    "-7",
    "2147483648",
    "9223372036854775808",
    "1000000000000",
    "10" * 20,
    "1e3",
    "nan",
    "inf",
    "",
    "x",
    "3.5",
    "0x10",
]
FLOAT_ABSURD = ["nan", "inf", "-inf", "1e999", "-1", "0", "x", "", "1e-320", "1e300", "-1e300"]
# Values every command must refuse: not finite, or past float32 (where every number ends up).
FLOAT_NONFINITE = {"nan", "inf", "-inf", "1e999", "-1e999", "1e300", "-1e300"}
SEED_ABSURD = ["-1", "9223372036854775808", "1" + "0" * 30, "x", "1.5"]


def _bad(draw, flags: dict, p: float) -> bool:
    """Whether this choice is a bad one: ``p`` scaled by the case's hostility (0 for an all-valid case)."""
    return draw(st.floats(0, 1)) < p * flags["hostility"]


def _int(draw, flag: str, ok: list[str], culprits: list[str], flags: dict, p_bad: float = 0.25) -> list[str]:
    """``[flag, value]``: a cheap valid value, or an absurd one (recorded as a culprit)."""
    if _bad(draw, flags, p_bad):
        culprits.append(flag)
        return [flag, draw(st.sampled_from(INT_ABSURD))]
    return [flag, draw(st.sampled_from(ok))]


def _float(draw, flag: str, ok: list[str], culprits: list[str], flags: dict, p_bad: float = 0.2) -> list[str]:
    if _bad(draw, flags, p_bad):
        value = draw(st.sampled_from(FLOAT_ABSURD))
        culprits.append(flag)
        flags["nonfinite"] |= value in FLOAT_NONFINITE
        return [flag, value]
    return [flag, draw(st.sampled_from(ok))]


def _maybe(draw, p: float = 0.5) -> bool:
    return draw(st.floats(0, 1)) < p


def _pick(draw, files: dict[str, bool], culprits: list[str], flags: dict) -> str:
    """A fixture file token ``@NAME``; names mapped to False are hostile (a culprit; NaN ones non-finite)."""
    good = sorted(n for n, ok in files.items() if ok)
    name = draw(st.sampled_from(sorted(files) if _bad(draw, flags, 0.5) or not good else good))
    if not files[name]:
        culprits.append(Path(name).name)
        flags["nonfinite"] |= name.startswith("nan") or name.startswith("inf") or name in MUST_REFUSE
    return "@" + name


# ----------------------------------------------------------------------------- fixture files (tokens)

MESHES = {
    "tet.obj": True,
    "tet.ply": True,
    "tet.glb": True,
    "tet.stl": True,
    "nan.obj": False,
    "inf.obj": False,
    "overflow.obj": False,
    "huge.obj": False,
    "subnormal.obj": False,
    "truncated.obj": False,
    "badindex.obj": False,
    "empty.obj": False,
    "junk.obj": False,
    "collinear.obj": False,
    "words.obj": False,
    "hostile.ply": False,
    "truncated.ply": False,
    "escape.gltf": False,
    "junk.gltf": False,
    "empty.glb": False,
    "badmagic.glb": False,
    "lying.glb": False,
    "nomesh.glb": False,
    "bigaccessor.gltf": False,
    "junk.stl": False,
    "missing.obj": False,
    "folder": False,
    "tet.txt": False,
    "negcount.gltf": False,
    "stride.gltf": False,
    "extreq.gltf": False,
    "deep.gltf": False,
    "badview.gltf": False,
}
FRAMES = {
    "frame.npz": True,
    "stack.npz": True,
    "nan_depth.npz": False,
    "inf_normal.npz": False,
    "nan_position.npz": False,
    "nan_pose.npz": False,
    "bad_shape.npz": False,
    "truncated.npz": False,
    "pickle.npz": False,
    "empty.npz": False,
    "junk.npz": False,
    "missing.npz": False,
    "huge_depth.npz": False,
    "bomb.npz": True,
    "depthbomb.npz": False,
    "bignormal.npz": False,
    "cplx_depth.npz": False,
}
MODELS = {
    "unet.onnx": True,
    "truncated.onnx": False,
    "junk.onnx": False,
    "empty.onnx": False,
    "relu.onnx": False,
    "missing.onnx": False,
    "liar.onnx": False,
}
POINTS = {
    "p.npy": True,
    "nan_p.npy": False,
    "inf_p.npy": False,
    "far_p.npy": True,
    "p2.npy": False,
    "p1d.npy": False,
    "pobj.npy": False,
    "ptrunc.npy": False,
    "phuge.npy": False,
    "pempty.npy": True,
    "pint.npy": True,
    "missing_p.npy": False,
    "cplx_p.npy": False,
    "bool_p.npy": False,
}
NORMALS = {
    "n.npy": True,
    "zero_n.npy": True,
    "big_n.npy": True,
    "nan_n.npy": False,
    "inf_n.npy": False,
    "cplx_n.npy": False,
    "n2.npy": False,
}
VOLUMES = {
    "vol.json": True,
    "truncated_vol.json": False,
    "empty.json": False,
    "nan_vol.json": False,
    "list.json": False,
    "missing_vol.json": False,
    "deep_vol.json": False,
    "latin1_vol.json": False,
    "typo_vol.json": False,
}
BAKES = {
    "baked.ply": True,
    "tex.glb": True,
    "empty.glb": False,
    "nomesh.glb": False,
    "tet.obj": False,
    "junk.ply": False,
    "truncated_baked.ply": False,
    "missing.ply": False,
}
POSES = {
    "poses.json": True,
    "nan_poses.json": False,
    "junk.json": False,
    "empty_poses.json": False,
    "bad_poses.json": False,
    "huge_poses.json": False,
    "typo_poses.json": False,
    "scaled_poses.json": False,
    "singular_poses.json": False,
    "same_poses.json": False,
    "deep_poses.json": False,
    "latin1_poses.json": False,
}
REGIONS = {
    "regions.json": True,
    "nan_regions.json": False,
    "junk.json": False,
    "flat_regions.json": False,
    "bad_edges.json": False,
    "far_regions.json": True,
    "deep_regions.json": False,
    "typo_regions.json": False,
}
DATASETS = {
    "dataset.json": True,
    "junk.json": False,
    "nan_dataset.json": False,
    "big_dataset.json": False,
    "noscene_dataset.json": False,
    "typo_dataset.json": False,
    "empty.json": False,
    "deep_dataset.json": False,
    "latin1_dataset.json": False,
}
EXPORTS = {"export": True, "empty_dir": False, "missing_dir": False, "bad_manifest": False}
PARITY_INPUTS = {"pin.npz": True, "bomb_pin.npz": True, "nan_pin.npz": False, "big_pin.npz": False}
LEVELS = {
    "level/level.gltf": True,
    "badlevel/zero_trees.gltf": False,
    "badlevel/deep.gltf": False,
    "badlevel/typo.gltf": False,
    "badlevel/negcount.gltf": False,
    "badlevel/stride.gltf": False,
}
LEVEL_CONFIGS = {
    "level/fast.json": True,
    "badlevel/latin1.json": False,
    "badlevel/deep.json": False,
    "badlevel/typo.json": False,
    "badlevel/nan.json": False,
}
# Hostile fixtures no command may accept (a success reading one is nonsense accepted).
MUST_REFUSE = {
    *(n for n in MESHES if n.endswith(".gltf") and not MESHES[n]),
    "depthbomb.npz",
    "bignormal.npz",
    "cplx_depth.npz",
    "cplx_p.npy",
    "bool_p.npy",
    "cplx_n.npy",
    *(n for n in VOLUMES if not VOLUMES[n]),
    *(n for n in POSES if not POSES[n]),
    "deep_regions.json",
    "typo_regions.json",
    "deep_dataset.json",
    "latin1_dataset.json",
    "big_pin.npz",
    *(n for n in LEVELS if not LEVELS[n]),
    *(n for n in LEVEL_CONFIGS if not LEVEL_CONFIGS[n]),
}


# ----------------------------------------------------------------------------- cases


@dataclass
class Case:
    command: str
    argv: list[str]  # tokens: "@NAME" a fixture file, "@OUT" the output path
    out: str  # output name inside the case folder ("" when the command writes nothing)
    out_is_dir: bool
    culprits: list[str] = field(default_factory=list)
    nonfinite: bool = False  # an input that must be refused went in (NaN, inf, a hostile fixture)
    bad_out: str = ""  # the output replaced by one that cannot be written (BAD_OUTPUTS)
    signal: str = ""  # SIGINT / SIGTERM sent after ``delay`` seconds
    delay: float = 0.0
    prefill: str = ""  # glsl: the output folder holds an earlier "export" or a "user" folder first
    copies: list[str] = field(
        default_factory=list
    )  # fixtures copied into the case folder (inputs as outputs)


# Outputs that cannot be written: below a regular file, inside /proc, an existing path of the other kind
# (a folder where a file is wanted, a file where a folder is), a name longer than a file system allows.
BAD_OUTPUTS = ("below_file", "proc", "wrong_kind", "long_name")
# Commands a signal is sent to (no GL context: an interrupted OSMesa context would outlive the case).
SIGNALLED = ("bake", "volumes", "probe", "level")


def _flags(draw) -> dict:
    """Per case: how hostile it is (0: every choice valid, so the command must succeed and its output is
    checked; higher: more bad choices), whether a non-finite value went in, whether its output is one that
    cannot be written, and whether a signal interrupts it."""
    hostility = draw(st.sampled_from([0.0, 0.0, 0.5, 1.0, 2.0]))
    bad_out = draw(st.sampled_from(BAD_OUTPUTS)) if draw(st.floats(0, 1)) < 0.06 * hostility else ""
    sig = draw(st.sampled_from(["SIGINT", "SIGTERM"])) if draw(st.floats(0, 1)) < 0.06 else ""
    delay = draw(st.sampled_from([0.0, 0.02, 0.08, 0.2, 0.5])) if sig else 0.0
    return {"hostility": hostility, "nonfinite": False, "bad_out": bad_out, "signal": sig, "delay": delay}


def _finish(command, argv, out, out_is_dir, culprits, flags) -> Case:
    bad_out = flags["bad_out"] if out and "@OUT" in argv else ""
    if bad_out:
        culprits.append("--out")
    sig = flags["signal"] if command in SIGNALLED else ""
    return Case(command, argv, out, out_is_dir, culprits, flags["nonfinite"], bad_out, sig, flags["delay"])


def _choice(
    draw, flags: dict, culprits: list[str], culprit: str, ok: list[str], bad: list[str], p: float = 0.3
) -> str:
    """A value from ``ok``, or (hostile) from ``bad`` with ``culprit`` recorded."""
    if _bad(draw, flags, p):
        culprits.append(culprit)
        return draw(st.sampled_from(bad))
    return draw(st.sampled_from(ok))


def _seed(draw, flags: dict, culprits: list[str]) -> list[str]:
    return ["--seed", _choice(draw, flags, culprits, "--seed", ["0", "5"], SEED_ABSURD)]


@st.composite
def bake_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = ["bake", _pick(draw, MESHES, c, f)]
    texture = _maybe(draw, 0.3)
    ok = [".glb"] if texture else [".ply", ".glb"]
    out = _choice(draw, f, c, "--out", ok, [".obj", ".txt", "", ".ply" if texture else ".gltf"], 0.15)
    argv += _int(draw, "--rays", ["1", "2", "3"], c, f, p_bad=0.3)
    if texture:
        argv += ["--to", "texture", *_int(draw, "--resolution", ["4", "8", "16"], c, f)]
        if _maybe(draw, 0.3):
            argv += _int(draw, "--margin", ["0", "1"], c, f)
        if _maybe(draw, 0.3):
            argv += ["--uv", draw(st.sampled_from(["auto", "mesh", "xatlas"]))]
    else:
        if _maybe(draw, 0.4):
            argv += ["--method", draw(st.sampled_from(["vertex", "least-squares"]))]
        if _maybe(draw, 0.3):
            argv += _float(draw, "--samples-per-vertex", ["0.5", "1", "4"], c, f)
        if _maybe(draw, 0.3):
            argv += _int(draw, "--samples-per-face-cap", ["1", "2", "64"], c, f)
        if _maybe(draw, 0.2):
            argv += _float(draw, "--alpha", ["0", "1", "100"], c, f)
    if _maybe(draw, 0.2):
        argv += _int(draw, "--workers", ["1", "2"], c, f)
    if _maybe(draw, 0.2):
        argv += _seed(draw, f, c)
    if _maybe(draw, 0.2):
        argv += _float(draw, "--max-distance", ["0.1", "1", "1e30"], c, f)
    if _maybe(draw, 0.15):
        argv += ["--kernel", "obscurance", *_float(draw, "--half-distance", ["0.05", "1"], c, f)]
    return _finish("bake", [*argv, "--out", "@OUT"], "out" + out, False, c, f)


@st.composite
def render_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = ["render", _pick(draw, MESHES, c, f)]
    if _maybe(draw, 0.25):
        argv += ["--cameras", _pick(draw, POSES, c, f)]
    else:
        argv += _int(draw, "--views", ["1", "2"], c, f)
    w = _int(draw, "--size", ["1", "3", "8", "16"], c, f)[1]
    h = _int(draw, "--size", ["1", "5", "8"], c, f)[1]
    argv += ["--size", w, h, *_int(draw, "--rays", ["1", "2"], c, f, p_bad=0.2)]
    if _maybe(draw, 0.2):
        argv += _float(draw, "--yfov", ["10", "40", "170"], c, f)
    if _maybe(draw, 0.2):
        argv += _seed(draw, f, c)
    if _maybe(draw, 0.2):
        argv += _int(draw, "--workers", ["1", "2"], c, f)
    if _maybe(draw, 0.2):
        argv += _float(draw, "--max-distance", ["0.1", "1e30"], c, f)
    if _maybe(draw, 0.2):
        argv += ["--normals", draw(st.sampled_from(["smooth", "flat"]))]
    return _finish("render", [*argv, "--out", "@OUT"], "out", True, c, f)


@st.composite
def infer_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = ["infer"]
    if _maybe(draw, 0.8):
        argv.append(_pick(draw, MODELS, c, f))
    argv.append(_pick(draw, FRAMES, c, f))
    out = _choice(draw, f, c, "--out", [".png", ".npy", ".exr"], [".jpg", ".png.tmp", ""], 0.2)
    argv += ["--out", "@OUT"]
    if _maybe(draw, 0.3):
        argv += ["--composite", "@OUT2"]
    if _maybe(draw, 0.3):
        argv += _float(draw, "--radius", ["0.05", "1", "1e6"], c, f)
    if _maybe(draw, 0.3):
        argv += ["--index", _choice(draw, f, c, "--index", ["0"], ["1", "2", *INT_ABSURD])]
    c.append("--index")  # the stacked file needs one
    return _finish("infer", argv, "ao" + out, False, c, f)


@st.composite
def probe_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = ["probe", _pick(draw, VOLUMES, c, f), "--points", _pick(draw, POINTS, c, f)]
    argv += ["--normals", _pick(draw, NORMALS, c, f)]
    if _maybe(draw, 0.3):
        argv += ["--distance", draw(st.sampled_from(["blend", "short", "long"]))]
    if _maybe(draw, 0.3):
        argv += ["--order", draw(st.sampled_from(["linear", "quadratic"]))]
    out = _choice(draw, f, c, "--out", [".npy"], [".npz", ".png", ""], 0.2)
    return _finish("probe", [*argv, "--out", "@OUT"], "ao" + out, False, c, f)


VOLUME_SETS = {
    "samples": ["1", "2"],
    "directions": ["4", "16"],
    "grid": ["1", "2", "3"],
    "iterations": ["0", "1"],
    "boundary_grid": ["1", "2"],
    "cell_rays": ["4", "8"],
    "max_region_cells": ["1", "4"],
    "min_cells": ["1", "2"],
    "workers": ["1", "2"],
    "seed": ["0", "7"],
}
VOLUME_FLOATS = {
    "beta": ["0", "1"],
    "blend": ["0", "0.5", "1"],
    "max_distance_rel": ["0.5", "4"],
    "backface_threshold": ["0", "0.25"],
}


@st.composite
def volumes_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = ["volumes", _pick(draw, MESHES, c, f)]
    sets = {"samples": "1", "directions": "8", "grid": "2", "cell_rays": "4"}
    for key in draw(
        st.lists(st.sampled_from(sorted(VOLUME_SETS) + sorted(VOLUME_FLOATS)), max_size=2, unique=True)
    ):
        if key in VOLUME_SETS:
            sets[key] = _int(draw, key, VOLUME_SETS[key], c, f, p_bad=0.6)[1]
        else:
            sets[key] = _float(draw, key, VOLUME_FLOATS[key], c, f, p_bad=0.6)[1]
    if _bad(draw, f, 0.1):
        sets["bogus"] = "1"
        c.append("bogus")
    for k, v in sets.items():
        argv += ["--set", f"{k}={v}"]
    if _maybe(draw, 0.3):
        argv += ["--regions", _pick(draw, REGIONS, c, f)]
    if _maybe(draw, 0.2):
        argv += ["--glsl", "@OUT2"]
    out = _choice(draw, f, c, "--out", [".json"], [".npy", ".gltf"], 0.2)
    return _finish("volumes", [*argv, "--out", "@OUT"], "vol" + out, False, c, f)


@st.composite
def view_case(draw) -> Case:
    c, f = [], _flags(draw)
    inputs = [_pick(draw, BAKES, c, f) for _ in range(draw(st.integers(1, 2)))]
    argv = ["view", *inputs]
    if _maybe(draw, 0.3):
        argv += [
            "--size",
            _int(draw, "--size", ["1", "64"], c, f)[1],
            _int(draw, "--size", ["1", "48"], c, f)[1],
        ]
    if _maybe(draw, 0.2):
        argv += _int(draw, "--port", ["0", "8000"], c, f)
    return _finish("view", [*argv, "--out", "@OUT"], "page", True, c, f)


FIELD_SETS = {
    "steps": ["1", "2"],
    "batch": ["8", "16"],
    "samples": ["32", "64"],
    "check_every": ["1"],
    "holdout_views": ["0", "1"],
    "threads": ["1"],
    "seed": ["0", "3"],
}


@st.composite
def train_field_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = ["train", "field", "--mesh", _pick(draw, MESHES, c, f), "--no-progress"]
    argv += [
        "--size",
        _choice(
            draw,
            f,
            c,
            "--size",
            ["4x4", "4", "8x2"],
            ["0x4", "4x-1", "x", "99999999999x4", "4x4x4x4x4x4x4x4"],
            0.2,
        ),
    ]
    argv += _int(draw, "--octaves", ["0", "1", "2"], c, f)
    argv += _int(draw, "--rays", ["1", "2"], c, f, p_bad=0.2)
    sets = {
        "steps": "1",
        "batch": "8",
        "samples": "32",
        "check_every": "1",
        "holdout_views": "1",
        "holdout_size": "[8,8]",
        "threads": "1",
    }
    for key in draw(st.lists(st.sampled_from(sorted(FIELD_SETS)), max_size=2, unique=True)):
        sets[key] = _int(draw, key, FIELD_SETS[key], c, f, p_bad=0.7)[1]
    sets["holdout_size"] = _choice(
        draw, f, c, "holdout_size", ["[8,8]", "[4,6]"], ["[0,8]", "[100000000,100000000]", "[8]", "x"], 0.15
    )
    sets["lr"] = _choice(draw, f, c, "lr", ["0.01"], ["nan", "inf", "-1", "1e308"], 0.15)
    f["nonfinite"] |= sets["lr"] in ("nan", "inf")
    for k, v in sets.items():
        argv += ["--set", f"{k}={v}"]
    return _finish("train", [*argv, "--out", "@OUT"], "field.pt", False, c, f)


# What a refusal of each hostile dataset config names: the file, or the setting that is bad in it.
DATASET_CULPRITS = {
    "nan_dataset.json": "max_distance",
    "big_dataset.json": "views",
    "noscene_dataset.json": "scenes",
    "typo_dataset.json": "sizee",
}
DATASET_SETS = {
    "labels.rays": ["1", "2"],
    "frames_per_shard": ["1", "2"],
    "holdout_every": ["0", "2"],
    "seed": ["0", "1"],
    "scenes.0.views": ["1", "2"],
}


@st.composite
def dataset_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = ["dataset", _pick(draw, DATASETS, c, f), "--no-progress"]
    c += [DATASET_CULPRITS.get(n, n) for n in c]
    for key in draw(st.lists(st.sampled_from(sorted(DATASET_SETS)), max_size=2, unique=True)):
        argv += ["--set", f"{key}={_int(draw, key, DATASET_SETS[key], c, f, p_bad=0.6)[1]}"]
        c.append(key.split(".")[-1])
    if _maybe(draw, 0.2):
        size = _choice(
            draw, f, c, "size", ["[8,8]", "[4,6]"], ["[0,8]", "[100000000,100000000]", "[8]", "8"], 0.6
        )
        argv += ["--set", f"size={size}"]
    return _finish("dataset", [*argv, "--out", "@OUT"], "data", True, c, f)


@st.composite
def glsl_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = [
        "glsl",
        _pick(draw, {**MODELS, "relu.onnx": True, "unet.onnx": False, "ext/conv.onnx": True}, c, f),
    ]
    argv += ["--target", _choice(draw, f, c, "--target", ["image"], ["vector"], 0.3)]
    if _maybe(draw, 0.3):
        argv += ["--precision", draw(st.sampled_from(["fp32", "fp16"]))]
    if _bad(draw, f, 0.3):
        argv += [
            "--bind",
            draw(
                st.sampled_from(
                    ["x=gbuffer.xyzw", "x=gbuffer.xyzwx99999999999", "x=", "=", "x=t.q", "nosuch=t.x"]
                )
            ),
        ]
        c.append("--bind")
    prefill = draw(st.sampled_from(["", "", "export", "user"]))
    if prefill == "user":
        if _maybe(draw):
            argv.append("--force")
        else:
            c.append("--out")
            f["nonfinite"] = True  # a folder of other files is never replaced without --force
    case = _finish("glsl", [*argv, "--out", "@OUT"], "glsl", True, c, f)
    case.prefill = "" if case.bad_out else prefill
    return case


@st.composite
def parity_case(draw) -> Case:
    c, f = [], _flags(draw)
    argv = ["parity", _pick(draw, EXPORTS, c, f)]
    if _maybe(
        draw, 0.3
    ):  # the export's own inputs from a file: real arrays, NaN, past float32, unread members
        argv += ["--inputs", _pick(draw, PARITY_INPUTS, c, f)]
        return _finish("parity", [*argv, "--out", "@OUT"], "parity.json", False, c, f)
    argv += [
        "--size",
        _int(draw, "--size", ["4", "8"], c, f, p_bad=0.5)[1],
        _int(draw, "--size", ["4"], c, f, p_bad=0.5)[1],
    ]
    if _maybe(draw, 0.3):
        argv += _seed(draw, f, c)
    if _bad(draw, f, 0.3):
        argv += ["--inputs", _pick(draw, FRAMES, c, f)]
        c.append("--inputs")
    return _finish("parity", [*argv, "--out", "@OUT"], "parity.json", False, c, f)


LEVEL_GEN_SETS = {
    "terrain_cells": ["1", "2", "4"],
    "houses": ["0", "1", "2"],
    "house_boxes": ["1", "2"],
    "trees": ["0", "1"],
    "shrubs": ["0", "2"],
    "grass": ["0", "3"],
    "crown_subdivisions": ["0", "1"],
}
LEVEL_GEN_FLOATS = {
    "terrain_size": ["10", "40"],
    "terrain_height": ["0", "2"],
    "blocker_height": ["0", "6"],
    "shrub_density": ["0", "0.8"],
    "tree_transmission": ["0", "0.5", "1"],
}


@st.composite
def level_case(draw) -> Case:
    """``neuralao level``: generator parameters from small to absurd (a count past memory, a NaN size)."""
    c, f = [], _flags(draw)
    argv = ["level", "--set", "buildings=[]", "--set", "terrain_cells=3", "--set", "crown_subdivisions=0"]
    if _maybe(draw, 0.3):
        argv += _seed(draw, f, c)
    keys = sorted(LEVEL_GEN_SETS) + sorted(LEVEL_GEN_FLOATS)
    for key in draw(st.lists(st.sampled_from(keys), max_size=3, unique=True)):  # a later --set would win
        if key in LEVEL_GEN_SETS:
            value = _int(draw, key, LEVEL_GEN_SETS[key], c, f, p_bad=0.6)[1]
        else:
            value = _float(draw, key, LEVEL_GEN_FLOATS[key], c, f, p_bad=0.6)[1]
        argv += ["--set", f"{key}={value}"]
    return _finish("level", [*argv, "--out", "@OUT"], "lvl", True, c, f)


LEVEL_BAKE_SETS = {
    "trace.rays": ["2", "4"],
    "workers": ["1", "2"],
    "seed": ["0", "3"],
    "trace.samples_per_face_cap": ["1", "2"],
    "decorators.local_rays": ["2", "4"],
}
LEVEL_BAKE_FLOATS = {
    "trace.alpha": ["0", "1"],
    "trace.samples_per_vertex": ["0.5", "1"],
    "blend.long_weight": ["0", "0.5", "1"],
    "trace.backface_threshold": ["0", "0.25"],
}


@st.composite
def level_bake_case(draw) -> Case:
    """``neuralao bake LEVEL --config``: hostile level files and configs, absurd settings."""
    c, f = [], _flags(draw)
    argv = ["bake", _pick(draw, LEVELS, c, f), "--config", _pick(draw, LEVEL_CONFIGS, c, f)]
    keys = sorted(LEVEL_BAKE_SETS) + sorted(LEVEL_BAKE_FLOATS)
    for key in draw(st.lists(st.sampled_from(keys), max_size=2, unique=True)):
        if key in LEVEL_BAKE_SETS:
            value = _int(draw, key, LEVEL_BAKE_SETS[key], c, f, p_bad=0.6)[1]
        else:
            value = _float(draw, key, LEVEL_BAKE_FLOATS[key], c, f, p_bad=0.6)[1]
        argv += ["--set", f"{key}={value}"]
    return _finish("bake", [*argv, "--out", "@OUT"], "baked_level", True, c, f)


@st.composite
def same_path_case(draw) -> Case:
    """An output that is also an input (or two outputs on one path): refused, the input left as it was."""
    kind = draw(st.sampled_from(["bake", "probe", "infer", "composite", "volumes"]))
    if kind == "bake":
        argv = ["bake", "@COPY:tet.obj", "--rays", "2", "--out", "@COPY:tet.obj"]
    elif kind == "probe":
        argv = [
            "probe",
            "@vol.json",
            "--points",
            "@COPY:p.npy",
            "--normals",
            "@n.npy",
            "--out",
            "@COPY:p.npy",
        ]
    elif kind == "infer":
        argv = ["infer", "@COPY:frame.npz", "--out", "@COPY:frame.npz"]
    elif kind == "composite":
        argv = ["infer", "@frame.npz", "--out", "@OUT", "--composite", "@OUT"]
    else:
        argv = ["volumes", "@tet.obj", "--regions", "@COPY:regions.json", "--out", "@COPY:regions.json"]
    command = argv[0]
    copies = sorted({t.split(":", 1)[1] for t in argv if t.startswith("@COPY:")})
    case = Case(command, argv, "ao.png" if kind == "composite" else "", False, ["--out", "--composite"], True)
    case.copies = copies
    return case


@st.composite
def garbage_case(draw) -> Case:
    argv = draw(
        st.lists(
            st.sampled_from(
                [
                    "bake",
                    "--rays",
                    "-v",
                    "--out",
                    "nosuch",
                    "render",
                    "",
                    "-",
                    "--",
                    "train",
                    "mlp",
                    "--help-me",
                    "x" * 300,
                ]
            ),
            max_size=4,
        )
    )
    if "-v" in argv:
        argv.remove("-v")  # verbose re-raises internal errors on purpose
    return Case("", argv, "", False, [], False)


CASES = st.one_of(
    bake_case(),
    render_case(),
    infer_case(),
    probe_case(),
    volumes_case(),
    view_case(),
    train_field_case(),
    dataset_case(),
    glsl_case(),
    parity_case(),
    level_case(),
    level_bake_case(),
    same_path_case(),
    garbage_case(),
)


# ----------------------------------------------------------------------------- hostile files


def _obj(verts, faces=((1, 2, 3), (1, 2, 4), (1, 3, 4), (2, 3, 4))) -> str:
    return "".join(f"v {x} {y} {z}\n" for x, y, z in verts) + "".join(f"f {a} {b} {c}\n" for a, b, c in faces)


TET = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]


def _glb(doc: dict, blob: bytes = b"") -> bytes:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = (
        struct.pack("<II", len(js), 0x4E4F534A)
        + js
        + (struct.pack("<II", len(blob), 0x004E4942) + blob if blob else b"")
    )
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def _tet_gltf(uri: str, count: int = 4) -> dict:
    return {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": count,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1, 1],
            }
        ],
        "bufferViews": [{"buffer": 0, "byteLength": 48}],
        "buffers": [{"uri": uri, "byteLength": 48}],
    }


def _write_files(d: Path, work: Path) -> None:
    import onnx
    import trimesh
    from onnx import TensorProto
    from onnx import helper as oh

    rng = np.random.default_rng(0)
    junk = rng.integers(0, 256, 300, dtype=np.uint8).tobytes()
    tet = trimesh.Trimesh(np.array(TET, float), [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], process=False)
    (d / "tet.obj").write_text(_obj(TET))
    tet.export(d / "tet.ply")
    tet.export(d / "tet.glb")
    tet.export(d / "tet.stl")
    (d / "tet.txt").write_text(_obj(TET))
    (d / "nan.obj").write_text(_obj([*TET[:3], ("nan", 0, 1)]))
    (d / "inf.obj").write_text(_obj([*TET[:3], ("inf", 0, 1)]))
    (d / "overflow.obj").write_text(_obj([(0, 0, 0), (1e308, 0, 0), (0, 1e308, 0), (-1e308, -1e308, 1e308)]))
    (d / "huge.obj").write_text(_obj([(x * 1e38, y * 1e38, z * 1e38) for x, y, z in TET]))
    (d / "subnormal.obj").write_text(_obj([(x * 1e-310, y * 1e-310, z * 1e-310) for x, y, z in TET]))
    (d / "truncated.obj").write_text(_obj(TET)[:25])
    (d / "badindex.obj").write_text(_obj(TET, ((1, 2, 99),)))
    (d / "empty.obj").write_text("")
    (d / "junk.obj").write_bytes(junk)
    (d / "words.obj").write_text("v a b c\nv 1 2\nf x y z\n")
    (d / "collinear.obj").write_text(_obj([(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)]))
    (d / "hostile.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 1000000000000\nproperty float x\n"
        "property float y\nproperty float z\nelement face 1\n"
        "property list uchar int vertex_indices\nend_header\n0 0 0\n"
    )
    ply = (d / "tet.ply").read_bytes()
    (d / "truncated.ply").write_bytes(ply[: len(ply) // 2])
    (d / "escape.gltf").write_text(json.dumps(_tet_gltf("../../../../../../etc/hostname")))
    (d / "bigaccessor.gltf").write_text(
        json.dumps(_tet_gltf("data:application/octet-stream;base64," + "A" * 64, count=10**12))
    )
    (d / "junk.gltf").write_text('{"asset": {"version": "2.0"}, "nodes": [{"mesh": 7}]')
    (d / "empty.glb").write_bytes(b"")
    (d / "badmagic.glb").write_bytes(b"glTX" + junk)
    (d / "lying.glb").write_bytes(
        struct.pack("<III", 0x46546C67, 2, 1 << 31) + struct.pack("<II", 1 << 30, 0x4E4F534A)
    )
    (d / "nomesh.glb").write_bytes(
        _glb({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{}]})
    )
    (d / "junk.stl").write_bytes(junk)
    (d / "folder").mkdir()
    # G-buffer frames: a real render, then broken copies
    assert (
        main(
            [
                "render",
                str(d / "tet.obj"),
                "--views",
                "2",
                "--size",
                "16",
                "16",
                "--rays",
                "2",
                "--out",
                str(work / "render"),
            ]
        )
        == 0
    )
    from neuralao.runtime.foundation.io import read_npz

    frame = read_npz(work / "render" / "view_0000.npz")
    np.savez(d / "frame.npz", **frame)
    np.savez(d / "stack.npz", **{k: np.stack([v, v]) for k, v in frame.items()})
    for name, key, value in (
        ("nan_depth", "depth", np.nan),
        ("inf_normal", "normal_cam", np.inf),
        ("nan_position", "position", np.nan),
        ("nan_pose", "pose", np.nan),
        ("huge_depth", "depth", 3e38),
    ):
        broken = dict(frame)
        broken[key] = np.full_like(frame[key], value)
        np.savez(d / f"{name}.npz", **broken)
    np.savez(
        d / "bad_shape.npz",
        **{**frame, "depth": frame["depth"][:3], "normal_cam": frame["normal_cam"][..., :2]},
    )
    raw = (d / "frame.npz").read_bytes()
    (d / "truncated.npz").write_bytes(raw[: len(raw) // 2])
    np.savez(d / "pickle.npz", depth=np.array([{"a": 1}], dtype=object))
    np.savez(d / "empty.npz")
    (d / "junk.npz").write_bytes(junk)
    # models
    unet = Path(__file__).resolve().parents[1] / "runtime" / "models" / "unet-fast" / "model.onnx"
    (d / "unet.onnx").write_bytes(unet.read_bytes())
    (d / "truncated.onnx").write_bytes(unet.read_bytes()[:2000])
    (d / "junk.onnx").write_bytes(junk)
    (d / "empty.onnx").write_bytes(b"")
    x = oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4, "h", "w"])
    y = oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4, "h", "w"])
    relu = oh.make_model(
        oh.make_graph([oh.make_node("Relu", ["x"], ["y"], name="")], "g", [x], [y]),
        opset_imports=[oh.make_opsetid("", 19)],
    )
    (d / "relu.onnx").write_bytes(relu.SerializeToString())
    liar = onnx.ModelProto()
    liar.CopyFrom(relu)
    liar.metadata_props.add(key="neuralao_kind", value="unet")
    (d / "liar.onnx").write_bytes(liar.SerializeToString())
    # points and normals
    p = rng.uniform(-0.2, 1.2, (6, 3))
    np.save(d / "p.npy", p)
    np.save(d / "nan_p.npy", np.where(np.arange(6)[:, None] == 2, np.nan, p))
    np.save(d / "inf_p.npy", np.where(np.arange(6)[:, None] == 4, np.inf, p))
    np.save(d / "far_p.npy", p * np.array([1e30, 1e6, 1e300, -1e308, 1.0, -1e30])[:, None])
    np.save(d / "p2.npy", p[:, :2])
    np.save(d / "p1d.npy", p[:, 0])
    np.save(d / "pobj.npy", np.array([None] * 6, dtype=object), allow_pickle=True)
    np.save(d / "pempty.npy", np.zeros((0, 3)))
    np.save(d / "pint.npy", np.arange(18).reshape(6, 3))
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 3), }"
    header += " " * (-(len(header) + 11) % 64) + "\n"
    (d / "phuge.npy").write_bytes(
        b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + b"\0" * 48
    )
    (d / "ptrunc.npy").write_bytes((d / "p.npy").read_bytes()[:100])
    n = rng.normal(size=(6, 3))
    np.save(d / "n.npy", n)
    np.save(d / "zero_n.npy", np.zeros((6, 3)))
    np.save(d / "nan_n.npy", np.full((6, 3), np.nan))
    np.save(d / "n2.npy", n[:5])
    # volumes, bakes, export
    assert (
        main(
            [
                "volumes",
                str(d / "tet.obj"),
                "--out",
                str(d / "vol.json"),
                "--set",
                "samples=2",
                "--set",
                "directions=16",
                "--set",
                "grid=2",
            ]
        )
        == 0
    )
    vol = (d / "vol.json").read_text()
    (d / "truncated_vol.json").write_text(vol[: len(vol) // 2])
    data = json.loads(vol)
    data["regions"][0]["centre"] = [float("nan")] * 3
    (d / "nan_vol.json").write_text(json.dumps(data))
    (d / "list.json").write_text("[1, 2, 3]")
    (d / "empty.json").write_text("")
    (d / "junk.json").write_text("{not json")
    assert main(["bake", str(d / "tet.obj"), "--rays", "2", "--out", str(d / "baked.ply")]) == 0
    baked = (d / "baked.ply").read_bytes()
    (d / "truncated_baked.ply").write_bytes(baked[: len(baked) - 20])
    (d / "junk.ply").write_bytes(junk)
    assert (
        main(
            [
                "bake",
                str(d / "tet.obj"),
                "--rays",
                "2",
                "--to",
                "texture",
                "--resolution",
                "8",
                "--out",
                str(d / "tex.glb"),
            ]
        )
        == 0
    )
    assert main(["glsl", str(d / "relu.onnx"), "--target", "image", "--out", str(d / "export")]) == 0
    (d / "empty_dir").mkdir()
    (d / "bad_manifest").mkdir()
    (d / "bad_manifest" / "manifest.json").write_text('{"kind": "onnx-glsl", "target": 3}')
    # cameras, regions, datasets
    pose = {"eye": [2.0, 1.5, 2.0], "target": [0.3, 0.3, 0.3], "yfov_deg": 50}
    (d / "poses.json").write_text(json.dumps([pose]))
    (d / "nan_poses.json").write_text(json.dumps([{**pose, "eye": [float("nan"), 0, 1]}]))
    (d / "empty_poses.json").write_text("[]")
    (d / "bad_poses.json").write_text(json.dumps([{"eye": [1, 2], "target": "x"}]))
    (d / "huge_poses.json").write_text(json.dumps([{**pose, "eye": [1e300, 1e300, 1e300]}]))
    box = {"name": "a", "min": [-0.5, -0.5, -0.5], "max": [0.2, 1.5, 1.5]}
    (d / "regions.json").write_text(
        json.dumps({"regions": [box, {"name": "b", "min": [0.2, -0.5, -0.5], "max": [1.5, 1.5, 1.5]}]})
    )
    (d / "nan_regions.json").write_text(json.dumps({"regions": [{**box, "min": [float("nan"), 0, 0]}]}))
    (d / "flat_regions.json").write_text(json.dumps({"regions": [{**box, "max": [-0.5, 1.5, 1.5]}]}))
    (d / "bad_edges.json").write_text(json.dumps({"regions": [box], "edges": [[0, 5]]}))
    (d / "far_regions.json").write_text(
        json.dumps({"regions": [box, {"min": [1e30, 0, 0], "max": [2e30, 1, 1]}]})
    )
    scene = {"name": "tet", "mesh": str(d / "tet.obj"), "cameras": "orbit", "views": 1, "split": "train"}
    base = {"name": "fz", "size": [8, 8], "labels": {"rays": 2}, "frames_per_shard": 1, "scenes": [scene]}
    (d / "dataset.json").write_text(json.dumps(base))
    (d / "nan_dataset.json").write_text(
        json.dumps({**base, "labels": {"rays": 2, "max_distance_rel": float("nan")}})
    )
    (d / "big_dataset.json").write_text(json.dumps({**base, "scenes": [{**scene, "views": 10**15}]}))
    (d / "noscene_dataset.json").write_text(json.dumps({**base, "scenes": []}))
    (d / "typo_dataset.json").write_text(json.dumps({**base, "sizee": [8, 8]}))
    _write_round_two(d, work, frame, base, pose, unet)


DEEP = "[" * 5000 + "]" * 5000  # JSON nested past any parser's recursion


def _deep_in(doc: dict, key: str) -> str:
    """``doc`` as JSON with ``key``'s value nested 5,000 deep (what the bounded reader must refuse)."""
    return json.dumps({**doc, key: "@DEEP@"}).replace('"@DEEP@"', DEEP)


def _latin1(doc: dict) -> bytes:
    """``doc`` as JSON in Latin-1 with a non-ASCII string: not UTF-8."""
    return json.dumps({**doc, "name": "caf\u00e9"}, ensure_ascii=False).encode("latin-1")


def _npz_bomb(arrays: dict, key: str, shape: tuple[int, ...]) -> bytes:
    """An npz of ``arrays`` plus member ``key`` whose header declares ``shape`` (float64): it would inflate
    past any machine's memory; its stored bytes are a few hundred."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for k, v in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asarray(v))
            zf.writestr(f"{k}.npy", member.getvalue())
        header = f"{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}"
        header += " " * (-(len(header) + 11) % 64) + "\n"
        zf.writestr(
            f"{key}.npy", b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + bytes(512)
        )
    return buf.getvalue()


def _gltf_variants(d: Path, doc: dict, stem: str) -> None:
    """Hostile copies of a glTF document (its buffers beside it): a negative accessor count, a byteStride
    below its element, a required extension nobody implements, JSON nested 5,000 deep in extras, a
    bufferView past its buffer."""
    negcount = json.loads(json.dumps(doc))
    negcount["accessors"][0]["count"] = -3
    (d / f"{stem}negcount.gltf").write_text(json.dumps(negcount))
    stride = json.loads(json.dumps(doc))
    view = stride["accessors"][0]["bufferView"]
    stride["bufferViews"][view]["byteStride"] = 4
    (d / f"{stem}stride.gltf").write_text(json.dumps(stride))
    required = {**doc, "extensionsRequired": ["KHR_nonexistent"], "extensionsUsed": ["KHR_nonexistent"]}
    (d / f"{stem}extreq.gltf").write_text(json.dumps(required))
    (d / f"{stem}deep.gltf").write_text(_deep_in(doc, "extras"))
    badview = json.loads(json.dumps(doc))
    badview["bufferViews"][0]["byteOffset"] = 1 << 40
    (d / f"{stem}badview.gltf").write_text(json.dumps(badview))


def _write_round_two(d: Path, work: Path, frame: dict, dataset: dict, pose: dict, unet: Path) -> None:
    """The hostile fixtures of the readers, outputs and generators (module doc)."""
    import onnx
    from onnx import TensorProto, numpy_helper
    from onnx import helper as oh

    rng = np.random.default_rng(1)
    # glTF: a valid tetrahedron with an index buffer, then its hostile copies
    pos = np.array(TET, np.float32)
    idx = np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], np.uint16)
    blob = pos.tobytes() + idx.tobytes()
    tet = _tet_gltf("data:application/octet-stream;base64," + __import__("base64").b64encode(blob).decode())
    tet["meshes"][0]["primitives"][0]["indices"] = 1
    tet["accessors"].append({"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"})
    tet["bufferViews"] = [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 24}]
    tet["buffers"] = [{"uri": tet["buffers"][0]["uri"], "byteLength": len(blob)}]
    _gltf_variants(d, tet, "")
    # frames: an unread member past memory (valid), a read one (refused), normals past float32's
    # squares, a complex channel
    d.joinpath("bomb.npz").write_bytes(_npz_bomb(frame, "albedo", (1 << 40,)))
    d.joinpath("depthbomb.npz").write_bytes(
        _npz_bomb({k: v for k, v in frame.items() if k != "depth"}, "depth", (1 << 20, 1 << 20))
    )
    np.savez(d / "bignormal.npz", **{**frame, "normal_cam": frame["normal_cam"] * np.float32(1e20)})
    np.savez(d / "cplx_depth.npz", **{**frame, "depth": frame["depth"] + 1j})
    # points and normals: complex, boolean, non-finite, longer than float32's square root
    p = np.load(d / "p.npy")
    np.save(d / "cplx_p.npy", p + 0j)
    np.save(d / "bool_p.npy", p > 0.5)
    n = np.load(d / "n.npy")
    np.save(d / "nan_n.npy", np.where(np.arange(6)[:, None] == 1, np.nan, n))
    np.save(d / "inf_n.npy", np.where(np.arange(6)[:, None] == 3, np.inf, n))
    np.save(d / "cplx_n.npy", n + 1j)
    np.save(d / "big_n.npy", n * np.array([1, 1e20, 1e-30, 1e300, 1, 1])[:, None])
    # volumes and regions files: deep, Latin-1, a misspelt key
    vol = json.loads((d / "vol.json").read_text())
    (d / "deep_vol.json").write_text(_deep_in(vol, "stats"))
    (d / "latin1_vol.json").write_bytes(_latin1(vol))
    (d / "typo_vol.json").write_text(json.dumps({**vol, "blnd": 0.5}))
    regions = json.loads((d / "regions.json").read_text())
    (d / "deep_regions.json").write_text(_deep_in(regions, "edges"))
    typo = json.loads(json.dumps(regions))
    typo["regions"][0]["mxa"] = [1, 1, 1]
    (d / "typo_regions.json").write_text(json.dumps(typo))
    # camera files: a misspelt key, a scaled pose, a singular pose, eye on target, deep, Latin-1
    (d / "typo_poses.json").write_text(
        json.dumps([{**{k: v for k, v in pose.items() if k != "yfov_deg"}, "fov": 50}])
    )
    scaled = [[2.0, 0, 0, 2.0], [0, 2.0, 0, 1.5], [0, 0, 2.0, 2.0], [0, 0, 0, 1]]
    (d / "scaled_poses.json").write_text(json.dumps([{"pose": scaled}]))
    singular = [[1.0, 0, 0, 2.0], [0, 0, 0, 1.5], [0, 0, 1.0, 2.0], [0, 0, 0, 1]]
    (d / "singular_poses.json").write_text(json.dumps([{"pose": singular}]))
    (d / "same_poses.json").write_text(json.dumps([{**pose, "target": pose["eye"]}]))
    (d / "deep_poses.json").write_text(_deep_in({"cameras": [pose]}, "x"))
    (d / "latin1_poses.json").write_bytes(_latin1({"cameras": [pose]}))
    # dataset configs: deep, Latin-1
    (d / "deep_dataset.json").write_text(_deep_in(dataset, "labels"))
    (d / "latin1_dataset.json").write_bytes(_latin1(dataset))
    # parity inputs for the relu export: real, an unread member past memory, NaN, past float32
    x = rng.standard_normal((1, 4, 8, 8)).astype(np.float32)
    np.savez(d / "pin.npz", x=x)
    (d / "bomb_pin.npz").write_bytes(_npz_bomb({"x": x}, "unused", (1 << 40,)))
    np.savez(d / "nan_pin.npz", x=np.where(x > 1.5, np.nan, x))
    np.savez(d / "big_pin.npz", x=x.astype(np.float64) * 1e300)
    # an ONNX model whose weights are external data beside it
    xi = oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4, "h", "w"])
    yo = oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4, "h", "w"])
    w = numpy_helper.from_array(rng.standard_normal((4, 4, 1, 1)).astype(np.float32), "w")
    conv = oh.make_model(
        oh.make_graph([oh.make_node("Conv", ["x", "w"], ["y"], name="c")], "g", [xi], [yo], [w]),
        opset_imports=[oh.make_opsetid("", 19)],
    )
    (d / "ext").mkdir()
    onnx.save(
        conv, d / "ext" / "conv.onnx", save_as_external_data=True, location="conv.weights", size_threshold=0
    )
    # a level (small, fast to bake) and its hostile copies and configs
    level = d / "level"
    sets = ["buildings=[]", "terrain_cells=3", "crown_subdivisions=0", "houses=1", "trees=1", "shrubs=2"]
    assert main(["level", *(a for v in [*sets, "grass=2"] for a in ("--set", v)), "--out", str(level)]) == 0
    fast = {
        "trace": {"rays": 4, "samples_per_vertex": 1.0, "samples_per_face_cap": 2, "block_samples": 4096},
        "decorators": {"samples_per_instance": 16, "holdout_samples": 16, "local_rays": 4},
        "grass": {"rays": 4},
        "lod": {"enabled": False},
        "workers": 1,
    }
    (level / "fast.json").write_text(json.dumps(fast))
    bad = d / "badlevel"
    bad.mkdir()
    shutil.copy(level / "level.bin", bad / "level.bin")
    doc = json.loads((level / "level.gltf").read_text())
    zero = json.loads(json.dumps(doc))
    tree = next(n for n in zero["nodes"] if n.get("extras", {}).get("role") == "tree")
    for a in tree["extensions"]["EXT_mesh_gpu_instancing"]["attributes"].values():
        zero["accessors"][a]["count"] = 0
    (bad / "zero_trees.gltf").write_text(json.dumps(zero))
    typo = json.loads(json.dumps(doc))
    next(n for n in typo["nodes"] if n.get("extras", {}).get("role") == "shrub")["extras"]["densty"] = 1.0
    (bad / "typo.gltf").write_text(json.dumps(typo))
    _gltf_variants(bad, doc, "")
    (bad / "latin1.json").write_bytes(_latin1({"trace": fast["trace"]}).replace(b'"name"', b'"output"'))
    (bad / "deep.json").write_text(_deep_in(fast, "blend"))
    (bad / "typo.json").write_text(json.dumps({**fast, "trace": {**fast["trace"], "rayz": 4}}))
    (bad / "nan.json").write_text(
        json.dumps(fast).replace('"rays": 4, "samples', '"rays": 4, "alpha": NaN, "samples', 1)
    )


@pytest.fixture(scope="module")
def fuzz_env(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli_fuzz")
    files = root / "in"
    files.mkdir()
    _write_files(files, root)
    # every command module imported now: a signal that lands in a first import would leave a half-imported
    # library (torch, PyOpenGL) behind for the next cases
    from neuralao.pipeline.cli.main import COMMANDS

    for module, _ in COMMANDS.values():
        __import__(module)
    yield root, files
    report = os.environ.get("NEURALAO_FUZZ_REPORT")
    for never in ("internal errors", "warnings", "partial outputs", "temporaries left"):
        STATS[never] += 0  # asserted never to happen: a case that did would have failed the run
    if report:
        Path(report).write_text(json.dumps(dict(sorted(STATS.items())), indent=2) + "\n")


# ----------------------------------------------------------------------------- the contract

PROGRESS = re.compile(r"\[\d\d:\d\d")  # a tqdm bar: "... 1/1 [00:00<00:00, 6.4view/s]"
MARKERS = {
    "render": "render.json",
    "view": "index.html",
    "dataset": "manifest.json",
    "glsl": "manifest.json",
    "level": "level.gltf",
}
SIGNAL_EXIT = {"SIGINT": (130, "interrupted (Ctrl-C)"), "SIGTERM": (143, "terminated (SIGTERM)")}
# What a file written by a command must have: the umask's permissions, as any command-line tool gives.
UMASK = os.umask(0o022)
os.umask(UMASK)


def _bad_output(case: Case, work: Path) -> Path:
    """An output of ``case``'s kind that cannot be written (BAD_OUTPUTS)."""
    suffix = Path(case.out).suffix
    if case.bad_out == "below_file":
        (work / "a_file").write_text("x")
        return work / "a_file" / ("out" + suffix)
    if case.bad_out == "proc":
        return Path("/proc/neuralao-fuzz") / ("out" + suffix)
    if case.bad_out == "long_name":
        return work / ("x" * 300 + suffix)
    if case.out_is_dir:
        (work / ("a_file" + suffix)).write_text("x")
        return work / ("a_file" + suffix)
    (work / ("a_folder" + suffix)).mkdir()
    return work / ("a_folder" + suffix)


def _materialise(case: Case, files: Path, work: Path) -> tuple[list[str], Path, Path]:
    out = work / case.out if case.out else work / "none"
    if case.bad_out:
        out = _bad_output(case, work)
    out2 = work / ("composite" + Path(case.out).suffix if case.command == "infer" else "glsl_out")
    if case.prefill == "export":  # an earlier export, with a pass the new one does not have
        shutil.copytree(files / "export", out)
        (out / "glsl" / "stale_pass.comp").write_text("// an earlier model's pass\n")
    elif case.prefill == "user":
        out.mkdir()
        (out / "notes.txt").write_text("a user's own file\n")
    for name in case.copies:
        shutil.copy(files / name, work / name)
    argv = []
    for token in case.argv:
        if token == "@OUT":
            argv.append(str(out))
        elif token == "@OUT2":
            argv.append(str(out2))
        elif token.startswith("@COPY:"):
            argv.append(str(work / token.split(":", 1)[1]))
        elif token.startswith("@"):
            argv.append(str(files / token[1:]))
        else:
            argv.append(token)
    return argv, out, out2


class _LateSignal(BaseException):
    """The signal arrived outside the command (before main took it over, or after it returned): what a
    process's default disposition would do then, not the command's to handle."""


def _run_signalled(argv: list[str], name: str, delay: float) -> tuple[int | None, str, list]:
    """``_run`` with signal ``name`` sent to this process after ``delay`` seconds (a timer that the
    command's own code never sees); rc None when it came outside the command."""
    sig = getattr(signal, name)
    armed = {"on": True}

    def fire(signum, frame):
        if armed["on"]:
            os.kill(os.getpid(), sig)

    def late(signum, frame):  # SIGTERM outside the command (main restores this handler when it returns)
        raise _LateSignal()

    def late_int(signum, frame):
        raise KeyboardInterrupt()

    # no garbage collection meanwhile: a signal handled inside a gc callback (hypothesis keeps one) is
    # swallowed there, which no real process would do
    gc.disable()
    handlers = {s: signal.getsignal(s) for s in (signal.SIGALRM, signal.SIGTERM, signal.SIGINT)}
    signal.signal(signal.SIGALRM, fire)
    signal.signal(signal.SIGTERM, late)
    signal.signal(signal.SIGINT, late_int)
    try:
        try:
            signal.setitimer(signal.ITIMER_REAL, max(delay, 1e-4))
            result = _run(argv)
        finally:
            armed["on"] = False
            signal.setitimer(signal.ITIMER_REAL, 0)
    except (KeyboardInterrupt, _LateSignal):
        result = (None, "", [])
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
        gc.enable()
    return result


def _run(argv: list[str]) -> tuple[int, str, list[warnings.WarningMessage]]:
    err = io.StringIO()
    with (
        warnings.catch_warnings(record=True) as caught,
        contextlib.redirect_stderr(err),
        contextlib.redirect_stdout(io.StringIO()),
    ):
        warnings.simplefilter("always")
        try:
            rc = main(argv)
        except SystemExit as e:
            rc = e.code if isinstance(e.code, int) else 2
    return rc, err.getvalue(), [w for w in caught if not issubclass(w.category, DeprecationWarning)]


def _error_lines(stderr: str) -> list[str]:
    lines = [seg.rsplit("\r", 1)[-1] for seg in stderr.split("\n")]
    return [ln for ln in lines if ln.strip() and not PROGRESS.search(ln)]


def _check_output(case: Case, out: Path) -> None:
    """A success must leave a valid output: read it back; every file in it has the umask's permissions."""
    from neuralao.runtime.foundation.io import read_npz

    for f in [out] if out.is_file() else [p for p in out.rglob("*") if p.is_file()]:
        mode = f.stat().st_mode & 0o777
        assert mode == 0o666 & ~UMASK, f"{f} was written with mode {oct(mode)}, umask {oct(UMASK)}"
    if case.command == "bake" and "--config" in case.argv:
        from neuralao.pipeline.geometry.level_files import read_gltf_json

        doc, _ = read_gltf_json(out / "level_baked.glb")
        assert doc["meshes"]
        return
    if case.command == "level":
        from neuralao.pipeline.geometry.level_files import read_level

        assert read_level(out / "level.gltf").nodes and isinstance(
            json.loads((out / "bake.json").read_text()), dict
        )
        return
    if (
        case.command == "bake"
        and out.suffix == ".ply"
        or (case.command == "bake" and "--to" not in case.argv)
    ):
        from neuralao.pipeline.bakes.vertex import read_baked_mesh

        v, faces, ao, _ = read_baked_mesh(out)
        assert ao.shape == (len(v),) and np.isfinite(ao).all() and (0 <= ao).all() and (ao <= 1).all()
    elif case.command == "bake":
        from neuralao.pipeline.bakes.texture import read_texture_glb

        _, red = read_texture_glb(out)
        assert np.isfinite(red).all() and (0 <= red).all() and (red <= 1).all()
    elif case.command == "render":
        record = json.loads((out / "render.json").read_text())
        for view in record["views"]:
            frame = read_npz(out / view["file"])
            for k, a in frame.items():
                assert a.dtype.kind not in "fc" or np.isfinite(a).all(), k
            assert ((0 <= frame["ao"]) & (frame["ao"] <= 1)).all()
    elif case.command == "infer":
        if out.suffix == ".png":
            from PIL import Image

            assert Image.open(out).size == (16, 16)
        elif out.suffix == ".npy":
            ao = np.load(out)
            assert ao.shape == (16, 16) and np.isfinite(ao).all() and (0 <= ao).all() and (ao <= 1).all()
        else:
            import OpenEXR

            with OpenEXR.File(str(out)) as f:
                ao = f.channels()["Y"].pixels
            assert ao.shape == (16, 16) and np.isfinite(ao).all() and (0 <= ao).all() and (ao <= 1).all()
    elif case.command == "probe":
        ao = np.load(out)
        assert ao.ndim == 1 and ao.dtype == np.float32 and np.isfinite(ao).all()
        assert (0 <= ao).all() and (ao <= 1).all()
    elif case.command == "volumes":
        from neuralao.runtime.volumes import read_volumes

        vol = read_volumes(out)
        assert all(np.isfinite(m.coefficients).all() for m in vol.models)
    elif case.command == "view":
        assert (out / "index.html").is_file() and (out / "scene.js").stat().st_size > 0
    elif case.command == "train":
        from neuralao.pipeline.models.field import load_checkpoint

        ckpt = load_checkpoint(out)
        assert np.isfinite(ckpt["metrics"]["val_rmse"])
    elif case.command == "dataset":
        assert json.loads((out / "manifest.json").read_text())["scenes"]
    elif case.command == "glsl":
        import onnx

        assert json.loads((out / "manifest.json").read_text())["kind"] == "onnx-glsl"
        onnx.checker.check_model(onnx.load(str(out / "model.onnx")))  # its weights inside, none beside
        assert not (out / "glsl" / "stale_pass.comp").exists() and not (out / "notes.txt").exists()
    elif case.command == "parity":
        json.loads(out.read_text())


def _leftovers(work: Path) -> list[str]:
    return [str(p.relative_to(work)) for p in work.rglob("*") if re.match(r"^\..*\.tmp", p.name)]


def check_case(root: Path, files: Path, case: Case) -> None:
    """Run one case and assert the contract (module doc)."""
    STATS["cases"] += 1
    work = root / f"case{STATS['cases']:05d}"
    work.mkdir()
    argv, out, out2 = _materialise(case, files, work)
    t0 = time.perf_counter()
    rc, stderr, caught = _run_signalled(argv, case.signal, case.delay) if case.signal else _run(argv)
    if case.signal:  # an interrupt between a library's open() and its `with` leaves the file to the garbage
        # collector: a ResourceWarning, which Python shows only in development mode, never in a normal run
        caught = [w for w in caught if not issubclass(w.category, ResourceWarning)]
    STATS["seconds"] = round(STATS["seconds"] + time.perf_counter() - t0, 3)
    STATS[f"exit {rc}"] += 1
    STATS[f"{case.command or 'top'} exit {rc}"] += 1
    lines = _error_lines(stderr)
    assert "Traceback" not in stderr, f"traceback for {argv}:\n{stderr}"
    assert not caught, f"warning for {argv}: {[str(w.message) for w in caught]}"
    leftovers = _leftovers(work)
    assert not leftovers, f"temporary files left by {argv}: {leftovers}"
    for name in case.copies:  # an input named as an output is left as it was
        assert (work / name).read_bytes() == (files / name).read_bytes(), f"{argv} changed its input {name}"
    marker = out / MARKERS.get(case.command, "") if case.out_is_dir and case.command in MARKERS else out
    if rc is None:  # the signal came outside the command
        STATS["signal outside the command"] += 1
    elif case.signal and rc in (130, 143):
        STATS["interrupted"] += 1
        want_rc, words = SIGNAL_EXIT[case.signal]
        assert rc == want_rc and len(lines) == 1 and words in lines[0], (
            f"{argv} on {case.signal}: {rc} {lines}"
        )
        if "--config" in case.argv:  # a level bake keeps its finished stages for the rerun: not an output
            marker = out / "level_baked.glb"
        if case.out and not case.bad_out and marker.exists():  # what is there is whole and valid
            _check_output(case, out)
    elif rc == 2:
        assert len(lines) == 1, f"{argv}: expected one stderr line, got {lines}"
        prefix = f"neuralao {case.command}" if case.command else "neuralao"
        assert lines[0].startswith(prefix) and ": error: " in lines[0], lines[0]
        STATS["refused"] += 1
        if (
            case.culprits
        ):  # a flag may be named as the setting it sets: --samples-per-vertex, samples_per_vertex
            names = {n for c in case.culprits for n in (c, c.lstrip("-"), c.lstrip("-").replace("-", "_"))}
            assert any(n in lines[0] for n in names), f"{argv}: {lines[0]!r} names none of {case.culprits}"
        if case.prefill == "export":  # refused: the earlier export is still there, untouched
            assert (out / "glsl" / "stale_pass.comp").is_file(), f"{argv} refused but removed the old export"
        elif case.prefill == "user":
            assert (out / "notes.txt").is_file(), f"{argv} refused but removed the user's folder"
        elif case.out and not case.bad_out:
            assert not marker.exists(), f"{argv} refused but left {marker}"
    else:
        assert rc == 0, f"exit {rc} for {argv}: {stderr.strip()}"
        assert not case.nonfinite, f"{argv}: exit 0 from an input that must be refused"
        assert not case.bad_out, f"{argv}: exit 0 writing an output that cannot be written ({case.bad_out})"
        assert not lines or case.command == "", f"{argv}: success with stderr {lines}"
        STATS["valid result"] += 1
        if case.out:
            _check_output(case, out)
    with contextlib.suppress(OSError):
        shutil.rmtree(work)


@settings(
    max_examples=FUZZ_EXAMPLES,
    derandomize=FUZZ_SEED is None,
    database=None,
    deadline=None,
    print_blob=True,
    suppress_health_check=list(HealthCheck),
)
@seed(FUZZ_SEED or 0)
@given(case=CASES)
def test_cli_invocation_keeps_the_contract(fuzz_env, case):
    check_case(*fuzz_env, case)
