"""Extension points: one registry per kind of part (dynamics model, planner, task, low level, method).

A part is one class that declares its name with the registry's decorator; its *options* are the keyword arguments
of its constructor that have defaults (minus the registry's ``context``: what the pipeline passes itself, such as
the world model a planner plans on, or its seed). Configs select a part by name (``planner.name=cem``,
``dynamics.model=ensemble``, a task's ``task:`` field); the config checks, the trained-run loader, the exporter and
the studies all read the registry, so a new part is known everywhere once its class is registered. Installed
packages add parts through the entry-point group ``hierloco.<kind>s`` (e.g. ``hierloco.planners``); an entry point
names the class, and its name must be the class's registered name.

A part that is not installed can be named by its *import path* ``package.module:Class``, but only where the user
names it: :meth:`Registry.import_path` imports it, checks that it is a class (of a given base) and registers it under
that path. The config checks call it for what the user's command line and config name
(:func:`hierloco.pipeline.config.check_import_paths`); looking a name up (``registry[name]``) never imports, so an
import path read from a file received with a run directory (its ``run.json``, its ``config.yaml``, a checkpoint, a
record) names code nobody vouched for and is refused (``docs/pipeline.md``, "Received run directories are data").

.. code-block:: toml

    [project.entry-points."hierloco.planners"]
    my_planner = "my_package.planning:MyPlanner"

Example:
    >>> SHAPES = Registry("shape", context=("scale",))
    >>> @SHAPES.register("square")
    ... class Square:
    ...     def __init__(self, scale=1.0, *, side: float = 2.0):
    ...         self.area = (scale * side) ** 2
    >>> SHAPES.names(), SHAPES.options("square")
    (['square'], {'side': 2.0})
    >>> SHAPES.build("square", scale=1.0, side=3.0).area
    9.0
    >>> SHAPES.check_options("square", {"sides": 4})
    ["shape 'square' has no option 'sides' (its options: side)"]
"""

from __future__ import annotations

import importlib
import importlib.metadata
import inspect
from typing import Any, Callable, Generic, Iterable, Mapping, TypeVar

T = TypeVar("T")


def is_import_path(name: Any) -> bool:
    """Whether ``name`` is an import path (``package.module:Class``) rather than a registered name."""
    return isinstance(name, str) and ":" in name


