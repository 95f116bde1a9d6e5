#!/usr/bin/env bash
# Set-up and the two entry points of the project.
#   ./run.sh demo   create .venv if needed, install, run the main job (CMU trial 02_01, or
#                   motion generated on the humanoid when the data folder lacks it)
#   ./run.sh test   create .venv if needed, install, run the whole test suite
set -euo pipefail
cd "$(dirname "$0")"

PY=${PYTHON:-python3}
VENV=.venv
STAMP=$VENV/.setup-stamp

system_packages() {
    # Offscreen rendering (MUJOCO_GL=egl via Mesa) and the browser the report test drives.
    local need=()
    for pkg in libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0 chromium; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need+=("$pkg")
    done
    [ ${#need[@]} -eq 0 ] && return 0
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "run.sh: installing system packages: ${need[*]}" >&2
        (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}") >&2 \
            || echo "run.sh: could not install ${need[*]}; rendering/browser tests will skip" >&2
    else
        echo "run.sh: missing system packages: ${need[*]}" >&2
        echo "run.sh: install them with: sudo apt-get install ${need[*]}" >&2
    fi
}

quiet() {
    # pip's notes about this machine's local package mirrors are noise; errors still show.
    set +o pipefail
    "$@" 2>&1 | { grep -v -e "^WARNING: Location" -e "^ *$" || true; } >&2
    local rc=${PIPESTATUS[0]}
    set -o pipefail
    return "$rc"
}

python_env() {
    local want
    want=$(cat pyproject.toml run.sh | sha256sum | cut -d' ' -f1)
    if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$want" ]; then return 0; fi
    [ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV"
    quiet "$VENV/bin/python" -m pip install -q --upgrade pip
    # torch pinned first, from pip's configured index: where that holds a CPU wheel,
    # the CPU build; from PyPI on Linux, the CUDA build. README, 'Install elsewhere': the CPU index.
    quiet "$VENV/bin/python" -m pip install -q "torch==2.13.0"
    quiet "$VENV/bin/python" -m pip install -q -e ".[test,ray,bench]"
    echo "$want" >"$STAMP"
}

export MUJOCO_GL=${MUJOCO_GL:-egl}
cmd=${1:-demo}
shift || true
case "$cmd" in
    demo)
        system_packages
        python_env
        exec "$VENV/bin/sidql" demo "$@"
        ;;
    test)
        system_packages
        python_env
        "$VENV/bin/ruff" check sim sidql tests benchmarks
        exec "$VENV/bin/python" -m pytest "$@"
        ;;
    *)
        echo "usage: ./run.sh demo|test [args...]" >&2
        exit 64
        ;;
esac
