"""A run monitor for tests: it adds up the rollouts it is told of."""

from avrisk.pipeline.run import SilentMonitor


class Counting(SilentMonitor):
    """A monitor that adds up the rollouts it is told of, replayed and simulated."""

    def __init__(self):
        self.total, self.replayed, self.simulated = 0, 0, 0

    def start(self, total, description):
        self.total = total

    def advance(self, n, *, replayed):
        if replayed:
            self.replayed += n
        else:
            self.simulated += n
