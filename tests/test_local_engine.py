"""The local engine with several workers: tasks of one context run at once on threads, a task of another
context waits for those before it, and the results are the one-at-a-time engine's."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from neuralao.pipeline.engines.engine import Context, LocalEngine, ResultStore, Task
from neuralao.runtime.foundation.errors import NeuralaoError


def _state(payload):
    return {"name": payload, "log": []}


def _together(state, args):
    """Waits for a second task at the barrier: with one worker it times out."""
    barrier, value, timeout = args
    barrier.wait(timeout=timeout)
    return state["name"], value * 2


def _square(state, value):
    return {"v": np.array(value * value)}


def _logged(state, args):
    log, name, value = args
    log.append(("start", name, time.perf_counter()))
    time.sleep(0.05)
    log.append(("end", name, time.perf_counter()))
    return name, np.sqrt(value)


def test_two_workers_run_two_tasks_of_a_context_at_once():
    ctx = Context("a", _state, "a")
    barrier = threading.Barrier(2)
    tasks = [Task(ctx, _together, (barrier, v, 20.0)) for v in range(6)]
    got = dict(LocalEngine(workers=2).map(tasks))
    assert got == {i: ("a", 2 * i) for i in range(6)}
    with pytest.raises(threading.BrokenBarrierError):  # one at a time: nobody meets the first task
        lone = [Task(ctx, _together, (threading.Barrier(2), v, 0.5)) for v in range(2)]
        list(LocalEngine(workers=1).map(lone))


def test_a_new_context_waits_for_the_tasks_before_it_and_results_match_one_worker():
    log: list = []
    a, b = Context("a", _state, "a"), Context("b", _state, "b")
    tasks = [Task(a, _logged, (log, "a", v)) for v in range(5)] + [
        Task(b, _logged, (log, "b", v)) for v in range(5)
    ]
    two = LocalEngine(workers=2)
    got = dict(two.map(tasks))
    last_a = max(t for kind, name, t in log if kind == "end" and name == "a")
    first_b = min(t for kind, name, t in log if kind == "start" and name == "b")
    assert first_b >= last_a
    assert len(two.task_seconds) == 10 and two.completed == 10
    # ten tasks of 50 ms, two at a time: the caller waited for them at least 250 ms, and not much more
    assert 0.25 <= two.waited <= sum(two.task_seconds) + 0.5
    one = dict(LocalEngine(workers=1).map(tasks))
    assert got.keys() == one.keys() and all(got[k][0] == one[k][0] and got[k][1] == one[k][1] for k in got)
    assert list(two.ordered(tasks)) == [one[i] for i in range(10)]


@pytest.mark.parametrize("field", ["workers", "threads"])
@pytest.mark.parametrize("value", [0, -1, 1.5, True])
def test_bad_worker_and_thread_counts_are_errors(field, value):
    with pytest.raises(NeuralaoError, match=field):
        LocalEngine(**{field: value})


def test_each_task_is_noted_with_its_map_call(tmp_path):
    """An engine notes beside every task's seconds the map call (wave) it ran in, counted from 0; a task
    whose result a store held runs in none."""
    ctx = Context("a", _state, "a")
    for workers in (1, 2):
        engine = LocalEngine(workers=workers)
        store = ResultStore(tmp_path / f"store{workers}")
        list(engine.map([Task(ctx, _square, v) for v in range(3)]))
        list(engine.map([Task(ctx, _square, v, key=f"k{v}") for v in range(2)], store))
        list(engine.map([Task(ctx, _square, v, key=f"k{v}") for v in range(4)], store))  # two stored
        assert engine.task_waves == [0, 0, 0, 1, 1, 2, 2]
        assert len(engine.task_seconds) == len(engine.task_waves)


def _sleep(state, seconds):
    time.sleep(seconds)
    return {"slept": np.array(seconds)}


def test_tasks_beside_each_other_are_timed_by_their_threads_cpu():
    """Several tasks at once on one thread each: a task's seconds are its thread's CPU time (time spent
    waiting, for the interpreter lock the others hold or here asleep, is not its work); one at a time, the
    wall clock's."""
    ctx = Context("a", _state, "a")
    tasks = [Task(ctx, _sleep, 0.2) for _ in range(2)]
    beside = LocalEngine(workers=2, threads=1)
    list(beside.map(tasks))
    alone = LocalEngine(workers=1)
    list(alone.map(tasks))
    assert max(beside.task_seconds) < 0.05 and min(alone.task_seconds) >= 0.2
