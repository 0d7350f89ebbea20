"""Whole models through the GLSL generator on Mesa vs onnxruntime: the baked MLP (fragment) and a
U-Net-shaped network (compute), torch-exported and hand-built (batch norm kept), fp32 and fp16,
and their exports run back from disk."""

from __future__ import annotations

import io
import json

import numpy as np
import onnx
import pytest
import torch
from helpers import onnx_vs_torch_tol
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh
from torch import nn

from neuralao.export.glsl import (
    MAX_UNIFORM_BLOCK_BYTES,
    generate_compute,
    generate_mlp_fragment,
    validate_glsl,
    write_compute_export,
    write_mlp_export,
)
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute, run_mlp_fragment

# ----------------------------------------------------------------------------- baked MLP


def _torch_mlp(sizes=(48, 16, 8, 1), seed=0) -> nn.Sequential:
    torch.manual_seed(seed)
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(nn.Tanh())
    return nn.Sequential(*layers).eval()


def _export_mlp(net: nn.Module) -> onnx.ModelProto:
    buf = io.BytesIO()
    torch.onnx.export(
        net,
        (torch.zeros(2, 48),),
        buf,
        dynamo=False,
        input_names=["normals"],
        output_names=["ao"],
        dynamic_axes={"normals": {0: "N"}, "ao": {0: "N"}},
        opset_version=17,
    )
    return onnx.load_from_string(buf.getvalue())


def _helper_mlp(net: nn.Sequential) -> onnx.ModelProto:
    """The same network as MatMul + Add + Tanh nodes built with onnx.helper."""
    nodes, inits, x = [], [], "normals"
    linears = [m for m in net if isinstance(m, nn.Linear)]
    for i, lin in enumerate(linears):
        inits += [
            nh.from_array(lin.weight.detach().numpy().T.copy(), f"W{i}"),
            nh.from_array(lin.bias.detach().numpy().copy(), f"b{i}"),
        ]
        nodes += [
            oh.make_node("MatMul", [x, f"W{i}"], [f"m{i}"]),
            oh.make_node("Add", [f"m{i}", f"b{i}"], [f"a{i}"]),
        ]
        x = f"a{i}"
        if i < len(linears) - 1:
            nodes.append(oh.make_node("Tanh", [x], [f"h{i}"]))
            x = f"h{i}"
    graph = oh.make_graph(
        nodes,
        "mlp",
        [oh.make_tensor_value_info("normals", TensorProto.FLOAT, ["N", 48])],
        [oh.make_tensor_value_info(x, TensorProto.FLOAT, ["N", 1])],
        inits,
    )
    return oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)])


