"""``dobs-envs train | evaluate | benchmark | tune``: :mod:`dobs_envs.cli` finds this package by name
(``importlib.import_module("agents.cli")``) and calls :func:`add_parser`; :mod:`~agents.cli.parser` holds the
argument parsers, :mod:`~agents.cli.commands` what each sub-command does."""
from .parser import add_parser

__all__ = ["add_parser"]
