#!/usr/bin/env bash
# Set up arches-render and run it: the one script behind the README's two commands.
#
#   bash setup.sh demo [ARGS...]   install, then render scenes/default.toml to out/default.exr + .png
#   bash setup.sh test [ARGS...]   install with the test extra, then run pytest (ARGS go to pytest)
#                                  in ARCHES_TEST_WORKERS processes (pytest-xdist; default: the
#                                  cores, at most 4), a test file per process at a time
#
# Installs what is missing and nothing else: the Debian packages libllvm19 (Dr.Jit's LLVM
# backend needs libLLVM >= 16), python3, python3-venv and python3-pip (and, for the tests,
# chromium, the preview page's browser, and nodejs and npm, which install Khronos's glTF
# validator into .venv/node); a virtualenv in .venv;
# the project in editable mode. Safe to run again. Environment: PYTHON (interpreter that
# creates .venv, default python3).
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")"

MIN_LLVM=16
VENV=.venv
STAMP="$VENV/.arches-setup"

say() { printf 'setup: %s\n' "$*"; }
die() { printf 'setup: error: %s\n' "$*" >&2; exit 1; }

usage() {
    cat >&2 <<'EOF'
usage: bash setup.sh demo [ARGS...]   install, then render scenes/default.toml (ARGS go to 'arches-render render')
       bash setup.sh test [ARGS...]   install with the test extra, then run the tests (ARGS go to pytest)
EOF
    exit 2
}

# Run a command with its output hidden; show the output's tail if it fails.
quietly() {
    local log rc
    log=$(mktemp)
    if "$@" >"$log" 2>&1; then
        rm -f "$log"
    else
        rc=$?
        tail -n 60 "$log" >&2
        rm -f "$log"
        die "'$*' failed (exit $rc)"
    fi
}

# Print the path of a libLLVM with major version >= MIN_LLVM, if there is one.
find_libllvm() {
    local f name major
    if [[ -n "${DRJIT_LIBLLVM_PATH:-}" && -e "$DRJIT_LIBLLVM_PATH" ]]; then
        set -- "$DRJIT_LIBLLVM_PATH"
    else
        shopt -s nullglob
        set -- /usr/lib/*-linux-gnu/libLLVM*.so* /usr/lib64/libLLVM*.so* /usr/lib/libLLVM*.so* \
               /usr/local/lib/libLLVM*.so*
        shopt -u nullglob
    fi
    for f in "$@"; do
        name=${f##*/}
        if [[ $name =~ ^libLLVM[-.]?(so\.)?([0-9]+) ]]; then
            major=${BASH_REMATCH[2]}
            if (( major >= MIN_LLVM )); then
                printf '%s\n' "$f"
                return 0
            fi
        fi
    done
    return 1
}

deb_installed() {
    [[ "$(dpkg-query -W -f='${Status}' "$1" 2>/dev/null)" == "install ok installed" ]]
}

