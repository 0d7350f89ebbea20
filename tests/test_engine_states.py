"""A worker's states (the engines' state cache): a state prepared ahead is built once, on a thread of its
own, and a task that wants it before the build ends waits for that build instead of making a second; heavy
states (a level's BVHs) share a worker only as far as ``heavy_states`` allows, and one prepared but not yet
used is the last to go. The same on a Ray cluster: tests/test_ray.py."""

from __future__ import annotations

import threading
import time

import pytest

from neuralao.pipeline.engines.engine import Context, LocalEngine, Task, _StateCache


class _Builds:
    """A build that counts its calls and, if ``gate`` is given, waits for it to open."""

    def __init__(self, gate: threading.Event | None = None):
        self.calls, self.closed, self.gate = 0, [], gate

    def __call__(self, name: str):
        def build():
            self.calls += 1
            if self.gate is not None:
                assert self.gate.wait(10)
            return _State(name, self.closed)

        return build


class _State:
    def __init__(self, name: str, closed: list):
        self.name, self._closed = name, closed

    def close(self) -> None:
        self._closed.append(self.name)


def test_a_task_before_the_prepared_build_ends_waits_for_it():
    gate = threading.Event()
    builds = _Builds(gate)
    cache = _StateCache(2, heavy=2)
    assert cache.prepare("bvh", builds("bvh"), heavy=True)
    assert not cache.prepare("bvh", builds("bvh"), heavy=True)  # already under way: nothing more
    got: dict = {}

    def first_task():
        got["state"], got["built"] = cache.obtain("bvh", builds("x"))

    task = threading.Thread(target=first_task)
    task.start()
    time.sleep(0.3)
    assert task.is_alive() and builds.calls == 1  # the task waits; no second build
    gate.set()
    task.join(10)
    assert got["state"].name == "bvh" and builds.calls == 1
    built = got["built"]
    assert built.prepared and 0.25 < built.waited <= built.seconds + 0.05
    state, again = cache.obtain("bvh", builds("x"))
    assert state is got["state"] and again is None  # reported once, to its first task


def test_a_state_prepared_before_its_task_costs_that_task_no_wait():
    builds = _Builds()
    cache = _StateCache(2, heavy=2)
    cache.prepare("bvh", builds("bvh"), heavy=True)
    time.sleep(0.2)
    state, built = cache.obtain("bvh", builds("x"), heavy=True)
    assert state.name == "bvh" and builds.calls == 1 and built.prepared and built.waited < 0.05


def test_a_failed_prepared_build_fails_its_task_and_the_next_builds_again():
    def broken():
        raise ValueError("no extent")

    cache = _StateCache(2, heavy=2)
    cache.prepare("bvh", broken, heavy=True)
    with pytest.raises(ValueError, match="no extent"):
        cache.get("bvh", broken, heavy=True)
    assert cache.get("bvh", _Builds()("bvh"), heavy=True).name == "bvh"


@pytest.mark.parametrize("heavy", [1, 2])
def test_a_prepared_heavy_state_beside_the_one_in_use_as_far_as_heavy_states_allow(heavy):
    """The trees' gold BVH prepared while the opaque one is in use: with 2 heavy states both stay (the
    resampling goes on with the opaque one, built once); with 1 the opaque one goes first (closed). A light
    state beside them never evicts either; building a heavy one drops the light ones."""
    builds = _Builds()
    cache = _StateCache(1, heavy=heavy)
    cache.get("opaque", builds("opaque"), heavy=True)
    cache.get("pieces", builds("pieces"))
    cache.prepare("gold", builds("gold"), heavy=True)
    cache.get("solve", builds("solve"))  # light: evicts only the light one before it
    opaque = cache.get("opaque", builds("opaque again"), heavy=True)
    assert builds.closed[0] == "pieces"
    if heavy == 2:
        assert opaque.name == "opaque" and builds.closed == ["pieces"]
    else:  # the gold build dropped the opaque one, whose rebuild then dropped the gold one
        assert opaque.name == "opaque again" and builds.closed[1] == "opaque" and "gold" in builds.closed


def test_a_prepared_heavy_state_goes_last():
    """Room for a third heavy state (the LOD's one simplification) goes from the one a task has used, not
    from the prepared one no task has used yet."""
    builds = _Builds()
    cache = _StateCache(2, heavy=2)
    cache.get("opaque", builds("opaque"), heavy=True)
    cache.prepare("gold", builds("gold"), heavy=True)
    cache.get("opaque", builds("x"), heavy=True)  # the opaque one used again: the gold one is older
    cache.get("simplify", builds("simplify"), heavy=True)
    assert builds.closed == ["opaque"]
    assert cache.obtain("gold", builds("x"), heavy=True)[1].prepared


def test_the_local_engine_prepares_nothing():
    """Its tasks fill the cores (and a level bake holds its BVHs itself): the first task builds the state."""
    builds = _Builds()
    ctx = Context("a", lambda payload: builds("a")(), None)
    engine = LocalEngine()
    engine.prepare(ctx)
    assert builds.calls == 0
    list(engine.map([Task(ctx, lambda state, args: state.name, None)]))
    assert builds.calls == 1 and engine.state_prepared == [False]
    assert engine.state_waits == engine.state_seconds
