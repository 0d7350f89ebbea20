"""npz files as the pipeline writes them: the same bytes as zipfile's own one-shot member writer, read back
exactly, and a bake's task file that a crash left unreadable counts as missing."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from neuralao.pipeline.bakes.level_stages import TaskFiles
from neuralao.runtime.foundation.io import read_npz, write_npz


def writestr_npz(path, **arrays) -> None:
    """The reference: each member's .npy made whole in memory by numpy, then ``ZipFile.writestr``."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asarray(arrays[name], order="C"), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue())


RNG = np.random.default_rng(7)
ARRAYS = {
    "scalar": np.array(3.5),
    "text": np.array(["a", "bcd"]),
    "bytes": np.array(b"xy"),
    "empty": np.zeros((0, 3), np.float32),
    "fortran": np.asfortranarray(RNG.random((50, 7))),
    "strided": RNG.random((100, 10))[:, ::3],
    "big_endian": np.arange(10, dtype=">i4"),
    "mask": RNG.random(1001) > 0.5,
    "record": np.zeros(3, dtype=[("a", "<f4"), ("b", "<i2")]),
    "chunks": RNG.random(5_000_000),  # 40 MB: several of the writer's chunks
}


@pytest.mark.parametrize("name", sorted(ARRAYS))
@pytest.mark.parametrize("sync", [True, False])
def test_write_npz_gives_writestrs_bytes_and_reads_back_exactly(tmp_path, name, sync):
    arrays = {name: ARRAYS[name], "_key": np.array("bake")}
    writestr_npz(tmp_path / "ref.npz", **arrays)
    write_npz(tmp_path / "out.npz", sync=sync, **arrays)
    assert (tmp_path / "out.npz").read_bytes() == (tmp_path / "ref.npz").read_bytes()
    back = read_npz(tmp_path / "out.npz")[name]
    assert back.dtype == ARRAYS[name].dtype and back.shape == ARRAYS[name].shape
    assert np.array_equal(back, ARRAYS[name])


def test_write_npz_refuses_object_arrays(tmp_path):
    with pytest.raises(ValueError, match="object"):
        write_npz(tmp_path / "o.npz", x=np.array([{"a": 1}], dtype=object))
    assert not list(tmp_path.iterdir())  # nothing left behind


@pytest.mark.parametrize("damage", ["empty", "truncated", "garbage", "other_key"])
def test_an_unreadable_task_file_is_missing_not_an_error(tmp_path, damage):
    files = TaskFiles(tmp_path / "stage", "key-1")
    files.put("p00000", {"v": np.arange(100_000, dtype=np.float64)})
    assert files.has("p00000") and np.array_equal(files.get("p00000")["v"], np.arange(100_000))
    path = files.path("p00000")
    data = path.read_bytes()
    if damage == "empty":
        path.write_bytes(b"")
    elif damage == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        path.write_bytes(b"PK\x03\x04" + bytes(range(256)) * 8)
    else:
        TaskFiles(tmp_path / "stage", "key-2").put("p00000", {"v": np.zeros(3)})
    assert not files.has("p00000") and files.get("p00000") is None
