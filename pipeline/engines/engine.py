"""Execution engines: map a function over independent tasks, in this process or on a Ray cluster.

The whole interface is :meth:`Engine.map` over :class:`Task` objects. A task names

* a :class:`Context`: what many tasks share (a scene and its label settings). A worker builds it
  once into a *state* (an Embree scene, a GL renderer) with ``context.build(context.payload)`` and
  keeps it, keyed by ``context.key`` (a content hash), for every later task of that context;
* ``fn(state, args) -> result``: a module-level function (pickled by reference), pure given its
  inputs, so where and how often it runs never changes the result.

``map`` yields ``(index, result)`` pairs, ``index`` being the task's position in the input, in
completion order; callers that write files do so themselves, on the driver, atomically, as results
arrive. ``prepare(context)`` has every worker start building a context's state in the background, ahead
of the tasks that need it (a level's BVH while the stages before its own run). Engines:

* :class:`LocalEngine` (the default): runs each task in this process, in order (or ``workers`` at once
  on threads), keeping the state of the latest context; ``prepare`` builds nothing (its tasks fill the
  cores). No Ray import.
* :class:`RayEngine`: one actor per worker (``num_cpus=1``), each caching the states of its latest
  contexts and building prepared ones on a thread of its own. Payloads travel through the object store
  (put once, fetched once per actor that needs them): workers need no shared filesystem, only the
  installed package. Results return through the object store. An actor whose process dies is restarted
  and its pending tasks are retried (``max_restarts=-1``, ``max_task_retries=-1``); a task raising
  :class:`NeuralaoError` fails the run with that message.

Big data that many tasks of one context read but the context does not own (the level's baked vertex
values, read by every resampling task) travels as :class:`Shared` inside a task's ``args`` tuple: Ray
puts it in the object store once and each actor fetches it once (the latest few are cached by key);
locally the value is passed as is.

A :class:`ResultStore` (optional) keeps finished results on disk, so a driver that is killed and
rerun skips every task it already has (the dataset stage has its own, the shards themselves).

The command line chooses an engine with ``--engine local|ray [--address ADDR] [--ray-workers N]``
(:mod:`neuralao.pipeline.cli.engine_options`).
"""

from __future__ import annotations

import collections
import hashlib
import logging
import os
import shutil
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, as_completed, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import read_npz, remove_stale_temporaries, write_npz
from neuralao.runtime.foundation.limits import release_free_memory

log = logging.getLogger(__name__)

# Tasks queued per actor: one running, one waiting, so an actor never idles while a result travels.
TASKS_PER_WORKER = 2
# Object-store refs the Ray engine keeps when no task in flight needs them, per kind (:func:`_kind`).
KEPT = {"context": 2, "payload": 4, "shared": 0}
# States an actor keeps (least recently used goes first): a level bake alternates few meshes.
STATES_PER_WORKER = 2
# Seconds to wait for each step of checking a cluster address (resolving its name, connecting, the GCS's
# answer) before calling it unreachable: ray.init itself retries for minutes, whatever answers there.
CONNECT_TIMEOUT_S = 5.0
# Ray's own limits on joining a cluster, read once when ray is imported (its defaults: 20 tries of up to
# 30 s each): set for that import only, when this process joins a cluster by address and had not imported
# ray yet (never for a private instance, whose processes inherit the environment).
RAY_JOIN_LIMITS = {"RAY_py_gcs_connect_timeout_s": "5", "RAY_NUM_REDIS_GET_RETRIES": "2"}
# What a wrong --address most often is: another port of the head node (its dashboard, a client server).
GCS_HINT = "is it the GCS port of `ray start --head`, 6379 by default?"
# Rays per point-tracing task (neuralao.pipeline.tracing.engine_labeller): ~0.1-0.2 s of tracing on one
# core, so Ray's ~3 ms per task is noise, and enough tasks that the last ones balance across workers.
CHUNK_RAYS = 1 << 20
# Environment a worker process needs to render and trace like the driver (GL platform, threads).
FORWARDED_ENV = ("PYOPENGL_PLATFORM", "OMP_NUM_THREADS", "OMP_WAIT_POLICY", "NEURALAO_MESHES")


@dataclass(frozen=True)
class Context:
    """State shared by tasks, built once per worker and cached by ``key``."""

    key: str  # content hash of everything ``build`` reads: equal keys must build equal states
    build: Callable[[Any], Any]  # module-level function: payload -> state (may have a close())
    # picklable input of ``build`` (numpy arrays, dataclasses), not a path; a tuple's top-level
    # :class:`Shared` items (a level that several contexts build from) travel once to each worker, which
    # keeps one copy for every context that holds them: ``build`` receives their values (:meth:`value`)
    payload: Any
    # A state of gigabytes (a level's BVH): a worker drops every other state before building it, so
    # two never share its memory.
    heavy: bool = False

    def value(self) -> Any:
        """The payload ``build`` receives (every top-level :class:`Shared` replaced by its value)."""
        return _unshare(self.payload)


def no_state(payload) -> None:
    """The ``build`` of a context whose tasks read no state (a solve's blocks, their arguments all)."""
    return None


