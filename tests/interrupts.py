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
