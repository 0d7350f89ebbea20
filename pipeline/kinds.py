"""The one registry of model kinds: what each kind of model is trained, exported, checked and reported with.

A kind is the ``kind`` a checkpoint and an export manifest record (``mlp``, ``field``, ``unet``), plus
``onnx-glsl``, the export of a user's ONNX file by `neuralao glsl` (checked by `neuralao parity`, never
trained here). Adding a kind adds one :class:`ModelKind` to :data:`KINDS`; `neuralao train`,
`neuralao export`, `neuralao parity`, the report and the selection read it from here.

Modules are named, not imported: importing every exporter costs torch + the GL runner (about 2 s,
measured), which `neuralao parity` of a `neuralao glsl` export and `neuralao select` don't need;
:func:`module` imports one on use.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType


@dataclass(frozen=True)
class ModelKind:
    # The kind, as checkpoints and export manifests record it.
    name: str
    # Module with parity(export_dir, ...) and, for a checkpoint kind, export_checkpoint(ckpt, out).
    exporter: str
    # Module with the training (settings class, train()); None: not trained by `neuralao train`.
    trainer: str | None = None
    # One-line help of `neuralao train NAME`.
    train_help: str = ""
    # One network per mesh: parity frames are held-back views of its scene when the dataset holds it.
    per_mesh: bool = False
    # A report family (rows loaded from export folders): its position in the report's tables.
    report_order: int | None = None
    # Scatter-plot colour of its report rows.
    colour: str = "k"
    # Takes the AO radius at run time (evaluated at every ReportSettings.radii_rel).
    radius_input: bool = False
    # Can show the two sides of a single-sided surface differently (fed the viewer-facing normal).
    two_sided: bool = True


KINDS: dict[str, ModelKind] = {
    k.name: k
    for k in (
        ModelKind(
            "mlp",
            exporter="neuralao.export.mlp",
            trainer="neuralao.pipeline.models.mlp",
            train_help="the baked MLP of Erra et al. (16 object-space normals -> AO), one network per mesh",
            per_mesh=True,
            report_order=3,
            colour="tab:orange",
        ),
        ModelKind(
            "unet",
            exporter="neuralao.export.unet",
            trainer="neuralao.pipeline.models.unet_train",
            train_help="the DeepAO screen-space U-Net (depth + camera normal -> AO)",
            report_order=5,
            colour="tab:red",
            radius_input=True,
        ),
        ModelKind(
            "field",
            exporter="neuralao.export.field",
            trainer="neuralao.pipeline.models.field",
            train_help=(
                "a per-mesh neural AO field (object-space position + normal -> AO), one network per mesh"
            ),
            per_mesh=True,
            report_order=4,
            colour="tab:purple",
        ),
        ModelKind("onnx-glsl", exporter="neuralao.export.onnx_glsl"),
    )
}

# Kinds `neuralao train` trains and `neuralao export` exports from a checkpoint, in that order.
TRAINED: dict[str, ModelKind] = {n: k for n, k in KINDS.items() if k.trainer is not None}
# Kinds the report loads from export folders, in report order.
REPORTED: dict[str, ModelKind] = dict(
    sorted(
        ((n, k) for n, k in KINDS.items() if k.report_order is not None), key=lambda nk: nk[1].report_order
    )
)


def module(kind: str, role: str = "exporter") -> ModuleType:
    """The module of ``kind`` for ``role`` ("exporter" or "trainer"), imported."""
    return importlib.import_module(getattr(KINDS[kind], role))
