"""The registry (:mod:`hierloco.registry`): names, import paths given by the user, and what ``names()`` lists."""
import pytest

from hierloco.registry import Registry


class Base:
    def __init__(self, *, width: int = 3):
        self.width = width


def make_registry():
    registry = Registry("part", group="hierloco.test-parts-none")
    registry.register("plain")(type("Plain", (Base,), {}))
    return registry


def test_an_import_path_is_looked_up_but_not_listed_as_a_name():
    registry = make_registry()
    path = f"{__name__}:Base"
    with pytest.raises(ValueError, match="import path that was not given"):
        registry[path]
    assert registry.import_path(path, base=Base) is Base
    assert registry[path] is Base and path in registry
    assert registry.names() == ["plain"]  # other tests' import paths never show in a listing
    assert registry.options(path) == {"width": 3}
    registry.unregister(path)
    assert path not in registry


def test_an_import_path_to_a_registered_part_is_another_name_of_it():
    registry = make_registry()
    plain = registry["plain"]
    globals()["Plain"] = plain
    try:
        assert registry.import_path(f"{__name__}:Plain") is plain
        assert plain.registry_name == "plain"
    finally:
        del globals()["Plain"]


def test_an_import_path_that_is_not_a_subclass_is_refused_before_anything_is_registered():
    registry = make_registry()
    with pytest.raises(ValueError, match="not a Registry subclass"):
        registry.import_path(f"{__name__}:Base", base=Registry)
    assert f"{__name__}:Base" not in registry
