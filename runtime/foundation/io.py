"""Atomic writes and hashing: nothing is ever half-written.

Every output file goes through :func:`atomic_path` (write to a temporary name in the same
directory, fsync, rename), so an interrupted run leaves either the old file or the new one.
"""

from __future__ import annotations

import contextlib
import hashlib
import io as _io
import json
import math
import os
import shutil
import signal
import stat
import struct
import tempfile
import threading
import zipfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import available_memory, format_bytes
from neuralao.runtime.foundation.signals import raise_received


def _umask() -> int:
    """The process's umask, read without changing it (``os.umask`` can only read it by setting it, which
    races with any thread creating a file meanwhile)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def new_file_mode(path: str | os.PathLike | None = None) -> int:
    """The permissions a written file gets: those of the file it replaces, else 0o666 less the umask (what
    ``open(path, "w")`` gives; ``mkstemp`` alone would make every output private, 0o600)."""
    if path is not None:
        try:
            st = os.stat(path)
            if stat.S_ISREG(st.st_mode):
                return stat.S_IMODE(st.st_mode)
        except OSError:
            pass
    return 0o666 & ~_umask()


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) and SIGTERM over the few statements that create a temporary and note its name,
    then act on one that came meanwhile: an interrupt between the two would leave a temporary no cleanup
    knows of. Signals reach Python code in the main thread only, so elsewhere there is nothing to hold."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[tuple[int, object]] = []
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    saved = {s: h for s, h in saved.items() if h is not None}  # None: a handler Python did not install
    for s in saved:
        signal.signal(s, lambda signum, frame: pending.append((signum, frame)))
    try:
        yield
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)
        for signum, frame in pending[:1]:
            handler = saved[signum]
            if callable(handler):
                handler(signum, frame)  # raises KeyboardInterrupt (or the command's SIGTERM exception)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)


# This thread's open publish_together blocks, innermost last: each a list of (publish, discard) of the
# outputs finished inside it, held back until the block ends (other threads' files, a bake's task files,
# are not held).
_LOCAL = threading.local()


def _held() -> list[list[tuple[Callable[[], None], Callable[[], None]]]]:
    if not hasattr(_LOCAL, "held"):
        _LOCAL.held = []
    return _LOCAL.held


@contextlib.contextmanager
def publish_together() -> Iterator[None]:
    """Outputs that :func:`atomic_path` and :func:`atomic_folder` finish inside the block take their places
    only when the block ends without an error, all of them (in the order they were finished); if anything
    fails (a full disk on the second file, Ctrl-C), none does and their temporaries are removed. For a
    command that writes several outputs: the user finds all of them or none, never the first alone."""
    held: list[tuple[Callable[[], None], Callable[[], None]]] = []
    _held().append(held)
    published = 0
    try:
        yield
        raise_received()
        with _signals_held():
            for publish, _ in held:
                publish()
                published += 1
    finally:
        _held().remove(held)
        for _, discard in held[published:]:
            discard()


def _named(e: OSError, path: Path, tmp: Path | None) -> OSError:
    """``e`` naming ``path``: a failed write (a full disk) names no file, and a temporary's name means
    nothing to the user."""
    if e.filename is None or (tmp is not None and str(e.filename) == str(tmp)):
        return OSError(e.errno, e.strerror or str(e), str(path))
    return e


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None, sync: bool = True) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it onto ``path`` if the block succeeds.

    ``suffix`` defaults to the target's suffix so libraries that infer a format from the file name
    (numpy, PIL, trimesh) still do the right thing. The file gets :func:`new_file_mode`'s permissions.
    Whatever ends the block (an error, Ctrl-C, SIGTERM), the temporary is removed. ``sync``: flush the
    file to the disk before the rename (a power cut then leaves the old file or the new one, whole); a
    cache whose reader redoes an unreadable file can skip it.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp_path: Path | None = None
    try:
        with _signals_held():
            fd, tmp = tempfile.mkstemp(
                prefix=f".{path.name}.",
                suffix=".tmp" + (suffix if suffix is not None else path.suffix),
                dir=path.parent,
            )
            tmp_path = Path(tmp)
            try:
                os.fchmod(fd, new_file_mode(path))
            finally:
                os.close(fd)
        try:
            yield tmp_path
            if sync:
                with open(tmp_path, "rb+") as f:
                    os.fsync(f.fileno())
        except OSError as e:
            raise _named(e, path, tmp_path) from e
        raise_received()  # a signal a library swallowed meanwhile: the output is not published
        if _held():  # published with the block's other outputs, or discarded with them
            done, tmp_path = tmp_path, None
            _held()[-1].append((lambda: os.replace(done, path), lambda: done.unlink(missing_ok=True)))
        else:
            os.replace(tmp_path, path)
    finally:
        if tmp_path is not None and tmp_path.exists():
            tmp_path.unlink()


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty temporary folder next to ``path``; if the block succeeds it takes ``path``'s place
    whole (a folder there before is removed, never merged with: no file of an earlier output survives
    beside the new ones), else it is removed and ``path`` is left as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp: Path | None = None
    old: Path | None = None
    try:
        with _signals_held():
            tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
            old = tmp.with_name(tmp.name.removesuffix(".tmp") + ".old.tmp")
        os.chmod(tmp, 0o777 & ~_umask())
        try:
            yield tmp
        except OSError as e:
            raise _named(e, path, None) from e
        raise_received()

        def swap(tmp: Path = tmp, old: Path = old) -> None:
            with _signals_held():  # both renames or neither: an interrupt never leaves the old folder aside
                moved = path.is_dir() and not path.is_symlink()
                if moved:
                    os.rename(path, old)
                try:
                    os.replace(tmp, path)
                except OSError:
                    if moved:
                        os.rename(old, path)
                    raise
                if moved:
                    shutil.rmtree(old, ignore_errors=True)

        if _held():  # published with the block's other outputs, or discarded with them
            done, tmp, old = tmp, None, None
            _held()[-1].append((swap, lambda: shutil.rmtree(done, ignore_errors=True)))
        else:
            swap()
    finally:
        for leftover in (tmp, old):
            if leftover is not None and leftover.is_dir():
                shutil.rmtree(leftover, ignore_errors=True)


def remove_stale_temporaries(directory: str | os.PathLike) -> list[Path]:
    """Delete temporaries that :func:`atomic_path` left in ``directory`` when a run was killed
    (SIGKILL skips its ``finally``). Call it before resuming work in that folder. Returns what went."""
    d = Path(directory)
    stale = [p for p in d.glob(".*.tmp*") if p.is_file()] if d.is_dir() else []
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, obj: Any) -> None:
    write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_npz(path: str | os.PathLike, *, sync: bool = True, **arrays: np.ndarray) -> None:
    """Uncompressed npz written atomically, byte-for-byte deterministic for identical arrays.

    ``np.savez`` stamps each member with the current time, so two identical datasets would hash
    differently; here every member gets a fixed timestamp and members are sorted by name. Each array's
    bytes go from its memory to the file (no copy of the whole member), and the member's declared size is
    set first, so the bytes are those of ``ZipFile.writestr``. ``sync``: see :func:`atomic_path`.
    """
    with atomic_path(path, sync=sync) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for name in sorted(arrays):
                _write_member(zf, f"{name}.npy", np.asarray(arrays[name], order="C"))


# Bytes handed to the zip member per write: large enough to stream at memory speed, small enough not to
# copy an array whole when its buffer cannot be passed as it is.
_WRITE_CHUNK = 1 << 24


def _write_member(zf: zipfile.ZipFile, name: str, array: np.ndarray) -> None:
    """One .npy member of ``zf``: the header numpy writes (format 1.0, or 2.0 for a header too long for it),
    then the array's bytes in C order, straight from its buffer."""
    if array.dtype.hasobject:
        raise ValueError(f"{name}: object arrays are not written (no pickles)")
    head = _io.BytesIO()
    header = np.lib.format.header_data_from_array_1_0(array)
    try:
        np.lib.format.write_array_header_1_0(head, header)
    except ValueError:  # a header over 64 KiB (a shape of very many dimensions)
        np.lib.format.write_array_header_2_0(head, header)
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.external_attr = 0o644 << 16
    flat = np.ascontiguousarray(array).reshape(-1).view(np.uint8)
    info.file_size = head.tell() + len(flat)  # what writestr sets: its zip64 choice follows from it
    with zf.open(info, "w") as f:
        f.write(head.getvalue())
        for lo in range(0, len(flat), _WRITE_CHUNK):
            f.write(flat[lo : lo + _WRITE_CHUNK])


