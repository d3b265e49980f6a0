"""Public names of a package imported on first use (PEP 562), so that importing a package
does not pay for Pinocchio, scipy or matplotlib before they are needed."""

from __future__ import annotations

import importlib


def lazy_names(package: str, where: dict[str, str]):
    """(__getattr__, __dir__) for ``package``: ``where`` maps a public name to the module
    (relative to the package) that defines it."""

    def __getattr__(name: str):
        if name in where:
            module = importlib.import_module(f"{package}.{where[name]}")
            return getattr(module, name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted(set(where) | {"__all__"})

    return __getattr__, __dir__