def _normal_image(h=20, w=24, seed=0):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(h, w, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    yy, xx = np.mgrid[:h, :w]
    mask = (yy - h / 2) ** 2 + (xx - w / 2) ** 2 < (0.45 * min(h, w)) ** 2
    return n, mask


def _mlp_reference(model: onnx.ModelProto, n: np.ndarray) -> np.ndarray:
    x = np.tile(n.reshape(-1, 3), (1, 16))
    return run_onnxruntime(model.SerializeToString(), {"normals": x})[0].reshape(n.shape[:2])


@pytest.mark.parametrize("build", ["torch", "helper"])
def test_mlp_parity(build):
    net = _torch_mlp()
    model = _export_mlp(net) if build == "torch" else _helper_mlp(net)
    ops = {n.op_type for n in model.graph.node}
    assert ops == ({"Gemm", "Tanh"} if build == "torch" else {"MatMul", "Add", "Tanh"})
    n, mask = _normal_image()
    ref = _mlp_reference(model, n)
    for fold in (True, False):
        shader = generate_mlp_fragment(model, fold_repeated_input=fold)
        assert shader.manifest["network"]["fold_repeated_input"] is fold
        for dialect in ("glsl330", "es300"):
            ao = run_mlp_fragment(shader, n, mask, dialect=dialect)
            assert ao.shape == ref.shape and ao.dtype == ref.dtype == np.float32
            err = float(np.abs(ao[mask] - ref[mask]).max())
            assert err <= TOL.parity_mlp_fp32, f"{dialect} fold={fold}: {err:.3g}"
            assert np.all(ao[~mask] == 1.0)


def test_mlp_out_of_range_inputs_stay_finite():
    """Weights x100 and normals of length 0 and 100: pre-activations in the thousands; the
    overflow-safe tanh keeps every hidden unit in [-1, 1], so |ao| <= sum|w_out| + |b_out|."""
    net = _torch_mlp(seed=1)
    with torch.no_grad():
        for p in net.parameters():
            p.mul_(100.0)
    model = _export_mlp(net)
    n, mask = _normal_image(8, 10, seed=2)
    n[:4] *= 0.0
    n[4:] *= 100.0
    mask[:] = True
    last = [m for m in net if isinstance(m, nn.Linear)][-1]
    bound = float(last.weight.abs().sum() + last.bias.abs().sum())
    ref = _mlp_reference(model, n)
    for fold in (True, False):
        ao = run_mlp_fragment(generate_mlp_fragment(model, fold_repeated_input=fold), n, mask)
        assert np.all(np.isfinite(ao))
        assert np.abs(ao).max() <= bound * (1 + 1e-6)
        # Saturated units agree exactly; the rest differ by fp32 rounding of sums ~1e3 in size.
        assert np.abs(ao - ref).max() <= TOL.parity_mlp_fp32 * 100.0**2


def test_mlp_64x32_uniform_blocks_fit_16k(tmp_path):
    net = _torch_mlp((48, 64, 32, 1), seed=3)
    model = _export_mlp(net)
    shader = generate_mlp_fragment(model, fold_repeated_input=False, weights="uniform")
    assert shader.manifest["parameter_bytes_fp32"] == 20996
    assert len(shader.uniform_blocks) >= 2
    assert all(arr.nbytes <= MAX_UNIFORM_BLOCK_BYTES for _, _, arr in shader.uniform_blocks)
    manifest_path = write_mlp_export(shader, tmp_path / "mlp")
    manifest = json.loads(manifest_path.read_text())
    for b in manifest["uniform_blocks"]:
        assert (tmp_path / "mlp" / b["file"]).stat().st_size == b["bytes"] <= MAX_UNIFORM_BLOCK_BYTES
    for name in ("mlp.vert", "mlp.frag", "mlp_es300.vert", "mlp_es300.frag"):
        assert (tmp_path / "mlp" / name).is_file()
    n, mask = _normal_image(12, 16, seed=4)
    ref = _mlp_reference(model, n)
    for dialect in ("glsl330", "es300"):
        ao = run_mlp_fragment(tmp_path / "mlp", n, mask, dialect=dialect)  # the files on disk only
        assert np.abs(ao[mask] - ref[mask]).max() <= TOL.parity_mlp_fp32


# ----------------------------------------------------------------------------- U-Net-shaped compute


class TinyUNet(nn.Module):
    """conv3x3 + LeakyReLU, avgpool 2 (x3) / bilinear x2, conv, BatchNorm2d, LeakyReLU, concat, conv,
    1x1 conv, sigmoid: the DeepAO layout at toy widths. Input H, W multiples of 8."""

    def __init__(self, widths=(4, 6, 8, 8), seed=0):
        super().__init__()
        torch.manual_seed(seed)
        w = widths
        self.down = nn.ModuleList(
            nn.Conv2d(4 if i == 0 else w[i - 1], w[i], 3, padding=1) for i in range(len(w))
        )
        self.up = nn.ModuleList(nn.Conv2d(w[i + 1], w[i], 3, padding=1) for i in range(len(w) - 1))
        self.bn = nn.ModuleList(nn.BatchNorm2d(w[i]) for i in range(len(w) - 1))
        self.fuse = nn.ModuleList(nn.Conv2d(2 * w[i], w[i], 3, padding=1) for i in range(len(w) - 1))
        self.out = nn.Conv2d(w[0], 1, 1)
        g = torch.Generator().manual_seed(seed + 1)
        for bn in self.bn:  # non-trivial running statistics and affine parameters
            bn.running_mean.copy_(torch.randn(bn.num_features, generator=g) * 0.5)
            bn.running_var.copy_(torch.rand(bn.num_features, generator=g) * 2 + 0.3)
            bn.weight.data.copy_(torch.rand(bn.num_features, generator=g) + 0.5)
            bn.bias.data.copy_(torch.randn(bn.num_features, generator=g) * 0.3)
        self.eval()

    def forward(self, x):
        act = nn.functional.leaky_relu
        skips = []
        for i, conv in enumerate(self.down):
            x = act(conv(x), 0.01)
            if i < len(self.down) - 1:
                skips.append(x)
                x = nn.functional.avg_pool2d(x, 2)
        for i in reversed(range(len(self.up))):
            x = nn.functional.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)
            x = act(self.bn[i](self.up[i](x)), 0.01)
            x = act(self.fuse[i](torch.cat([x, skips[i]], dim=1)), 0.01)
        return torch.sigmoid(self.out(x))


