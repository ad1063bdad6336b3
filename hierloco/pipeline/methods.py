"""Methods and studies: the recipes ``hierloco train`` and ``hierloco study`` run, by name.

A method is a recipe package: ``train.py`` (its ``main``, decorated with :func:`hierloco.pipeline.entry.recipe_main`),
``config.yaml`` and ``utils.py`` (its ``plan``, ``checks`` and ``manifest``), as ``hierloco/recipes/lat/``. A study
is a package with ``run.py`` (its ``main``, decorated with :func:`hierloco.pipeline.study.study_main`) and
``config.yaml``, as ``hierloco/recipes/compare/``. Every folder of :mod:`hierloco.recipes` with a ``train.py`` is a
method under its folder's name, every one with a ``run.py`` a study; an installed package adds one through the
entry-point group ``hierloco.methods`` or ``hierloco.studies``, naming the package that holds its recipe:

.. code-block:: toml

    [project.entry-points."hierloco.methods"]
    my_method = "my_package.recipes.my_method"

A recipe of the user's own is also found where the user names it on the command line (:meth:`Recipes.find`): by
a module path (``hierloco train my_package.recipes.my_method``) or a folder (``hierloco train ./my_method``).
The studies, ``hierloco evaluate`` and the tests read these registries; nothing else lists the methods. A run's
``run.json`` (a file that may have come with the run directory from someone else) names a registered method or
nothing, so reading it imports no code of its own.

Example:
    >>> METHODS.names()[:3]
    ['ik', 'lat', 'lib']
    >>> METHODS["lat"].train_script.name
    'train.py'
    >>> STUDIES["compare"].script.name
    'run.py'
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from hierloco.registry import Registry


class RecipeNotFound(ValueError):
    """A method or study that no registry, module path or folder names (one line)."""


@dataclass(frozen=True)
class Recipe:
    """A recipe: its ``name``, the Python ``package`` that holds it and its ``script`` (``train.py`` for a method,
    ``run.py`` for a study) beside ``config.yaml``."""

    name: str
    package: str
    script_name: str = "train.py"

    @property
    def folder(self) -> Path:
        spec = importlib.util.find_spec(self.package)
        if spec is None or not spec.submodule_search_locations:
            raise RecipeNotFound(f"{self.name!r}: its recipe package {self.package!r} cannot be found")
        return Path(next(iter(spec.submodule_search_locations)))

    @property
    def script(self) -> Path:
        return self.folder / self.script_name

    @property
    def train_script(self) -> Path:
        return self.script

    def utils(self) -> ModuleType:
        """A method's ``utils`` module (``plan``, ``checks``, ``manifest``, ``METHOD``)."""
        return importlib.import_module(f"{self.package}.utils")

    def main(self):
        """The recipe's entry point (``train.py``'s or ``run.py``'s ``main``)."""
        return importlib.import_module(f"{self.package}.{Path(self.script_name).stem}").main


Method = Recipe  # a method's recipe


class Recipes(Registry):
    """The recipes with a ``script`` (``train.py``: methods; ``run.py``: studies): the folders of
    :mod:`hierloco.recipes`, then the entry points of ``hierloco.<kind>s``, then those the user names
    (:meth:`find`)."""

    def __init__(self, kind: str, script: str, *, group: str, needs: tuple[str, ...] = ()):
        super().__init__(kind, group=group)
        self.script = script
        self.needs = (script, "config.yaml") + tuple(needs)

    def _is_recipe(self, folder: Path) -> bool:
        return all((folder / name).is_file() for name in self.needs)

    def _load_entry_points(self) -> None:
        if self._entry_points_loaded:
            return
        self._entry_points_loaded = True
        import hierloco.recipes

        for folder in sorted(Path(next(iter(hierloco.recipes.__path__))).iterdir()):
            if self._is_recipe(folder):
                self._entries.setdefault(folder.name, Recipe(folder.name, f"hierloco.recipes.{folder.name}",
                                                             self.script))
        for entry_point in importlib.metadata.entry_points(group=self.group):
            self._entries.setdefault(entry_point.name, Recipe(entry_point.name, entry_point.value, self.script))

    def __getitem__(self, name: str) -> Recipe:
        self._load_entry_points()
        if name not in self._entries:
            what = f"a recipe folder or a {self.group} entry point, never an import path" if ":" in str(name) \
                else f"{self.kind}s: {', '.join(self.names())}"
            raise RecipeNotFound(f"unknown {self.kind} {name!r} ({what})")
        return self._entries[name]

    def import_path(self, reference: str, *, base: type | None = None) -> Recipe:
        raise RecipeNotFound(f"{self.kind} {reference!r}: a {self.kind} is a recipe folder or a {self.group} entry "
                             "point, never an import path")

    def find(self, reference: str) -> Recipe:
        """The recipe ``reference`` names on the user's command line: a registered name, a module path
        (``my_package.recipes.my_method``, an importable package holding the recipe) or a folder holding it
        (``./my_method``: its parent goes on ``sys.path`` and the folder is imported as a package of its name). A
        module path or folder is registered under its recipe's folder name for this process. Raises
        :class:`RecipeNotFound` (one line) when nothing fits."""
        self._load_entry_points()
        if reference in self._entries:
            return self._entries[reference]
        folder = Path(reference).expanduser()
        if "/" in reference or reference.startswith(".") or folder.is_dir():
            if not folder.is_dir():
                raise RecipeNotFound(f"{self.kind} {reference!r}: no such folder")
            folder = folder.resolve()
            if not self._is_recipe(folder):
                raise RecipeNotFound(f"{self.kind} folder {reference!r} has no {' and '.join(self.needs)}")
            if not folder.name.isidentifier():
                raise RecipeNotFound(f"{self.kind} folder {reference!r}: its name must be a Python identifier (it is "
                                     "imported as a package)")
            if str(folder.parent) not in sys.path:
                sys.path.insert(0, str(folder.parent))
            package = folder.name
        elif all(part.isidentifier() for part in reference.split(".")):
            package = reference
        else:
            raise RecipeNotFound(f"unknown {self.kind} {reference!r} ({self.kind}s: {', '.join(self.names())}; or a "
                                 "module path, or a folder)")
        try:
            spec = importlib.util.find_spec(package)
        except (ImportError, ValueError):
            spec = None
        if spec is None or not spec.submodule_search_locations:
            raise RecipeNotFound(f"unknown {self.kind} {reference!r} ({self.kind}s: {', '.join(self.names())}; or a "
                                 "module path, or a folder)")
        found_folder = Path(next(iter(spec.submodule_search_locations)))
        if not self._is_recipe(found_folder):
            raise RecipeNotFound(f"{self.kind} {reference!r}: package {package} has no {' and '.join(self.needs)}")
        recipe = Recipe(found_folder.name, package, self.script)
        known = self._entries.get(recipe.name)
        if known is not None and known.package != package:
            raise RecipeNotFound(f"{self.kind} {reference!r}: its name {recipe.name!r} is taken by {known.package}")
        self._entries[recipe.name] = recipe
        return recipe


METHODS = Recipes("method", "train.py", group="hierloco.methods", needs=("utils.py",))
STUDIES = Recipes("study", "run.py", group="hierloco.studies")

__all__ = ["METHODS", "STUDIES", "Method", "Recipe", "RecipeNotFound", "Recipes"]
