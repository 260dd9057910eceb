"""Run directories: an estimator run against a black box, recorded and resumable."""

from avrisk.pipeline.layout import SUMMARY_SCHEMA, RunDirectoryError
from avrisk.pipeline.manifest import RecordIntegrityWarning
from avrisk.pipeline.run import RunMonitor, RunSettings, SilentMonitor, run_estimation
from avrisk.pipeline.store import RunDirectory

__all__ = [
    "SUMMARY_SCHEMA",
    "RecordIntegrityWarning",
    "RunDirectory",
    "RunDirectoryError",
    "RunMonitor",
    "RunSettings",
    "SilentMonitor",
    "run_estimation",
]
