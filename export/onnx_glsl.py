"""GLSL for a user's own ONNX model (`neuralao glsl`, :mod:`neuralao.pipeline.cli.glsl`), and its parity
check.

    neuralao glsl MODEL.onnx --target image|vector|wgsl [--precision fp32|fp16] [--dialect ...] [--hlsl-msl]
                  [--bind INPUT=TEXTURE.CHANNELS[xREPEATS] ...] --out DIR
    neuralao parity DIR [--inputs X.npz] [--seed N] [--size W H]

Targets (the op tables of :mod:`neuralao.export.glsl`):

* ``image``: an NCHW image network (1, C, H, W) -> images, H and W static or symbolic; GLSL 4.30
  compute passes + ``weights.bin`` + a manifest of passes, textures and formats. ``fp16`` stores the
  intermediate textures as RGBA16F (arithmetic stays fp32).
* ``wgsl``: the image target's passes in WGSL for WebGPU (same op table, writer and manifest; folder
  ``wgsl/``, format ``neuralao-wgsl-compute``); parity runs them with ``wgpu`` (lavapipe here).
* ``image`` with ``--dialect vulkan``: the passes in Vulkan GLSL and their SPIR-V (folder ``vulkan/``,
  format ``neuralao-vulkan-compute``; descriptor set and bindings per pass in its manifest); parity
  runs the SPIR-V with ``wgpu`` on its Vulkan adapter.
* ``vector``: a per-pixel network, every input (N, k) bound to channels of a named RGBA32F texture
  (``--bind position=position.xyz --bind normal=normal.xyz``; an input of width <= 4 without a
  ``--bind`` reads the texture of its own name, channels ``xyzw[:k]``). The first texture's w channel
  is the foreground mask. Texture and input names live in the manifest only: the shader's samplers are
  ``u_tex<unit>``, so no name the user chose reaches shader source. One fragment pass in GLSL 3.30,
  ES 3.00 and 4.30 (``--dialect`` keeps a subset), weights in std140 uniform blocks. ``fp16`` is a
  run-time choice here (RGBA16F textures), recorded for parity.

The export folder (self-describing, every file atomic, ``manifest.json`` last)::

    DIR/model.onnx        the source model, byte for byte
    DIR/glsl/             the generated shaders, weights and the GLSL manifest
    DIR/manifest.json     kind "onnx-glsl": target, precision, bindings, inputs, ops, hashes

Parity runs the shaders read back from DIR against onnxruntime on seeded random inputs of the
declared shapes (symbolic sizes from ``--size``, checked against the program and a memory bound before
anything is allocated, refused when it disagrees with a static size; scalar inputs uniform in [0.1, 2]),
or on the arrays of an ``.npz`` (image: one array per graph input, scalars included; vector: one (H, W, 4)
array per texture). A vector model exported with a static batch N runs in chunks of N pixels.

Image target inputs: one image (1, C, H, W) and any number of single-element scalars ((1, 1, 1, 1),
(1,) or (), e.g. an AO radius), each a ``uniform float`` (the GLSL manifest's ``uniforms``).
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import onnx
from onnx.external_data_helper import uses_external_data

from neuralao.export.glsl import (
    DIALECTS,
    MAX_TEXTURE_SIZE,
    InputBinding,
    generate_compute,
    generate_vector_fragment,
    load_compute_export,
    load_mlp_export,
    write_compute_export,
    write_mlp_export,
)
from neuralao.export.glsl.frame import generate_frame
from neuralao.export.onnx_io import load_onnx, ort_session
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import read_npz, sha256_file, write_bytes, write_json
from neuralao.runtime.foundation.limits import FLOAT32_MAX, check_finite_arrays
from neuralao.runtime.foundation.manifest import read_manifest as read_export_manifest
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame_runner import model_frame_settings

log = logging.getLogger(__name__)

KIND = "onnx-glsl"
GLSL_DIR = "glsl"
TARGETS = ("image", "vector", "wgsl")
SHADER_DIRS = {"image": GLSL_DIR, "vector": GLSL_DIR, "wgsl": "wgsl"}
VULKAN_DIR = "vulkan"  # the image target's folder with --dialect vulkan
_BIND = re.compile(
    r"^(?P<input>[^=]+)=(?P<texture>[A-Za-z_][A-Za-z0-9_]*)\.(?P<channels>[xyzw]{1,4})(x(?P<rep>\d+))?$"
)


def parse_bindings(texts: list[str]):
    """``INPUT=TEXTURE.CHANNELS[xREPEATS]`` strings -> {input: InputBinding}."""
    out = {}
    for t in texts:
        m = _BIND.match(t)
        if not m:
            raise NeuralaoError(
                f"--bind {t!r}: expected INPUT=TEXTURE.CHANNELS[xREPEATS], e.g. normal=gbuffer.xyz"
            )
        if m["input"] in out:
            raise NeuralaoError(f"--bind: input {m['input']!r} bound twice")
        out[m["input"]] = InputBinding(m["texture"], m["channels"], int(m["rep"] or 1))
    return out


def _input_dims(proto: onnx.ModelProto) -> dict[str, list]:
    init = {t.name for t in proto.graph.initializer}
    return {
        vi.name: [
            d.dim_value if d.HasField("dim_value") else (d.dim_param or None)
            for d in vi.type.tensor_type.shape.dim
        ]
        for vi in proto.graph.input
        if vi.name not in init
    }


def default_bindings(proto: onnx.ModelProto, given: dict):
    """Given bindings, completed for inputs of width <= 4 by the texture of the input's own name.

    The texture name is the ONNX name as it is (ONNX input names are unique, so two inputs never share
    a texture by accident); it names the texture for the host and in the manifest only, the shader's
    samplers are generated (``u_tex<unit>``)."""
    dims_of = _input_dims(proto)
    unknown = sorted(set(given) - set(dims_of))
    if unknown:
        raise NeuralaoError(f"--bind names {unknown}, which are not graph inputs ({sorted(dims_of)})")
    out = dict(given)
    bound = {b.texture: n for n, b in given.items()}
    for name, dims in dims_of.items():
        if name in out:
            continue
        width = dims[-1] if dims else None
        if len(dims) != 2 or not isinstance(width, int) or not 1 <= width <= 4:
            raise NeuralaoError(
                f"input {name!r} of shape {dims} needs --bind {name}=TEXTURE.CHANNELS[xREPEATS]"
            )
        if name in bound:
            raise NeuralaoError(
                f"input {name!r} would read the texture of its own name, which --bind gives to "
                f"{bound[name]!r}; bind {name!r} too (--bind {name}=TEXTURE.CHANNELS)"
            )
        out[name] = InputBinding(name, "xyzw"[:width])
    return out


def _refuse_image_model(proto: onnx.ModelProto) -> None:
    """The vector target takes (N, k) inputs: an (N, C, H, W) input means an image model."""
    for name, dims in _input_dims(proto).items():
        if len(dims) == 4:
            raise NeuralaoError(
                f"input {name!r} of shape {dims} is an image (N, C, H, W): this is an image "
                "model, use --target image (--target vector takes per-pixel (N, k) inputs)"
            )


def _check_out_dir(out_dir: Path) -> None:
    """--out must be a folder or not exist yet (nor any file stand where a parent folder must go)."""
    for d in (out_dir, *out_dir.parents):
        if d.exists():
            if not d.is_dir():
                what = "--out" if d == out_dir else f"--out {out_dir}: its parent"
                raise NeuralaoError(f"{what} {d} is a file, not a folder: choose a folder for the export")
            return


# protobuf's limit on one serialized message: past it, ONNX keeps weights in external files.
_PROTO_MAX_BYTES = (2 << 30) - 1


def _self_contained(onnx_path: Path, proto: onnx.ModelProto) -> bytes:
    """The bytes of the export's model.onnx: the file as it is, or, when it keeps weights in external data
    files beside it, the model with those weights inlined (``proto`` was loaded with them), so the export
    holds everything it needs and its own ``parity`` loads it."""
    raw = onnx.load(str(onnx_path), load_external_data=False)
    tensors = [*raw.graph.initializer, *(a.t for n in raw.graph.node for a in n.attribute if a.HasField("t"))]
    if not any(uses_external_data(t) for t in tensors):
        return onnx_path.read_bytes()
    if proto.ByteSize() > _PROTO_MAX_BYTES:
        raise NeuralaoError(
            f"{onnx_path} keeps {proto.ByteSize()} bytes of weights in external data, more than one ONNX "
            "file can hold inline (2 GiB): the export cannot carry them"
        )
    return proto.SerializeToString()


def is_neuralao_unet(proto: onnx.ModelProto) -> bool:
    """True for a screen-space U-Net exported by neuralao (its ONNX metadata says so)."""
    return any(p.key == "neuralao_kind" and p.value == "unet" for p in proto.metadata_props)


def export_model(
    onnx_path,
    target: str,
    out_dir,
    precision: str = "fp32",
    bind: list[str] | None = None,
    dialects: list[str] | None = None,
    hlsl_msl: bool = False,
    preset: str = "gpu",
) -> dict:
    """Generate and write the export of a user's ONNX file; returns its manifest. ``hlsl_msl`` (image
    target): HLSL and MSL of every pass beside its GLSL (SPIRV-Cross); ``preset`` (image, wgsl targets):
    a name of :data:`neuralao.export.glsl.image.PRESETS`."""
    if target not in TARGETS:
        raise NeuralaoError(f"--target must be one of {TARGETS}, got {target!r}")
    if precision not in ("fp32", "fp16"):
        raise NeuralaoError(f"--precision must be fp32 or fp16, got {precision!r}")
    if hlsl_msl and target != "image":
        raise NeuralaoError("--hlsl-msl applies to --target image (HLSL and MSL are made from its GLSL)")
    if hlsl_msl and dialects == ["vulkan"]:
        raise NeuralaoError("--hlsl-msl is made from the GLSL 4.30 passes: leave out --dialect vulkan")
    onnx_path, out_dir = Path(onnx_path), Path(out_dir)
    _check_out_dir(out_dir)
    proto = load_onnx(onnx_path)
    shader_dir = VULKAN_DIR if target == "image" and dialects == ["vulkan"] else SHADER_DIRS[target]
    glsl_dir = out_dir / shader_dir
    extra: dict = {}
    if target in ("image", "wgsl"):
        if bind:
            raise NeuralaoError("--bind applies to --target vector only")
        allowed = (["glsl430"], ["vulkan"]) if target == "image" else (["glsl430"],)
        if dialects and dialects not in allowed:
            raise NeuralaoError(
                "the image target is GLSL 4.30 compute (--dialect glsl430) or Vulkan GLSL with its SPIR-V "
                "(--dialect vulkan), one of them"
            )
        dialect = "wgsl" if target == "wgsl" else (dialects or ["glsl430"])[0]
        if dialect == "vulkan":
            extra["dialect"] = dialect
        program = generate_compute(proto, precision=precision, kind="onnx", dialect=dialect, preset=preset)
        if is_neuralao_unet(proto):  # a neuralao U-Net: its frame passes around the network
            program = generate_frame(program, model_frame_settings(proto))
            extra["frame_passes"] = len(program.manifest["frame"]["passes"])
        out_dir.mkdir(parents=True, exist_ok=True)
        write_compute_export(program, glsl_dir, cross=hlsl_msl)
        extra["passes"] = len(program.manifest["passes"])
        extra["preset"] = preset
        name_key = "wgsl_name" if target == "wgsl" else "glsl_name"
        extra["uniforms"] = {u["onnx_input"]: u[name_key] for u in program.manifest["uniforms"]}
    else:
        unknown = sorted(set(dialects or []) - set(DIALECTS))
        if unknown:
            raise NeuralaoError(f"unknown --dialect {unknown} (choose from {sorted(DIALECTS)})")
        given = parse_bindings(bind or [])
        _refuse_image_model(proto)
        bindings = default_bindings(proto, given)
        # the file name stays out of the shader (it is the manifest's "source"), as the input names do
        shader = generate_vector_fragment(
            proto, bindings, kind="onnx", description="neuralao GLSL of a user's ONNX model (vector target)"
        )
        if dialects:
            shader.sources = {k: v for k, v in shader.sources.items() if k in dialects}
            shader.manifest["dialects"] = {
                k: v for k, v in shader.manifest["dialects"].items() if k in dialects
            }
        out_dir.mkdir(parents=True, exist_ok=True)
        write_mlp_export(shader, glsl_dir)
        extra["bindings"] = {n: b.to_json() for n, b in bindings.items()}
        extra["dialects"] = sorted(shader.sources)
    write_bytes(out_dir / "model.onnx", _self_contained(onnx_path, proto))
    manifest = {
        "kind": KIND,
        "format_version": 1,
        "target": target,
        "precision": precision,
        "onnx": "model.onnx",
        "onnx_sha256": sha256_file(out_dir / "model.onnx"),
        "source": str(onnx_path),
        "glsl": shader_dir,  # the shader folder (WGSL, Vulkan too, under this key for older readers)
        "glsl_manifest_sha256": sha256_file(glsl_dir / "manifest.json"),
        "inputs": {
            n: [str(d) if d is not None else None for d in dims] for n, dims in _input_dims(proto).items()
        },
        "outputs": [o.name for o in proto.graph.output],
        "ops": sorted({n.op_type for n in proto.graph.node}),
        **extra,
    }
    write_json(out_dir / "manifest.json", manifest)
    return manifest


def read_manifest(export_dir: Path) -> dict:
    manifest = read_export_manifest(export_dir, KIND, "a `neuralao glsl`")
    missing = [k for k in ("onnx", "glsl", "target", "inputs", "outputs", "precision") if k not in manifest]
    if missing or manifest["target"] not in TARGETS:
        what = f"has no {', '.join(missing)}" if missing else f"has target {manifest['target']!r}"
        path = Path(export_dir) / "manifest.json"
        raise NeuralaoError(f"{path} {what}: not a `neuralao glsl` export manifest")
    return manifest


# Seeded inputs are this size (W, H) unless --size says otherwise (image: rounded up to what the program
# takes).
DEFAULT_SIZE = (64, 48)
# Parity holds the inputs, every texture of the program and onnxruntime's tensors at once; a --size whose
# textures (or, for the vector target, per-pixel tensors) would pass this many bytes is refused before
# anything is allocated (a mistyped 100000 100000 asked for 298 GiB).
PARITY_MAX_BYTES = 2 << 30


def _gib(n: float) -> str:
    return f"{n / (1 << 30):.3g} GiB"


def _shape(dims: list, size: tuple[int, int], what: str) -> tuple[int, ...]:
    """Declared dims with symbolic ones filled: NCHW -> (1, C, H, W) with H, W from size (W, H)."""
    out = []
    for i, d in enumerate(dims):
        if d is not None and str(d).isdigit():
            out.append(int(d))
        elif len(dims) == 4 and i in (2, 3):
            out.append(size[1] if i == 2 else size[0])
        elif i == 0:
            out.append(1)
        else:
            raise NeuralaoError(f"{what}: dimension {i} is symbolic ({d!r}) and no rule fills it")
    return tuple(out)


def _static(d) -> int | None:
    return int(d) if d is not None and str(d).isdigit() else None


def _positive_size(size: tuple[int, int], what: str = "--size") -> tuple[int, int]:
    w, h = (int(v) for v in size)
    if w < 1 or h < 1:
        raise NeuralaoError(f"{what} {w} {h}: width and height must be at least 1")
    return w, h


def _image_size(manifest: dict, dims: list, size: tuple[int, int] | None) -> tuple[int, int]:
    """(W, H) of the seeded image input: the declared static size, else ``size``, else DEFAULT_SIZE
    rounded up to the multiples the program takes; checked against the program and PARITY_MAX_BYTES."""
    # Lazy, here and in parity: the runners load PyOpenGL, which fails to import without a GL library
    # (and costs 0.15 s measured); `neuralao glsl` only writes shaders, parity runs them.
    from neuralao.runtime.glsl_runner import size_multiples, texture_sizes

    fixed = (_static(dims[3]), _static(dims[2])) if len(dims) == 4 else (None, None)
    if size is None:
        mh, mw = size_multiples(manifest)
        low = int(manifest["pad"]["multiple"])
        w, h = (max(-(-v // m) * m, -(-low // m) * m) for v, m in zip(DEFAULT_SIZE, (mw, mh), strict=True))
        w, h = fixed[0] or w, fixed[1] or h
    else:
        w, h = _positive_size(size)
        if any(f is not None and f != v for f, v in zip(fixed, (w, h), strict=True)):
            want = " ".join(str(f) if f is not None else "?" for f in fixed)
            raise NeuralaoError(
                f"--size {w} {h}: this export's input {dims} is static ({want}); "
                "--size is taken only when it equals the static size (or omit it)"
            )
    try:
        textures = texture_sizes(manifest, h, w, max_bytes=PARITY_MAX_BYTES)
    except NeuralaoError as e:  # name the flag when the size came from it
        raise NeuralaoError(f"--size {w} {h}: {e}" if size is not None else str(e)) from None
    log.debug("parity at %dx%d: %s of textures", w, h, _gib(sum(t[3] for t in textures.values())))
    return w, h


def _vector_size(
    glsl: dict, n_textures: int, size: tuple[int, int] | None, what: str = "--size"
) -> tuple[int, int]:
    """(W, H) of the textures, checked against the texture limit and PARITY_MAX_BYTES (textures, the
    per-pixel inputs and the widest layer, twice: onnxruntime holds an operand and a result). ``what``
    names where the size came from in errors."""
    w, h = DEFAULT_SIZE if size is None else _positive_size(size, what)
    if w > MAX_TEXTURE_SIZE or h > MAX_TEXTURE_SIZE:
        raise NeuralaoError(f"{what} {w} {h}: textures are at most {MAX_TEXTURE_SIZE} wide and high")
    net = glsl["network"]
    widths = [layer.get("out", layer.get("width", 0)) for layer in net["layers"]] + [net["output_width"]]
    per_pixel = 16 * (n_textures + 1) + 4 * (net["input_width"] + 2 * max(widths))
    if w * h * per_pixel > PARITY_MAX_BYTES:
        raise NeuralaoError(
            f"{what} {w} {h} needs about {_gib(w * h * per_pixel)} ({per_pixel} bytes a pixel), "
            f"over parity's bound of {_gib(PARITY_MAX_BYTES)}: choose a smaller size"
        )
    return w, h


def _static_batch(manifest: dict) -> int | None:
    """The static batch N of a vector export's inputs (e.g. an MLP exported for N = 4096), else None."""
    batches = {_static(manifest["inputs"][n][0]) for n in manifest["bindings"]} - {None}
    if len(batches) > 1:
        raise NeuralaoError(f"the inputs declare different static batch sizes {sorted(batches)}")
    return batches.pop() if batches else None


