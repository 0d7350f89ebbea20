"""Hard cases the other test files do not reach: labels on the real triangle-soup assemblies,
batch norm with (near-)zero variance and ONNX Clip with lo > hi through the GLSL generator, and truncated
copies of the real mesh files."""

from __future__ import annotations

import numpy as np
import pytest
from onnx import TensorProto
from onnx import helper as oh
from onnx import numpy_helper as nh

from neuralao.export.glsl import generate_compute
from neuralao.export.onnx_io import run_onnxruntime
from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
from neuralao.pipeline.geometry.camera import orbit
from neuralao.pipeline.geometry.scene import load_scene, mesh_root
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import run_compute


@pytest.mark.parametrize("name", ["beetle", "BrainStem", "2CylinderEngine"])
def test_triangle_soup_labels_are_finite_and_speckle_free(name):
    """Interpenetrating parts, inconsistent winding, degenerate faces: every label finite, in [0, 1],
    background exactly 1; the back-face rule flags samples inside parts instead of returning black.
    Self-intersection speckle would show as isolated fully-occluded valid pixels whose 4 neighbours
    are all open: there must be (almost) none."""
    scene = load_scene(name)
    cam = orbit(scene, 1, 48, 40, seed=3)[0]
    frame = render_gbuffer(scene, cam)
    ao, valid = Labeller(scene, LabelSettings(rays=32, seed=1)).label_frame(frame)
    mask = frame["mask"]
    assert mask.sum() > 50
    assert np.isfinite(ao).all() and (ao >= 0).all() and (ao <= 1).all()
    assert (ao[~mask] == 1).all() and not valid[~mask].any()
    assert valid[mask].mean() > 0.5  # the rule flags inside samples, it does not throw away the frame
    pad = np.pad(ao, 1, constant_values=1.0)
    open_around = np.minimum.reduce([pad[:-2, 1:-1], pad[2:, 1:-1], pad[1:-1, :-2], pad[1:-1, 2:]]) > 0.9
    speckles = valid & (ao < 0.1) & open_around
    assert speckles.sum() <= max(1, int(0.002 * mask.sum())), f"{speckles.sum()} speckles"


def _bn_model(var: np.ndarray, eps: float, clip: tuple[float, float] | None = None):
    c = len(var)
    rng = np.random.default_rng(5)
    inits = [
        nh.from_array(rng.uniform(0.5, 2, c).astype(np.float32), "s"),
        nh.from_array(rng.normal(size=c).astype(np.float32), "b"),
        nh.from_array(rng.normal(size=c).astype(np.float32), "m"),
        nh.from_array(var.astype(np.float32), "v"),
    ]
    nodes = [oh.make_node("BatchNormalization", ["x", "s", "b", "m", "v"], ["y"], name="bn", epsilon=eps)]
    out = "y"
    if clip is not None:
        inits += [nh.from_array(np.float32(clip[0]), "lo"), nh.from_array(np.float32(clip[1]), "hi")]
        nodes.append(oh.make_node("Clip", ["y", "lo", "hi"], ["z"], name="clip"))
        out = "z"
    shape = [1, c, 9, 11]
    graph = oh.make_graph(
        nodes,
        "g",
        [oh.make_tensor_value_info("x", TensorProto.FLOAT, shape)],
        [oh.make_tensor_value_info(out, TensorProto.FLOAT, shape)],
        inits,
    )
    return oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)])


@pytest.mark.parametrize("var,eps", [(0.0, 1e-5), (1e-12, 1e-5), (0.0, 1e-12)])
def test_batch_norm_with_near_zero_variance_folds_to_finite_parity(var, eps):
    """running_var 0 (a channel that never varied in training): scale = gamma / sqrt(eps) is large
    but finite; GLSL agrees with onnxruntime relative to that scale."""
    model = _bn_model(np.array([var, 1.0, var, 0.5]), eps)
    x = np.random.default_rng(0).normal(size=(1, 4, 9, 11)).astype(np.float32)
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    out = run_compute(generate_compute(model), x)
    assert out.shape == ref.shape and out.dtype == ref.dtype
    assert np.isfinite(out).all()
    scale = np.abs(ref).max() + 1.0
    assert np.abs(out - ref).max() <= TOL.glsl_op_fp32 * scale


def test_clip_with_lo_above_hi_matches_onnxruntime():
    """GLSL's clamp() is undefined for lo > hi; ONNX Clip then returns hi everywhere."""
    model = _bn_model(np.ones(4), 1e-5, clip=(0.5, -0.25))
    x = np.random.default_rng(1).normal(size=(1, 4, 9, 11)).astype(np.float32)
    ref = run_onnxruntime(model.SerializeToString(), {"x": x})[0]
    out = run_compute(generate_compute(model), x)
    assert np.allclose(ref, -0.25) and np.abs(out - ref).max() <= TOL.glsl_op_fp32


@pytest.mark.parametrize(
    "name,rel", [("spot.obj", "spot.obj"), ("FlightHelmet", "FlightHelmet/FlightHelmet.gltf")]
)
def test_truncated_real_files_are_a_clear_error_or_a_smaller_valid_mesh(tmp_path, name, rel):
    """A real file cut at 3 points: loading either fails with a one-line NeuralaoError or yields a
    mesh with finite vertices and in-range faces (OBJ is line-based: a cut file is a smaller mesh)."""
    src = mesh_root() / rel
    data = src.read_bytes()
    for frac in (0.07, 0.5, 0.93):
        cut = tmp_path / f"cut{frac}{src.suffix}"
        cut.write_bytes(data[: int(len(data) * frac)])
        if src.suffix == ".gltf":  # keep the buffers next to it, so only the JSON is truncated
            for f in src.parent.iterdir():
                if f.suffix != ".gltf" and not (tmp_path / f.name).exists():
                    (tmp_path / f.name).symlink_to(f)
        try:
            s = load_scene(cut)
        except NeuralaoError as e:
            assert "\n" not in str(e) and str(e)
            continue
        assert len(s.faces) > 0 and np.isfinite(s.vertices).all()
        assert s.faces.min() >= 0 and s.faces.max() < len(s.vertices)
