"""The shipped release exports under ``runtime/models/<name>/`` (ONNX + GLSL + manifest with provenance).

``runtime/models/index.json`` (written by ``make models``, see ``pipeline/release/ship.py``) names every
shipped model and, per model kind, the default that ``neuralao infer`` and ``neuralao report`` use
when no other export is given.
"""

from __future__ import annotations

from pathlib import Path

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.manifest import read_json, read_manifest
from neuralao.runtime.onnx_io import get_metadata, load_onnx
from neuralao.runtime.predict import is_hybrid

MODELS_DIR = Path(__file__).resolve().parent / "models"
INDEX = MODELS_DIR / "index.json"


def read_index(models_dir: Path | None = None) -> dict:
    """The index of shipped models; none shipped -> one-line error naming the make target."""
    path = Path(models_dir or MODELS_DIR) / "index.json"
    if not path.is_file():
        raise NeuralaoError(f"no shipped models ({path} is missing); run `make models` or give an export")
    index = read_json(path, "index of shipped models")
    if not isinstance(index, dict) or not isinstance(index.get("models"), dict):
        raise NeuralaoError(f"{path} lists no models")
    return index


def shipped_models(models_dir: Path | None = None) -> dict[str, Path]:
    """name -> export folder of every shipped model."""
    models_dir = Path(models_dir or MODELS_DIR)
    index = read_index(models_dir)
    return {name: models_dir / name for name in index["models"]}


def default_export(kind: str, models_dir: Path | None = None) -> Path:
    """The export folder of the default shipped model of ``kind`` (e.g. "unet")."""
    models_dir = Path(models_dir or MODELS_DIR)
    index = read_index(models_dir)
    name = index.get("default", {}).get(kind)
    if name is None:
        raise NeuralaoError(f"no default shipped {kind} model in {Path(models_dir) / 'index.json'}")
    folder = Path(models_dir) / name
    if not (folder / "manifest.json").is_file():
        raise NeuralaoError(f"shipped model {name} has no manifest at {folder / 'manifest.json'}")
    return folder


def default_model(kind: str, models_dir: Path | None = None) -> Path:
    """model.onnx of the default shipped model of ``kind``."""
    return export_model(default_export(kind, models_dir))


def export_model(folder: str | Path) -> Path:
    """The ONNX model of an export folder: the file its manifest names (``onnx``, by default model.onnx),
    which must be a file inside the folder; one line naming the folder otherwise."""
    folder = Path(folder)
    if not (folder / "manifest.json").is_file():
        raise NeuralaoError(
            f"{folder} is a folder but not an export (no manifest.json); give an export folder as "
            "`neuralao export` writes it, or an .onnx file"
        )
    name = read_manifest(folder).get("onnx", "model.onnx")
    if not isinstance(name, str) or Path(name).name != name or name in ("", ".", ".."):
        raise NeuralaoError(f"{folder}/manifest.json: 'onnx' must name a file in the folder, got {name!r}")
    if not (folder / name).is_file():
        raise NeuralaoError(f"export folder {folder} has no {name} (its manifest's model)")
    return folder / name


def pure_unet_export(models_dir: Path | None = None) -> Path:
    """The export folder of a shipped pure U-Net (one that needs no GTAO input): the index's default U-Net
    if it is pure, else the first pure one by name (read from each model's ONNX metadata). For consumers
    without a GTAO pass."""
    index = read_index(models_dir)
    default = index.get("default", {}).get("unet")
    models = shipped_models(models_dir)
    for name in [default, *sorted(n for n in models if n != default)]:
        folder = models.get(name)
        if folder is None or index["models"][name].get("kind", "unet") != "unet":
            continue
        if not is_hybrid(get_metadata(load_onnx(folder / "model.onnx"))):
            return folder
    raise NeuralaoError("no shipped pure (non-hybrid) U-Net; give an export folder")
