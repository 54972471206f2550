"""Training samples prepared ahead by worker processes (``train.data_workers``).

A training step's sample is a pure function of the step (``training_data``: the pool's slots are
a function of (seed, slot, step), the draw is seeded with (seed, step, rank)), so it can be made
by any process holding its own copy of the pool. :class:`PrefetchPool` starts ``workers``
processes, each with its own pool, hands step s to worker s mod workers, and keeps ``AHEAD``
steps per worker in flight. The trainer gets exactly the groups that the in-process pool would
give (a test compares them), while the model's forward and backward pass run in the main process
beside the preparation of the next steps: the rig, operators and frontal images of new pool
identities and the S sources of each step (rendered, featurised, augmented), which a step on a
GPU would otherwise wait for.

Every worker prepares every pool identity it meets, so the workers repeat each other's pool
work; per step of its own a worker prepares about ``workers / pool_refresh`` identities. Workers
ignore SIGINT (the trainer's own handler stops the run cleanly) and are daemons: they end with
the main process. An exception in a worker is raised in the main process with the worker's
traceback; a worker that dies raises RetargetError with its exit code.
"""
from __future__ import annotations

import multiprocessing
import queue
import signal
import traceback

from .errors import RetargetError

#: Steps in flight per worker.
AHEAD = 2
#: Seconds between two checks that the workers are alive while waiting for a step.
POLL_S = 5.0


def _worker(data_cfg: dict, model_cfg, seed: int, tasks, results) -> None:
    """Worker loop: build the pool, then answer (step, rank) tasks until None."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    results.cancel_join_thread()   # exiting never waits for undelivered groups (only at close)
    import torch

    torch.set_num_threads(1)
    from .training_data import make_pool

    try:
        pool = make_pool(data_cfg, model_cfg, seed)
    except Exception:  # noqa: BLE001 - reported to the main process
        results.put(("error", None, traceback.format_exc()))
        return
    while True:
        task = tasks.get()
        if task is None:
            return
        step, rank = task
        try:
            results.put(("ok", step, pool.sample(step, rank)))
        except Exception:  # noqa: BLE001 - reported to the main process
            results.put(("error", step, traceback.format_exc()))


class PrefetchPool:
    """``sample(step, rank)`` as the in-process pool's (``training_data.make_pool``), made ahead
    by ``workers`` processes. Steps are expected in increasing order from the first one asked
    for (a resumed run starts anywhere); asking for another step starts the schedule again there.
    ``close()`` stops the workers."""

    def __init__(self, data_cfg: dict, model_cfg, seed: int, workers: int, rank: int = 0):
        if workers < 1:
            raise ValueError(f"PrefetchPool needs at least one worker, got {workers}")
        self.args = (data_cfg, model_cfg, seed)
        self.workers, self.rank = workers, rank
        self.procs: list = []     # started by the first sample() (again after close())
        self._ready: dict[int, object] = {}
        self._next = None         # the next step to hand out
        self._asked = None        # steps below this one are in flight or ready

    def _start(self) -> None:
        ctx = multiprocessing.get_context("spawn")   # a fresh interpreter: no forked GL context
        self.tasks = [ctx.Queue() for _ in range(self.workers)]
        self.results = ctx.Queue()
        self.procs = [ctx.Process(target=_worker, args=(*self.args, q, self.results), daemon=True,
                                  name=f"retarget-data-{i}")
                      for i, q in enumerate(self.tasks)]
        for p in self.procs:
            p.start()
        self._ready.clear()
        self._next = None

    def _ask(self, up_to: int) -> None:
        while self._asked < up_to:
            self.tasks[self._asked % len(self.tasks)].put((self._asked, self.rank))
            self._asked += 1

    def _receive(self) -> None:
        try:
            kind, step, payload = self.results.get(timeout=POLL_S)
        except queue.Empty:
            dead = [(p.name, p.exitcode) for p in self.procs if not p.is_alive()]
            if dead:
                raise RetargetError(f"training data worker {dead[0][0]} died (exit code "
                                    f"{dead[0][1]}); run with train.data_workers: 0 to see the "
                                    f"error in the main process") from None
            return
        if kind == "error":
            where = "building its pool" if step is None else f"preparing step {step}"
            raise RetargetError(f"a training data worker failed {where}:\n{payload}")
        if self._next is not None and step >= self._next:   # else: of an abandoned schedule
            self._ready[step] = payload

    def sample(self, step: int, rank: int = 0):
        """The ``training_data.Group`` of ``step`` (``rank`` must be the pool's)."""
        if rank != self.rank:
            raise ValueError(f"this PrefetchPool prepares rank {self.rank}'s samples, not {rank}'s")
        if not self.procs:
            self._start()
        if step != self._next:            # the first call, or a jump: start the schedule at step
            self._ready.clear()
            self._next = self._asked = step
        self._ask(step + AHEAD * len(self.tasks))
        while step not in self._ready:
            self._receive()
        self._next = step + 1
        return self._ready.pop(step)

    def close(self) -> None:
        """Stop the workers (tasks still queued are dropped); a later sample() starts new ones."""
        if not self.procs:
            return
        for q in self.tasks:
            try:
                q.put(None)
            except (OSError, ValueError):
                pass
        for p in self.procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
                p.join(timeout=5)
        for q in (*self.tasks, self.results):
            q.cancel_join_thread()   # do not block exit on undelivered groups
            q.close()
        self.procs = []
