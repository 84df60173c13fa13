"""First complete maps for every kind of source, as a user meets them (issue 24), headless Chromium.

Each case runs the real command a user types, ``pushbroom explore <source> --port P`` (a fresh Python
process, default settings: 50,000 SCPs, 100 SCOPs, the default methods lrm, prm, mlp, nr, the sweep on),
and measures

1. **command to URL**: from starting the process until it prints the URL (Python start-up, imports,
   reading the files, the DEM, the truth);
2. **first complete maps**: from the URL until the browser (already open, as a user's is) shows a map
   title ``<method> row: RMSE`` for every checked method that can run on the sensor, and no preview,
   "waiting" or "computing" text.  mlp's training is excluded (issue 24: it shows its progress while it
   runs): its map is not waited for;
3. **command to maps**: the two together;
4. **CPU seconds** (user + system, all threads) the command used up to the URL and from the URL to the maps,
   and the browser's (Chromium's processes and Playwright's driver) from the URL to the maps: on a shared
   machine the wall times stretch with the load, these do not (much).

The machine's load average (1 min) is recorded with every figure: the machine may be shared, say so
when quoting them.  A first run after a change of the kernels compiles them (the progress line on
stderr): run ``pushbroom warmup`` first, the figures here are for a warmed set-up.

Usage::

    python benchmarks/explorer_first_maps.py --port 8130 --json benchmarks/results/explorer_first_maps.json
    python benchmarks/explorer_first_maps.py --cases dimap,rpc --repeat 2
    python benchmarks/explorer_first_maps.py --root /path/to/old/checkout   # before/after figures
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from explorer_browser import ARGS, CHROMIUM, MAPS_DONE  # one browser set-up, one "maps complete" test

ROOT = Path(__file__).resolve().parent.parent

DIMAP17 = "tests/data/rpc/PHRDIMAP_P1BP--2017030824934340CP.XML"
DEM17 = "assets/dem/MNT_P1BP--2017030824934340CP.tif"

#: name -> (source options of ``pushbroom explore``, the sensor has scanlines)
CASES: dict[str, tuple[list[str], bool]] = {
    "preset": ([], True),
    "dimap-dem": (["--dimap", DIMAP17, "--dem", DEM17, "--dem-datum", "egm96"], True),
    "dimap2018-dem": (["--dimap", "assets/rpc/PHRDIMAP_P1BP--2018122638935449CP.XML", "--dem",
                       "assets/dem/MNT_P1BP--2018122638935449CP.tif"], True),
    "dg": (["--dg", "tests/data/rpc/rpc_WV1.xml"], True),
    "isd-ctx": (["--isd", "tests/data/usgscsm/ctxLineScan.json"], True),
    "isd-orbital": (["--isd", "tests/data/usgscsm/orbitalLineScan.json"], True),
    "isd-constvel": (["--isd", "tests/data/usgscsm/constVelocityLineScan.json"], True),
    "isd-mvic": (["--isd", "tests/data/ale/nhmvic_tdi_isd.json"], True),
    "rpc": (["--rpc", "tests/data/rpc/rpc_PLEIADES.xml"], False),
    "rpc-dem": (["--rpc", DIMAP17, "--dem", DEM17, "--dem-datum", "egm96"], False),
}
DEFAULT_CASES = "preset,dimap-dem,dg,isd-ctx,isd-orbital,isd-constvel,isd-mvic,rpc,rpc-dem"
"""Every source kind (and ALE's New Horizons MVIC TDI ISD)."""


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def expected_maps(methods: list[str], has_lines: bool, root: Path) -> list[str]:
    """The methods whose map must be drawn: not mlp (its training is excluded), not a search method on a
    sensor without scanlines (shown unavailable)."""
    sys.path.insert(0, str(root))
    from explorer.methods import registry

    reg = registry()
    return [m for m in methods if m != "mlp" and (has_lines or not reg[m].needs_line_geometry)]


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system) the process has used so far (its threads included): a figure the machine's
    load does not inflate, unlike the wall times."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _browser_cpu_s(exclude: int) -> float:
    """CPU seconds (user + system) used so far by this process's descendants other than the command ``exclude``
    and its own descendants: the browser (Chromium's renderer, GPU and other processes) and Playwright's driver.
    On a machine of 2 cores the browser's drawing and the command compete for them."""
    import psutil

    total = 0.0
    skip = {exclude}
    with contextlib.suppress(psutil.Error):
        skip |= {c.pid for c in psutil.Process(exclude).children(recursive=True)}
    for child in psutil.Process().children(recursive=True):
        if child.pid in skip:
            continue
        with contextlib.suppress(psutil.Error):
            t = child.cpu_times()
            total += t.user + t.system
    return total


def _reader(stream, q: queue.Queue) -> None:
    for line in iter(stream.readline, ""):
        q.put((time.perf_counter(), line))
    q.put((time.perf_counter(), None))


