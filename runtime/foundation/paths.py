"""Where a command may write: every output path is checked before any work starts, so a run never
traces for minutes and then fails to write (or overwrites its own input).

    check_outputs({"--out": ("ao.png", FILE), "--composite": ("c.png", FILE)},
                  {"FRAME": "frame.npz"})

An output must be a path that can be created as the kind it is (a file, or a folder): not an existing
folder where a file is wanted nor an existing file where a folder is wanted, not below a file, on a file
system this process can write to (a probe file is created and removed in the nearest existing folder: this
refuses /proc, /sys, read-only mounts and folders without write permission alike), with a name the file
system can hold. Outputs must differ from each other and from every input, a glTF input's files beside it
included (its buffers and images), and an OBJ input's material library and its textures
(:func:`mesh_references`). Each refusal is one line that names the flag.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import re
import struct
import tempfile
from collections.abc import Collection, Iterable, Mapping
from pathlib import Path
from urllib.parse import unquote

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.manifest import MAX_JSON_BYTES, parse_json, read_json

FILE, FOLDER = "file", "folder"
# Room a name needs beside itself for the temporaries of atomic writes (".NAME.xxxxxxxx.tmp" + suffix).
_TEMP_AFFIXES = 24
_MAX_MTL_BYTES = 16 << 20  # an OBJ material library read for its texture names (its reader reads it whole)


def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_output(flag: str, path: str | os.PathLike, kind: str = FILE) -> Path:
    """``path`` as an output of ``kind`` (FILE or FOLDER), refused in one line naming ``flag`` when it
    cannot be written (module doc). Returns it as a Path. Creates nothing that stays."""
    text = os.fspath(path)
    if not text or "\0" in text:
        raise NeuralaoError(f"{flag} {text!r} is not a path")
    p = Path(text)
    check_name_lengths(flag, p)
    if p.exists() or p.is_symlink():
        if kind == FILE and p.is_dir():
            raise NeuralaoError(f"{flag} {p} is a folder; a file is wanted here")
        if kind == FILE and p.exists() and not p.is_file():
            raise NeuralaoError(f"{flag} {p} is not a regular file (a device or a pipe); choose a file")
        if kind == FOLDER and not p.is_dir():
            raise NeuralaoError(f"{flag} {p} is a file; a folder is wanted here")
    full = p.absolute()
    base = _nearest_existing(full if kind == FOLDER else full.parent)
    if not base.is_dir():
        raise NeuralaoError(f"{flag} {p} is below {base}, which is a file, not a folder")
    created = full.relative_to(base).parts if full != base else ()
    longest = max((len(os.fsencode(part)) for part in created), default=0)
    if longest + _TEMP_AFFIXES > _name_max(base):
        raise NeuralaoError(
            f"{flag}: a name in {p} is too long for the file system ({_name_max(base)} bytes at most, "
            f"less {_TEMP_AFFIXES} for temporary names)"
        )
    _probe_writable(flag, p, base)
    return p


# Linux's limits on one name and on a whole path (bytes); past them every call on the path fails.
NAME_MAX, PATH_MAX = 255, 4095


def check_name_lengths(flag: str, path: str | os.PathLike) -> None:
    """Refuse a path the file system cannot even look up: a name longer than NAME_MAX bytes, or a path
    longer than PATH_MAX (every call on it would fail with "File name too long")."""
    raw = os.fsencode(path)
    longest = max((len(part) for part in raw.split(b"/")), default=0)
    shown = os.fsdecode(raw[:60]) + ("..." if len(raw) > 60 else "")
    if longest > NAME_MAX:
        raise NeuralaoError(
            f"{flag} {shown}: a name in it is {longest} bytes, more than the {NAME_MAX} a file system allows"
        )
    if len(raw) > PATH_MAX:
        raise NeuralaoError(
            f"{flag} {shown}: the path is {len(raw)} bytes, more than the {PATH_MAX} a file system allows"
        )


def _probe_writable(flag: str, path: Path, folder: Path) -> None:
    """Create and remove a temporary file in ``folder``: the one test that every kind of unwritable place
    fails (permissions, read-only mounts, /proc and /sys, which even root cannot create files in)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".neuralao-probe.", suffix=".tmp", dir=folder)
    except OSError as e:
        why = e.strerror or type(e).__name__
        raise NeuralaoError(f"{flag} {path}: cannot create files in {folder} ({why})") from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)