class Registry(Generic[T]):
    """Names -> classes (or factories) of one kind of part.

    Args:
        kind: what the parts are, in messages ("planner").
        group: the entry-point group installed packages add parts through (default ``hierloco.<kind>s``).
        context: constructor arguments the pipeline supplies itself; they are not options.
        modules: modules that register built-in parts, imported on the first lookup (so that reading the registry
            does not import every part up front).
    """

    def __init__(self, kind: str, *, group: str | None = None, context: Iterable[str] = (),
                 modules: Iterable[str] = ()):
        self.kind = kind
        self.group = group or f"hierloco.{kind}s"
        self.context = tuple(context)
        self.modules = tuple(modules)
        self._entries: dict[str, T] = {}
        self._imported: dict[str, T] = {}  # import paths the user gave: other names of parts, not listed by names()
        self._entry_points_loaded = False

    # ------------------------------------------------------------------------------------------------ adding
    def register(self, name: str) -> Callable[[T], T]:
        """Class decorator: registers the class under ``name`` and sets its ``registry_name``. Registering another
        class under a taken name raises ``ValueError``; registering the same class again is a no-op."""

        def add(entry: T) -> T:
            known = self._entries.get(name)
            if known is not None and known is not entry and _qualname(known) != _qualname(entry):
                raise ValueError(f"{self.kind} {name!r} is already registered ({_qualname(known)})")
            self._entries[name] = entry
            try:
                entry.registry_name = name  # type: ignore[attr-defined]
            except (AttributeError, TypeError):  # a function: its name is the key
                pass
            return entry

        return add

    def unregister(self, name: str) -> None:
        """Removes ``name`` (tests that register a part of their own remove it afterwards)."""
        self._entries.pop(name, None)
        self._imported.pop(name, None)

    # ------------------------------------------------------------------------------------------------ reading
    def _load_entry_points(self) -> None:
        if self._entry_points_loaded:
            return
        self._entry_points_loaded = True
        for module in self.modules:
            importlib.import_module(module)
        for entry_point in importlib.metadata.entry_points(group=self.group):
            if entry_point.name in self._entries:
                continue
            try:
                target = entry_point.load()
            except Exception as error:  # a user's package: report what it raised, naming the entry point
                raise ValueError(f"{self.kind} {entry_point.name!r} (entry point {entry_point.value!r} of group "
                                 f"{self.group!r}): loading it failed: {type(error).__name__}: {error}") from error
            registered = getattr(target, "registry_name", entry_point.name)
            if registered != entry_point.name:
                raise ValueError(f"entry point {entry_point.name!r} of group {self.group!r} names a {self.kind} "
                                 f"registered as {registered!r}: the names must agree")
            self.register(entry_point.name)(target)

    def names(self) -> list[str]:
        """Every registered name (built-in, registered in this process, or from installed packages), sorted; import
        paths given in this process (:meth:`import_path`) are looked up too but not listed."""
        self._load_entry_points()
        return sorted(self._entries)

    def __contains__(self, name: object) -> bool:
        self._load_entry_points()
        return name in self._entries or name in self._imported

    def __iter__(self):
        return iter(self.names())

    def __getitem__(self, name: str) -> T:
        """The part registered as ``name`` (or imported by :meth:`import_path` under that import path). Never
        imports anything: an import path nobody imported raises ``ValueError`` saying so."""
        self._load_entry_points()
        if name in self._entries:
            return self._entries[name]
        if name in self._imported:
            return self._imported[name]
        if is_import_path(name):
            raise ValueError(f"{self.kind} {name!r} is an import path that was not given on the command line or in "
                             f"the config: hierloco imports code only where you name it yourself ({self.kind}s: "
                             f"{', '.join(self.names())})")
        raise ValueError(f"unknown {self.kind} {name!r} ({self.kind}s: {', '.join(self.names())})")

    def import_path(self, reference: str, *, base: type | None = None) -> T:
        """The part named by the import path ``package.module:Class``, imported now and registered under
        ``reference`` (its module may register it under a name of its own too). Only for a path the user gave (their
        command line, their config, their code), never for one read from a received file.

        Raises ``ValueError`` in one line when it cannot be imported, or names something that is not a class (a
        subclass of ``base``, when given), before anything is registered."""
        self._load_entry_points()
        if reference in self._entries or reference in self._imported:
            target = self._entries.get(reference, self._imported.get(reference))
        else:
            module, _, attribute = reference.partition(":")
            try:
                target = getattr(importlib.import_module(module), attribute)
            except Exception as error:  # noqa: BLE001  (the user's module: what it raised, in one line)
                raise ValueError(f"{self.kind} {reference!r}: cannot import it ({type(error).__name__}: "
                                 f"{' '.join(str(error).split())})") from None
        if not inspect.isclass(target) or (base is not None and not issubclass(target, base)):
            what = f"the class {_qualname(target)}" if inspect.isclass(target) else \
                f"{'a function' if callable(target) else 'a ' + type(target).__name__} ({_qualname(target)})"
            wanted = f"a {base.__name__} subclass" if base is not None else "a class"
            raise ValueError(f"{self.kind} {reference!r} is {what}, not {wanted}")
        if reference not in self._entries and reference not in self._imported:
            if self._entries.get(getattr(target, "registry_name", None)) is not target:
                try:
                    target.registry_name = reference  # a part nobody registered: the path is its name
                except (AttributeError, TypeError):
                    pass
            self._imported[reference] = target
        return target

    def options(self, name: str) -> dict[str, Any]:
        """The options of ``name`` and their defaults: its constructor's keyword arguments with defaults, minus the
        registry's context."""
        entry = self[name]
        target = entry.__init__ if inspect.isclass(entry) else entry
        options = {}
        for parameter in inspect.signature(target).parameters.values():
            if parameter.name in self.context or parameter.name == "self":
                continue
            if parameter.kind in (parameter.VAR_KEYWORD, parameter.VAR_POSITIONAL):
                continue
            if parameter.default is not parameter.empty:
                options[parameter.name] = parameter.default
        return options

    def check_options(self, name: str, given: Mapping[str, Any]) -> list[str]:
        """Problems with ``given`` options of ``name``: unknown ones, each naming the valid ones, and values whose
        type differs from the default's (a number where a number is expected, ...). Empty when all is well."""
        try:
            options = self.options(name)
        except ValueError as error:
            return [str(error)]
        problems = []
        for key, value in given.items():
            if key not in options:
                problems.append(f"{self.kind} {name!r} has no option {key!r} (its options: "
                                f"{', '.join(options) or 'none'})")
            elif not _same_kind(options[key], value):
                problems.append(f"{self.kind} {name!r}: option {key}={value!r} should be like its default "
                                f"{options[key]!r}")
        return problems

    def select(self, name: str, values: Mapping[str, Any]) -> dict[str, Any]:
        """The options of ``name`` found in ``values`` (a config section shared by every part of this kind: the
        options of other parts are left out)."""
        options = self.options(name)
        return {key: value for key, value in values.items() if key in options}

    def build(self, name: str, /, *args, **kwargs) -> Any:
        """``self[name](*args, **kwargs)``: context first, then options."""
        return self[name](*args, **kwargs)


def _qualname(entry) -> str:
    return f"{getattr(entry, '__module__', '?')}.{getattr(entry, '__qualname__', repr(entry))}"


def _same_kind(default: Any, value: Any) -> bool:
    """Whether ``value`` may stand for an option whose default is ``default``: numbers for numbers (an int for a
    float), booleans for booleans, strings for strings; anything for ``None`` and containers."""
    if default is None or value is None or isinstance(default, (list, tuple, dict)):
        return True
    if isinstance(default, bool) or isinstance(value, bool):
        return isinstance(default, bool) and isinstance(value, bool)
    if isinstance(default, (int, float)):
        return isinstance(value, (int, float)) and (isinstance(default, float) or isinstance(value, int))
    return isinstance(value, type(default))


def without_defaults(values: Mapping[str, Any], defaults: Mapping[str, Any], keep: Iterable[str] = ()) -> dict:
    """``values`` without the entries equal to their default, except those in ``keep``.

    A stage key holds what changes its artifact. An option added later, at a default that reproduces what was done
    before, must not change the keys of finished runs and committed records; so keys hold the options that were
    always keyed (``keep``) and any other option only when it differs from its default.

    Example:
        >>> without_defaults({"hidden": 512, "model": "mlp", "members": 5}, {"model": "mlp", "members": 5},
        ...                  keep=("hidden",))
        {'hidden': 512}
    """
    keep = set(keep)
    return {key: value for key, value in values.items()
            if key in keep or key not in defaults or value != defaults[key]}


__all__ = ["Registry", "is_import_path", "without_defaults"]
