"""What the machine can hold, and what an input number must be: every count a user can type (rays,
views, sizes, samples, steps...) is checked here before anything is allocated, and a count past the
bound is a one-line :class:`NeuralaoError` that names the flag or setting and gives the bound.

    check_count("--rays", rays, bytes_each=RAY_BYTES * workers)   # memory the count would take
    check_pixels("--size", w, h)                                   # one frame's buffers
    check_seed("--seed", seed)                                     # what numpy and torch accept

The bound is the memory available now (``MemAvailable``, capped by a cgroup limit), so it is the
same figure a failed allocation would have hit, reported before the allocation instead of after it.
The per-item sizes below are generous upper estimates of what the code allocates per item (working
buffers and temporaries included), not exact footprints: the check refuses what cannot fit, and
anything it lets through still has to fit in practice.
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

from neuralao.runtime.foundation.errors import NeuralaoError

# Bytes per ray per tracing thread: the labeller's float32 ray buffers (directions, origins, two
# scratch arrays), Embree's outputs, the direction temporaries and the per-hit int64 indices.
RAY_BYTES = 128
# Bytes per ray once per labeller: the Hammersley tables (uint64 and float64 copies, cos/sin).
RAY_TABLE_BYTES = 64
# A tracing thread's own cost (stack and scratch), so a worker count alone is bounded too.
THREAD_BYTES = 8 << 20
# Bytes per pixel of one rendered, labelled frame: the GL float targets, the frame's numpy channels,
# the float64 points and normals of the labeller and the previews.
PIXEL_BYTES = 512
# Bytes per surface sample of a bake or a field: position, normal, barycentrics, face and weight, the
# labeller's per-point arrays and the sample's rows of the least-squares system.
SAMPLE_BYTES = 512
# Bytes on disk per pixel of a written frame (.npz channels plus three PNG previews).
PIXEL_DISK_BYTES = 64
# The largest cap (samples per face and the like): caps allocate nothing, but they meet int64
# arithmetic, so any value up to here behaves as "no cap".
MAX_CAP = 1 << 62
# The largest float32. Distances, sizes and weights end up in float32 buffers (rays, G-buffers, shader
# uniforms), where a larger float64 turns into inf: such a value is refused where it is typed.
FLOAT32_MAX = 3.4028234663852886e38
# The smallest normal float32: a non-zero value below it is 0 or a subnormal there (a distance of 1e-300
# would be a zero distance, a divisor of 1e-40 an overflow), so it is refused like a value past the largest.
FLOAT32_TINY = 1.1754943508222875e-38
# The largest seed: numpy's SeedSequence and torch.manual_seed both take any value in [0, 2^63).
MAX_SEED = (1 << 63) - 1


def available_memory() -> int:
    """Bytes of memory this process can still allocate: /proc/meminfo MemAvailable, capped by the
    cgroup v2 limit; the physical memory where neither is readable."""
    avail = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = 1 << 34  # 16 GiB: only on systems that report nothing at all
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = Path("/sys/fs/cgroup/memory.current").read_text().strip()
        if limit != "max":
            avail = min(avail, max(int(limit) - int(used), 0))
    except (OSError, ValueError):
        pass
    return max(int(avail), 1)


def release_free_memory() -> None:
    """Hand the heap's free pages back to the system (glibc's malloc_trim; a no-op elsewhere).

    glibc keeps freed blocks of up to 32 MB in its arenas once big arrays have come and gone, so a
    process's resident memory stays at its peak long after; a level bake's driver and workers call
    this between stages and tasks so their memory is what they hold."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def free_disk(path: str | os.PathLike) -> int:
    """Free bytes on the file system that ``path`` (or its nearest existing parent) is on."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return int(shutil.disk_usage(p).free)
    except OSError:
        return 1 << 62  # unknown: let the write itself report it


def format_bytes(n: float) -> str:
    """``7.28 TiB``-style size."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024.0
    return f"{n:.3g} EiB"  # unreachable