def _set_pad_multiple(model: onnx.ModelProto, multiple: int) -> onnx.ModelProto:
    p = model.metadata_props.add()
    p.key, p.value = "pad_multiple", str(multiple)
    return model


def _export_unet(net: TinyUNet) -> onnx.ModelProto:
    buf = io.BytesIO()
    torch.onnx.export(
        net,
        (torch.zeros(1, 4, 16, 16),),
        buf,
        dynamo=False,
        input_names=["gbuffer"],
        output_names=["ao"],
        dynamic_axes={"gbuffer": {2: "H", 3: "W"}, "ao": {2: "H", 3: "W"}},
        opset_version=17,
    )
    return _set_pad_multiple(onnx.load_from_string(buf.getvalue()), 8)


def _helper_unet(net: TinyUNet) -> onnx.ModelProto:
    """The same network hand-built with onnx.helper, keeping BatchNormalization nodes (dynamo-style)."""
    nodes, inits = [], [nh.from_array(np.array([1, 1, 2, 2], np.float32), "scale2")]
    count = iter(range(1000))

    def const(t: torch.Tensor) -> str:
        name = f"c{next(count)}"
        inits.append(nh.from_array(t.detach().numpy().astype(np.float32).copy(), name))
        return name

    def node(op, inputs, **attrs) -> str:
        out = f"v{next(count)}"
        nodes.append(oh.make_node(op, inputs, [out], name=f"{op}_{out}", **attrs))
        return out

    def conv(m: nn.Conv2d, x: str) -> str:
        p = m.padding[0]
        return node(
            "Conv", [x, const(m.weight), const(m.bias)], pads=[p, p, p, p], kernel_shape=list(m.kernel_size)
        )

    def lrelu(x: str) -> str:
        return node("LeakyRelu", [x], alpha=0.01)

    x, skips = "gbuffer", []
    for i, m in enumerate(net.down):
        x = lrelu(conv(m, x))
        if i < len(net.down) - 1:
            skips.append(x)
            x = node("AveragePool", [x], kernel_shape=[2, 2], strides=[2, 2])
    for i in reversed(range(len(net.up))):
        x = node("Resize", [x, "", "scale2"], mode="linear", coordinate_transformation_mode="half_pixel")
        bn = net.bn[i]
        x = node(
            "BatchNormalization",
            [
                conv(net.up[i], x),
                const(bn.weight),
                const(bn.bias),
                const(bn.running_mean),
                const(bn.running_var),
            ],
            epsilon=bn.eps,
        )
        x = node("Concat", [lrelu(x), skips[i]], axis=1)
        x = lrelu(conv(net.fuse[i], x))
    y = node("Sigmoid", [conv(net.out, x)])
    graph = oh.make_graph(
        nodes,
        "unet",
        [oh.make_tensor_value_info("gbuffer", TensorProto.FLOAT, [1, 4, "H", "W"])],
        [oh.make_tensor_value_info(y, TensorProto.FLOAT, [1, 1, "H", "W"])],
        inits,
    )
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)])
    onnx.checker.check_model(model)
    return _set_pad_multiple(model, 8)


