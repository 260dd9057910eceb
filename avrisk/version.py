"""avrisk's version, as ``pyproject.toml`` gives it; a leaf module.

Records (run summaries, provenance, rollout tables) carry it. The recording
modules import it from here, not from the package's top level, which imports
the scenario-level API and so would close an import circle through them.
"""

__all__ = ["__version__"]

__version__ = "0.1.0"