def _run_per_pixel(sess, feeds: dict[str, np.ndarray], batch: int | None, width: int) -> np.ndarray:
    """onnxruntime on (n, k) per-pixel feeds -> (n, width): in one run, or with a static batch N in
    chunks of N rows, the last one padded with zero rows (their results dropped)."""
    n = len(next(iter(feeds.values())))
    if n == 0:
        return np.zeros((0, width), np.float32)
    if batch is None:
        return sess.run(None, feeds)[0].reshape(n, -1)
    parts = []
    for i in range(0, n, batch):
        chunk = {k: v[i : i + batch] for k, v in feeds.items()}
        rows = len(next(iter(chunk.values())))
        pad = batch - rows
        chunk = {k: np.concatenate([v, np.zeros((pad, v.shape[1]), v.dtype)]) for k, v in chunk.items()}
        parts.append(sess.run(None, chunk)[0].reshape(batch, -1)[:rows])
    return np.concatenate(parts)


def read_inputs(path: str | Path, names: list[str]) -> dict[str, np.ndarray]:
    """The arrays ``names`` of a ``--inputs`` .npz (no other member is inflated), each of real numbers,
    finite and within float32 (the shaders and onnxruntime run in float32): a value that is not is refused
    here, naming the array, rather than blamed on the shaders it would break."""
    arrays = read_npz(path, names)
    for key, a in arrays.items():
        if a.dtype.kind not in "iufb" or a.dtype.names is not None:
            raise NeuralaoError(f"--inputs {path}: array {key!r} holds {a.dtype} values, not real numbers")
        check_finite_arrays({key: a}, f"--inputs {path}", "array")
        if a.dtype.kind == "f" and a.size and np.abs(a).max() > FLOAT32_MAX:
            raise NeuralaoError(
                f"--inputs {path}: array {key!r} holds values up to {np.abs(a).max():.3g}, past float32's "
                f"{FLOAT32_MAX:.4g} (the shaders and onnxruntime run in float32)"
            )
    return arrays


