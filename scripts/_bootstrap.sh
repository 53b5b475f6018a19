# Sourced by scripts/run.sh and scripts/test.sh: create or update the virtual environment at
# .venv from the locked requirements and (re)build the Rust extension into it.
# Needs only Python >= 3.11 and the Rust toolchain (cargo) on the machine.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

say() { printf '\033[1m[texsense]\033[0m %s\n' "$*" >&2; }

# need_debian PROGRAM PACKAGE WHAT: install Debian's PACKAGE when PROGRAM is missing (as root
# with apt-get), else say what will not work
need_debian() {
  if command -v "$1" >/dev/null 2>&1 || [ -x "/usr/sbin/$1" ] || [ -x "/usr/bin/$1" ]; then
    return 0
  fi
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    say "installing Debian's $2 ($3)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$2" >/dev/null
  else
    say "$2 is missing and apt-get is not available as root: $3 will not work"
  fi
}

python_ok() { "$1" -c 'import sys; sys.exit(sys.version_info < (3, 11))' >/dev/null 2>&1; }
PYTHON_BIN="${PYTHON:-}"
if [ -z "$PYTHON_BIN" ]; then
  for candidate in python3.11 python3 python3.12 python3.13; do
    if python_ok "$candidate"; then PYTHON_BIN="$candidate"; break; fi
  done
fi
if [ -z "$PYTHON_BIN" ] || ! python_ok "$PYTHON_BIN"; then
  say "Python >= 3.11 is needed (set PYTHON=/path/to/python3.11)"; exit 2
fi
if ! command -v cargo >/dev/null 2>&1; then
  say "the Rust toolchain (cargo) is needed: https://rustup.rs"; exit 2
fi

if [ ! -x .venv/bin/python ]; then
  say "creating .venv with $PYTHON_BIN"
  "$PYTHON_BIN" -m venv .venv
fi
LOCK=requirements/lock.txt
STAMP=.venv/.texsense-lock.sha256
want="$(sha256sum "$LOCK" | cut -d' ' -f1)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$want" ]; then
  say "installing locked Python packages ($LOCK)"
  .venv/bin/python -m pip install --quiet --upgrade pip
  # the build tool first, then the Rust core compiles while the other packages install (from
  # a clean clone each takes minutes; `maturin develop` below then finds the core built)
  .venv/bin/python -m pip install --quiet "$(grep -m1 '^maturin==' "$LOCK")"
  prebuilt="$(mktemp -d "${TMPDIR:-/tmp}/texsense-build.XXXXXX")"
  ( .venv/bin/maturin build --release --quiet -i .venv/bin/python -o "$prebuilt" \
      >"$prebuilt/log" 2>&1 || true ) &
  prebuild=$!
  .venv/bin/python -m pip install --quiet -r "$LOCK"
  wait "$prebuild"  # a failed build shows itself in `maturin develop` below
  rm -rf "$prebuilt"
  echo "$want" > "$STAMP"
fi
say "building the Rust core (texsense._core)"
VIRTUAL_ENV="$ROOT/.venv" PATH="$ROOT/.venv/bin:$PATH" \
  .venv/bin/maturin develop --release --quiet >/dev/null
export PATH="$ROOT/.venv/bin:$PATH"
export PYO3_PYTHON="$ROOT/.venv/bin/python"
# `texsense station` (docs/station.md) starts Debian's Mosquitto; its tests run it too
need_debian mosquitto mosquitto "texsense station and its tests"
