"""Ctrl-C in the middle of a run, for tests of interrupting and resuming."""

from contextlib import contextmanager

from avrisk.pipeline.chunks import ChunkFiles


@contextmanager
def ctrl_c_at_chunk(monkeypatch, n):
    """Inside the block, a run stops with Ctrl-C as it records its ``n``-th chunk.

    The first ``n - 1`` chunks are recorded as usual; after the block,
    recording is as usual again (the resumed run).
    """
    record = ChunkFiles.record
    calls = []

    def stopped(self, batch):
        calls.append(1)
        if len(calls) == n:
            raise KeyboardInterrupt
        return record(self, batch)

    monkeypatch.setattr(ChunkFiles, "record", stopped)
    try:
        yield
    finally:
        monkeypatch.setattr(ChunkFiles, "record", record)


def ctrl_c_when(f, stop):
    """``f`` that raises a Ctrl-C instead of evaluating once ``stop`` says so.

    ``stop(sizes)`` sees the sizes of the batches evaluated so far (the list
    returned beside the wrapper, which a test may read afterwards). Seeded
    like ``f`` (``needs_seeds``).
    """
    sizes = []

    def interrupted(x, **seeds):
        if stop(sizes):
            raise KeyboardInterrupt
        sizes.append(len(x))
        return f(x, **seeds)

    interrupted.needs_seeds = getattr(f, "needs_seeds", False)
    return interrupted, sizes


def without_wall_time(estimate):
    """A recorded estimate (a dict) without its wall time, which no rerun repeats."""
    return {k: v for k, v in estimate.items() if k != "wall_time_s"}
