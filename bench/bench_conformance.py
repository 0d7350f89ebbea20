"""onnx's node tests and light models through the GLSL image target: passed, refused, wrong.

    .venv/bin/python bench/bench_conformance.py --out build/bench [--no-light] [--dialect glsl430|wgsl]

Node tests: every single-node case onnx ships for an op in the image target's table (see
export/node_tests.py for the rules: the first input is the image, the others become initializers; the
test's own tolerance). Light models: onnx's ``light`` variants of eight classic CNNs (weights made by
ConstantOfShape), at their 224 x 224 input, against onnxruntime on a seeded input.

Writes DIR/conformance.json and DIR/conformance.md (the tables of docs/shader-conformance.md);
``--dialect wgsl`` runs the WGSL passes on WebGPU (wgpu) instead and writes conformance-wgsl.*.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import onnx

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402

OUTCOMES = ("passed", "matches_onnxruntime", "refused", "wrong", "crashed")


def _reason_kind(reason: str) -> str:
    """A refusal in a few words: the image target's input rules, or the op's own reason."""
    if "must have rank 4" in reason:
        return "input not rank 4"
    if "has batch" in reason:
        return "batch > 1"
    if "must be float32" in reason:
        return "input not float32"
    if "graph input" in reason or "scalars" in reason:
        return "a second image input"
    return reason.split(": ", 1)[-1][:90]


def node_table(results) -> tuple[str, dict]:
    from neuralao.export.node_tests import counts_by_op

    counts = counts_by_op(results)
    total = Counter()
    lines = [
        "| op | passed | matches onnxruntime | refused | wrong | crashed | refused because |",
        "|---|---|---|---|---|---|---|",
    ]
    for op, c in counts.items():
        total.update(c)
        why = Counter(_reason_kind(r.reason) for r in results if r.op == op and r.outcome == "refused")
        reasons = "; ".join(f"{k} ({n})" for k, n in why.most_common())
        lines.append(f"| {op} | " + " | ".join(str(c.get(o, 0)) for o in OUTCOMES) + f" | {reasons} |")
    lines.append("| **all** | " + " | ".join(f"**{total.get(o, 0)}**" for o in OUTCOMES) + " | |")
    return "\n".join(lines), {op: dict(c) for op, c in counts.items()}


def light_models(dialect: str = "glsl430") -> list[dict]:
    from onnx.backend.test import __file__ as test_init

    from neuralao.export.glsl import generate_compute
    from neuralao.export.onnx_io import run_onnxruntime
    from neuralao.runtime.foundation.errors import NeuralaoError
    from neuralao.runtime.glsl_runner import run_compute_all
    from neuralao.runtime.wgsl_runner import run_wgsl_all

    run_program = run_wgsl_all if dialect == "wgsl" else run_compute_all
    rows = []
    for path in sorted((Path(test_init).parent / "data" / "light").glob("*.onnx")):
        model = onnx.load(path)
        name = path.stem.removeprefix("light_")
        t0 = time.perf_counter()
        try:
            program = generate_compute(model, dialect=dialect)
        except NeuralaoError as e:
            rows.append({"model": name, "outcome": "refused", "reason": str(e)})
            continue
        inits = {i.name for i in model.graph.initializer}
        vi = next(i for i in model.graph.input if i.name not in inits)
        x = (
            np.random.default_rng(0)
            .normal(size=[d.dim_value for d in vi.type.tensor_type.shape.dim])
            .astype(np.float32)
        )
        ref = run_onnxruntime(model.SerializeToString(), {vi.name: x})[0]
        t1 = time.perf_counter()
        got = next(iter(run_program(program, x).values()))
        err = float(np.abs(got - ref).max()) if got.shape == ref.shape else float("inf")
        rows.append(
            {
                "model": name,
                "outcome": "passed" if err <= 1e-4 * max(1.0, float(np.abs(ref).max())) else "wrong",
                "max_abs_err": err,
                "max_abs_ref": float(np.abs(ref).max()),
                "passes": len(program.manifest["passes"]),
                "generate_s": round(t1 - t0, 2),
                "run_s": round(time.perf_counter() - t1, 2),
            }
        )
    return rows


def light_table(rows: list[dict]) -> str:
    lines = [
        "| model | outcome | max abs err | max abs value | passes | why refused |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r["outcome"] == "refused":
            lines.append(f"| {r['model']} | refused | | | | {r['reason']} |")
        else:
            lines.append(
                f"| {r['model']} | {r['outcome']} | {r['max_abs_err']:.2g} | {r['max_abs_ref']:.3g} | "
                f"{r['passes']} | |"
            )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--no-light", action="store_true", help="skip the light models (minutes on llvmpipe)")
    ap.add_argument(
        "--dialect",
        default="glsl430",
        choices=("glsl430", "wgsl"),
        help="glsl430: GLSL on GL (llvmpipe); wgsl: WGSL on WebGPU (wgpu, lavapipe)",
    )
    args = ap.parse_args()
    from neuralao.export.glsl import ImageOps
    from neuralao.export.node_tests import run_node_tests

    t0 = time.perf_counter()
    results = run_node_tests(ImageOps.OPS, args.dialect)
    table, counts = node_table(results)
    seconds = time.perf_counter() - t0
    light = [] if args.no_light else light_models(args.dialect)
    stem = "conformance-wgsl" if args.dialect == "wgsl" else "conformance"
    report = {
        "cpu": cpu_name(),
        "dialect": args.dialect,
        "node_tests": counts,
        "node_seconds": round(seconds, 1),
        "light": light,
        "cases": [r.__dict__ for r in results],
    }
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / f"{stem}.json", report)
    md = [f"Node tests ({len(results)} cases, {seconds:.0f} s on {cpu_name()}):", "", table]
    if light:
        md += ["", "Light models:", "", light_table(light)]
    write_text(args.out / f"{stem}.md", "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
