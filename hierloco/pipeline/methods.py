"""Methods: the recipes a study can run, by name.

A method is a recipe package: ``train.py`` (its ``main``, decorated with :func:`hierloco.pipeline.entry.recipe_main`),
``config.yaml`` and ``utils.py`` (its ``plan``, ``checks`` and ``manifest``), as ``recipes/lat/``. Every folder of
``recipes/`` with a ``train.py`` is a method under its folder's name; an installed package adds one through the
entry-point group ``hierloco.methods``, naming the package that holds its recipe:

.. code-block:: toml

    [project.entry-points."hierloco.methods"]
    my_method = "my_package.recipes.my_method"

The studies (``recipes/compare``, ``recipes/ablations``, ...), ``recipes/evaluate.py`` and the tests read this
registry; nothing else lists the methods. A method is never named by an import path: the ``method`` of a run's
``run.json`` (a file that may have come with the run directory from someone else) selects a registered recipe or
nothing, so reading it imports no code of its own.

Example:
    >>> METHODS.names()[:3]
    ['ik', 'lat', 'lib']
    >>> METHODS["lat"].train_script.name
    'train.py'
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from hierloco.registry import Registry


@dataclass(frozen=True)
class Method:
    """The recipe of a method: its ``name`` and the Python ``package`` that holds ``train.py``, ``utils.py`` and
    ``config.yaml``."""

    name: str
    package: str

    @property
    def folder(self) -> Path:
        spec = importlib.util.find_spec(self.package)
        if spec is None or not spec.submodule_search_locations:
            raise ValueError(f"method {self.name!r}: its recipe package {self.package!r} cannot be found")
        return Path(next(iter(spec.submodule_search_locations)))

    @property
    def train_script(self) -> Path:
        return self.folder / "train.py"

    def utils(self) -> ModuleType:
        """The recipe's ``utils`` module (``plan``, ``checks``, ``manifest``, ``METHOD``)."""
        return importlib.import_module(f"{self.package}.utils")

    def main(self):
        """The recipe's entry point (``train.py``'s ``main``)."""
        return importlib.import_module(f"{self.package}.train").main


class _Methods(Registry):
    """The method registry: the recipe folders of ``recipes/``, then the ``hierloco.methods`` entry points."""

    def _load_entry_points(self) -> None:
        if self._entry_points_loaded:
            return
        self._entry_points_loaded = True
        import recipes

        for folder in sorted(Path(next(iter(recipes.__path__))).iterdir()):
            if (folder / "train.py").is_file() and (folder / "utils.py").is_file():
                self._entries.setdefault(folder.name, Method(folder.name, f"recipes.{folder.name}"))
        for entry_point in importlib.metadata.entry_points(group=self.group):
            self._entries.setdefault(entry_point.name, Method(entry_point.name, entry_point.value))

    def __getitem__(self, name: str) -> Method:
        self._load_entry_points()
        if name not in self._entries:
            what = "a recipe folder or a hierloco.methods entry point, never an import path" if ":" in str(name) \
                else f"methods: {', '.join(self.names())}"
            raise ValueError(f"unknown method {name!r} ({what})")
        return self._entries[name]

    def import_path(self, reference: str, *, base: type | None = None) -> Method:
        raise ValueError(f"method {reference!r}: a method is a recipe folder or a hierloco.methods entry point, never "
                         "an import path")


METHODS = _Methods("method")

__all__ = ["METHODS", "Method"]
