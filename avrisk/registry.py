"""Name registries: build a component from its name in a YAML file or the CLI.

Code imports classes directly; registries serve configuration only, so that
every dependency of code shows in the import graph (``docs/design.md``).
Configuration names a component in one of two forms
(:func:`check_component_name`):

* a registered name, ``[a-z_][a-z0-9_]*`` (``"idm_mobil"``, ``"min_ttc"``): a
  factory registered with :meth:`Registry.register`;
* an import path ``package.module:attribute`` to a user's own class or
  factory, imported by :func:`load_component` only where the caller allows
  importing user code.

A component validates its own parameters (``params`` in YAML): its params
model is a Pydantic model given at registration or declared by the factory as
the class attribute ``Params``; unknown keys are refused, and a component
without a params model takes no params. The calling code's own arguments (a
network, a device) are passed to the factory as they are::

    class MyEgo:
        class Params(pydantic.BaseModel):
            gain: float = 0.5

        def __init__(self, gain: float = 0.5) -> None: ...

    get_policy("mypkg.egos:MyEgo", {"gain": 0.8}, allow_import=True)  # avrisk.agents

This module is a leaf (it imports nothing of avrisk), so the pure-data
scenario layer checks the form of names with it.
"""

from __future__ import annotations

import difflib
import importlib
import inspect
import re
from collections.abc import Callable, Mapping
from typing import Any

from pydantic import BaseModel, ValidationError

#: A name a factory may be registered under (and YAML may name).
REGISTERED_NAME = re.compile(r"[a-z_][a-z0-9_]*")

_IDENTIFIER = r"[A-Za-z_][A-Za-z0-9_]*"

#: An import path ``package.module:attribute`` to a user's class or factory.
IMPORT_PATH = re.compile(rf"{_IDENTIFIER}(?:\.{_IDENTIFIER})*:{_IDENTIFIER}")


class ComponentError(ValueError):
    """A component named in configuration cannot be built.

    Its name is malformed or unknown, importing it is refused or fails, or its
    params do not validate. The message names the component and, for params,
    each offending field.
    """


class UnknownComponentError(ComponentError, KeyError):
    """A name that is not registered (a ``KeyError`` too); lists the known ones."""

    def __str__(self) -> str:
        """The message as given (a ``KeyError`` would quote it)."""
        return str(self.args[0])


def is_import_path(name: str) -> bool:
    """Whether ``name`` has the form ``package.module:attribute``.

    Examples
    --------
    >>> is_import_path("mypkg.egos:MyEgo"), is_import_path("min_ttc")
    (True, False)
    """
    return IMPORT_PATH.fullmatch(name) is not None


def check_component_name(name: str) -> str:
    """Return ``name`` if it is a registered name or an import path in form.

    Whether a registered name is known is checked only when the component is
    built (:meth:`Registry.build`).

    Raises
    ------
    ComponentError
        Naming both allowed forms, with a corrected import path where ``name``
        looks like one written with a dot instead of the colon.

    Examples
    --------
    >>> check_component_name("mypkg.egos:MyEgo")
    'mypkg.egos:MyEgo'
    >>> check_component_name("egos.MyEgo")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    avrisk.registry.ComponentError: 'egos.MyEgo' is neither ... mean 'egos:MyEgo'?
    """
    if REGISTERED_NAME.fullmatch(name) or is_import_path(name):
        return name
    module, _, attribute = name.rpartition(".")
    suggestion = f"{module}:{attribute}"
    hint = f"; did you mean {suggestion!r}?" if is_import_path(suggestion) else ""
    raise ComponentError(
        f"{name!r} is neither a registered name (lowercase letters, digits and "
        "'_', e.g. 'idm_mobil') nor an import path 'package.module:attribute'"
        f"{hint}"
    )


