"""The consumer runtime runs without the training and baking stack: with torch, torchvision, embreex,
pyrender and ray made unimportable, every module under runtime/ imports, the shipped U-Net infers a
synthetic G-buffer through onnxruntime, and a generated GLSL pass (GTAO) runs on the headless GL context.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BLOCKED = ("torch", "torchvision", "embreex", "pyrender", "ray")

# Installed first in the child: any import of a blocked package (or a submodule) raises ImportError.
BLOCKER = textwrap.dedent(f"""
    import sys

    class Blocker:
        blocked = {BLOCKED!r}

        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in self.blocked:
                raise ImportError(f"{{name}} is blocked: the consumer runtime must not need it")
            return None

    for name in list(sys.modules):
        if name.split(".")[0] in Blocker.blocked:
            del sys.modules[name]
    sys.meta_path.insert(0, Blocker())
""")

CONSUMER = textwrap.dedent("""
    import importlib
    import pkgutil

    import numpy as np

    import neuralao.runtime

    names = [m.name for m in pkgutil.walk_packages(neuralao.runtime.__path__, "neuralao.runtime.")]
    for name in names:
        importlib.import_module(name)
    print("imported", len(names))

    from neuralao.runtime.baselines import run_gtao
    from neuralao.runtime.infer import infer
    from neuralao.runtime.shipped import default_model

    h, w = 48, 64
    depth = np.full((h, w), 4.0, np.float32)
    depth[12:36, 16:48] = 3.0
    depth[:4] = 0.0  # a background strip
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1.0
    frame = {"depth": depth, "normal_cam": normal, "mask": depth > 0, "yfov": np.float32(0.9)}

    ao = infer(default_model("unet"), frame, radius=0.5)
    ok = ao.shape == (h, w) and np.isfinite(ao).all() and 0 <= ao.min() and ao.max() <= 1
    print("unet", ao.shape, bool(ok), bool((ao[:4] == 1).all()))

    gtao = run_gtao(frame, 0.5)
    ok = gtao.shape == (h, w) and np.isfinite(gtao).all() and 0 <= gtao.min() and gtao.max() <= 1
    print("gtao", gtao.shape, bool(ok))
""")


def _run(code: str) -> subprocess.CompletedProcess:
    env = dict(
        os.environ, PYOPENGL_PLATFORM=os.environ.get("PYOPENGL_PLATFORM", "osmesa"), PYTHONPATH=str(ROOT)
    )
    return subprocess.run(
        [sys.executable, "-c", BLOCKER + code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600
    )


def test_the_blocker_refuses_the_training_stack():
    for name in BLOCKED:
        proc = _run(f"import {name}")
        assert proc.returncode != 0 and f"{name} is blocked" in proc.stderr, (name, proc.stderr[-500:])
    proc = _run("import torch.nn")
    assert proc.returncode != 0 and "torch is blocked" in proc.stderr  # the parent package is refused first


def test_runtime_imports_and_runs_without_the_training_stack():
    proc = _run(CONSUMER)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("imported ") and int(lines[0].split()[1]) >= 10
    assert "unet (48, 64) True True" in lines
    assert "gtao (48, 64) True" in lines
