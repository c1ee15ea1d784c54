"""Set-up that waits for a heavy module's import: ``import ddtrack`` stays light (no JAX, Gymnasium, Matplotlib),
yet JAX still runs in float64 and Gymnasium still knows ``ddtrack/DiffDriveTracking-v0`` once they are imported
(the actions are in ``ddtrack/__init__.py``)."""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
from collections.abc import Callable, Sequence
from types import ModuleType


class _AfterImport(importlib.abc.MetaPathFinder):
    """A finder that finds nothing itself: it wraps the real loader of a watched module so that, once the module
    has run, the actions waiting for it run with the module as argument."""

    def __init__(self) -> None:
        self.waiting: dict[str, list[Callable[[ModuleType], None]]] = {}

    def find_spec(
        self, name: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if name not in self.waiting:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None:
                break
        else:
            return None
        loader = spec.loader
        if loader is None or not hasattr(loader, "exec_module"):  # a namespace package or a legacy loader
            return spec
        actions = self.waiting.pop(name)
        run_module = loader.exec_module

        def exec_module(module: ModuleType) -> None:
            run_module(module)
            for action in actions:
                action(module)

        loader.exec_module = exec_module  # type: ignore[method-assign]  # this spec's own loader: nothing shared changes
        return spec


_finder = _AfterImport()


def after_import(name: str, action: Callable[[ModuleType], None]) -> None:
    """Call ``action(module)`` now if the top-level module ``name`` is imported, else right after its import."""
    if name in sys.modules:
        action(sys.modules[name])
        return
    _finder.waiting.setdefault(name, []).append(action)
    if _finder not in sys.meta_path:
        sys.meta_path.insert(0, _finder)
