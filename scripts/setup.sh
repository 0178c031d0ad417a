#!/usr/bin/env bash
# Installs what choreo needs, and only what is missing, so running it again is a no-op:
#   - Debian packages to build (a C++ compiler for torch-sys) and to make the torch venv;
#   - the Rust toolchain (rustup) when cargo is absent, and its rustfmt and clippy components;
#   - libtorch: the PyPI torch wheel in .torchenv, with .torchenv/libtorch -> its torch/ folder
#     (.cargo/config.toml points LIBTORCH there; build.rs gives the binary an rpath to it).
# With --test it also installs what the test suite uses: ffmpeg and sox (fixtures in other
# formats are made from ../shared/audio at test time), blender and python3-numpy (the motion
# exporters' round-trip test), schemathesis (PyPI) in .venv-schemathesis (the API test that
# runs it against the real server), and for the page's browser test (tests/web.rs): Debian's
# chromium, Node.js 20+ with npm, and `npm ci` of tests/web (playwright-core), clients/typescript
# (openapi-typescript, openapi-fetch, typescript: the TypeScript client's drift checks) and web
# (esbuild and three.js, to check that web/dist is what web/src builds to), and the Standard
# Webhooks reference library (PyPI standardwebhooks) in .venv-webhooks, which the webhook test
# verifies signatures with. Building choreo never needs npm: the page's and the client's built
# files are committed (web/dist, clients/typescript/dist).
#
# Usage: scripts/setup.sh [--test]
set -euo pipefail
cd "$(dirname "$0")/.."

TORCH="torch==2.13.0"
CUDA_RUNTIME="nvidia-cuda-runtime==13.0.96.*"
CUPTI="nvidia-cuda-cupti==13.0.85.*"
VENV=.torchenv
SCHEMATHESIS="schemathesis==4.32.5"
ST_VENV=.venv-schemathesis
MOTO="moto[server]==5.2.5"
MOTO_VENV=.venv-moto
STANDARDWEBHOOKS="standardwebhooks==1.1.0"
WH_VENV=.venv-webhooks

with_tests=0
case "${1:-}" in
  --test) with_tests=1 ;;
  "") ;;
  *) echo "usage: $0 [--test]" >&2; exit 2 ;;
esac

log() { echo "setup: $*" >&2; }

as_root() {
  if [[ $(id -u) -eq 0 ]]; then "$@"
  elif command -v sudo >/dev/null 2>&1; then sudo "$@"
  else log "root is needed to run: $*"; exit 1
  fi
}

