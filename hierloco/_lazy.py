"""Package namespaces that load their modules on first use (PEP 562), so importing one submodule of a package does
not import all of them (a recipe plans its stages without TorchRL; ``docs/pipeline.md``)."""

from __future__ import annotations

import importlib
from typing import Callable


def lazy_names(package: str, where: dict[str, str], namespace: dict) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for ``package``: each name of ``where`` (name -> module) is imported from its
    module the first time it is asked for, then kept in ``namespace`` (the package's globals)."""

    def __getattr__(name: str):
        if name in where:
            value = getattr(importlib.import_module(where[name]), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(where))

    return __getattr__, __dir__
