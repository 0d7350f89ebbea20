"""`--engine ray`: a real two-node Ray cluster on loopback (ray.cluster_utils.Cluster, one CPU a node)
gives datasets and bakes byte-identical to the local engine, also when a worker or the driver is
killed mid-run; the local engine never imports Ray; bad addresses are one-line errors.

One module-scoped cluster, tiny meshes, few rays: the module runs in about a minute on 2 cores.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

# Ray maps 127.0.0.1 to the machine's outward address unless this is off (its switch for clusters on
# laptops): set before ray is imported, here and in every `ray start` and CLI driver this module runs.
os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
ray = pytest.importorskip("ray")

from helpers import kill_a_worker_mid_run  # noqa: E402

from neuralao.pipeline.bakes.vertex import BakeSettings, bake, write_baked_mesh  # noqa: E402
from neuralao.pipeline.datasets.dataset import DatasetSettings, build_dataset  # noqa: E402
from neuralao.pipeline.engines import engine as engine_mod  # noqa: E402
from neuralao.pipeline.engines.engine import LocalEngine, RayEngine  # noqa: E402
from neuralao.pipeline.geometry.scene import load_scene  # noqa: E402
from neuralao.runtime.foundation.errors import NeuralaoError  # noqa: E402

CONFIG = {
    "name": "tiny-ray",
    "seed": 3,
    "size": [32, 24],
    "holdout_every": 2,
    "frames_per_shard": 1,
    "labels": {"rays": 16},
    "scenes": [
        {"name": "suzanne", "mesh": "suzanne", "cameras": "orbit", "views": 4, "split": "train"},
        {"name": "box", "mesh": "cornell_box", "cameras": "interior", "views": 2, "split": "val"},
    ],
}
BAKE = BakeSettings(rays=128, samples_per_vertex=4.0, seed=5)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster():
    """Address of a head + one worker node (1 CPU each, real raylets) on 127.0.0.1; this process is
    connected. ray.cluster_utils.Cluster starts and stops exactly the processes it owns."""
    from ray.cluster_utils import Cluster

    node = {"num_cpus": 1, "object_store_memory": 100 * 2**20}
    c = Cluster(initialize_head=True, head_node_args=node | {"include_dashboard": False})
    try:
        c.add_node(**node)
        engine_mod._connect(c.address)
        c.wait_for_nodes()
        assert {n["NodeManagerAddress"] for n in ray.nodes() if n["Alive"]} == {"127.0.0.1"}
        yield c.address
    finally:
        ray.shutdown()
        c.shutdown()


@pytest.fixture
def ray_engine(cluster):
    """Two actors, one per node; closed after each test, so the CLI drivers of other tests find the
    cluster's CPUs free."""
    with RayEngine(cluster) as engine:
        yield engine


@pytest.fixture(scope="module")
def config_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "tiny.json"
    path.write_text(json.dumps(CONFIG))
    return path


@pytest.fixture(scope="module")
def local_dataset(tmp_path_factory, config_file):
    from neuralao.runtime.foundation.settings import load_settings

    out = tmp_path_factory.mktemp("local") / "ds"
    return out, build_dataset(load_settings(DatasetSettings, config_file, []), out, progress=False)


@pytest.fixture(scope="module")
def local_bake(tmp_path_factory):
    scene = load_scene("spot")
    result = bake(scene, BAKE)
    path = tmp_path_factory.mktemp("bake") / "spot.ply"
    write_baked_mesh(path, scene, result.ao)
    return scene, result.ao, path.read_bytes()


def _shard_bytes(root: Path, manifest: dict) -> list[bytes]:
    return [(root / s["file"]).read_bytes() for s in manifest["shards"]]