def _integer(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise NeuralaoError(f"{name} must be an integer, got {value!r}")
    return value


def check_count(
    name: str,
    value: object,
    *,
    low: int = 1,
    bytes_each: float = 1.0,
    each: str = "",
    budget: int | None = None,
    shown: str | None = None,
) -> int:
    """``value`` as an int in [low, bound]: bound = the memory (``budget``, default the available memory)
    divided by ``bytes_each``, the bytes one unit of the count makes the command allocate (``each``
    says what they are, for the message). Anything else is a one-line error naming ``name``."""
    value = _integer(name, value)
    text = shown if shown is not None else str(value)
    if value < low:
        raise NeuralaoError(f"{name} must be >= {low}, got {text}")
    budget = available_memory() if budget is None else budget
    bound = max(int(budget // max(bytes_each, 1.0)), 0)
    if value > bound:
        per = f" at {format_bytes(bytes_each)} each{f' ({each})' if each else ''}"
        raise NeuralaoError(
            f"{name} {text} is more than this machine can hold: at most {bound}{per}, "
            f"{format_bytes(budget)} of memory available"
        )
    return value


def check_int_range(name: str, value: object, low: int, high: int) -> int:
    """An integer in [low, high] (a cap or an index that allocates nothing itself)."""
    value = _integer(name, value)
    if not low <= value <= high:
        raise NeuralaoError(f"{name} must be an integer in [{low}, {high}], got {value}")
    return value


def check_pixels(name: str, width: object, height: object, frames: int = 1, max_side: int = 8192) -> None:
    """An image size: each side in [1, max_side], and ``frames`` frames of it in memory."""
    w, h = _integer(name, width), _integer(name, height)
    if not (1 <= w <= max_side and 1 <= h <= max_side):
        raise NeuralaoError(f"{name} must be between 1 and {max_side} in each dimension, got {w} {h}")
    check_count(
        name,
        w * h * max(frames, 1),
        bytes_each=PIXEL_BYTES,
        each="per pixel of a frame",
        shown=f"{w} {h} ({w * h} pixels)",
    )


def check_disk(name: str, nbytes: float, folder: str | os.PathLike, shown: str) -> None:
    """Refuse an output of about ``nbytes`` that the disk under ``folder`` cannot hold."""
    free = free_disk(folder)
    if nbytes > free:
        raise NeuralaoError(
            f"{name} {shown} would write about {format_bytes(nbytes)}, more than the "
            f"{format_bytes(free)} free on the disk of {folder}"
        )


def check_seed(name: str, value: object) -> int:
    """A seed in [0, 2^63): what numpy's and torch's generators accept."""
    value = _integer(name, value)
    if not 0 <= value <= MAX_SEED:
        raise NeuralaoError(f"{name} must be an integer in [0, 2^63 - 1], got {value}")
    return value


def check_finite_number(name: str, value: object, low: float | None = None, strict: bool = True) -> float:
    """A finite number (above ``low``, strictly unless ``strict`` is False)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise NeuralaoError(f"{name} must be a finite number, got {value!r}")
    if low is not None and (value <= low if strict else value < low):
        raise NeuralaoError(f"{name} must be {'>' if strict else '>='} {low:g}, got {value!r}")
    return float(value)


def check_float32(name: str, value: object) -> float:
    """A finite number that float32 holds as it is (0, or FLOAT32_TINY <= |value| <= FLOAT32_MAX): what every
    float flag and setting must be, whatever it means, before any command uses it."""
    number = check_finite_number(name, value)
    if abs(number) > FLOAT32_MAX:
        raise NeuralaoError(
            f"{name} {value!r} is out of range: it is used in float32, whose largest is {FLOAT32_MAX:.4g}"
        )
    if 0 < abs(number) < FLOAT32_TINY:
        raise NeuralaoError(
            f"{name} {value!r} is too small: it is used in float32, where it would be 0 or lose its "
            f"digits (the smallest is {FLOAT32_TINY:.4g})"
        )
    return number


def check_finite_arrays(arrays: dict, what: str, kind: str = "channel") -> None:
    """Refuse NaN or inf in any floating array of ``arrays`` (name -> array): one line naming the first
    such ``kind`` of ``what`` and how many of its values are not finite. Non-float arrays pass."""
    import numpy as np

    for name, value in arrays.items():
        a = np.asarray(value)
        if a.dtype.kind in "fc" and not np.isfinite(a).all():
            bad = int(a.size - np.count_nonzero(np.isfinite(a)))
            raise NeuralaoError(
                f"{what}: {kind} {name!r} has {bad} non-finite value(s) (NaN or inf) of {a.size}"
            )
