"""Wiring: the only layer that joins the estimation engine and the simulator."""

from avrisk.pipeline.run import RunMonitor, RunSettings, SilentMonitor, run_estimation
from avrisk.pipeline.store import SUMMARY_SCHEMA, RunDirectory, RunDirectoryError

__all__ = [
    "SUMMARY_SCHEMA",
    "RunDirectory",
    "RunDirectoryError",
    "RunMonitor",
    "RunSettings",
    "SilentMonitor",
    "run_estimation",
]