@dataclass(frozen=True)
class Task:
    """One unit of work: ``fn(state of context, args)``."""

    context: Context
    fn: Callable[[Any, Any], Any]  # module-level function: (state, args) -> picklable result
    args: Any  # picklable, small (points, cameras); big shared data belongs in the context
    key: str | None = None  # result key in a ResultStore (None: never stored)
    # Tasks of the same affinity go to the same worker where an engine has several (RayEngine): a cache
    # they share there (a subdomain's factor, made by its first task) is then made once. None: any worker.
    affinity: int | None = None
    # A task of another stage's work run in this map's wave (a plan made beside the trace): the engine
    # notes it beside the task's seconds (``Engine.task_aside``), so a projection does not take it for
    # this stage's kind of work.
    aside: bool = False


@dataclass(frozen=True)
class Shared:
    """A top-level item of a task's ``args`` tuple that many tasks read (module doc), or of a context's
    payload that several contexts build from: the function receives ``value``; ``key`` is a content hash of
    it (equal keys must mean equal values)."""

    key: str
    value: Any


@dataclass(frozen=True)
class _SharedRef:
    key: str
    boxed: list  # [ObjectRef]: boxed so Ray does not fetch it for every task


def _kind(key: str) -> str:
    """The kind of an object-store key of the Ray engine: a Shared item of a task's args ("shared/...") or
    of a context's payload ("payload/..."), or a context's payload (its context's key)."""
    return key.split("/", 1)[0] if key.startswith(("shared/", "payload/")) else "context"


def _resolved(ray, args: Any, cache) -> Any:
    """``args`` with every top-level :class:`_SharedRef` replaced by its value, fetched once per ``cache``."""
    if not isinstance(args, tuple):
        return args
    return tuple(
        cache.get(a.key, lambda a=a: ray.get(a.boxed[0])) if isinstance(a, _SharedRef) else a for a in args
    )


def _unshare(args: Any) -> Any:
    """``args`` with every top-level :class:`Shared` replaced by its value (the local engine)."""
    if isinstance(args, tuple):
        return tuple(a.value if isinstance(a, Shared) else a for a in args)
    return args


def content_key(*parts: Any) -> str:
    """sha256 over numpy arrays (dtype, shape, bytes) and reprs of everything else."""
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(repr(part).encode())
        h.update(b"\0")
    return h.hexdigest()


@dataclass(frozen=True)
class _Built:
    """How a task came by its context's state, the first time it was used on its worker."""

    seconds: float  # building it (fetching the payload included), wherever it was built
    waited: float  # the task's own wait for it: ``seconds`` if the task built it, less if it was prepared
    prepared: bool  # built ahead on a thread of its own (:meth:`Engine.prepare`)


@dataclass
class _Entry:
    """A state of :class:`_StateCache`: done once ``future`` is; ``fresh`` until a task has used it."""

    future: Future
    heavy: bool
    prepared: bool
    fresh: bool = True
    seconds: float = 0.0


class _StateCache:
    """The states of the latest ``size`` light contexts and of at most ``heavy`` heavy ones (least recently
    used evicted and closed). Building a heavy state drops every light one, and heavy ones until
    ``heavy - 1`` remain, those no task has used yet (prepared ahead) last: with ``heavy`` 1 a heavy state
    never shares its worker's memory with another state.

    Thread-safe: a state is built once, by the first caller (or by :meth:`prepare`'s thread), and every
    other caller that wants it waits for that build."""

    def __init__(self, size: int, heavy: int = 1):
        self.size, self.heavy = size, heavy
        self._states: collections.OrderedDict[str, _Entry] = collections.OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: str, build: Callable[[], Any], heavy: bool = False) -> Any:
        """The state of ``key``, built by ``build()`` unless it is here or being built."""
        return self.obtain(key, build, heavy)[0]

    def obtain(self, key: str, build: Callable[[], Any], heavy: bool = False) -> tuple[Any, _Built | None]:
        """:meth:`get`, and how the state was come by the first time a task uses it (None after)."""
        t0 = time.perf_counter()
        with self._lock:
            entry = self._states.get(key)
            mine = entry is None
            if mine:
                entry = self._add(key, heavy, prepared=False)
            else:
                self._states.move_to_end(key)
        if mine:
            _build_into(entry, build)
        try:
            state = entry.future.result()  # waits for a build under way elsewhere
        except BaseException:
            with self._lock:  # a failed build is not kept: the next task of the context tries again
                if self._states.get(key) is entry:
                    del self._states[key]
            raise
        waited = entry.seconds if mine else time.perf_counter() - t0  # building it is all it waited for
        with self._lock:
            first, entry.fresh = entry.fresh, False
        return state, (_Built(entry.seconds, waited, entry.prepared) if first else None)

    def prepare(self, key: str, build: Callable[[], Any], heavy: bool = False) -> bool:
        """Start building the state of ``key`` on a thread of its own (False: it is here or being built).
        A task that wants it meanwhile waits for this build; until a task has used it, it is evicted last."""
        with self._lock:
            if key in self._states:
                return False
            entry = self._add(key, heavy, prepared=True)
        builder = threading.Thread(target=_build_into, args=(entry, build), daemon=True)
        builder.start()
        return True

    def _add(self, key: str, heavy: bool, prepared: bool) -> _Entry:
        """A new entry for ``key``, after evicting what its kind of state leaves no room for (lock held)."""
        if heavy:
            light = [k for k, e in self._states.items() if not e.heavy]
            heavies = [k for k, e in self._states.items() if e.heavy]
            used = [k for k in heavies if not self._states[k].fresh]
            order = used + [k for k in heavies if k not in used]  # least recently used first
            victims = light + order[: max(0, len(heavies) - (self.heavy - 1))]
        else:
            light = [k for k, e in self._states.items() if not e.heavy]
            victims = light[: max(0, len(light) - (self.size - 1))]
        for old in victims:
            self._close(self._states.pop(old))
        entry = self._states[key] = _Entry(Future(), heavy, prepared)
        return entry

    @staticmethod
    def _close(entry: _Entry) -> None:
        try:
            state = entry.future.result()  # one still being built is waited for, then closed
        except Exception:  # noqa: BLE001 - its build failed: nothing to close
            return
        if (close := getattr(state, "close", None)) is not None:
            close()
        del state
        release_free_memory()

    def clear(self) -> None:
        with self._lock:
            while self._states:
                self._close(self._states.popitem(last=False)[1])


