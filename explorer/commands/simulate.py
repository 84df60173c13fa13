"""``pushbroom presets`` and ``pushbroom simulate``."""

from __future__ import annotations

import argparse
import json
import time
from typing import TYPE_CHECKING

from explorer.commands._args import (
    MAX_ATTITUDE_RATE_SCALE,
    MAX_JITTER_SCALE,
    MAX_RELIEF_M,
    existing_file,
    float_in_range,
    name_text,
    output_file,
    positive_int,
    random_seed,
)

if TYPE_CHECKING:
    from explorer.scene import Scene


FILE_SOURCES = ("scene", "isd", "dimap", "dg")
"""File options :func:`scene_from_args` reads (each where the command offers it)."""
PERTURBATIONS = {"relief": 0.0, "relief_seed": 0, "attitude_rate_scale": 1.0, "jitter_scale": 1.0}
"""Preset perturbation options and their defaults."""


def add_file_sources(p: argparse.ArgumentParser) -> None:
    """``--isd``, ``--dimap``, ``--dg``: real sensors, read by :func:`explorer.sources.load_source`."""
    p.add_argument("--isd", default=None, type=existing_file, help="a USGS CSM line-scan ISD (JSON): the camera")
    p.add_argument("--dimap", default=None, type=existing_file, help="a Pleiades DIMAP: the rigorous model")
    p.add_argument("--dg", default=None, type=existing_file, help="a DigitalGlobe / Maxar XML: the rigorous model")


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    """The options every command that builds a scene accepts."""
    p.add_argument("--preset", default=None, type=name_text,
                   help="preset id (default: the presets file's default, WSU)")
    p.add_argument("--scene", default=None, type=existing_file, help="scene JSON file (instead of --preset)")
    p.add_argument("--relief", type=float_in_range(0.0, MAX_RELIEF_M, "--relief", "m"), default=0.0,
                   help="synthetic relief amplitude, metres")
    p.add_argument("--relief-seed", type=random_seed, default=0)
    p.add_argument("--attitude-rate-scale",
                   type=float_in_range(0.0, MAX_ATTITUDE_RATE_SCALE, "--attitude-rate-scale"), default=1.0)
    p.add_argument("--jitter-scale", type=float_in_range(0.0, MAX_JITTER_SCALE, "--jitter-scale"), default=1.0)


def scene_from_args(args: argparse.Namespace, preset: str | None = None) -> Scene:
    """The scene of the command's source options, through the one loader of every command
    (:func:`explorer.sources.load_source`): a file (``--scene``, and where the command offers them ``--isd``,
    ``--dimap``, ``--dg``) as that loader reads it -- the sensor itself, the truth -- or the preset with the
    perturbation options.

    Raises
    ------
    InputError
        Two sources, or perturbation options (which shape a synthetic preset) with a file.
    """
    from explorer.errors import InputError
    from explorer.presets import build_scene
    from explorer.sources import load_source

    files = [(k, getattr(args, k)) for k in FILE_SOURCES if getattr(args, k, None) is not None]
    if len(files) > 1 or (files and (preset or getattr(args, "preset", None))):
        given = [f"--{k}" for k, _ in files] + (["--preset"] if preset or getattr(args, "preset", None) else [])
        raise InputError("give one source: " + " and ".join(given) + " were given")
    if files:
        changed = [f"--{n.replace('_', '-')}" for n, default in PERTURBATIONS.items()
                   if getattr(args, n, default) != default]
        if changed:
            raise InputError(f"{', '.join(changed)} shape(s) a synthetic preset; not applicable to --{files[0][0]}")
        kind, value = files[0]
        return load_source(kind, value).scene
    return build_scene(
        preset or args.preset,
        relief_m=args.relief,
        relief_seed=args.relief_seed,
        attitude_rate_scale=args.attitude_rate_scale,
        jitter_amplitude_scale=args.jitter_scale,
    )


def cmd_presets(args: argparse.Namespace) -> int:
    from explorer.presets import presets_table

    rows = presets_table()
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    head = (f"{'id':7} {'sensor':12} {'region':25} {'rows x cols':>12} {'GSD m':>6} {'lat':>7} {'lon':>8} "
            f"{'alt km':>6} {'roll':>5} {'pitch':>5}")
    print(head)
    print("-" * len(head))
    for r in rows:
        size = f"{r['rows']}x{r['columns']}"
        print(f"{r['id']:7} {r['sensor'][:12]:12} {r['region'][:25]:25} {size:>12} {r['gsd_m']:6.2f} "
              f"{r['lat_deg']:7.2f} {r['lon_deg']:8.2f} {r['altitude_km']:6.0f} {r['roll_deg']:5.1f} "
              f"{r['pitch_deg']:5.1f}")
    return 0


def summarize_scene(scene: Scene) -> str:
    """A few lines describing the scene's geometry."""
    along, across = scene.ground_sample_distance()
    fp = scene.footprint()
    s0 = scene.exterior.position(scene.scanline_time(0.0))
    return "\n".join([
        f"scene {scene.name}: {scene.n_rows} rows x {scene.n_columns} columns",
        f"  GSD at centre: along {along:.4f} m, across {across:.4f} m",
        f"  line period {scene.timing.line_period_s * 1e3:.6f} ms, imaging time "
        f"{scene.n_rows * scene.timing.line_period_s:.3f} s",
        f"  focal length {scene.interior.focal_length_m} m, "
        f"detector pitch {scene.interior.detector_pitch_m * 1e6:.4f} um",
        f"  perspective centre at first line (ENU m): {s0.round(1).tolist()}",
        f"  footprint corners (ENU m): {fp[:, :2].round(1).tolist()}",
        f"  terrain: {type(scene.terrain).__name__}, heights {scene.terrain.min_height:.1f} .. "
        f"{scene.terrain.max_height:.1f} m",
    ])


def cmd_simulate(args: argparse.Namespace) -> int:
    from explorer.memory import check_allocation
    from explorer.points import BYTES_PER_POINT, simulate_points

    n = int(args.n) * int(args.layers)
    check_allocation(n * BYTES_PER_POINT, f"--n {args.n} x --layers {args.layers} ({n:,} points)",
                     "lower --n or --layers")
    scene = scene_from_args(args)
    t0 = time.perf_counter()
    pts = simulate_points(scene, args.n, layers=args.layers, kind=args.kind, seed=args.seed)
    dt = time.perf_counter() - t0
    print(summarize_scene(scene))
    gr, gc, gl = pts.grid_shape
    layout = (f"grid {gr} x {gc} x {gl}" if gr else "a denser grid thinned evenly: the terrain has no height "
              "under part of the image")
    print(f"simulated {len(pts)} {args.kind.upper()}s ({layout}; asked for about {args.n} per layer) in {dt:.3f} s")
    if args.out:
        pts.save_npz(args.out, scene)
        print(f"wrote {args.out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("presets", help="list the sensor presets")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=cmd_presets)

    p = sub.add_parser("simulate", help="simulate SCOPs/SCPs on a preset or a sensor file and save them as .npz")
    add_scene_arguments(p)
    add_file_sources(p)
    p.add_argument("--n", type=positive_int, default=100, help="about this many points per layer (>= 4)")
    p.add_argument("--layers", type=positive_int, default=1, help="height layers of a 3D grid")
    p.add_argument("--kind", choices=("scop", "scp"), default="scop")
    p.add_argument("--seed", type=random_seed, default=0)
    p.add_argument("--out", default=None, type=output_file,
                   help="output .npz file, written under exactly this name (arrays row, col, ground, time, scene_json)")
    p.set_defaults(func=cmd_simulate)