def load_component(
    path: str, *, allow_import: bool, kind: str = "component"
) -> Callable[..., Any]:
    """Import the class or factory named by ``package.module:attribute``.

    Parameters
    ----------
    path : str
        The import path, e.g. ``"mypkg.egos:MyEgo"``.
    allow_import : bool
        Whether user code may be imported here: only for a spec given
        explicitly on the command line, never for one read back from a run
        directory or an output file.
    kind : str, default="component"
        What is loaded, for messages (``"ego policy"``).

    Returns
    -------
    callable
        The attribute; errors raised while its module runs propagate as they
        are.

    Raises
    ------
    ComponentError
        If ``path`` is not an import path, importing is not allowed, the
        module cannot be imported, or has no such attribute or one that cannot
        be called.
    """
    if not is_import_path(path):
        raise ComponentError(
            f"{kind} {path!r} is not an import path 'package.module:attribute'"
        )
    if not allow_import:
        raise ComponentError(
            f"the scenario names {kind} {path!r} by import path; avrisk imports "
            "user code only from a scenario given on the command line, not from "
            "one stored with earlier results: pass the scenario file (SPEC) again"
        )
    module_name, _, attribute = path.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        missing = exc.name or ""
        if module_name == missing or module_name.startswith(missing + "."):
            raise ComponentError(
                f"{kind} {path!r}: no module named {missing!r}; is its package "
                "installed, or its folder on PYTHONPATH?"
            ) from None
        raise ComponentError(f"{kind} {path!r}: importing failed: {exc}") from exc
    except ImportError as exc:
        raise ComponentError(f"{kind} {path!r}: importing failed: {exc}") from exc
    try:
        component = getattr(module, attribute)
    except AttributeError:
        public = [n for n in vars(module) if not n.startswith("_")]
        close = difflib.get_close_matches(attribute, public, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ComponentError(
            f"{kind} {path!r}: module {module_name!r} has no attribute "
            f"{attribute!r}{hint}"
        ) from None
    if not callable(component):
        raise ComponentError(
            f"{kind} {path!r} is {component!r}, not a class or factory"
        )
    return component


class Registry:
    """Factories by name for one kind of component.

    Parameters
    ----------
    kind : str
        What is registered, for messages (``"ego policy"``, ``"safety measure"``).
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        # name -> (factory, params model or None)
        self._factories: dict[str, tuple[Callable[..., Any], Any]] = {}

    def register(
        self,
        name: str,
        factory: Callable[..., Any],
        *,
        params: type[BaseModel] | None = None,
    ) -> None:
        """Make ``factory`` available as ``build(name, ...)``.

        Parameters
        ----------
        name : str
            ``[a-z_][a-z0-9_]*``, unique in this registry.
        factory : callable
            Called with the validated params and the caller's arguments as
            keywords.
        params : type of pydantic.BaseModel, optional
            The params model; default: ``factory.Params`` if it has one, else
            the component takes no params.
        """
        if not REGISTERED_NAME.fullmatch(name):
            raise ValueError(
                f"cannot register {self.kind} {name!r}: a registered name is "
                "lowercase letters, digits and '_', not starting with a digit"
            )
        if name in self._factories:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        self._factories[name] = (factory, params or _declared_params(factory))

    def names(self) -> list[str]:
        """The registered names, sorted."""
        return sorted(self._factories)

    def get(self, name: str) -> Callable[..., Any]:
        """The factory registered as ``name`` (for code that calls it itself).

        Raises
        ------
        UnknownComponentError
            If ``name`` is not registered; the message lists the known names.
        """
        if name not in self._factories:
            raise self._unknown(name)
        return self._factories[name][0]

    def _unknown(self, name: str, *, also: str = "") -> UnknownComponentError:
        """The error for an unregistered ``name``: the closest name, then all.

        ``also`` is added after the known names (another form a name may take).
        """
        close = difflib.get_close_matches(name, self.names(), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        return UnknownComponentError(
            f"unknown {self.kind} {name!r}{hint}; known: {', '.join(self.names())}"
            f"{also}"
        )

    def build(
        self,
        name: str,
        params: Mapping[str, Any] | None = None,
        /,
        *,
        allow_import: bool = False,
        **context: Any,
    ) -> Any:
        """Build the component ``name`` from its ``params``.

        Parameters
        ----------
        name : str
            A registered name, or an import path ``package.module:attribute``
            (see :func:`load_component`; its ``Params`` attribute, if any, is
            its params model).
        params : mapping, optional
            The component's parameters from configuration, validated by its
            params model and passed to the factory as keywords.
        allow_import : bool, default=False
            Whether an import path may be imported.
        **context
            What avrisk offers every component of this kind (a network, the
            number of vehicles, a device): the factory receives those its
            signature names (all of them if it takes ``**kwargs``), as they
            are; they override the params model's defaults, and a key it
            receives may not also be given in ``params``.

        Returns
        -------
        object
            What the factory returns.

        Raises
        ------
        UnknownComponentError
            If ``name`` is neither registered nor an import path; the message
            lists the known names.
        ComponentError
            If importing is refused or fails, or ``params`` do not validate;
            e.g. ``ego policy 'constant': params.accel: Input should be a
            valid number (got 'fast')``.
        """
        if is_import_path(name):
            factory = load_component(name, allow_import=allow_import, kind=self.kind)
            model = _declared_params(factory)
        elif name in self._factories:
            factory, model = self._factories[name]
        else:
            raise self._unknown(
                name, also=" (or an import path 'package.module:attribute')"
            )
        params = params or {}
        context = _accepted(factory, context)
        clash = sorted(params.keys() & context.keys())
        if clash:
            raise ComponentError(
                f"{self.kind} {name!r}: params {', '.join(clash)} are set by avrisk; "
                "remove them"
            )
        kwargs = _validate_params(f"{self.kind} {name!r}", model, params)
        return factory(**(kwargs | context))


def _accepted(factory: Callable[..., Any], context: dict[str, Any]) -> dict[str, Any]:
    """The part of ``context`` that ``factory``'s signature takes."""
    try:
        parameters = inspect.signature(factory).parameters
    except (TypeError, ValueError):  # no signature to read: offer everything
        return context
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return context
    return {k: v for k, v in context.items() if k in parameters}


def _declared_params(factory: Callable[..., Any]) -> type[BaseModel] | None:
    """The params model a factory declares as its ``Params`` attribute, if any."""
    model = getattr(factory, "Params", None)
    if model is None or (isinstance(model, type) and issubclass(model, BaseModel)):
        return model
    raise ComponentError(
        f"{factory!r} declares Params = {model!r}; a params model must be a "
        "subclass of pydantic.BaseModel"
    )


def _validate_params(
    component: str, model: type[BaseModel] | None, params: Mapping[str, Any]
) -> dict[str, Any]:
    """``params`` validated by ``model``, as keyword arguments of the factory.

    Unknown keys are refused whatever the model's ``extra`` setting, so that a
    misspelt parameter is never silently left at its default.
    """
    if model is None:
        if params:
            raise ComponentError(
                f"{component} takes no params; remove {', '.join(sorted(params))}"
            )
        return {}
    try:
        validated = model.model_validate(dict(params), extra="forbid")
    except ValidationError as exc:
        lines = []
        for err in exc.errors(include_url=False):
            where = ".".join(["params", *(str(p) for p in err["loc"])])
            msg = err["msg"].removeprefix("Value error, ")
            if err["type"] == "extra_forbidden":
                close = difflib.get_close_matches(
                    str(err["loc"][-1]), model.model_fields, n=1
                )
                hint = f"did you mean {close[0]!r}? " if close else ""
                msg = f"unknown; {hint}allowed: {', '.join(model.model_fields)}"
            elif not isinstance(err["input"], Mapping | list):
                msg = f"{msg} (got {err['input']!r})"
            lines.append(f"{component}: {where}: {msg}")
        raise ComponentError("\n".join(lines)) from None
    return dict(validated)