def _unet_reference(model: onnx.ModelProto, x: np.ndarray, multiple: int = 8) -> np.ndarray:
    h, w = x.shape[2:]
    xp = np.pad(x, [(0, 0), (0, 0), (0, (-h) % multiple), (0, (-w) % multiple)], mode="reflect")
    return run_onnxruntime(model.SerializeToString(), {"gbuffer": xp})[0][:, :, :h, :w]


def _gbuffer(h, w, seed=0):
    return np.random.default_rng(seed).normal(size=(1, 4, h, w)).astype(np.float32)


SIZES = [
    (24, 40),
    (21, 37),
]  # 40x24: a non-power-of-two multiple of 8; 37x21 pads to it (same internal sizes)


@pytest.mark.parametrize("preset", ["cpu", "gpu"])
@pytest.mark.parametrize("build", ["torch", "helper_bn"])
def test_unet_parity_fp32(build, preset, tmp_path):
    net = TinyUNet()
    model = _export_unet(net) if build == "torch" else _helper_unet(net)
    ops = {n.op_type for n in model.graph.node}
    assert ("BatchNormalization" in ops) == (build == "helper_bn")
    program = generate_compute(model, preset=preset)
    assert program.manifest["preset"]["name"] == preset
    assert program.pad_multiple == 8
    convs = [p for p in program.manifest["passes"] if p["kind"] == "conv"]
    assert sum(p.get("folded_batch_norm", False) for p in convs) == (3 if build == "helper_bn" else 0)
    assert all("Concat" in p["ops"] for p in convs if p["onnx_nodes"] and len(p["conv"]["layer_offsets"]) > 1)
    for src in program.sources.values():
        validate_glsl(src, "comp")
    with torch.no_grad():
        torch_ref = net(torch.from_numpy(_gbuffer(*SIZES[0]))).numpy()
    for h, w in SIZES:
        x = _gbuffer(h, w)
        ref = _unet_reference(model, x)
        got = run_compute(program, x)
        assert got.shape == ref.shape == (1, 1, h, w) and got.dtype == ref.dtype == np.float32
        err = float(np.abs(got - ref).max())
        assert err <= TOL.parity_unet_fp32, f"{build} {w}x{h}: {err:.3g}"
        if (h, w) == SIZES[0]:
            assert np.abs(ref - torch_ref).max() <= onnx_vs_torch_tol(torch_ref, model)  # the same network
    # The export on disk runs alone; flip_y reads/writes bottom-up images.
    write_compute_export(program, tmp_path / "unet")
    x = _gbuffer(*SIZES[0], seed=1)
    from_disk = run_compute(tmp_path / "unet", x)
    np.testing.assert_array_equal(from_disk, run_compute(program, x))
    flipped = run_compute(tmp_path / "unet", x[:, :, ::-1].copy(), flip_y=True)
    np.testing.assert_array_equal(flipped[:, :, ::-1], from_disk)


@pytest.mark.parametrize("preset", ["cpu", "gpu"])
def test_unet_parity_fp16(preset):
    net = TinyUNet(seed=5)
    model = _export_unet(net)
    program = generate_compute(model, precision="fp16", preset=preset)
    assert program.manifest["storage"]["internal_format"] == "RGBA16F"
    for h, w in SIZES:
        x = _gbuffer(h, w, seed=2)
        got, ref = run_compute(program, x), _unet_reference(model, x)
        assert got.shape == ref.shape
        err = float(np.abs(got - ref).max())
        assert err <= TOL.parity_fp16, f"fp16 {w}x{h}: {err:.3g}"
