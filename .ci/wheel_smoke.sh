#!/usr/bin/env bash
# What a user of the wheel gets: build it, install it into a fresh venv OUTSIDE the checkout, run the CLI there.
set -euo pipefail
cd "$(dirname "$0")/.."
top=$(pwd)
work=$(mktemp -d /tmp/pushbroom-wheel.XXXXXX)
trap 'rm -rf "$work"' EXIT
.venv/bin/python -m pip wheel -q --no-deps --no-build-isolation . -w "$work/dist" 2>&1 | grep -v "^WARNING: Location" || true
rm -rf build
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install -q --upgrade pip 2>&1 | grep -v "^WARNING: Location" || true
"$work/venv/bin/pip" install -q "torch==2.13.0" 2>&1 | grep -v "^WARNING: Location" || true
constraints=(); [ -f requirements/lock.txt ] && constraints=(-c "$top/requirements/lock.txt")
"$work/venv/bin/pip" install -q "${constraints[@]}" "$work"/dist/*.whl 2>&1 | grep -v "^WARNING: Location" || true
cp tests/data/rpc/rpc_WV2.xml "$work/rpc_WV2.xml"
cd "$work"
mkdir run && cd run
pb="$work/venv/bin/pushbroom"
echo "[wheel] installed at $("$work/venv/bin/python" -c 'import explorer, os; print(os.path.dirname(explorer.__file__))')"
"$pb" presets >/dev/null
"$pb" simulate --preset ISB --n 100 --seed 0 --out pts.npz >/dev/null
test -s pts.npz
"$pb" rpc info "$work/rpc_WV2.xml" >/dev/null
"$work/venv/bin/python" -m explorer --help >/dev/null
# the data the course notebooks read from the installed package (notebook 08, notebook 10's paper tables)
"$work/venv/bin/python" - <<'PY'
from importlib.resources import files

from explorer import paper_tables

rpc = files("explorer.assets") / "rpc"
for name in ("rpc_PLEIADES.xml", "PHRDIMAP_P1BP--2018122638935449CP.XML", "PHRDIMAP_P1BP--2017030824934340CP.XML",
             "PROVENANCE.md"):
    assert (rpc / name).is_file(), f"the wheel lacks assets/rpc/{name}"
assert paper_tables.LRM_TABLE3["rows"]
PY
exported="explore --export: not available"
if "$pb" explore --help 2>/dev/null | grep -q -- "--export"; then
  exported="explore --export: ok"
  "$pb" explore --preset WSU --scops 30 --scps 2000 --methods exact,lrm --export export_dir >/dev/null
  test -s export_dir/summary.json && test -s export_dir/residuals.csv && test -s export_dir/panels.html
fi
best=$("$work/venv/bin/python" - "$pb" <<'PY'
import subprocess, sys, time
times = []
for _ in range(3):
    t0 = time.perf_counter(); subprocess.run([sys.argv[1], "--help"], check=True, capture_output=True)
    times.append(time.perf_counter() - t0)
print(f"{min(times):.3f}")
PY
)
echo "[wheel] presets, simulate, rpc info, python -m explorer: ok; $exported; pushbroom --help best of 3: ${best} s"