def run_case(name: str, page, args: argparse.Namespace, port: int) -> dict:
    opts, has_lines = CASES[name]
    root = Path(args.root).resolve()
    methods = args.methods.split(",")
    expect = expected_maps(methods, has_lines, root)
    cmd = [*args.prefix.split(), sys.executable, "-m", "explorer", "explore", *opts, "--port", str(port),
           "--methods", args.methods]
    if not args.sweep:
        cmd.append("--no-sweep")
    env = dict(os.environ, PYTHONPATH=str(root), PYTHONUNBUFFERED="1")
    out: dict = {"case": name, "command": " ".join(cmd[1:]), "expect_maps": expect, "load_start": _load()}
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=root, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    q: queue.Queue = queue.Queue()
    threading.Thread(target=_reader, args=(proc.stdout, q), daemon=True).start()
    err: list[str] = []
    threading.Thread(target=lambda: err.extend(iter(proc.stderr.readline, "")), daemon=True).start()
    url = None
    try:
        while url is None:
            t, line = q.get(timeout=args.timeout)
            if line is None:
                raise RuntimeError(f"{name}: the command ended before printing a URL: {''.join(err)[-2000:]}")
            if "pushbroom explorer: http" in line:
                url = line.split()[2]
                t_url = t
        out["command_to_url_s"] = t_url - t0
        out["url_load"] = _load()
        cpu_url = _cpu_s(proc.pid) if not args.prefix else float("nan")
        out["cpu_to_url_s"] = cpu_url
        browser_cpu = _browser_cpu_s(proc.pid)
        page.goto(url)
        while True:
            n = page.evaluate(MAPS_DONE, [expect])
            if n is not None:
                break
            if time.perf_counter() - t_url > args.timeout:
                raise TimeoutError(f"{name}: maps not complete after {args.timeout} s")
            time.sleep(0.02)
        t_maps = time.perf_counter()
        out["cpu_url_to_maps_s"] = _cpu_s(proc.pid) - cpu_url if not args.prefix else float("nan")
        out["browser_cpu_url_to_maps_s"] = _browser_cpu_s(proc.pid) - browser_cpu
        out["first_maps_s"] = t_maps - t_url
        out["command_to_maps_s"] = t_maps - t0
        out["maps_load"] = _load()
        status = page.evaluate("() => [...document.querySelectorAll('p')].map(p => p.innerText)"
                               ".filter(t => t.startsWith('Status:')).join(' | ')")
        out["status_then"] = status
        page.goto("about:blank")
    finally:
        if proc.poll() is None:  # Ctrl-C to the command's own process group (the command, a --prefix profiler)
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    compiled = [e for e in err if "Compiling" in e or "compil" in e.lower()]
    out["compile_lines"] = len(compiled)
    print(f"  {name:>14}: command->URL {out['command_to_url_s']:.2f} s (load {out['load_start']}; CPU "
          f"{out['cpu_to_url_s']:.2f} s), URL->maps {out['first_maps_s']:.2f} s (load {out['maps_load']}; the "
          f"command's CPU {out['cpu_url_to_maps_s']:.2f} s, the browser's {out['browser_cpu_url_to_maps_s']:.2f} s), "
          f"whole {out['command_to_maps_s']:.2f} s"
          + (f"  [compiled kernels: {len(compiled)} lines]" if compiled else ""), flush=True)
    return out


def run(args: argparse.Namespace) -> dict:
    from playwright.sync_api import sync_playwright

    cases = args.cases.split(",")
    out: dict = {"root": str(Path(args.root).resolve()), "methods": args.methods, "sweep": args.sweep,
                 "machine": {"cpus": os.cpu_count(), "platform": platform.platform()}, "load_start": _load(),
                 "runs": []}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        page = browser.new_context(viewport={"width": 1400, "height": 900}).new_page()
        page.set_default_timeout(args.timeout * 1000)
        for r in range(args.repeat):
            for i, name in enumerate(cases):
                try:
                    out["runs"].append(dict(run_case(name, page, args, args.port + i % 10), repeat=r))
                except (RuntimeError, TimeoutError) as exc:
                    print(f"  {name:>14}: {exc}", flush=True)
                    out["runs"].append({"case": name, "repeat": r, "error": str(exc)})
        browser.close()
    out["load_end"] = _load()
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--root", default=str(ROOT), help="checkout whose explorer package is measured")
    p.add_argument("--cases", default=DEFAULT_CASES, help=f"comma-separated, of: {', '.join(CASES)}")
    p.add_argument("--methods", default="lrm,prm,mlp,nr", help="checked methods (default: the explorer's default)")
    p.add_argument("--no-sweep", dest="sweep", action="store_false", help="serve with --no-sweep")
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--port", type=int, default=8130, help="first port (case i uses port + i)")
    p.add_argument("--timeout", type=float, default=180.0)
    p.add_argument("--prefix", default="", help="run the command under this (e.g. 'py-spy record -o F -f raw --')")
    p.add_argument("--json", help="write the results here")
    args = p.parse_args()
    out = run(args)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
