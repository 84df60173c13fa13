"""``pushbroom explore``: serve the interactive explorer (``docs/explorer.md``)."""

from __future__ import annotations

import argparse

from explorer.commands._args import port_number


def cmd_explore(args: argparse.Namespace) -> int:
    from explorer.presets import preset_spec

    if args.preset:
        preset_spec(args.preset)  # an unknown preset is an error before the server starts
    from explorer.app import serve  # viser and plotly load only for this command

    return serve(preset=args.preset, host=args.host, port=args.port,
                 methods=args.methods.split(",") if args.methods else None)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("explore", help="serve the interactive 3D explorer (viser) and print its URL")
    p.add_argument("--preset", default=None, help="preset shown first (default: the presets file's default, WSU)")
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=port_number, default=8080, help="port (default 8080; 0 picks a free one)")
    p.add_argument("--methods", default=None,
                   help="comma-separated methods checked at start (default lrm,prm,mlp,nr where registered)")
    p.set_defaults(func=cmd_explore)