def _cli(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "neuralao.pipeline.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


def test_two_node_dataset_is_byte_identical(ray_engine, local_dataset, config_file, tmp_path):
    from neuralao.runtime.foundation.settings import load_settings

    nodes = {node for _, node in ray_engine.worker_info()}
    assert len(nodes) == 2, "one actor per node"
    root, manifest = local_dataset
    out = tmp_path / "ds"
    remote = build_dataset(
        load_settings(DatasetSettings, config_file, []), out, progress=False, engine=ray_engine
    )
    assert ray_engine.completed == len(manifest["shards"]) == 6
    assert remote["dataset_hash"] == manifest["dataset_hash"]
    assert _shard_bytes(out, remote) == _shard_bytes(root, manifest)
    assert (out / "manifest.json").read_bytes() == (root / "manifest.json").read_bytes()
    # the back layer added on the cluster: only the layers rendered there, the bytes of a local build's
    layered = replace(load_settings(DatasetSettings, config_file, []), back_layer=True)
    remote = build_dataset(layered, out, progress=False, engine=ray_engine)
    local = build_dataset(layered, tmp_path / "local", progress=False)
    assert ray_engine.completed == 6 and remote == local
    assert remote["dataset_hash"] == manifest["dataset_hash"]
    for entry in remote["shards"]:
        assert (out / entry["layer_file"]).read_bytes() == (
            tmp_path / "local" / entry["layer_file"]
        ).read_bytes()


def test_two_node_bake_is_byte_identical(ray_engine, local_bake, tmp_path, monkeypatch):
    monkeypatch.setattr(engine_mod, "CHUNK_RAYS", 1 << 15)  # many small tasks over both nodes
    scene, ao, data = local_bake
    for method in ("least-squares", "vertex"):
        settings = replace(BAKE, method=method)
        reference = ao if method == "least-squares" else bake(scene, settings).ao
        remote = bake(scene, settings, engine=ray_engine)
        assert ray_engine.completed > 4
        np.testing.assert_array_equal(remote.ao, reference)
    write_baked_mesh(tmp_path / "spot.ply", scene, bake(scene, BAKE, engine=ray_engine).ao)
    assert (tmp_path / "spot.ply").read_bytes() == data


# Small tasks on the tiny level (scheduling only): pieces of at most 100 faces (the terrain alone, then
# the buildings), several trace blocks and resampling tasks, one task per tree.
LEVEL_TASKS = ["trace.block_samples=256", "task_rays=4096", "piece_faces=100"]


@pytest.fixture(scope="module")
def local_level(tmp_path_factory):
    from neuralao.pipeline.bakes.level import bake_level
    from neuralao.pipeline.bakes.level_settings import load_level_settings
    from neuralao.pipeline.geometry.level_gen import settings_for, write_level

    root = tmp_path_factory.mktemp("level")
    level, cfg = write_level(root / "in", settings_for("tiny", seed=2), "tiny")
    info = bake_level(level, load_level_settings(cfg, LEVEL_TASKS), root / "local")
    return level, cfg, root / "local", info


def _stage_arrays(out: Path) -> dict[str, np.ndarray]:
    """Every array of every stored stage but the timings (seconds_*), the trace's reuse count and the LOD's
    resampling blocks and their count, which are sized by the workers' threads (their values reach the
    LOD's arrays, compared here)."""
    from neuralao.runtime.foundation.io import read_npz

    arrays = {}
    for f in sorted((out / "stages").rglob("*.npz")):
        if f.parent.name == "lod_resample":
            continue
        for k, v in read_npz(f).items():
            if not k.startswith("seconds_") and k not in ("reused_tasks", "resample_tasks"):
                arrays[f"{f.relative_to(out / 'stages').with_suffix('')}/{k}"] = v
    return arrays


def _assert_same_level_bake(out: Path, local: Path, info: dict) -> None:
    files = sorted(p.relative_to(local) for p in local.rglob("*") if p.is_file())
    # Outputs and trace blocks; the bake log and the stage files record timings (compared array by array).
    files = [
        f for f in files if f.parts[0] != "stages" and f.name[:8] != "bake_log" or f.parent.name == "trace"
    ]
    assert sum(f.parent.name == "trace" for f in files) >= info["counts"]["samples"] // 256 + 1 > 2
    assert info["counts"]["pieces"] == 3 and any(f.suffix == ".glb" for f in files)
    for f in files:
        assert (out / f).read_bytes() == (local / f).read_bytes(), f
    mine, theirs = _stage_arrays(out), _stage_arrays(local)
    assert (
        mine.keys() == theirs.keys()
        and {"lod/p00000/ao_least_squares", "decorators/coefficients"} <= mine.keys()
    )
    for k, v in theirs.items():
        np.testing.assert_array_equal(mine[k], v, err_msg=k)
    assert not list((out / "stages").glob("*.parts")), "task results are removed once their stage is stored"


def _level_bake_args(level: Path, cfg: Path, out: Path, *engine_flags: str) -> list[str]:
    """`neuralao bake LEVEL --config CFG --out OUT --engine ray FLAGS` with the small tasks of LEVEL_TASKS."""
    args = ["bake", str(level), "--config", str(cfg), "--out", str(out), "--engine", "ray", *engine_flags]
    for kv in LEVEL_TASKS:
        args += ["--set", kv]
    return args


def test_two_node_level_bake_driver_killed_mid_stage_resumes_to_same_bytes(cluster, local_level, tmp_path):
    """`neuralao bake LEVEL --config ... --engine ray`: trace blocks, trees' in-place traces and fits, the
    pieces' solves, LODs and outputs, grass and shrub resampling as tasks (states rebuilt on the workers);
    the driver is killed once the solve stage has written a piece's result, and the rerun ends with the
    local library run's bytes."""
    level, cfg, local, info = local_level
    out = tmp_path / "ray"
    args = _level_bake_args(level, cfg, out, "--address", cluster)
    parts = out / "stages" / "solve"
    p = _cli(*args, start_new_session=True)
    _kill_when(p, lambda: any(parts.glob("[!.]*.npz")), timeout=120)
    assert p.returncode == -signal.SIGKILL and not (out / "level_baked.glb").exists()
    assert (out / "stages" / "trace.npz").is_file()
    kept = {f.name: f.stat().st_mtime_ns for f in (out / "stages" / "trace").glob("*.npz")}
    p = _cli(*args)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 0, err
    reused = {st["stage"] for st in json.loads((out / "bake_log.json").read_text())["stages"] if st["reused"]}
    assert "trace" in reused, reused
    assert {f.name: f.stat().st_mtime_ns for f in (out / "stages" / "trace").glob("*.npz")} == kept
    _assert_same_level_bake(out, local, info)


def test_two_node_level_bake_in_subdomains_driver_killed_mid_solve_resumes_to_same_bytes(
    cluster, local_level, tmp_path
):
    """The terrain's piece solved in subdomains, each subdomain's rows of the equations made by its worker
    (on either node) from the piece's samples there, the first buildings' piece (144 vertices in 36
    components) in groups of its components, a task each: the driver is killed once the pieces and groups
    solved beside the subdomains' assembly are written, and the rerun ends with the bytes of a local bake of
    the same settings."""
    from neuralao.pipeline.bakes.level import bake_level
    from neuralao.pipeline.bakes.level_settings import load_level_settings

    level, cfg, *_ = local_level
    split = ["trace.subdomains=4", "trace.component_vertices=100"]
    local = tmp_path / "local"
    info = bake_level(level, load_level_settings(cfg, [*LEVEL_TASKS, *split]), local)
    assert next(st for st in info["stages"] if st["stage"] == "solve")["seconds_driver"] > 0
    out = tmp_path / "ray"
    args = _level_bake_args(level, cfg, out, "--address", cluster, "--set", split[0], "--set", split[1])
    p = _cli(*args, start_new_session=True)
    _kill_when(p, lambda: any((out / "stages" / "solve").glob("[!.]*.npz")), timeout=120)
    assert p.returncode == -signal.SIGKILL and not (out / "level_baked.glb").exists()
    # killed in the subdomains' solve: the coordinated piece's result is not there yet
    here = [f.name for f in (local / "stages" / "solve").glob("*.npz") if np.load(f)["seconds_driver"] > 0]
    assert len(here) == 1 and not (out / "stages" / "solve" / here[0]).exists()
    p = _cli(*args)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 0, err
    _assert_same_level_bake(out, local, info)


def test_level_bake_on_one_actor_of_two_threads_is_byte_identical(local_level, tmp_path):
    """`--ray-threads 2`: one actor holding both CPUs of a private Ray instance (one BVH per machine)
    traces with two threads and writes the local bake's bytes."""
    level, cfg, local, info = local_level
    out = tmp_path / "threads"
    args = _level_bake_args(level, cfg, out, "--ray-threads", "2")
    p = _cli(*args)
    _, err = p.communicate(timeout=180)
    assert p.returncode == 0, err
    log = json.loads((out / "bake_log.json").read_text())
    assert log["task_threads"] == 2
    # each stage's tasks noted with their waves (map calls), the same count as the local bake's
    assert {k: len(v) for k, v in log["task_waves"].items()} == {
        k: len(v) for k, v in log["task_seconds"].items()
    }
    assert max(log["task_waves"]["samples"]) == max(info["task_waves"]["samples"]) == 1  # its two passes
    # Both BVHs built ahead by the actor (two heavy states: the gold one from the solve on), each once
    _assert_prepared(log, gold_after="trace", actors=1)
    _assert_same_level_bake(out, local, info)


def _assert_prepared(log: dict, gold_after: str, actors: int) -> None:
    """The bake ``log`` prepared the opaque BVH before the foliage and the gold one after the stage
    ``gold_after``; each of the ``actors`` built each once, ahead, for the trace and the trees."""
    order = [st["stage"] for st in log["stages"]]
    # the opaque BVH prepared as soon as the level is cut into pieces, before the foliage and the samples
    assert order.index("geometry") + 1 == order.index("prepare_opaque") < order.index("foliage")
    assert order[order.index("prepare_gold") - 1] == gold_after
    rows = {st["stage"]: st for st in log["stages"]}
    for stage in ("trace", "decorators"):
        assert rows[stage]["states_prepared"] == actors, rows[stage]
        assert rows[stage]["state_wait_seconds_max"] <= max(log["state_seconds"][stage])
    # the stages after the trace that read only the opaque BVH found it there (its gold neighbour took
    # nothing from it)
    for stage in ("small_decorators", "blend_check"):
        assert "states_built" not in rows[stage], rows[stage]


def test_level_worker_killed_mid_stage_changes_nothing(ray_engine, local_level, tmp_path):
    """An actor SIGKILLed while the trees' in-place tasks run is restarted (its state rebuilt) and the
    bake's bytes do not change."""
    from neuralao.pipeline.bakes.level import bake_level
    from neuralao.pipeline.bakes.level_settings import load_level_settings

    level, cfg, local, info = local_level
    out = tmp_path / "ray"
    kill_a_worker_mid_run(
        ray_engine,
        lambda: bake_level(level, load_level_settings(cfg, LEVEL_TASKS), out, engine=ray_engine),
        lambda: any((out / "stages" / "decorators.parts").glob("[!.]*.npz")),
        "tree task",
    )
    _assert_same_level_bake(out, local, info)


def test_level_lod_per_piece_in_tiles_is_byte_identical(ray_engine, local_level, tmp_path):
    """The LOD simplified per piece at one quadric error, the terrain in tiles (a task each, in the solve's
    first wave), with the samples' passes and the glTF's parts as tasks: the same bytes on two nodes as in
    this process."""
    from neuralao.pipeline.bakes.level import bake_level
    from neuralao.pipeline.bakes.level_settings import load_level_settings

    level, cfg, *_ = local_level
    settings = load_level_settings(cfg, [*LEVEL_TASKS, "lod.max_error=1.0", "lod.tile_faces=300"])
    info = bake_level(level, settings, tmp_path / "local")
    rows = {st["stage"]: st for st in info["stages"]}
    # the simplifications ran in the solve's first wave, beside each piece's solve: the terrain's in tiles
    assert rows["lod"]["simplify_tasks"] == 0 and rows["solve"]["tasks"] > 2 * info["counts"]["pieces"]
    log = bake_level(level, settings, tmp_path / "ray", engine=ray_engine)
    # single-CPU actors hold one BVH at a time: the gold one is prepared once the opaque one is done with
    _assert_prepared(log, gold_after="blend_check", actors=2)
    _assert_same_level_bake(tmp_path / "ray", tmp_path / "local", info)


def test_worker_killed_mid_run_changes_nothing(ray_engine, local_bake, monkeypatch):
    monkeypatch.setattr(engine_mod, "CHUNK_RAYS", 1 << 14)  # ~100 tasks, a few ms each
    scene, ao, _ = local_bake
    before = ray_engine.worker_info()
    r = kill_a_worker_mid_run(
        ray_engine,
        lambda: bake(scene, BAKE, engine=ray_engine),
        lambda: ray_engine.completed >= 3,
        "task",
        1,
        60,
    )
    np.testing.assert_array_equal(r.ao, ao)
    after = ray_engine.worker_info()
    assert after[0] == before[0], "the other actor kept running"


def _kill_when(p: subprocess.Popen, ready, timeout: float = 90) -> None:
    """SIGKILL the process group of ``p`` once ``ready()`` holds (or ``p`` has exited)."""
    deadline = time.time() + timeout
    while p.poll() is None and not ready():
        assert time.time() < deadline, "the driver made no progress"
        time.sleep(0.02)
    if p.poll() is None:
        os.killpg(p.pid, signal.SIGKILL)
    p.wait()


def test_dataset_driver_killed_resumes_to_same_bytes(cluster, local_dataset, config_file, tmp_path):
    root, manifest = local_dataset
    out = tmp_path / "ds"
    args = (
        "dataset",
        str(config_file),
        "--out",
        str(out),
        "--no-progress",
        "--engine",
        "ray",
        "--address",
        cluster,
    )
    progress = out / "progress.json"

    def two_shards() -> bool:
        try:
            return len(json.loads(progress.read_text()).get("shards", {})) >= 2
        except (OSError, ValueError):
            return False

    p = _cli(*args, start_new_session=True)
    _kill_when(p, two_shards)
    assert p.returncode == -signal.SIGKILL and not (out / "manifest.json").exists()
    p = _cli(*args)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 0, err
    assert (out / "manifest.json").read_bytes() == (root / "manifest.json").read_bytes()
    assert _shard_bytes(out, manifest) == _shard_bytes(root, manifest)
    assert not progress.exists() and not list(out.rglob("*.tmp*"))


def test_bake_driver_killed_resumes_to_same_bytes(cluster, local_bake, tmp_path):
    _, _, data = local_bake
    out = tmp_path / "spot.ply"
    chunks = tmp_path / ".spot.ply.chunks"
    flags = [f"--rays={BAKE.rays}", f"--samples-per-vertex={BAKE.samples_per_vertex}", f"--seed={BAKE.seed}"]
    args = ("bake", "spot", *flags, "--out", str(out), "--engine", "ray", "--address", cluster)
    args += ("--chunk-rays", str(1 << 12))  # small tasks: the first run is still tracing when killed
    p = _cli(*args, start_new_session=True)
    _kill_when(p, lambda: len(list(chunks.glob("[!.]*.npz"))) >= 5)  # finished results, not temporaries
    assert p.returncode == -signal.SIGKILL and not out.exists()
    kept = len(list(chunks.glob("[!.]*.npz")))
    p = _cli(*args)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 0, err
    reused = re.search(r"(\d+) of (\d+) tasks done by an earlier run", err)
    assert reused and int(reused[1]) == kept and int(reused[2]) > kept, err[-300:]
    assert out.read_bytes() == data and not chunks.exists()


def test_local_engine_never_imports_ray(tmp_path, config_file):
    code = (
        "import sys; from neuralao.pipeline.cli.main import main; "
        f"assert main(['dataset', {str(config_file)!r}, '--out', {str(tmp_path / 'ds')!r}, "
        "'--no-progress']) == 0; "
        f"assert main(['bake', 'spot', '--rays', '8', '--out', {str(tmp_path / 'a.ply')!r}]) == 0; "
        "assert 'ray' not in sys.modules, 'ray was imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--engine", "ray", "--address", "127.0.0.1:{port}"], "cannot reach a Ray cluster at 127.0.0.1:"),
        (["--engine", "ray", "--address", "nonsense"], "--address must be HOST:PORT"),
        (["--address", "127.0.0.1:6379"], "need --engine ray"),
        (["--ray-threads", "2"], "need --engine ray"),
        (["--ray-heavy-states", "2"], "need --engine ray"),
        (["--engine", "ray", "--ray-heavy-states", "0"], "--ray-heavy-states must be >= 1"),
        (["--engine", "ray", "--ray-threads", "0"], "--ray-threads must be >= 1"),
        (
            ["--engine", "ray", "--ray-workers", "0", "--address", "127.0.0.1:{port}"],
            "--ray-workers must be >= 1",
        ),
    ],
)
def test_bad_engine_flags_are_one_line_errors(flags, message, config_file, tmp_path):
    flags = [f.format(port=_free_port()) for f in flags]
    p = _cli("dataset", str(config_file), "--out", str(tmp_path / "x"), "--no-progress", *flags)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 2 and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "x" / "manifest.json").exists()