def read_npz(path: str | os.PathLike, keys: Iterable[str] | None = None) -> dict[str, np.ndarray]:
    """The arrays of an npz (no pickles): every one, or those of ``keys`` it holds (a member nothing reads
    is never inflated). Before a member is inflated, its header is checked against the bytes it stores
    and the memory available, so a member that cannot fit is named as such, not taken for corruption; a
    truncated or corrupt file is a one-line error."""
    # our own handle: np.load leaves its file open when the zip directory is unreadable
    with _reading_npz(path), open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
        wanted = z.files if keys is None else [k for k in z.files if k in set(keys)]
        out = {}
        for k in wanted:
            _check_npz_member(z.zip, k, path)
            out[k] = z[k]
        return out


@contextlib.contextmanager
def _reading_npz(path: str | os.PathLike) -> Iterator[None]:
    """Any failure to read an npz as one line: missing, a folder, or (whatever numpy or zipfile raise)
    corrupt or truncated; the npz checks' own errors pass through."""
    try:
        yield
    except FileNotFoundError:
        raise NeuralaoError(f"file not found: {path}") from None
    except IsADirectoryError:
        raise NeuralaoError(f"{path} is a folder, not an .npz file") from None
    except NeuralaoError:
        raise
    except Exception as e:
        raise NeuralaoError(f"cannot read {path}: corrupt or truncated ({type(e).__name__})") from None


