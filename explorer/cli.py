"""The ``pushbroom`` command line: thin wrappers over the library.

Each sub-command module in ``explorer.commands`` exposes ``register(subparsers)``.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys

from explorer.errors import ConvergenceError, InputError, SceneFileError
from explorer.rpc.readers import RPCFormatError

COMMAND_MODULES = (
    "explorer.commands.simulate",
    "explorer.commands.bench",
    "explorer.commands.explore",
    "explorer.commands.rpc",
    "explorer.commands.scene",
    "explorer.commands.ortho",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pushbroom", description="Best scanline search for linear pushbroom images."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMAND_MODULES:
        if importlib.util.find_spec(name) is not None:
            importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (InputError, SceneFileError, RPCFormatError, ConvergenceError, KeyError, FileNotFoundError) as exc:
        print(f"pushbroom {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