def test_worker_error_is_a_neuralao_error(ray_engine):
    """A NeuralaoError raised on a worker (here: building the Embree scene of a flat point) fails the
    run with its own one-line message, as it would locally."""
    from neuralao.pipeline.engines.engine import Task
    from neuralao.pipeline.geometry.scene import Scene
    from neuralao.pipeline.tracing.engine_labeller import labeller_context, trace_chunk
    from neuralao.pipeline.tracing.labeller import LabelSettings

    point = Scene(np.zeros((3, 3)), np.array([[0, 1, 2]]), "point")
    args = (np.zeros((1, 3)), np.ones((1, 3)), np.zeros(1, np.int64))
    tasks = [Task(labeller_context(point, LabelSettings()), trace_chunk, args)]
    for engine in (ray_engine, LocalEngine()):
        with pytest.raises(NeuralaoError, match="scene point has no extent"):
            dict(engine.map(tasks))


def test_ordered_gives_task_order_whatever_finishes_first(ray_engine):
    """``Engine.ordered``: results in task order on the cluster as here, though the first task (a large
    subdomain factor) finishes after the small ones behind it on the other worker."""
    import scipy.sparse as sp

    from neuralao.pipeline.engines.engine import Task
    from neuralao.pipeline.geometry.partitioned_solve import STATELESS, factorise

    def laplacian(n: int) -> sp.csc_matrix:
        return sp.diags([-np.ones(n - 1), 2.01 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csc")

    def solve(state, args):
        block, r = args
        return {"v": factorise(block).solve(r)}

    blocks = [laplacian(n) for n in (400_000, 5, 6, 7, 8, 9, 10)]
    rng = np.random.default_rng(3)
    rhs = [rng.uniform(size=(b.shape[0], 1)) for b in blocks]

    def tasks():
        return (Task(STATELESS, solve, (b, r)) for b, r in zip(blocks, rhs, strict=True))

    for engine in (ray_engine, LocalEngine()):
        got = [r["v"] for r in engine.ordered(tasks())]
        assert len(got) == len(blocks)
        for b, r, v in zip(blocks, rhs, got, strict=True):
            np.testing.assert_allclose(b @ v, r, rtol=1e-9, atol=1e-9)


def test_tasks_of_one_affinity_run_on_one_actor(ray_engine):
    """``Task.affinity``: the first six tasks on one actor, the next six on the other (the least-loaded
    choice without it would spread each six over both), so a cache their worker keeps (a subdomain's
    factor) is made once."""
    from neuralao.pipeline.engines.engine import Task
    from neuralao.pipeline.geometry.partitioned_solve import STATELESS

    def pid(state, args):
        return os.getpid()

    got = dict(ray_engine.map(Task(STATELESS, pid, i, affinity=i // 6) for i in range(12)))
    first, second = {got[i] for i in range(6)}, {got[i] for i in range(6, 12)}
    assert len(first) == len(second) == 1 and first != second


def test_a_prepared_state_is_built_once_per_actor_and_used(cluster, tmp_path):
    """``RayEngine.prepare``: each actor builds the context's state on a thread of its own while its other
    tasks run; the context's tasks that arrive before the build ends wait for it and get that state (one
    build per actor, noted as prepared, its first task's wait no longer than the build)."""
    import uuid

    from neuralao.pipeline.engines.engine import Context, Task
    from neuralao.pipeline.geometry.partitioned_solve import STATELESS

    builds = tmp_path / "builds"
    builds.mkdir()

    def build(payload):
        token = uuid.uuid4().hex
        (builds / f"{os.getpid()}_{token}").touch()
        time.sleep(3.0)
        return token

    def token(state, args):
        return os.getpid(), state

    def pid(state, args):
        time.sleep(0.05)
        return os.getpid()

    ctx = Context("prepared-bvh", build, None, heavy=True)
    with RayEngine(cluster, heavy_states=2) as engine:
        actors = {p for p, _ in engine.worker_info()}
        list(engine.map(Task(STATELESS, pid, i) for i in range(4)))  # the function on both actors
        engine.prepare(ctx)
        t0 = time.perf_counter()
        assert set(dict(engine.map(Task(STATELESS, pid, i) for i in range(8))).values()) == actors
        assert time.perf_counter() - t0 < 2.5  # beside the builds (about 0.2 s of their 3 s)
        got = dict(engine.map(Task(ctx, token, i) for i in range(8)))  # they arrive mid-build
        made = sorted(f.name.split("_") for f in builds.iterdir())
        assert {int(p) for p, _ in made} == actors and len(made) == len(actors)  # once per actor
        assert {(p, t) for p, t in got.values()} == {(int(p), t) for p, t in made}  # and used
        states = list(zip(engine.state_seconds, engine.state_waits, engine.state_prepared, strict=True))
        ahead = [(s, w) for s, w, prepared in states if prepared]
        assert len(ahead) == len(actors) and all(s >= 3.0 and 0.5 < w < s for s, w in ahead)