def npz_keys(path: str | os.PathLike) -> list[str]:
    """The array names of an npz, read from its zip directory (nothing inflated)."""
    return list(read_npz_directory(path))


def read_npz_directory(path: str | os.PathLike) -> dict[str, int]:
    """Array name -> inflated bytes of each member of an npz (its zip directory only)."""
    with _reading_npz(path), zipfile.ZipFile(path) as zf:
        return {i.filename.removesuffix(".npy"): i.file_size for i in zf.infolist()}


def _check_npz_member(zf: zipfile.ZipFile, key: str, path: str | os.PathLike) -> None:
    """Refuse member ``key`` before inflating it when it cannot be read: Python objects, a header that
    declares more bytes than the member holds, or more than the memory available."""
    names = set(zf.namelist())
    info = zf.getinfo(key + ".npy" if key + ".npy" in names else key)
    with zf.open(info) as f:
        shape, dtype = _npy_header(f)
    _check_npy_size(f"{path}: array {key!r}", shape, dtype, info.file_size)


def _npy_header(f) -> tuple[tuple[int, ...], np.dtype]:
    version = np.lib.format.read_magic(f)
    read = np.lib.format.read_array_header_2_0 if version >= (2, 0) else np.lib.format.read_array_header_1_0
    shape, _, dtype = read(f)
    return tuple(shape), dtype


def _check_npy_size(where: str, shape: tuple[int, ...], dtype: np.dtype, stored: int) -> None:
    if dtype.hasobject:
        raise NeuralaoError(f"{where} holds Python objects ({dtype}); only plain arrays are read")
    nbytes = math.prod(shape) * dtype.itemsize
    avail = available_memory()
    if nbytes > avail:
        raise NeuralaoError(
            f"{where} of shape {shape} ({format_bytes(nbytes)}) is more than the "
            f"{format_bytes(avail)} of memory available"
        )
    if nbytes > stored:
        raise NeuralaoError(
            f"{where}: its header declares shape {shape} ({nbytes} bytes) but it holds {stored} bytes "
            "(truncated or corrupt)"
        )