def parity(
    export_dir,
    frames=None,
    inputs: str | Path | None = None,
    seed: int = 0,
    size: tuple[int, int] | None = None,
) -> dict:
    """The export's shaders (read from disk) vs onnxruntime on seeded random or given inputs.

    ``size`` (W, H): of symbolic image dimensions / vector textures, checked before anything is
    allocated; None: the static size, else DEFAULT_SIZE (rounded up to the program's multiples).
    It must equal a static size, and is refused with ``inputs`` (whose arrays fix the size)."""
    # Lazy: the runners need PyOpenGL and a GL library (see _image_size)
    from neuralao.runtime.glsl_runner import (
        run_compute_all,
        run_vector_fragment,
        texture_names,
        texture_sizes,
    )
    from neuralao.runtime.wgsl_runner import run_spirv_all, run_wgsl_all

    export_dir = Path(export_dir)
    manifest = read_manifest(export_dir)
    if inputs is not None and size is not None:
        raise NeuralaoError("--size applies to seeded inputs; with --inputs the arrays give the size")
    proto = load_onnx(export_dir / manifest["onnx"])
    sess = ort_session(proto.SerializeToString())
    rng = np.random.default_rng(seed)
    rows = []
    if manifest["target"] in ("image", "wgsl"):
        program = load_compute_export(export_dir / manifest["glsl"])
        name = program.manifest["input"]["onnx_name"]
        dims = manifest["inputs"][name]
        scalar_names = [u["onnx_input"] for u in program.manifest.get("uniforms", [])]
        given = read_inputs(inputs, [name, *scalar_names]) if inputs is not None else None
        if given is not None:
            absent = [n for n in [name, *scalar_names] if n not in given]
            if absent:
                raise NeuralaoError(f"{inputs} has no array {absent[0]!r}")
            x = np.asarray(given[name], np.float32)
        else:
            size = _image_size(program.manifest, dims, size)
            x = rng.standard_normal(_shape(dims, size, name)).astype(np.float32)
        static = [(i, int(d)) for i, d in enumerate(dims) if d is not None and str(d).isdigit()]
        if x.ndim != len(dims) or any(x.shape[i] != d for i, d in static):
            raise NeuralaoError(f"input {name!r} of shape {list(x.shape)} does not fit the declared {dims}")
        if given is not None:
            texture_sizes(program.manifest, x.shape[2], x.shape[3], max_bytes=PARITY_MAX_BYTES)
        feeds = {name: x}
        for n in scalar_names:  # a uniform each: one element, fed to onnxruntime in its declared shape
            shape = _shape(manifest["inputs"][n], (1, 1), n)
            v = (
                np.asarray(given[n], np.float32)
                if given is not None
                else rng.uniform(0.1, 2.0, shape).astype(np.float32)
            )
            if v.size != 1:
                raise NeuralaoError(f"scalar input {n!r} of shape {list(v.shape)} must hold one value")
            feeds[n] = v.reshape(shape)
        ref = dict(zip(manifest["outputs"], sess.run(None, feeds), strict=True))
        runner = {
            "neuralao-wgsl-compute": run_wgsl_all,
            "neuralao-vulkan-compute": run_spirv_all,
        }.get(program.manifest["format"], run_compute_all)
        got = runner(program, x, scalars={n: feeds[n] for n in scalar_names})
        for o in manifest["outputs"]:
            if got[o].shape != ref[o].shape:
                raise NeuralaoError(f"output {o!r}: GLSL shape {got[o].shape}, onnxruntime {ref[o].shape}")
            diff = np.abs(got[o] - ref[o])
            if manifest["precision"] == "fp16":
                diff = diff / np.maximum(1.0, np.abs(ref[o]))
            rows.append({"output": o, "shape": list(ref[o].shape), "max_abs_err": float(diff.max())})
        tol = TOL.parity_fp16_image if manifest["precision"] == "fp16" else TOL.parity_unet_fp32
        shown = f"{x.shape[-1]}x{x.shape[-2]}"
    else:
        shaders = {d: load_mlp_export(export_dir / manifest["glsl"], dialect=d) for d in manifest["dialects"]}
        first = shaders[manifest["dialects"][0]]
        textures_names = texture_names(first)
        given = read_inputs(inputs, textures_names) if inputs is not None else None
        if given is not None:
            missing = [t for t in textures_names if t not in given]
            if missing:
                raise NeuralaoError(f"{inputs} lacks the textures {missing}")
            tex = {t: np.asarray(given[t], np.float32) for t in textures_names}
            shapes = {t.shape for t in tex.values()}
            if len(shapes) != 1 or len(next(iter(shapes))) != 3 or next(iter(shapes))[2] != 4:
                raise NeuralaoError(f"{inputs}: textures must all be (H, W, 4), got {sorted(shapes)}")
            h, w = next(iter(shapes))[:2]
            _vector_size(first.manifest, len(textures_names), (w, h), f"{inputs}: textures of W H =")
        else:
            w, h = _vector_size(first.manifest, len(textures_names), size)
            tex = {t: rng.uniform(-1, 1, size=(h, w, 4)).astype(np.float32) for t in textures_names}
            tex[textures_names[0]][..., 3] = rng.random((h, w)) > 0.1
        masked = tex[textures_names[0]][..., 3] >= 0.5
        feeds = {}
        for n, b in manifest["bindings"].items():
            lanes = ["xyzw".index(c) for c in b["channels"]]
            feeds[n] = np.tile(tex[b["texture"]][masked][:, lanes], (1, b["repeats"])).astype(np.float32)
        ref = _run_per_pixel(sess, feeds, _static_batch(manifest), first.output_width)
        for d in manifest["dialects"]:
            got = run_vector_fragment(shaders[d], tex, fp16=manifest["precision"] == "fp16", dialect=d)
            got = got[..., None] if got.ndim == 2 else got
            diff = np.abs(got[masked] - ref)
            if manifest["precision"] == "fp16":
                diff = diff / np.maximum(1.0, np.abs(ref))
            bg = float(np.abs(got[~masked] - 1.0).max()) if (~masked).any() else 0.0
            rows.append(
                {
                    "dialect": d,
                    "pixels": int(masked.sum()),
                    "max_abs_err": float(diff.max()) if diff.size else 0.0,
                    "background_max_abs_err": bg,
                }
            )
        tol = TOL.parity_fp16 if manifest["precision"] == "fp16" else TOL.parity_mlp_fp32
        shown = f"{w}x{h}"
    err = max(r["max_abs_err"] for r in rows)
    bg_ok = all(r.get("background_max_abs_err", 0.0) == 0.0 for r in rows)
    return {
        "kind": KIND,
        "target": manifest["target"],
        "precision": manifest["precision"],
        "inputs": str(inputs) if inputs else f"seeded random (seed {seed}, size {shown})",
        "max_abs_err": err,
        "tolerance": tol,
        "passed": bool(err <= tol and bg_ok),
        "checks": rows,
    }
