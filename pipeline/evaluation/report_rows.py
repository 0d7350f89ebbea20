"""The report's model rows: one :class:`Method` per export folder (each kind's ``report_row`` of
:mod:`neuralao.runtime.kinds` builds it from the folder's manifest; those of mlp, field and unet are
here), missing and broken exports as rows "not available", and the shipped release U-Nets picked by
role or name (:func:`pick_shipped`)."""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from pathlib import Path

from neuralao.pipeline.evaluation.plots import shipped_summary
from neuralao.pipeline.evaluation.report_settings import EXPECTED_EXPORTS, SHIPPED_PREFIX, Method
from neuralao.runtime import kinds
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.manifest import read_manifest

log = logging.getLogger(__name__)


def discover_exports(
    exports: Path | None, scenes: list[str], expected: list[str] | tuple[str, ...] = EXPECTED_EXPORTS
) -> list[Method]:
    """Model methods from export folders (every reported kind); broken ones and absent ``expected`` ones
    are unavailable. Rows of one network per mesh (``scene_exports``) with the same name are merged into
    one row listing every scene's export, after the other rows."""
    methods: list[Method] = []
    found: dict[str, Path] = {}
    if exports is not None and Path(exports).is_dir():
        for m in sorted(Path(exports).glob("*/manifest.json")):
            found[m.parent.name] = m.parent
    for name in expected:
        if name not in found:
            where = Path(exports) / name if exports is not None else name
            methods.append(
                Method(
                    name, _folder_family(name), "", "", "", available=False, reason=f"no export at {where}"
                )
            )
    merged: dict[str, Method] = {}
    for name, d in sorted(found.items()):
        m = _export_method(name, d, scenes)
        if m.scene_exports is None:
            methods.append(m)
            continue
        row = merged.setdefault(m.name, replace(m, scene_exports={}))
        for scene, export in m.scene_exports.items():
            if scene in row.scene_exports:
                row.available, row.reason = False, f"two {m.name} exports for scene {scene!r}"
            row.scene_exports[scene] = export
        row.bytes = max(row.bytes or 0, m.bytes or 0)
    return methods + list(merged.values())


def _folder_family(name: str) -> str:
    """The family of a row whose manifest is missing or unreadable: the reported kind its folder (or
    shipped model) name starts with (``mlp-16x8`` -> mlp, ``unet`` -> unet), else "unknown"."""
    name = name.removeprefix(SHIPPED_PREFIX)
    return next((k for k in kinds.reported() if name == k or name.startswith(f"{k}-")), "unknown")


def _export_method(name: str, d: Path, scenes: list[str]) -> Method:
    """The row of export folder ``d`` (row name ``name``), built by its kind's ``report_row``."""
    try:
        manifest = read_manifest(d)
    except NeuralaoError as e:
        return Method(
            name,
            _folder_family(name),
            "",
            "",
            "",
            available=False,
            reason=f"unreadable manifest ({e})",
        )
    kind = manifest.get("kind")
    if kind not in kinds.reported():
        return Method(name, "unknown", "", "", "", available=False, reason=f"unknown export kind {kind!r}")
    return kinds.role(kind, "report_row")(name, d, manifest, scenes)


def _not_held(m: Method, scene: str | None) -> Method:
    m.available, m.reason = False, f"trained for scene {scene!r}, which the dataset does not hold"
    return m


def mlp_row(name: str, d: Path, manifest: dict, scenes: list[str]) -> Method:
    """A baked MLP: one network for the scene its manifest names."""
    scene = manifest.get("scene")
    m = Method(
        name,
        "mlp",
        f"baked MLP {manifest.get('model_size', '')} (Erra et al.), one network per mesh",
        "GL fragment shader (generated GLSL)",
        "GL fragment shader, clamped to [0, 1]",
        scene=scene,
        bytes=manifest.get("parameter_bytes"),
        bytes_note="float32 weights",
        export=d,
    )
    return m if scene in scenes else _not_held(m, scene)


