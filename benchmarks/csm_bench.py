"""Every registered best-scanline method on a USGS CSM line-scan camera (default: the MRO CTX ISD).

Builds the project's scene from the ISD (``explorer.real.csm.scene_from_isd``, the same as
``pushbroom scene from-isd``), writes it (``--scene-out``), and runs the bench protocol of
``pushbroom bench`` on it (``explorer.bench.bench_scene``: SCPs simulated from the scene, learned
methods fitted on SCOPs) -- the bench CLI takes presets and RPC files, this script takes an ISD.

Usage::

    .venv/bin/python benchmarks/csm_bench.py [ISD] [--scps 200000] [--scops 30,100]
        [--methods all] [--layers 3] [--json out.json] [--scene-out ctx_scene.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CTX = ROOT / "tests" / "data" / "usgscsm" / "ctxLineScan.json"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("isd", nargs="?", default=str(CTX))
    ap.add_argument("--scps", type=int, default=200_000)
    ap.add_argument("--scops", default="30,100")
    ap.add_argument("--methods", default="all")
    ap.add_argument("--layers", type=int, default=1, help="height layers of the SCP/SCOP grids")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--scene-out", default=None)
    args = ap.parse_args()

    from explorer.bench import bench_scene, format_table, parse_counts, resolve_methods
    from explorer.real.csm import scene_from_isd

    scene = scene_from_isd(args.isd)
    print(f"scene {scene.name}: {scene.shape}, MPC fit to the CSM camera: {scene.metadata['csm_fit']}")
    if args.scene_out:
        scene.save(args.scene_out)
        print(f"wrote {args.scene_out}")
    result = bench_scene(scene, scene.name, resolve_methods(args.methods), parse_counts(args.scops), args.scps,
                         seed=args.seed, layers=args.layers)
    print(format_table(result.runs))
    if args.json:
        doc = {"scene": scene.name, "csm_fit": scene.metadata["csm_fit"], "runs": result.runs}
        Path(args.json).write_text(json.dumps(doc, indent=1, default=float) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
