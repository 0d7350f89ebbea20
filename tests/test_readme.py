"""The README's journeys, run as written on small inputs, so the front door cannot rot.

Every fenced ``bash`` block between the first journey and the command list runs in order, in one
temporary folder (later blocks use what earlier ones wrote, as a reader following the README would),
with ``neuralao`` and ``python3`` from this environment first on PATH and the repository's
``configs/`` and ``runtime/`` linked in (the README's commands run from the repository root). The
only change to a block is :data:`SMALL`: the documented convention that lowers ray counts, view
counts, frame sizes, texture resolutions, budgets and step counts. A block whose first line starts
with ``# long:`` (training for hours, a cluster of machines) is skipped, and that marker says why.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
FIRST_JOURNEY = "## Bake AO into a glTF"
END_OF_JOURNEYS = "## Commands"
LONG_MARKER = "# long:"
# (pattern, replacement): what a block's numbers become for the test (README, last paragraph).
SMALL: tuple[tuple[str, str], ...] = (
    (r"--rays \d+", "--rays 8"),
    (r"trace\.rays=\d+", "trace.rays=8"),
    (r"directions=\d+", "directions=64"),
    (r'"rays": \d+', '"rays": 8'),
    (r"--views \d+", "--views 1"),
    (r'"views": \d+', '"views": 2'),
    (r"--size \d+ \d+", "--size 64 64"),
    (r'"size": \[\d+, \d+\]', '"size": [64, 64]'),
    (r"--resolution \d+", "--resolution 32"),
    (r"--budget [\d.]+", "--budget 0.05"),
    (r"steps=\d+", "steps=200"),
    (r"internal_height=\d+", "internal_height=64"),
)
# Seconds the journeys may take before the test calls them hung (generous: the machine may be shared).
BLOCK_TIMEOUT = 900


def journey_blocks(text: str) -> list[tuple[str, str]]:
    """(section heading, block text) of every ```bash block of the journeys, in README order."""
    start, end = text.index(FIRST_JOURNEY), text.index(END_OF_JOURNEYS)
    blocks, heading = [], ""
    lines = text[start:end].split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("## "):
            heading = line[3:].strip()
        if line.strip() == "```bash":
            j = i + 1
            while lines[j].strip() != "```":
                j += 1
            blocks.append((heading, "\n".join(lines[i + 1 : j]) + "\n"))
            i = j
        i += 1
    return blocks


def small(block: str) -> str:
    """The block with :data:`SMALL` applied."""
    for pattern, replacement in SMALL:
        block = re.sub(pattern, replacement, block)
    return block


def test_readme_has_journey_blocks_and_marks_long_ones():
    blocks = journey_blocks(README.read_text())
    sections = {h for h, _ in blocks}
    assert {
        "Bake AO into a glTF",
        "A shader for your engine",
        "Run the shipped model on your own G-buffer",
        "Train your own",
        "Bake a level and volumes for dynamic objects",
        "Scale out on Ray",
    } <= sections
    long = [b for _, b in blocks if b.startswith(LONG_MARKER)]
    assert 1 <= len(long) < len(blocks)
    assert len(README.read_text().splitlines()) <= 300


@pytest.mark.slow
def test_readme_journeys_run_as_written(tmp_path):
    """One shell runs the blocks in order, as a reader pasting them would (variables carry over); a
    marker line on stderr before each block names the one that failed."""
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.setdefault("PYOPENGL_PLATFORM", "osmesa")
    for name in ("configs", "runtime"):
        (tmp_path / name).symlink_to(ROOT / name)
    blocks = [(h, small(b)) for h, b in journey_blocks(README.read_text()) if not b.startswith(LONG_MARKER)]
    assert len(blocks) >= 8
    script = "".join(f"echo '::block {k}::' >&2\n{b}" for k, (_, b) in enumerate(blocks))
    proc = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", script],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=BLOCK_TIMEOUT,
    )
    if proc.returncode != 0:
        k = int(re.findall(r"::block (\d+)::", proc.stderr)[-1])
        pytest.fail(f"README block in {blocks[k][0]!r} failed:\n{blocks[k][1]}\n{proc.stderr[-3000:]}")
    for out in (
        "spot-vertex.glb",
        "spot-texture.glb",
        "truck-texture.glb",
        "truck-view/index.html",
        "ao.png",
        "shaded.png",
        "my_ao.png",
        "my-shaders/manifest.json",
        "exports/my-unet/model.onnx",
        "my-unet-ao.png",
        "spot-view/index.html",
        "level-baked/level_baked.glb",
        "volumes.json",
        "ao.npy",
        "spot-ray.ply",
    ):
        assert (tmp_path / out).is_file(), out