def _same(a: Path, b: Path) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _paths(value: object) -> list[Path]:
    if value is None:
        return []
    if isinstance(value, str | os.PathLike):
        return [Path(value)] if os.fspath(value) else []
    if isinstance(value, Iterable):
        return [p for v in value for p in _paths(v)]
    return []


def _gltf_json(path: Path) -> object:
    """The JSON document of a .gltf, or of a .glb's first chunk (nothing past it is read), bounded as every
    JSON a user hands in; None when it is not one (its reader refuses it later, in its own words)."""
    try:
        with open(path, "rb") as f:
            if path.suffix.lower() == ".gltf":
                return parse_json(f.read(MAX_JSON_BYTES + 1), path, "glTF JSON")
            head = f.read(20)
            if len(head) < 20 or head[:4] != b"glTF" or head[16:20] != b"JSON":
                return None
            size = min(struct.unpack_from("<I", head, 12)[0], MAX_JSON_BYTES + 1)
            return parse_json(f.read(size), path, "glTF JSON")
    except (OSError, NeuralaoError):
        return None


def gltf_references(path: str | os.PathLike) -> list[tuple[Path, str]]:
    """The files a .gltf or .glb at ``path`` reads beside itself: (file, what it is, e.g. "buffer 0") for
    every relative uri of its buffers and images (data: URIs hold their bytes), percent-decoded and
    resolved against its folder as the glTF reader does. Only the JSON is read; none for any other file."""
    p = Path(path)
    if p.suffix.lower() not in (".gltf", ".glb") or not p.is_file():
        return []
    doc = _gltf_json(p)
    found = []
    for key in ("buffers", "images"):
        items = doc.get(key) if isinstance(doc, dict) else None
        for i, item in enumerate(items if isinstance(items, list) else []):
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and uri and not uri.lower().startswith("data:"):
                found.append((p.parent / unquote(uri), f"{key[:-1]} {i}"))
    return found