def field_row(name: str, d: Path, manifest: dict, scenes: list[str]) -> Method:
    """An AO field: named by its size (and octaves when not 4), so the fields of every scene of one size
    merge into one row; one whose scene the dataset does not hold keeps its folder's name."""
    scene = manifest.get("scene")
    octaves = manifest.get("octaves")
    m = Method(
        f"field-{manifest.get('model_size', '')}" + ("" if octaves == 4 else f"-o{octaves}"),
        "field",
        f"AO field {manifest.get('model_size', '')}, {manifest.get('octaves')} octaves "
        "(object-space position + normal), one network per mesh",
        "GL fragment shader (generated GLSL)",
        "GL fragment shader, clamped to [0, 1]",
        bytes=manifest.get("parameter_bytes"),
        bytes_note="float32 weights + encoding constants",
        export=d,
    )
    if scene not in scenes:
        return _not_held(replace(m, name=name, scene=scene), scene)
    m.scene_exports = {scene: d}
    return m


def unet_row(name: str, d: Path, manifest: dict, scenes: list[str]) -> Method:
    """A U-Net: one network for every scene, at full or reduced resolution (metadata ``scale``)."""
    scale = _unet_scale(manifest)
    at = "" if scale == 1 else f", run at 1/{scale} resolution (depth- and normal-aware upsampling)"
    return Method(
        name,
        "unet",
        f"DeepAO screen-space U-Net (Zhang et al.){at}",
        "GL compute shaders (generated GLSL)",
        "onnxruntime (GLSL parity-checked)",
        bytes=manifest.get("bytes_fp32"),
        bytes_note="float32 weights",
        export=d,
        scale=scale,
    )


def _unet_scale(manifest: dict) -> int:
    """Resolution divisor of a U-Net export (manifest metadata ``scale``; 1 when absent)."""
    try:
        return int((manifest.get("metadata") or {}).get("scale", 1))
    except (TypeError, ValueError):
        return 1


def pick_shipped(summary: dict, picks: list[str] | tuple[str, ...] | None) -> list[str]:
    """Names of the shipped U-Nets to report: ``picks`` holds roles and names. ``default``: the model
    index.json names default; ``fast``: ``index.json`` ``fast`` (per kind) if it names one, else the
    U-Net with the smallest GL time at 512x512 other than the default; ``all`` (or None): every one.
    A pick that matches nothing is left out with a log line (the report never fails on it)."""
    models = {n: m for n, m in summary["models"].items() if m.get("kind", "unet") == "unet"}
    if picks is None or "all" in picks:
        return list(models)
    default = (summary.get("default") or {}).get("unet")
    chosen: list[str] = []
    for pick in picks:
        if pick == "default":
            name = default
        elif pick == "fast":
            name = (summary.get("fast") or {}).get("unet")
            if name is None:
                timed = [
                    (float((m.get("gl_seconds") or {}).get("512x512") or math.inf), n)
                    for n, m in models.items()
                    if n != default
                ]
                name = min(timed)[1] if timed else None
        else:
            name = pick
        if name in models and name not in chosen:
            chosen.append(name)
        elif name not in models:
            log.info("shipped %s: no such model in %s", pick, summary.get("folder"))
    return chosen


def discover_shipped(
    models_dir: Path, scenes: list[str], picks: list[str] | tuple[str, ...] | None = None
) -> tuple[list[Method], dict]:
    """The shipped U-Nets of ``models_dir`` (runtime/models) picked by :func:`pick_shipped` (None:
    every one) as rows ``shipped:<name>``, and the summary of the index
    (:func:`neuralao.pipeline.evaluation.plots.shipped_summary`, its models cut to the picked ones and their
    ``roles``; its ``note`` says why none)."""
    summary = shipped_summary(models_dir)
    names = pick_shipped(summary, picks)
    others = [n for n in summary["models"] if n not in names]
    summary["models"] = {n: summary["models"][n] for n in names}
    summary["roles"] = {p: n for p in ("default", "fast") for n in pick_shipped({**summary}, [p])}
    summary["not_shown"] = others
    methods = []
    for name, info in summary["models"].items():
        if info.get("kind", "unet") != "unet":
            continue
        row = SHIPPED_PREFIX + name
        folder = Path(info["folder"])
        if not (folder / "manifest.json").is_file():
            m = Method(
                row, "unet", "", "", "", available=False, reason=f"no manifest at {folder / 'manifest.json'}"
            )
        else:
            m = _export_method(row, folder, scenes)
            m.description += f"; shipped release model {name} (runtime/models)"
        m.shipped = name
        methods.append(m)
    return methods, summary
