"""Paths seen while the current command line was parsed: the inputs (``existing_file``, ``raster_file``) and the
outputs (``output_file``) of :mod:`explorer.commands._args`.  :func:`explorer.cli.main` clears them before parsing
and refuses a command whose output is one of its inputs or another of its outputs (``--out X --report X``)."""

from __future__ import annotations

INPUTS: list[str] = []
OUTPUTS: list[str] = []


def clear() -> None:
    """Forget the paths of a previous command line."""
    INPUTS.clear()
    OUTPUTS.clear()