install_system_packages() {
    local missing=() pkg sudo=()
    if ! find_libllvm >/dev/null; then
        missing+=(libllvm19)
    fi
    # The tests drive the preview page in a real headless browser (Debian's Chromium).
    if [[ $mode == test ]] && ! command -v chromium >/dev/null; then
        missing+=(chromium)
    fi
    # ... and check exported glTF with Khronos's validator, which runs on Node.js.
    if [[ $mode == test ]] && ! command -v npm >/dev/null; then
        missing+=(nodejs npm)
    fi
    if command -v apt-get >/dev/null && command -v dpkg-query >/dev/null; then
        for pkg in python3 python3-venv python3-pip; do
            deb_installed "$pkg" || missing+=("$pkg")
        done
    elif ! command -v "${PYTHON:-python3}" >/dev/null; then
        missing+=(python3 python3-venv python3-pip)
    fi
    if (( ${#missing[@]} == 0 )); then
        say "system packages: present"
        return 0
    fi
    if ! command -v apt-get >/dev/null; then
        if [[ " ${missing[*]} " == *" libllvm19 "* ]]; then
            die "no libLLVM >= $MIN_LLVM found and apt-get is not available: install LLVM $MIN_LLVM or newer" \
                "(e.g. libllvm19) with your package manager, or set DRJIT_LIBLLVM_PATH to its libLLVM.so"
        fi
        if [[ " ${missing[*]} " == *" python3 "* ]]; then
            die "python3 (>= 3.10, with venv) is missing and apt-get is not available: install it, then re-run"
        fi
        die "${missing[*]} is missing and apt-get is not available: install it (the preview's browser test" \
            "runs /usr/bin/chromium), then re-run"
    fi
    if (( EUID != 0 )); then
        command -v sudo >/dev/null || die "installing ${missing[*]} needs root: re-run as root or install sudo"
        sudo=(sudo)
    fi
    say "apt-get install ${missing[*]}"
    quietly "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=300 update -qq
    quietly "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=300 \
        install -y -qq --no-install-recommends "${missing[@]}"
    find_libllvm >/dev/null || die "libllvm19 was installed but no libLLVM >= $MIN_LLVM was found under /usr/lib"
}

setup_venv() {
    local py=${PYTHON:-python3}
    if ! "$VENV/bin/python" -c '' 2>/dev/null; then
        command -v "$py" >/dev/null || py=/usr/bin/python3
        "$py" -c 'import sys; sys.exit(sys.version_info < (3, 10))' \
            || die "$py is Python $("$py" -c 'import platform; print(platform.python_version())'); arches-render needs >= 3.10"
        say "creating $VENV ($("$py" -c 'import sys; print(sys.executable)'))"
        quietly "$py" -m venv --clear "$VENV"
    else
        say "$VENV: present"
    fi
}

# pip install -e .[EXTRA] unless the same pyproject.toml was already installed with it.
install_project() {
    local extra=$1 spec=. key
    [[ -n $extra ]] && spec=".[$extra]"
    key="$(sha256sum pyproject.toml | cut -d' ' -f1) $("$VENV/bin/python" -c 'import sys; print(sys.version)' | head -n1)"
    if [[ -f $STAMP && -x $VENV/bin/arches-render ]]; then
        local done_key done_extra
        done_key=$(sed -n 1p "$STAMP")
        done_extra=$(sed -n 2p "$STAMP")
        if [[ $done_key == "$key" && ( -z $extra || $done_extra == "$extra" ) ]]; then
            say "pip install -e '$spec': already done for this pyproject.toml"
            return 0
        fi
    fi
    export PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_INPUT=1
    say "upgrading pip"
    quietly "$VENV/bin/python" -m pip install --upgrade pip
    say "pip install -e '$spec' (first run downloads Mitsuba, Dr.Jit, SciPy, ...: a few minutes)"
    quietly "$VENV/bin/python" -m pip install --prefer-binary -e "$spec"
    printf '%s\n%s\n' "$key" "$extra" >"$STAMP"
}

# Khronos's glTF validator (npm package gltf-validator) into .venv/node, for the export tests.
install_gltf_validator() {
    local dir=$VENV/node version=2.0.0-dev.3.10
    if [[ -f $dir/node_modules/gltf-validator/package.json ]] \
        && grep -q "\"version\": \"$version\"" "$dir/node_modules/gltf-validator/package.json"; then
        say "gltf-validator $version: present"
        return 0
    fi
    say "npm install gltf-validator@$version (Khronos's glTF validator, for the export tests)"
    quietly npm install --prefix "$dir" --no-audit --no-fund --silent "gltf-validator@$version"
}

[[ $# -ge 1 ]] || usage
mode=$1
shift
case $mode in
    demo) extra= ;;
    test) extra=test ;;
    -h|--help|help) usage ;;
    *) printf 'setup: unknown command %q\n' "$mode" >&2; usage ;;
esac

install_system_packages
setup_venv
install_project "$extra"
# An editable install leaves the project's own modules uncompiled, and where the
# environment sets PYTHONDONTWRITEBYTECODE every process compiled them again (0.3 s a
# render, a CLI call, a test's subprocess). Up-to-date files are skipped; a checkout that
# cannot be written only loses the time, so a failure here is not fatal.
"$VENV/bin/python" -m compileall -q -j 0 arches_render generators materials >/dev/null 2>&1 \
    || say "byte-compiling the project's modules failed (read-only checkout?): they compile at each start"
if [[ $mode == test ]]; then install_gltf_validator; fi

if [[ $mode == demo ]]; then
    say "arches-render render scenes/default.toml -o out/default.exr${*:+ $*}"
    mkdir -p out  # render refuses an output folder that does not exist
    exec "$VENV/bin/arches-render" render scenes/default.toml -o out/default.exr "$@"
else
    # Two processes on two cores take ~60 % of one's time: a render keeps the cores busy,
    # but scene loading, kernel compilation and the checks between renders are serial.
    # A file per process keeps its module fixtures (the sweep, the goldens) in one place.
    workers=${ARCHES_TEST_WORKERS:-$(nproc 2>/dev/null || echo 2)}
    (( workers > 4 )) && workers=4
    xdist=()
    (( workers > 1 )) && xdist=(-n "$workers" --dist loadfile)
    say "python -m pytest -q ${xdist[*]}${*:+ $*}"
    exec "$VENV/bin/python" -m pytest -q "${xdist[@]}" "$@"
fi