def read_npy(path: str | os.PathLike, what: str) -> np.ndarray:
    """The array of an .npy file of real numbers (ints or floats): its header is checked before anything
    is allocated (size against the file and the memory), and complex, boolean, structured or object arrays
    are refused (numpy would drop an imaginary part with only a warning). ``what`` names it in errors."""
    try:
        size = os.stat(path).st_size
        with open(path, "rb") as f:
            shape, dtype = _npy_header(f)
            header = f.tell()
    except FileNotFoundError:
        raise NeuralaoError(f"{what} file not found: {path}") from None
    except IsADirectoryError:
        raise NeuralaoError(f"{what} {path} is a folder, not an .npy file") from None
    except Exception as e:
        raise NeuralaoError(f"cannot read {what} {path}: not an .npy array ({type(e).__name__})") from None
    if dtype.kind not in "iuf" or dtype.names is not None:
        raise NeuralaoError(f"{what} {path} holds {dtype} values; it must hold real numbers (int or float)")
    _check_npy_size(f"{what} {path}", shape, dtype, size - header)
    try:
        return np.load(path, allow_pickle=False)
    except Exception as e:
        raise NeuralaoError(f"cannot read {what} {path}: corrupt or truncated ({type(e).__name__})") from None


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W) or (H, W, 3|4) image; float input in [0, 1] is quantised to 8 bits."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = (np.clip(np.nan_to_num(img), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    with atomic_path(path) as tmp:
        Image.fromarray(img).save(tmp, format="PNG")


def write_exr(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W) or (H, W, 3|4) float image as an OpenEXR file: float32 channels (Y, or R G B [A]),
    uncompressed scanlines, written atomically. Values are stored as they are (no clamping or
    quantisation): the point of EXR output is the full float32 AO.

    The layout (OpenEXR 2 single-part scanline file): magic and version, a header of typed attributes
    ending in a zero byte, one uint64 offset per scanline, then each scanline as int32 y, int32 byte
    count and the line's pixels channel by channel, channels in alphabetical order.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4) or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"EXR image must be (H, W) or (H, W, 3|4), got {np.shape(image)}")
    h, w, c = img.shape
    names = {1: ["Y"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}[c]
    order = sorted(range(c), key=lambda k: names[k])  # channels are stored alphabetically

    def attr(name: str, kind: str, value: bytes) -> bytes:
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value

    FLOAT = 2  # OpenEXR pixel type
    chlist = (
        b"".join(names[k].encode() + b"\0" + struct.pack("<iB3xii", FLOAT, 0, 1, 1) for k in order) + b"\0"
    )
    window = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    header = b"".join(
        [
            struct.pack("<ii", 20000630, 2),
            attr("channels", "chlist", chlist),
            attr("compression", "compression", b"\0"),  # NO_COMPRESSION
            attr("dataWindow", "box2i", window),
            attr("displayWindow", "box2i", window),
            attr("lineOrder", "lineOrder", b"\0"),  # INCREASING_Y
            attr("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
            attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
            attr("screenWindowWidth", "float", struct.pack("<f", 1.0)),
            b"\0",
        ]
    )
    line_bytes = w * c * 4
    first = len(header) + 8 * h
    offsets = np.arange(h, dtype="<u8") * (8 + line_bytes) + first
    planar = np.ascontiguousarray(img[:, :, order].transpose(0, 2, 1), dtype="<f4")  # (H, C, W)
    lines = np.empty((h, 8 + line_bytes), np.uint8)
    lines[:, :4] = np.arange(h, dtype="<i4").view(np.uint8).reshape(h, 4)
    lines[:, 4:8] = np.frombuffer(struct.pack("<i", line_bytes), np.uint8)
    lines[:, 8:] = planar.reshape(h, -1).view(np.uint8)
    with atomic_path(path) as tmp:
        tmp.write_bytes(header + offsets.tobytes() + lines.tobytes())


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def sha256_json(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=_json_default).encode()).hexdigest()
