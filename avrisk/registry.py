"""Name registries: build a component from its name in a YAML file or the CLI.

Code imports classes directly; registries serve configuration only (STYLE.md).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


class Registry:
    """Factories by name for one kind of component.

    Parameters
    ----------
    kind : str
        What is registered, for messages (``"policy"``, ``"safety measure"``).
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._factories: dict[str, Callable[..., Any]] = {}

    def register(self, name: str, factory: Callable[..., Any]) -> None:
        """Make ``factory(**kwargs)`` available as ``build(name, **kwargs)``."""
        if name in self._factories:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        self._factories[name] = factory

    def names(self) -> list[str]:
        """The registered names, sorted."""
        return sorted(self._factories)

    def get(self, name: str) -> Callable[..., Any]:
        """The factory registered as ``name`` (KeyError listing the known names)."""
        try:
            return self._factories[name]
        except KeyError:
            known = sorted(self._factories)
            raise KeyError(f"unknown {self.kind} {name!r}; known: {known}") from None

    def build(self, name: str, **kwargs: Any) -> Any:
        """Call the factory registered as ``name``.

        Raises
        ------
        KeyError
            If ``name`` is not registered; the message lists the known names.
        """
        return self.get(name)(**kwargs)