def _build_into(entry: _Entry, build: Callable[[], Any]) -> None:
    """``build()`` into ``entry``'s future, its seconds noted (an error goes to whoever waits for it)."""
    t0 = time.perf_counter()
    try:
        state = build()
    except BaseException as e:  # noqa: BLE001 - handed to the waiting task, which raises it
        entry.future.set_exception(e)
        return
    entry.seconds = time.perf_counter() - t0
    entry.future.set_result(state)


class Engine:
    """Runs tasks; see the module doc. Subclasses implement :meth:`_run`."""

    name = "engine"
    workers = 1  # tasks running at once
    threads: int | None = None  # threads per task (labelling); None: what the task's settings say
    # How ``task_seconds`` are taken: "wall" (the wall clock), or "thread_cpu" (each task's thread's CPU
    # seconds: a task beside others on threads of one process waits for the interpreter lock they hold,
    # which on a worker of its own it would not)
    task_clock = "wall"
    chunk_rays: int | None = None  # rays per bake task (EngineLabeller); None: CHUNK_RAYS
    # Heavy states (:attr:`Context.heavy`) a worker may hold at once: 2 lets a state prepared ahead
    # (:meth:`prepare`) be built beside the one the tasks still use; 1 drops every other state first.
    heavy_states = 1

    def __init__(self) -> None:
        self.completed = 0  # tasks finished (or loaded from a store) by the latest map
        # Seconds of every task this engine ran (the call on its worker, without building the context's
        # state) and of every state it built, in completion order; a caller timing its stages reads and
        # clears them. Beside each state's seconds: the seconds the first task that used it waited for it
        # (its build's, or less where it was prepared ahead) and whether it was prepared.
        self.task_seconds: list[float] = []
        self.state_seconds: list[float] = []
        self.state_waits: list[float] = []
        self.state_prepared: list[bool] = []
        # The map call (numbered from 0 for this engine) each task of ``task_seconds`` ran in: a caller's
        # next map starts once it has read this one's results, so a map's tasks are a wave that the next
        # waits for (what a projection onto more machines adds up, wave by wave).
        self.task_waves: list[int] = []
        self.task_aside: list[bool] = []  # each task's ``Task.aside``
        self._waves = 0

    def _timing(self, timed: _Timed) -> Any:
        """The result inside ``timed``, its seconds noted."""
        self.task_seconds.append(timed.seconds)
        if (built := timed.built) is not None:
            self.state_seconds.append(built.seconds)
            self.state_waits.append(built.waited)
            self.state_prepared.append(built.prepared)
        return timed.result

    def prepare(self, context: Context) -> None:
        """Start building ``context``'s state on every worker in the background, while this process and
        tasks of other contexts go on; the first task of ``context`` on a worker waits for that build
        instead of making its own. Results never depend on it. The base engine does nothing."""

    @property
    def task_rays(self) -> int:
        """Rays per point-tracing task: ``chunk_rays``, or the module default ``CHUNK_RAYS``."""
        return self.chunk_rays or CHUNK_RAYS

    def map(self, tasks: Iterable[Task], store: ResultStore | None = None) -> Iterator[tuple[int, Any]]:
        """Yield ``(index, result)`` for every task, in completion order. ``tasks`` is consumed lazily
        (a few ahead of the workers), so a generator may load one scene at a time."""
        self.completed = self.reused = 0
        wave, self._waves = self._waves, self._waves + 1
        pending = self._skip_stored(tasks, store)
        for index, task, result in self._run(pending):
            if task is None:
                self.reused += 1
            else:  # _run timed it (_timing) just before yielding it
                self.task_waves.append(wave)
                self.task_aside.append(task.aside)
                if store is not None and task.key is not None:
                    store.put(task.key, result)
            self.completed += 1
            yield index, result
        if self.reused:
            log.info("%d of %d tasks done by an earlier run (%s)", self.reused, self.completed, store.folder)

    def ordered(self, tasks: Iterable[Task]) -> Iterator[Any]:
        """Every task's result in task order, each as soon as it and those before it are done (a result
        that comes early waits, the only one held)."""
        early: dict[int, Any] = {}
        following = 0
        for index, result in self.map(tasks):
            early[index] = result
            while following in early:
                yield early.pop(following)
                following += 1

    def _skip_stored(self, tasks: Iterable[Task], store: ResultStore | None):
        """(index, task) of the tasks a store lacks; stored ones come back through ``self._stored``."""
        self._stored: collections.deque[tuple[int, Any]] = collections.deque()
        for index, task in enumerate(tasks):
            if store is not None and task.key is not None and (hit := store.get(task.key)) is not None:
                self._stored.append((index, hit))
                continue
            yield index, task

    def _drain_stored(self) -> Iterator[tuple[int, Task | None, Any]]:
        while self._stored:
            index, result = self._stored.popleft()
            yield index, None, result

    def _run(self, pending: Iterator[tuple[int, Task]]) -> Iterator[tuple[int, Task | None, Any]]:
        raise NotImplementedError

    def close(self) -> None:
        """Release workers (a no-op locally)."""

    def __enter__(self) -> Engine:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class LocalEngine(Engine):
    """Every task in this process (the state of the latest context is kept).

    states  : context key -> a state this process already holds (the level baker's own labeller), used
              for tasks of that context instead of building one; never closed here.
    workers : tasks running at once, on threads of this process (their numpy, SciPy and Embree calls
              release the GIL): 1 runs them in input order. Tasks of one context share its state; a task
              of another context starts when those before it have finished (its state may replace theirs).
    threads : tracing threads per task, as ``RayEngine.threads`` (None: what the task's settings say)."""

    name = "local"

    def __init__(
        self, states: dict[str, Any] | None = None, workers: int = 1, threads: int | None = None
    ) -> None:
        super().__init__()
        for name, value in (("workers", workers), ("threads", 1 if threads is None else threads)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise NeuralaoError(f"local {name} must be a positive integer, got {value!r}")
        self.workers, self.threads = workers, threads
        # Seconds the caller's thread has spent waiting for tasks running beside it (workers > 1): what
        # a stage's wall time less its driver's own work is.
        self.waited = 0.0
        self._cache = _StateCache(1)
        self._states = dict(states or {})
        self._lock = threading.Lock()  # one state built at a time; tasks wait for the one they need

    @property
    def task_clock(self) -> str:
        """Several tasks at once, each on one thread: "thread_cpu" (:attr:`Engine.task_clock`)."""
        return "thread_cpu" if self.workers > 1 and self.threads == 1 else "wall"

    def hold(self, key: str, state: Any) -> None:
        """Use ``state`` (held by the caller) for the tasks of context ``key`` from now on."""
        self._states[key] = state

    def release(self, key: str) -> None:
        """Forget the state :meth:`hold` was given for ``key`` (the caller frees it)."""
        self._states.pop(key, None)

    def _call(self, task: Task) -> _Timed:
        ctx = task.context
        built = None
        with self._lock:
            if ctx.key in self._states:
                state = self._states[ctx.key]
            else:
                state, built = self._cache.obtain(ctx.key, lambda: ctx.build(ctx.value()), ctx.heavy)
        return _timed_call(task.fn, state, _unshare(task.args), built, self.task_clock == "thread_cpu")

    def _run(self, pending):
        if self.workers == 1:
            for index, task in pending:
                yield from self._drain_stored()
                yield index, task, self._timing(self._call(task))
            yield from self._drain_stored()
            return
        with ThreadPoolExecutor(self.workers, thread_name_prefix="neuralao-task") as pool:
            running: dict[Future, tuple[int, Task]] = {}

            def finished(block: bool):
                """The next finished task (block) or every running one, in completion order; the time
                spent waiting for them is added to ``waited``."""
                t0 = time.perf_counter()
                futures = iter(
                    wait(running, return_when=FIRST_COMPLETED)[0] if block else as_completed(running)
                )
                while (future := next(futures, None)) is not None:
                    self.waited += time.perf_counter() - t0
                    index, task = running.pop(future)
                    yield index, task, self._timing(future.result())
                    t0 = time.perf_counter()
                self.waited += time.perf_counter() - t0

            for index, task in pending:
                yield from self._drain_stored()
                key = task.context.key
                while running and (
                    len(running) >= self.workers or any(t.context.key != key for _, t in running.values())
                ):
                    yield from finished(True)
                running[pool.submit(self._call, task)] = (index, task)
            yield from finished(False)
        yield from self._drain_stored()

    def close(self) -> None:
        self._cache.clear()  # e.g. a dataset's GL renderer


@dataclass(frozen=True)
class _Timed:
    """A task's result, the seconds of its call and how its context's state was come by, if this task was
    the first to use it on its worker (None: already in use)."""

    result: Any
    seconds: float
    built: _Built | None


def _timed_call(fn, state, args, built: _Built | None = None, cpu: bool = False) -> _Timed:
    """``fn(state, args)`` and its seconds: what a projection of a run's stages reads. ``cpu``: the
    seconds are this thread's CPU time, not the wall clock's (:attr:`Engine.task_clock`)."""
    clock = time.thread_time if cpu else time.perf_counter
    t0 = clock()
    result = fn(state, args)
    return _Timed(result, clock() - t0, built)


class _Worker:
    """Body of the Ray actor (wrapped by ``ray.remote`` in :class:`RayEngine`, so importing this
    module never imports Ray): caches states by context key, runs tasks."""

    def __init__(self, env: dict[str, str], heavy_states: int = 1):
        os.environ.update(env)  # before anything imports PyOpenGL
        self._cache = _StateCache(STATES_PER_WORKER, heavy_states)
        self._shared = _StateCache(STATES_PER_WORKER)  # Shared values of tasks' args by key
        self._payload_shared = _StateCache(STATES_PER_WORKER)  # Shared values of payloads by key

    def _builder(self, boxed_payload: list, build) -> Callable[[], Any]:
        """``build`` of the payload, fetched from the object store when the state is built. The payload
        comes boxed in a list so Ray does not fetch it for every task: only the first task of a context
        on this actor (or its prepared build) pulls it; its Shared items once for every context."""

        def built():
            import ray  # optional dependency: only --engine ray imports it

            return build(_resolved(ray, ray.get(boxed_payload[0]), self._payload_shared))

        return built

    def run(self, call: tuple):
        """One task: ``call`` is (context key, boxed payload, build, fn, args, heavy), one argument so that
        Ray serialises it once (as six arguments: 0.69 ms of driver CPU a task, against 0.58)."""
        import ray  # optional dependency: only --engine ray imports it

        key, boxed_payload, build, fn, args, heavy = call
        try:
            state, built = self._cache.obtain(key, self._builder(boxed_payload, build), heavy)
            args = _resolved(ray, args, self._shared)
            result = _timed_call(fn, state, args, built)
            release_free_memory()  # the task's temporaries, so the actor's memory is the states it holds
            return result
        except NeuralaoError as e:  # travels as a plain message: the driver re-raises it
            return _Failure(str(e))

    def prepare(self, key: str, boxed_payload: list, build, heavy: bool = False) -> bool:
        """Start building the state of ``key`` on a thread of this actor (:meth:`Engine.prepare`); the
        tasks after this call run meanwhile (Ray runs an actor's calls one at a time, in order)."""
        return self._cache.prepare(key, self._builder(boxed_payload, build), heavy)

    def where(self) -> tuple[int, str]:
        import ray  # optional dependency: only --engine ray imports it

        return os.getpid(), ray.get_runtime_context().get_node_id()


@dataclass(frozen=True)
class _Failure:
    message: str


class RayEngine(Engine):
    """Tasks on Ray actors; see the module doc.

    address : "HOST:PORT" of a running cluster (``ray start --head``), "auto" for the one on this
              machine, or None to start a private local Ray instance for this run.
    workers : actors to start; None: as many as the cluster's CPUs hold.
    threads : CPUs (and tracing threads) per actor. 1: one actor per CPU; a machine's cores: one actor per
              machine, which builds a level's BVH once for all of them and holds one copy (a 10x world's
              BVH is gigabytes), while single-threaded tasks (a solve, an output piece) leave cores idle.
    heavy_states : heavy states (a level's BVHs) an actor may hold at once (:attr:`Engine.heavy_states`);
              None: 2 for an actor of several threads (alone on its machine, it holds a prepared BVH beside
              the one in use: 0.28 GiB each for Table 1's level, about 2.8 GiB each for a world ten times
              it, of a 16-core machine's memory), 1 for single-CPU actors (a machine's cores each holding a
              second BVH would double its BVH memory).
    """

    name = "ray"

    def __init__(
        self,
        address: str | None = None,
        workers: int | None = None,
        threads: int = 1,
        heavy_states: int | None = None,
    ):
        super().__init__()
        if workers is not None and workers < 1:
            raise NeuralaoError(f"--ray-workers must be >= 1, got {workers}")
        if threads < 1:
            raise NeuralaoError(f"--ray-threads must be >= 1, got {threads}")
        if heavy_states is not None and heavy_states < 1:
            raise NeuralaoError(f"--ray-heavy-states must be >= 1, got {heavy_states}")
        self.threads = threads
        self.heavy_states = heavy_states or (2 if threads > 1 else 1)
        self.address = address
        self._ray = _connect(address)
        ray = self._ray
        cpus = int(ray.cluster_resources().get("CPU", 0))
        if cpus < 1 and workers is None:
            raise NeuralaoError(f"the Ray cluster at {address or 'local'} has no CPUs")
        if threads > max(cpus, 1):
            raise NeuralaoError(f"--ray-threads {threads} is more than the {cpus} CPUs of the Ray cluster")
        if workers is not None and workers * threads > cpus:
            # Each actor holds its CPUs: more than the cluster has would wait for ever.
            raise NeuralaoError(
                f"--ray-workers {workers} x --ray-threads {threads} is more than the cluster's {cpus} CPUs"
            )
        self.workers = workers or max(1, cpus // threads)
        env = {k: os.environ[k] for k in FORWARDED_ENV if k in os.environ}
        env.setdefault("OMP_NUM_THREADS", "1")  # tracing threads are Python threads, not OpenMP's
        actor = ray.remote(num_cpus=threads, max_restarts=-1, max_task_retries=-1)(_Worker)
        self._actors = [actor.remote(env, self.heavy_states) for _ in range(self.workers)]
        # context key, "shared/" + a task's Shared item's key or "payload/" + a payload's -> ObjectRef,
        # latest used last
        self._payloads: collections.OrderedDict[str, Any] = collections.OrderedDict()

    def worker_info(self) -> list[tuple[int, str]]:
        """(process id, node id) of every actor (tests check placement and kill one mid-run)."""
        return self._ray.get([a.where.remote() for a in self._actors])

    def _put(self, key: str, value: Any, live: set[str]):
        """The object-store ref of ``value``, put once per key. Refs no task in flight needs are dropped,
        but for the latest :data:`KEPT` of each kind (contexts' payloads, the Shared items of payloads): a
        level bake's stages take turns between contexts of the same level, which would otherwise be pickled
        and put again at every turn. The Shared values of tasks' args go as soon as no task needs them."""
        if key in self._payloads:
            self._payloads.move_to_end(key)
            return self._payloads[key]
        keep = set()
        for kind, count in KEPT.items():
            same = [k for k in self._payloads if _kind(k) == kind]
            count -= _kind(key) == kind  # room for this one
            keep.update(same[len(same) - count :] if count > 0 else [])
        for old in [k for k in self._payloads if k not in live and k not in keep]:
            del self._payloads[old]  # no task in flight needs it any more
        self._payloads[key] = self._ray.put(value)
        return self._payloads[key]

    def _payload_ref(self, ctx: Context, live: set[str]):
        if ctx.key in self._payloads:
            self._payloads.move_to_end(ctx.key)
            return self._payloads[ctx.key]
        # its Shared items go once each, under their own keys (and live as long as a payload holds them)
        return self._put(ctx.key, self._remote_args(ctx.payload, live, "payload/"), live)

    def prepare(self, context: Context) -> None:
        """Every actor starts building ``context``'s state on a thread of its own (:meth:`Engine.prepare`);
        its tasks queued after this call run meanwhile, and the first of ``context`` waits for the build."""
        ref = self._payload_ref(context, set(_ref_keys(Task(context, no_state, None))))
        for a in self._actors:  # not waited for: a lost actor's restart simply builds it for its first task
            a.prepare.remote(context.key, [ref], context.build, context.heavy)

    def _remote_args(self, args: Any, live: set[str], prefix: str = "shared/") -> Any:
        if not isinstance(args, tuple):
            return args
        return tuple(
            _SharedRef(a.key, [self._put(prefix + a.key, a.value, live)]) if isinstance(a, Shared) else a
            for a in args
        )

    def _run(self, pending):
        ray = self._ray
        inflight: dict[Any, tuple[int, Task, int]] = {}  # ref -> (index, task, actor)
        load = [0] * len(self._actors)
        holds: list[set[str]] = [set() for _ in self._actors]  # context keys each actor was sent
        capacity = TASKS_PER_WORKER * len(self._actors)
        exhausted = False
        try:
            while True:
                while not exhausted and len(inflight) < capacity:
                    nxt = next(pending, None)
                    if nxt is None:
                        exhausted = True
                        break
                    index, task = nxt
                    ctx = task.context
                    # Refs still needed: every context and Shared value of the tasks in flight and this one.
                    live = {k for _, t, _ in inflight.values() for k in _ref_keys(t)} | set(_ref_keys(task))
                    ref = self._payload_ref(ctx, live)
                    args = self._remote_args(task.args, live)
                    # The task's own actor if it names one (it queues there), else one that already
                    # holds this context's state, then the least loaded.
                    if task.affinity is not None:
                        a = task.affinity % len(load)
                    else:
                        a = min(
                            range(len(load)),
                            key=lambda i: (load[i] >= TASKS_PER_WORKER, ctx.key not in holds[i], load[i]),
                        )
                    holds[a].add(ctx.key)
                    out = self._actors[a].run.remote((ctx.key, [ref], ctx.build, task.fn, args, ctx.heavy))
                    inflight[out] = (index, task, a)
                    load[a] += 1
                yield from self._drain_stored()
                if not inflight:
                    if exhausted:
                        return
                    continue
                (ready,), _ = ray.wait(list(inflight), num_returns=1)
                index, task, a = inflight.pop(ready)
                load[a] -= 1
                result = _get(ray, ready)
                if isinstance(result, _Failure):
                    raise NeuralaoError(result.message)
                yield index, task, self._timing(result)
        finally:
            for ref in inflight:  # an abandoned run (error, interrupt): drop its queued work
                try:
                    ray.cancel(ref, force=False)
                except Exception:  # noqa: BLE001 - best effort; close() kills the actors anyway
                    pass

    def close(self) -> None:
        for a in getattr(self, "_actors", []):
            self._ray.kill(a)
        self._actors = []
        self._payloads.clear()


def _ref_keys(task: Task) -> list[str]:
    """Object-store keys a task needs: its context's and its Shared values'."""
    shared = [a for a in task.args if isinstance(a, Shared)] if isinstance(task.args, tuple) else []
    return [task.context.key, *("shared/" + a.key for a in shared)]


def _get(ray, ref):
    from ray.exceptions import RayActorError, RayError, RayTaskError  # optional dependency (ray)

    try:
        return ray.get(ref)
    except RayTaskError as e:
        cause = e.cause if isinstance(getattr(e, "cause", None), Exception) else None
        raise NeuralaoError(f"a Ray task failed: {type(cause or e).__name__}: {cause or e}") from None
    except RayActorError as e:
        raise NeuralaoError(f"a Ray worker was lost and could not be restarted: {e}") from None
    except RayError as e:
        raise NeuralaoError(f"Ray failed: {type(e).__name__}: {e}") from None


def _connect(address: str | None):
    """``ray`` after ray.init (an existing connection is reused). An address where no Ray cluster answers is a
    NeuralaoError within seconds (:func:`_check_gcs`), before ray is imported, rather than Ray's minutes of
    retries; ray.init then runs under :data:`RAY_JOIN_LIMITS`. ray.init installs a SIGTERM handler of its
    own (``sys.exit(15)``): the caller's is put back, and a SIGTERM that came during ray.init is handed to
    it."""
    import importlib.util

    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        return ray
    if importlib.util.find_spec("ray") is None:  # optional dependency: only --engine ray imports it
        raise NeuralaoError("--engine ray needs the 'ray' package (pip install -e .)")
    kwargs: dict[str, Any] = {"logging_level": "ERROR", "log_to_driver": False}
    limits: dict[str, str] = {}
    if address not in (None, "auto"):
        host, _, port = address.rpartition(":")
        if not host or not port.isdigit():
            raise NeuralaoError(f"--address must be HOST:PORT, got {address!r}")
        _check_gcs(address, host.strip("[]"), int(port))
        if ray is None:
            limits = {k: v for k, v in RAY_JOIN_LIMITS.items() if k not in os.environ}
    elif address is None:  # a private instance on loopback ("local": never join a stale cluster file)
        address = "local"
        kwargs.update(include_dashboard=False, _node_ip_address="127.0.0.1")
    os.environ.update(limits)
    try:
        import ray
    finally:
        for k in limits:
            del os.environ[k]
    main = threading.current_thread() is threading.main_thread()
    handler = signal.getsignal(signal.SIGTERM) if main else None
    try:
        ray.init(address=address, **kwargs)
    except SystemExit as e:  # from Ray's handler: a SIGTERM came during ray.init
        if handler is None or e.code != signal.SIGTERM:
            raise
        signal.signal(signal.SIGTERM, handler)
        signal.raise_signal(signal.SIGTERM)  # the caller's handler acts on it (the CLI's raises)
        raise
    except (ConnectionError, RuntimeError, ValueError) as e:
        reason = str(e).strip().splitlines()[0] if str(e).strip() else ""
        reason = reason or "its GCS answers, but ray.init could not join the cluster (see Ray's lines above)"
        raise NeuralaoError(f"cannot connect to Ray at {address}: {reason}") from None
    finally:
        if handler is not None:
            signal.signal(signal.SIGTERM, handler)
    return ray


def _check_gcs(address: str, host: str, port: int) -> None:
    """NeuralaoError unless Ray's GCS answers at host:port, each step within CONNECT_TIMEOUT_S: the name
    resolves, a TCP connection opens, and the call every Ray client makes first (GetClusterId, sent as
    HTTP/2 by hand: grpcio is not one of Ray's requirements) is answered with a gRPC message. Whatever else
    is there (a web server such as Ray's dashboard, another HTTP/2 or gRPC server, one that stays silent)
    is named in the message."""
    found: list = []
    resolver = threading.Thread(target=_resolve, args=(host, port, found), daemon=True)
    resolver.start()
    resolver.join(CONNECT_TIMEOUT_S)  # a daemon thread: a resolver that hangs never holds up the exit
    unreachable = f"cannot reach a Ray cluster at {address}"
    if not found:
        raise NeuralaoError(f"{unreachable}: {host} did not resolve within {CONNECT_TIMEOUT_S:g} s")
    if isinstance(found[0], OSError):
        raise NeuralaoError(f"{unreachable}: cannot resolve {host} ({found[0].strerror or found[0]})")
    try:
        sock = _open(found[0])
    except ConnectionRefusedError:
        raise NeuralaoError(
            f"{unreachable}: nothing listens there (connection refused; {GCS_HINT})"
        ) from None
    except TimeoutError:
        raise NeuralaoError(
            f"{unreachable}: no answer within {CONNECT_TIMEOUT_S:g} s (no machine there, or a firewall drops "
            "the connection)"
        ) from None
    except OSError as e:
        raise NeuralaoError(f"{unreachable}: {e.strerror or e}") from None
    with sock:
        found_instead = _gcs_answer(sock, f"{host}:{port}")
    if found_instead:
        raise NeuralaoError(
            f"cannot connect to Ray at {address}: no Ray cluster answered there; {found_instead} ({GCS_HINT})"
        )


def _resolve(host: str, port: int, found: list) -> None:
    try:
        found.append(socket.getaddrinfo(host, port, type=socket.SOCK_STREAM))
    except OSError as e:
        found.append(e)


def _open(addresses: list) -> socket.socket:
    """A TCP connection to the first of getaddrinfo's addresses that takes one (else the last one's error)."""
    error = OSError("no address")
    for family, kind, proto, _, sockaddr in addresses:
        sock = socket.socket(family, kind, proto)
        sock.settimeout(CONNECT_TIMEOUT_S)
        try:
            sock.connect(sockaddr)
            return sock
        except OSError as e:
            sock.close()
            error = e
    raise error


def _h2_frame(kind: int, flags: int, stream: int, payload: bytes = b"") -> bytes:
    return len(payload).to_bytes(3, "big") + bytes([kind, flags]) + stream.to_bytes(4, "big") + payload


def _hpack_literal(name: str, value: str) -> bytes:
    """One header in HPACK's "literal, new name, not indexed" form without Huffman coding: a 0 byte, then
    each string after its length (a 7-bit-prefix integer)."""
    out = bytearray([0])
    for text in (name.encode(), value.encode()):
        n = len(text)
        if n < 127:
            out.append(n)
        else:
            out.append(127)
            n -= 127
            while n >= 128:
                out.append(n & 127 | 128)
                n >>= 7
            out.append(n)
        out += text
    return bytes(out)


def _gcs_answer(sock: socket.socket, authority: str) -> str | None:
    """None if what listens on sock answers GetClusterId of Ray's GCS with a gRPC message, within
    CONNECT_TIMEOUT_S; else what answered instead."""
    call = (
        (":method", "POST"),
        (":scheme", "http"),
        (":path", "/ray.rpc.NodeInfoGcsService/GetClusterId"),
        (":authority", authority),
        ("content-type", "application/grpc"),
        ("te", "trailers"),
    )
    # HTTP/2: the client preface, empty SETTINGS, the call's headers on stream 1, then the request message
    # that ends the stream (a gRPC message is a 0 byte, the protobuf's length in 4 bytes, the protobuf: none)
    request = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + _h2_frame(4, 0, 0)
    request += _h2_frame(1, 4, 1, b"".join(_hpack_literal(*h) for h in call)) + _h2_frame(0, 1, 1, bytes(5))
    deadline = time.monotonic() + CONNECT_TIMEOUT_S
    buf, framed = b"", False
    try:
        sock.sendall(request)
        while len(buf) < 1 << 20:
            sock.settimeout(max(deadline - time.monotonic(), 1e-3))
            data = sock.recv(65536)
            if not data:
                return "the server there closed the connection without answering"
            buf += data
            if not framed and len(buf) >= 9:  # an HTTP/2 server's first frame is its SETTINGS
                if buf[3] != 4 or buf[5:9] != bytes(4):
                    text = buf[:4096].lower()
                    if text.startswith(b"http/") or b"<html" in text or b"<!doctype" in text:
                        return "a web server (HTTP/1) answered instead, such as Ray's dashboard"
                    return "what answered does not speak HTTP/2, so not gRPC"
                framed = True
            while len(buf) >= 9 and len(buf) >= 9 + int.from_bytes(buf[:3], "big"):
                size, kind, flags = int.from_bytes(buf[:3], "big"), buf[3], buf[4]
                stream = int.from_bytes(buf[5:9], "big") & 0x7FFFFFFF
                payload, buf = buf[9 : 9 + size], buf[9 + size :]
                if kind == 4 and not flags & 1:  # the server's SETTINGS, acknowledged
                    sock.sendall(_h2_frame(4, 1, 0))
                elif kind == 0 and stream == 1:  # DATA: the reply, if it is a gRPC message
                    if size >= 5 and payload[0] == 0 and 5 + int.from_bytes(payload[1:5], "big") >= size:
                        return None
                    return "an HTTP/2 server answered instead, but not with a gRPC message"
                elif kind == 7 or (kind == 3 and stream == 1) or (kind == 1 and stream == 1 and flags & 1):
                    return "an HTTP/2 or gRPC server answered instead, which does not know Ray's calls"
        return "an HTTP/2 server answered instead, but not with a gRPC message"
    except TimeoutError:
        return f"the server there accepted the connection but gave no answer within {CONNECT_TIMEOUT_S:g} s"
    except OSError as e:
        return f"the server there broke the connection ({e.strerror or e})"


class ResultStore:
    """Finished task results (dicts of numpy arrays) as ``<folder>/<key>.npz``, written atomically,
    so a rerun after a killed driver skips them. :meth:`clear` removes the folder when the run is done."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(self.folder)  # a killed driver's half-written result

    def _path(self, key: str) -> Path:
        return self.folder / f"{key}.npz"

    def get(self, key: str) -> dict[str, np.ndarray] | None:
        path = self._path(key)
        if not path.is_file():
            return None
        try:
            return read_npz(path)
        except NeuralaoError:
            return None  # unreadable: recompute

    def put(self, key: str, result: dict[str, np.ndarray]) -> None:
        write_npz(self._path(key), sync=False, **result)  # an unreadable one is recomputed

    def clear(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)
