"""The one reader of manifests: an export folder's ``manifest.json`` (the kind, files, hashes, passes and
provenance an engine and every command here follow), and the JSON of the files beside it.

Torch-free and below every layer, so the consumer runtime, the shader generator and the pipeline read a
manifest the same way. A manifest is JSON; before parsing, its size and nesting depth are bounded, so a
hostile file is a one-line error and never a MemoryError or a RecursionError.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError, reading

NAME = "manifest.json"
# A shipped model's manifest is ~60 KB (the U-Net's with its evaluation tables); 64 MiB is far beyond any
# manifest or bake config and far below what the parser's objects would take of memory.
MAX_JSON_BYTES = 64 << 20
# Manifests nest 6 deep; Python's parser recurses per level and fails near 1,000.
MAX_JSON_DEPTH = 64


# A JSON string literal (escapes included): what the depth count skips.
_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
# Per byte: +1 for an opening bracket, -1 for a closing one.
_STEP = np.zeros(256, np.int8)
_STEP[[ord("["), ord("{")]], _STEP[[ord("]"), ord("}")]] = 1, -1


def _depth(raw: bytes) -> int:
    """Deepest nesting of brackets outside strings (the parser's recursion depth), in C speed: strings
    are cut out, then the running count of openers minus closers is a cumulative sum."""
    if raw.count(b"[") + raw.count(b"{") <= MAX_JSON_DEPTH:
        return 0  # cannot nest deeper than the bound (the common case: no scan)
    step = _STEP[np.frombuffer(_STRING.sub(b"", raw), np.uint8)]
    return int(np.cumsum(step, dtype=np.int64).max(initial=0))


def parse_json(data: bytes | str, where: str | os.PathLike, what: str = "JSON") -> Any:
    """The parsed JSON of ``data`` (UTF-8 bytes or text), bounded in size and nesting depth; any failure is
    one line naming ``where`` (a file, a GLB's JSON chunk, a --set value). Every JSON a user hands in is
    parsed here: Python's parser recurses per level and would fail with a RecursionError."""
    try:  # text from the command line may carry undecodable bytes (as surrogates)
        raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    except UnicodeEncodeError as e:
        raise NeuralaoError(f"{where}: {what} is not UTF-8 (character {e.start})") from None
    if len(raw) > MAX_JSON_BYTES:
        raise NeuralaoError(f"{where}: {what} of {len(raw)} bytes is over {MAX_JSON_BYTES}")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise NeuralaoError(f"{where}: {what} is not UTF-8 (byte {e.start}); save it as UTF-8") from None
    if _depth(raw) > MAX_JSON_DEPTH:
        raise NeuralaoError(f"{where}: {what} nests deeper than {MAX_JSON_DEPTH} levels")
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise NeuralaoError(
            f"cannot read {where}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})"
        ) from None
    except RecursionError:  # nesting the count above could not see (never expected)
        raise NeuralaoError(f"{where}: {what} nests too deep") from None


def read_json(path: str | os.PathLike, what: str = "JSON file") -> Any:
    """The parsed JSON of ``path`` (UTF-8), bounded in size and depth; any failure is one line naming it."""
    path = Path(path)
    with reading(path, what):
        if path.stat().st_size > MAX_JSON_BYTES:
            raise NeuralaoError(f"{path}: {what} of {path.stat().st_size} bytes is over {MAX_JSON_BYTES}")
        raw = path.read_bytes()
    return parse_json(raw, path, what)


def read_manifest(folder: str | os.PathLike, kind: str | None = None, label: str = "") -> dict:
    """``folder``'s manifest.json as a dict; with ``kind``, one of that kind (``label`` names it in errors:
    "{folder} is not {label or kind} export")."""
    path = Path(folder) / NAME
    if not path.is_file():
        raise NeuralaoError(f"no export manifest at {path}")
    manifest = read_json(path, "export manifest")
    if not isinstance(manifest, dict):
        raise NeuralaoError(f"{path} is corrupt: an export manifest is a JSON object")
    if kind is not None and manifest.get("kind") != kind:
        raise NeuralaoError(f"{folder} is not {label or kind} export (kind {manifest.get('kind')!r})")
    return manifest