def obj_references(path: str | os.PathLike) -> list[tuple[Path, str]]:
    """The files an .obj at ``path`` reads beside itself, as its reader (trimesh) finds them: the material
    library named after the file's first ``mtllib`` and, in that library, every ``map_Kd`` texture (each
    the rest of its line, resolved against the OBJ's folder). The OBJ is searched, not parsed."""
    p = Path(path)
    if p.suffix.lower() != ".obj" or not p.is_file():
        return []
    try:
        with open(p, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:
            at = m.find(b"mtllib")
            if at < 0:
                return []
            end = m.find(b"\n", at)
            name = m[at + 6 : end if end >= 0 else len(m)].decode("utf-8", "replace").strip()
    except (OSError, ValueError):  # unreadable, or empty (mmap refuses 0 bytes)
        return []
    if not name:
        return []
    library = p.parent / name
    found = [(library, "material library")]
    try:
        with open(library, "rb") as f:
            text = f.read(_MAX_MTL_BYTES).decode("utf-8", "replace")
    except OSError:
        return found
    for line in text.splitlines():
        words = line.split()
        if words and words[0].lower() == "map_kd":
            texture = line[line.lower().index("map_kd") + 6 :].strip()
            if texture:
                found.append((p.parent / texture, f"texture of {name}"))
    return found


def mesh_references(path: str | os.PathLike) -> list[tuple[Path, str]]:
    """The files a mesh file reads beside itself: a glTF's buffers and images, an OBJ's material library
    and textures; none for any other file."""
    return gltf_references(path) + obj_references(path)


def check_outputs(
    outputs: Mapping[str, tuple[object, str]], inputs: Mapping[str, object] | None = None
) -> None:
    """Check every output (flag -> (path or None, kind)) with :func:`check_output`, then that no two
    outputs and no output and input (name -> path, list of paths or None) are the same file, nor an
    output and a file a mesh input reads beside itself (:func:`mesh_references`)."""
    given = {flag: (Path(os.fspath(p)), kind) for flag, (p, kind) in outputs.items() if p is not None}
    for flag, (p, kind) in given.items():
        check_output(flag, p, kind)
    for name, value in (inputs or {}).items():
        for src in _paths(value):
            check_name_lengths(name, src)
    flags = list(given)
    for i, a in enumerate(flags):
        for b in flags[i + 1 :]:
            if _same(given[a][0], given[b][0]):
                raise NeuralaoError(f"{a} and {b} name the same path {given[a][0]}; give each its own")
    for name, value in (inputs or {}).items():
        for src in _paths(value):
            for flag, (p, _) in given.items():
                if _same(p, src):
                    raise NeuralaoError(
                        f"{flag} {p} is also an input ({name}): writing it would destroy what is read; "
                        "choose another path"
                    )
            for ref, what in mesh_references(src):
                for flag, (p, _) in given.items():
                    if _same(p, ref):
                        raise NeuralaoError(
                            f"{flag} {p} is also an input ({what} of {name} {src}): writing it would destroy "
                            "what is read; choose another path"
                        )


def check_replaceable_folder(
    flag: str,
    path: str | os.PathLike,
    kinds: Collection[str],
    force: bool = False,
    inputs: Mapping[str, object] | None = None,
) -> None:
    """An export folder is written whole and then takes ``path``'s place (never merged with what was
    there, so no file of an earlier export survives beside the new one). That replaces, without asking, a
    missing or empty folder or an earlier export (a ``manifest.json`` whose ``kind`` is one of ``kinds``);
    any other folder only with ``force``. Never a folder that holds one of ``inputs`` (it would be deleted
    with the folder)."""
    p = Path(path)
    if not p.is_dir():
        return
    for name, value in (inputs or {}).items():
        for src in _paths(value):
            if os.path.realpath(src).startswith(os.path.realpath(p) + os.sep):
                raise NeuralaoError(
                    f"{flag} {p} holds the input {src} ({name}): the folder is replaced whole, which would "
                    "delete it; write the export elsewhere"
                )
    entries = sorted(x.name for x in p.iterdir())
    if not entries or force:
        return
    manifest = p / "manifest.json"
    try:
        kind = read_json(manifest, "manifest").get("kind") if manifest.is_file() else None
    except (NeuralaoError, AttributeError):
        kind = None
    if kind not in kinds:
        raise NeuralaoError(
            f"{flag} {p} is a folder that is not an export (it holds {entries[0]!r}"
            f"{f' and {len(entries) - 1} more' if len(entries) > 1 else ''}); an export replaces its folder "
            "whole: choose an empty or new folder, or give --force to replace this one"
        )


# A name the project makes a file or folder name of (a shipped model's, a dataset scene's, an evaluation
# category's): letters, digits, '.', '_', '-' and '+', starting with a letter or digit, so it is one path
# component under the folder it is written in, never '..', a subfolder, an absolute path or a NUL.
_PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]{0,127}")


def check_plain_name(what: str, name: object) -> str:
    """``name`` if it is a plain name (:data:`_PLAIN_NAME`), else a one-line error naming ``what``: it
    becomes a file or folder name, and a '/' or '..' in it would write outside the output folder."""
    if not isinstance(name, str) or not _PLAIN_NAME.fullmatch(name):
        shown = repr(name) if not isinstance(name, str) or len(name) <= 60 else repr(name[:60] + "...")
        raise NeuralaoError(
            f"{what} {shown} is not a plain name: it names files, so it takes letters, digits, '.', '_', "
            "'-' and '+' (at most 128, starting with a letter or digit)"
        )
    return name
