"""The command line's parser is light: building it (``pushbroom --help``) imports no heavy library."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("torch", "numba", "scipy", "viser", "plotly", "rasterio", "dask", "pyproj", "explorer.methods",
         "explorer.scene", "explorer.app")


def test_building_the_parser_imports_no_heavy_module() -> None:
    code = (
        "import sys, json\n"
        "from explorer.cli import build_parser\n"
        "p = build_parser()\n"
        "for argv in (['ortho', '--help'], ['scene', 'from-rpc', '--help'], ['bench', '--help']):\n"
        "    try:\n"
        "        p.parse_args(argv)\n"
        "    except SystemExit:\n"
        "        pass\n"
        f"print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r} or m in {HEAVY!r})))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = json.loads(proc.stdout.strip().splitlines()[-1])
    assert loaded == [], f"building the parser imported {loaded}"


def test_python_dash_m_explorer_is_the_cli() -> None:
    proc = subprocess.run([sys.executable, "-m", "explorer", "presets", "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert {"WSU", "agile"} <= {r["id"] for r in json.loads(proc.stdout)}
