"""The one registry of model kinds: where each kind of model is predicted, trained, exported, checked and
reported from.

A kind is the ``kind`` a checkpoint and an export manifest record and the ``neuralao_kind`` of its ONNX
metadata (``mlp``, ``field``, ``unet``), plus ``onnx-glsl``, the export of a user's ONNX file by
`neuralao glsl` (checked by `neuralao parity`, never trained or reported here). Adding a kind adds one
:class:`ModelKind` to :data:`KINDS` and writes the functions its roles name; `neuralao infer`,
`neuralao train`, `neuralao export`, `neuralao parity`, the report and the selection find it here.

Roles are ``"module:attribute"`` strings that :func:`role` imports on use, for two reasons: the roles
of training, export and the report live in ``neuralao.pipeline`` and ``neuralao.export``, which this
layer (the consumer runtime) must not import (import-linter contracts in pyproject.toml); and importing
every exporter costs torch + the GL runner (about 2 s, measured), which `neuralao infer` and
`neuralao parity` of a `neuralao glsl` export don't need. The views
(:func:`trained`, :func:`reported`, :func:`predicted`) read :data:`KINDS` when called, so a kind added
to it (a test's, say) reaches every consumer.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from neuralao.runtime.foundation.errors import NeuralaoError


@dataclass(frozen=True)
class ModelKind:
    # The kind, as checkpoints, export manifests and ONNX metadata (neuralao_kind) record it.
    name: str
    # `neuralao parity`: parity(export_dir, frames) -> {passed, ...}; with parity_on_inputs
    # parity(export_dir, inputs=, seed=, size=) instead.
    parity: str
    # Checked on seeded or given inputs (`neuralao parity --inputs/--seed/--size`), not on frames.
    parity_on_inputs: bool = False
    # onnxruntime: (onnx_path, **options) -> Predictor (neuralao.runtime.predict); None: `neuralao infer`
    # does not run it.
    predictor: str | None = None
    # `neuralao export`: export_checkpoint(ckpt_path, out_dir) -> manifest; None: not made from a checkpoint.
    exporter: str | None = None
    # Module of the kind's settings dataclass and train(); the training lines log under its name.
    trainer: str | None = None
    # `neuralao train NAME`: (argparse.ArgumentParser) -> None adds the flags, (argparse.Namespace) -> int
    # trains; None: not trained by `neuralao train`.
    train_flags: str | None = None
    train_run: str | None = None
    # One-line help of `neuralao train NAME`.
    train_help: str = ""
    # The report's row of one export folder: (row name, export dir, manifest dict, dataset scenes) ->
    # neuralao.pipeline.evaluation.report_settings.Method; None: not in the report.
    report_row: str | None = None
    # How the report runs and times its generated GLSL (neuralao.pipeline.evaluation.report_gl.GLPath).
    report_gl: str | None = None
    # Position of its rows in the report's tables (after the baselines' 0..2).
    report_order: int | None = None
    # Scatter-plot colour of its report rows.
    colour: str = "k"
    # One network per mesh: parity frames are held-back views of its scene when the dataset holds it.
    per_mesh: bool = False
    # Takes the AO radius at run time (evaluated at every ReportSettings.radii_rel).
    radius_input: bool = False
    # Can show the two sides of a single-sided surface differently (fed the viewer-facing normal).
    two_sided: bool = True


_TRAIN = "neuralao.pipeline.cli.train"
_ROWS = "neuralao.pipeline.evaluation.report_rows"
_GL = "neuralao.pipeline.evaluation.report_gl"

KINDS: dict[str, ModelKind] = {
    k.name: k
    for k in (
        ModelKind(
            "mlp",
            parity="neuralao.export.mlp:parity",
            predictor="neuralao.runtime.predict:mlp_predictor",
            exporter="neuralao.export.mlp:export_checkpoint",
            trainer="neuralao.pipeline.models.mlp",
            train_flags=f"{_TRAIN}:add_mlp_arguments",
            train_run=f"{_TRAIN}:run_mlp",
            train_help="the baked MLP of Erra et al. (16 object-space normals -> AO), one network per mesh",
            report_row=f"{_ROWS}:mlp_row",
            report_gl=f"{_GL}:MLP_GL",
            report_order=3,
            colour="tab:orange",
            per_mesh=True,
        ),
        ModelKind(
            "unet",
            parity="neuralao.export.unet:parity",
            predictor="neuralao.runtime.predict:unet_predictor",
            exporter="neuralao.export.unet:export_checkpoint",
            trainer="neuralao.pipeline.models.unet_train",
            train_flags=f"{_TRAIN}:add_unet_arguments",
            train_run=f"{_TRAIN}:run_unet",
            train_help="the DeepAO screen-space U-Net (depth + camera normal -> AO)",
            report_row=f"{_ROWS}:unet_row",
            report_gl=f"{_GL}:UNET_GL",
            report_order=5,
            colour="tab:red",
            radius_input=True,
        ),
        ModelKind(
            "field",
            parity="neuralao.export.field:parity",
            predictor="neuralao.runtime.predict:field_predictor",
            exporter="neuralao.export.field:export_checkpoint",
            trainer="neuralao.pipeline.models.field",
            train_flags=f"{_TRAIN}:add_field_arguments",
            train_run=f"{_TRAIN}:run_field",
            train_help=(
                "a per-mesh neural AO field (object-space position + normal -> AO), one network per mesh"
            ),
            report_row=f"{_ROWS}:field_row",
            report_gl=f"{_GL}:FIELD_GL",
            report_order=4,
            colour="tab:purple",
            per_mesh=True,
        ),
        ModelKind("onnx-glsl", parity="neuralao.export.onnx_glsl:parity", parity_on_inputs=True),
    )
}


def trained() -> dict[str, ModelKind]:
    """Kinds `neuralao train` trains and `neuralao export` exports from a checkpoint, in registry order."""
    return {n: k for n, k in KINDS.items() if k.train_run is not None}


def reported() -> dict[str, ModelKind]:
    """Kinds the report loads from export folders, in report order."""
    rows = [k for k in KINDS.values() if k.report_order is not None]
    return {k.name: k for k in sorted(rows, key=lambda k: k.report_order)}


def predicted() -> dict[str, ModelKind]:
    """Kinds `neuralao infer` runs through onnxruntime."""
    return {n: k for n, k in KINDS.items() if k.predictor is not None}


def role(kind: str, name: str) -> Any:
    """The object role ``name`` (a :class:`ModelKind` field holding ``"module:attribute"``) of ``kind``
    names, imported; a role without ``:attribute`` is the module itself."""
    ref = getattr(KINDS[kind], name)
    if ref is None:
        raise NeuralaoError(f"model kind {kind!r} has no {name}")
    module, _, attribute = ref.partition(":")
    loaded = importlib.import_module(module)
    return getattr(loaded, attribute) if attribute else loaded
