"""The numbers an image network's ONNX metadata declares, read the one way `neuralao glsl` and
`neuralao infer` both read them: ``pad_multiple`` and ``internal_height`` as integers within sane bounds,
each refusal one line naming the file and the key.

    metadata_pad_multiple(meta, "u.onnx", needed="...")   # -> int, or a one-line error
    metadata_internal_height(meta, "u.onnx")              # -> int or None (runs at the frame's size)

``meta`` maps keys to the text the file stores (or a manifest's JSON values).
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from neuralao.runtime.foundation.errors import NeuralaoError

# pad_multiple: the input's height and width are reflect-padded to a multiple of it (2 ** depth for a
# U-Net; past 4096 even a 1080p frame is mostly padding). internal_height: the rows the network runs at;
# 16384 rows are already gigabytes of activations, past them no buffer is sane.
MAX_PAD_MULTIPLE = 4096
MIN_INTERNAL_HEIGHT, MAX_INTERNAL_HEIGHT = 16, 16384
# How a U-Net's input is padded to its multiple: the only padding its consumers (the runtime's and the
# generated frame passes) do.
PAD_MODE = "reflect"


def metadata_integer(
    meta: Mapping[str, object], key: str, low: int, high: int, where: str = "", needed: str = ""
) -> int | None:
    """ONNX metadata ``key`` as an int in [low, high]; None when absent, unless ``needed`` says why it must
    be there. Metadata stores numbers as text: only an integer's digits are read (json.loads of hostile
    metadata recurses or overflows), so ``8.0``, ``nan`` or ``1e3`` are refused by name."""
    prefix = f"{where}: " if where else ""
    value = meta.get(key)
    if value is None:
        if needed:
            raise NeuralaoError(f"{prefix}metadata has no {key}, which {needed}")
        return None
    text = str(value).strip()
    shown = text if len(text) <= 24 else f"{text[:24]}... ({len(text)} characters)"
    if isinstance(value, bool) or not re.fullmatch(r"[+-]?[0-9]+", text):
        raise NeuralaoError(f"{prefix}metadata {key} {shown!r} is not an integer")
    # more digits than any bound: judged by its sign, never parsed
    number = (
        int(text) if len(text.lstrip("+-")) <= len(str(high)) + 1 else (-1 if text[0] == "-" else high + 1)
    )
    if number < low:
        rule = "must be positive" if low == 1 else f"must be >= {low}"
        raise NeuralaoError(f"{prefix}metadata {key} {shown} {rule}")
    if number > high:
        raise NeuralaoError(f"{prefix}metadata {key} {shown} is more than {high}")
    return number


def metadata_pad_multiple(meta: Mapping[str, object], where: str = "", needed: str = "") -> int | None:
    """Metadata ``pad_multiple`` as an int in [1, MAX_PAD_MULTIPLE] (None when absent and not ``needed``)."""
    return metadata_integer(meta, "pad_multiple", 1, MAX_PAD_MULTIPLE, where, needed)


def metadata_internal_height(meta: Mapping[str, object], where: str = "") -> int | None:
    """Metadata ``internal_height`` as an int in [MIN_INTERNAL_HEIGHT, MAX_INTERNAL_HEIGHT]; None (the
    network runs at the frame's size) when absent, empty or ``None``."""
    if str(meta.get("internal_height")).strip() in ("", "None"):  # what an export without one writes
        return None
    return metadata_integer(meta, "internal_height", MIN_INTERNAL_HEIGHT, MAX_INTERNAL_HEIGHT, where)


def metadata_pad_mode(meta: Mapping[str, object], where: str = "") -> str:
    """Metadata ``pad_mode``, which must be :data:`PAD_MODE`: anything else, or none, is a one-line error."""
    prefix = f"{where}: " if where else ""
    if meta.get("pad_mode") != PAD_MODE:
        raise NeuralaoError(
            f"{prefix}metadata pad_mode {meta.get('pad_mode')!r} is not {PAD_MODE!r}, "
            "the only padding its consumers do"
            if "pad_mode" in meta
            else f"{prefix}metadata has no pad_mode (the U-Net's input is padded {PAD_MODE!r})"
        )
    return PAD_MODE
