#!/usr/bin/env bash
# One entry point that does its own set-up on a fresh machine, then runs a job.
#   ./run.sh explore [--preset WSU] [--port 8080]   the explorer (main job)
#   ./run.sh test [pytest args]                     the whole test suite
#   ./run.sh setup                                  set-up only (venv, packages from the lock, warm kernels)
#   ./run.sh course [DIR]                           execute the course notebooks and write HTML to DIR
#   ./run.sh lab                                    JupyterLab on notebooks/ (a double click opens a notebook)
#   ./run.sh lock                                   refresh requirements/lock.txt from a fresh resolve
#   ./run.sh bench [...]  /  ./run.sh pushbroom ...  any CLI command
set -euo pipefail
cd "$(dirname "$0")"
VENV=.venv
PY="$VENV/bin/python"

system_packages() {
  # Debian packages: chromium (browser tests, Plotly static images), libtiff-dev + pkg-config (rpcm's srtm4)
  local need=()
  command -v chromium >/dev/null 2>&1 || need+=(chromium)
  pkg-config --exists libtiff-4 2>/dev/null || need+=(libtiff-dev pkg-config)
  if [ ${#need[@]} -gt 0 ] && command -v apt-get >/dev/null 2>&1; then
    local sudo=""; [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1 && sudo="sudo"
    echo "[setup] apt-get install ${need[*]}"
    $sudo apt-get update -qq >/dev/null 2>&1 || true
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${need[@]}" >/dev/null
  fi
}

LOCK=requirements/lock.txt
EXTRAS="test,bench,notebooks,cluster"

python_packages() {
  local stamp="$VENV/.installed-$(cat pyproject.toml setup.py "$LOCK" 2>/dev/null | sha1sum | cut -c1-12)"
  [ -f "$stamp" ] && return 0
  [ -x "$PY" ] || python3 -m venv "$VENV"
  "$PY" -m pip install -q --upgrade pip
  # torch first: 2.13.0 is the CPU build on machines without a GPU (a bare "torch" pulls CUDA wheels)
  "$PY" -m pip install -q "torch==2.13.0"
  # the tested versions of every dependency (requirements/lock.txt; `./run.sh lock` refreshes it)
  local constraints=(); [ -f "$LOCK" ] && constraints=(-c "$LOCK")
  "$PY" -m pip install -q "${constraints[@]}" -e ".[$EXTRAS]"
  # compile every numba kernel once into numba's on-disk cache, so the first real run compiles nothing
  if "$VENV/bin/pushbroom" warmup --help >/dev/null 2>&1; then "$VENV/bin/pushbroom" warmup; fi
  touch "$stamp"
}

lab_settings() {
  # the repository's JupyterLab opens a course .py (jupytext percent file) as a notebook on a double click:
  # notebooks/jupyterlab_overrides.json merged into this venv's JupyterLab settings overrides (this venv only;
  # notebooks/jupytext.toml keeps every save from changing the tracked .py)
  "$PY" - notebooks/jupyterlab_overrides.json "$VENV/share/jupyter/lab/settings/overrides.json" <<'PYCODE'
import json, os, sys
src, dest = sys.argv[1], sys.argv[2]
merged = json.load(open(dest)) if os.path.exists(dest) else {}
for plugin, settings in json.load(open(src)).items():
    for key, value in settings.items():
        old = merged.setdefault(plugin, {}).get(key)
        merged[plugin][key] = {**old, **value} if isinstance(old, dict) and isinstance(value, dict) else value
os.makedirs(os.path.dirname(dest), exist_ok=True)
with open(dest, "w") as f:
    json.dump(merged, f, indent=2)
PYCODE
}

refresh_lock() {
  # resolve the newest versions the project admits in a scratch venv, run nothing, write the lock
  local tmp; tmp=$(mktemp -d)
  python3 -m venv "$tmp/venv"
  "$tmp/venv/bin/pip" install -q --upgrade pip
  "$tmp/venv/bin/pip" install -q "torch==2.13.0"
  "$tmp/venv/bin/pip" install -q -e ".[$EXTRAS]"
  mkdir -p requirements
  { echo "# Tested versions: \`./run.sh setup\` installs with -c this file. Refresh: ./run.sh lock, then ./run.sh test."
    "$tmp/venv/bin/pip" freeze --exclude-editable | sed 's/^torch==2.13.0+cpu$/torch==2.13.0/'; } > "$LOCK"
  rm -rf "$tmp"
  echo "wrote $LOCK"
}

job="${1:-explore}"; shift || true
case "$job" in
  test)
    system_packages; python_packages
    # everything, the slow tests included (pyproject's default `-m 'not slow'` is the quick developer run)
    exec "$VENV/bin/pytest" -q -n 2 -m "slow or not slow" "$@" ;;
  explore)
    python_packages
    exec "$VENV/bin/pushbroom" explore "$@" ;;
  setup)
    system_packages; python_packages; lab_settings ;;
  lab)
    python_packages; lab_settings
    exec "$VENV/bin/jupyter" lab notebooks/ "$@" ;;
  course)
    python_packages; lab_settings
    exec "$PY" notebooks/build_course.py "$@" ;;
  lock)
    refresh_lock ;;
  pushbroom)
    python_packages; exec "$VENV/bin/pushbroom" "$@" ;;
  *)
    python_packages; exec "$VENV/bin/pushbroom" "$job" "$@" ;;
esac
