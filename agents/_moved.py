"""Names found lazily on a package whose former module was split into its submodules (PEP 562)."""
import importlib
import sys


def moved_names(package: str, moved: dict):
    """``(__getattr__, __dir__)`` for ``package``: ``moved`` maps each former name to the submodule that defines it;
    a name is imported from there when first asked for, so importing one submodule imports no other."""

    def __getattr__(name):
        if name in moved:
            return getattr(importlib.import_module(f"{package}.{moved[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted([*vars(sys.modules[package]), *moved])

    return __getattr__, __dir__
