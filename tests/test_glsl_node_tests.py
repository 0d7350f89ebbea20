"""onnx's node tests of the image target's newer ops (export/node_tests.py): none wrong, none crashed,
and the ones that fit the target (one (1, C, H, W) float image) pass. The whole table, every op, is
bench/bench_conformance.py's (docs/shader-conformance.md)."""

from __future__ import annotations

from neuralao.export.node_tests import counts_by_op, run_node_tests

OPS = (
    "DepthToSpace",
    "SpaceToDepth",
    "InstanceNormalization",
    "GroupNormalization",
    "LayerNormalization",
    "ReduceMean",
    "ReduceMax",
    "ReduceSum",
    "ReduceL2",
    "Softmax",
    "LogSoftmax",
    "Erf",
    "Gelu",
    "Mish",
    "Sum",
    "Mean",
    "Min",
    "Max",
    "LRN",
    "LpPool",
    "GlobalLpPool",
    "Dropout",
)


def test_node_tests_none_wrong():
    results = run_node_tests(OPS)
    bad = [(r.name, r.outcome, r.reason) for r in results if r.outcome in ("wrong", "crashed")]
    assert not bad, bad
    counts = counts_by_op(results)
    # the cases with a (1, C, H, W) input pass: DepthToSpace 2, SpaceToDepth 3, InstanceNormalization 1,
    # Erf 1, LpPool 6; the others' node tests use rank-3 or batched inputs, refused at the input
    passed = {op: c["passed"] for op, c in counts.items() if c["passed"]}
    assert passed == {
        "DepthToSpace": 2,
        "SpaceToDepth": 3,
        "InstanceNormalization": 1,
        "Erf": 1,
        "LpPool": 6,
    }, passed
    refused = [r for r in results if r.outcome == "refused"]
    assert all(r.op in r.reason or "input" in r.reason for r in refused)