apt_updated=0
apt_install() {
  local missing=() pkg
  for pkg in "$@"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done
  [[ ${#missing[@]} -eq 0 ]] && return 0
  if ! command -v apt-get >/dev/null 2>&1; then
    log "missing ${missing[*]} and there is no apt-get; install them with your package manager"; exit 1
  fi
  log "installing ${missing[*]}"
  if [[ $apt_updated -eq 0 ]]; then
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    apt_updated=1
  fi
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

# A compiler for torch-sys's C++ shim, and curl for rustup.
command -v c++ >/dev/null 2>&1 || apt_install build-essential
command -v curl >/dev/null 2>&1 || apt_install curl ca-certificates

# Python with venv and pip, for the torch wheel.
if ! command -v python3 >/dev/null 2>&1; then apt_install python3; fi
if ! python3 -c 'import venv, ensurepip' >/dev/null 2>&1; then apt_install python3-venv; fi

# Rust.
if ! command -v cargo >/dev/null 2>&1 && [[ ! -x "$HOME/.cargo/bin/cargo" ]]; then
  log "installing the Rust toolchain with rustup"
  curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal
fi
export PATH="$HOME/.cargo/bin:$PATH"
# rustfmt and clippy, which `make test` runs before the suite (rust-toolchain.toml lists them
# too); the minimal profile above has neither. Only when missing, so a toolchain that has both
# needs no network here.
if ! cargo fmt --version >/dev/null 2>&1 || ! cargo clippy --version >/dev/null 2>&1; then
  if command -v rustup >/dev/null 2>&1; then
    log "adding the rustfmt and clippy components"
    rustup component add rustfmt clippy
  else
    log "cargo fmt or cargo clippy is missing and there is no rustup to add them: install rustfmt and clippy"
    exit 1
  fi
fi

# libtorch from the PyPI torch wheel. Checked by the installed dist-info, not by importing
# torch (slow), so an already correct venv is left exactly as it is.
torch_ok() {
  local site
  site=$(ls -d "$VENV"/lib/python3*/site-packages 2>/dev/null | head -n1) || return 1
  [[ -n "$site" ]] &&
    [[ -d "$site/torch-2.13.0.dist-info" ]] &&
    compgen -G "$site/nvidia_cuda_runtime-13.0.96*.dist-info" >/dev/null &&
    compgen -G "$site/nvidia_cuda_cupti-13.0.85*.dist-info" >/dev/null &&
    [[ -f "$site/torch/lib/libtorch_cpu.so" ]]
}
if ! torch_ok; then
  [[ -x "$VENV/bin/pip" ]] || python3 -m venv "$VENV"
  log "installing $TORCH into $VENV (a large download, once)"
  "$VENV/bin/pip" install --quiet --no-deps "$TORCH" "$CUDA_RUNTIME" "$CUPTI"
  torch_ok || { log "torch is still not installed correctly in $VENV"; exit 1; }
fi
pyver=$("$VENV/bin/python" -c 'import sys; print(f"python{sys.version_info[0]}.{sys.version_info[1]}")')
target="lib/$pyver/site-packages/torch"
if [[ "$(readlink "$VENV/libtorch" 2>/dev/null || true)" != "$target" ]]; then
  ln -sfn "$target" "$VENV/libtorch"
  log "linked $VENV/libtorch -> $target"
fi

if [[ $with_tests -eq 1 ]]; then
  apt_install ffmpeg sox blender python3-numpy
  # schemathesis, pinned, in its own venv (tests/api/schemathesis.rs runs its `st`).
  if ! "$ST_VENV/bin/st" --version 2>/dev/null | grep -q "version ${SCHEMATHESIS#schemathesis==}$"; then
    [[ -x "$ST_VENV/bin/pip" ]] || python3 -m venv "$ST_VENV"
    log "installing $SCHEMATHESIS into $ST_VENV"
    "$ST_VENV/bin/pip" install --quiet "$SCHEMATHESIS"
    "$ST_VENV/bin/st" --version >/dev/null || { log "schemathesis is not runnable from $ST_VENV"; exit 1; }
  fi
  # The page's browser test: Debian's chromium (Playwright's own browser download is not used),
  # Node.js 20+ (playwright-core needs it) and the pinned npm packages of both lockfiles.
  apt_install chromium
  command -v node >/dev/null 2>&1 || apt_install nodejs
  command -v npm >/dev/null 2>&1 || apt_install npm
  node_major=$(node -p 'process.versions.node.split(".")[0]')
  if [[ $node_major -lt 20 ]]; then
    log "Node.js $(node --version) is too old for playwright-core: install Node.js 20 or later"; exit 1
  fi
  # clients/typescript before web: the page bundles the client's sources and their dependencies.
  for dir in tests/web clients/typescript web; do
    # Again only when the lockfile changed since the last install.
    if [[ ! $dir/node_modules/.package-lock.json -nt $dir/package-lock.json ]]; then
      log "npm ci in $dir"
      (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error)
    fi
  done
  # PostgreSQL's server binaries (/usr/lib/postgresql/<v>/bin); tests run them as the postgres
  # user when run as root, with setpriv (util-linux).
  if ! compgen -G "/usr/lib/postgresql/*/bin/initdb" >/dev/null; then apt_install postgresql; fi
  command -v setpriv >/dev/null 2>&1 || apt_install util-linux
  # moto's S3 server, pinned, in its own venv (tests/api/artifacts.rs runs its moto_server).
  if ! "$MOTO_VENV/bin/python" -c 'import moto, flask; assert moto.__version__ == "'"${MOTO#moto\[server\]==}"'"' 2>/dev/null; then
    [[ -x "$MOTO_VENV/bin/pip" ]] || python3 -m venv "$MOTO_VENV"
    log "installing $MOTO into $MOTO_VENV"
    "$MOTO_VENV/bin/pip" install --quiet "$MOTO"
    [[ -x "$MOTO_VENV/bin/moto_server" ]] || { log "moto_server is not runnable from $MOTO_VENV"; exit 1; }
  fi
  # The Standard Webhooks reference library (PyPI), pinned, in its own venv: tests/api/webhooks.rs
  # verifies the signatures choreo sends with it (tests/webhooks/verify.py), not with our code.
  if ! "$WH_VENV/bin/python" -c 'import importlib.metadata as m; assert m.version("standardwebhooks") == "'"${STANDARDWEBHOOKS#standardwebhooks==}"'"' 2>/dev/null; then
    [[ -x "$WH_VENV/bin/pip" ]] || python3 -m venv "$WH_VENV"
    log "installing $STANDARDWEBHOOKS into $WH_VENV"
    "$WH_VENV/bin/pip" install --quiet "$STANDARDWEBHOOKS"
  fi
  if [[ ! -d ../shared/audio ]]; then
    log "warning: ../shared/audio is missing; the upload tests need it"
  fi
fi
log "ok"
