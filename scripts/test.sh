#!/usr/bin/env bash
# Every test and check: lint and format (Python and Rust), types (mypy on the package, stubtest
# on the binding's stubs), clippy, Rust unit tests, pytest (the slow checks beside it).
source "$(dirname "${BASH_SOURCE[0]}")/_bootstrap.sh"
export TEXSENSE_NO_PROGRESS=1
# one BLAS thread per process: two pytest workers and the checks already fill the cores, and
# OpenBLAS threads that find their core busy spin (a 500x500 Cholesky factor, with a second
# process busy beside it: 37 CPU-ms with its default threads, 4.3 with one; a Preisach fit
# 5.6-6.2 -> 4.6-5.1 CPU-s). Set it yourself to try other counts.
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
say "ruff check";            ruff check python tests benchmarks examples
say "ruff format --check";   ruff format --check python tests benchmarks examples
say "cargo fmt --check";     cargo fmt --all --check
# the browser test drives Debian's chromium (docs/monitor.md); install it if we may
if [ ! -x "${TEXSENSE_CHROMIUM:-/usr/bin/chromium}" ] && ! command -v chromium >/dev/null 2>&1; then
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    say "installing Debian's chromium for the browser test"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
  else
    say "chromium is missing and apt-get is not available as root: the browser test will fail"
  fi
fi
# a real PostgreSQL server for the tests of the event store on PostgreSQL (docs/station.md)
if ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then
  need_debian initdb postgresql "the PostgreSQL tests"
fi
# the report tests read the PDFs back as text with poppler's pdftotext (docs/report.md)
need_debian pdftotext poppler-utils "the report tests"
# texsense on a mat's microcontroller (docs/embedded.md, tests/test_mcu.py): the C tests
# build with gcc; the emulated Cortex-M4 needs Debian's rustc and its rust-src, the Arm
# compiler with newlib, and QEMU; the header check runs cbindgen. One apt-get for all.
mcu_missing=()
mcu_need() {  # PROGRAM-OR-PATH PACKAGE
  case "$1" in
    /*) [ -e "$1" ] || mcu_missing+=("$2") ;;
    *) command -v "$1" >/dev/null 2>&1 || mcu_missing+=("$2") ;;
  esac
}
mcu_need gcc gcc
mcu_need cbindgen cbindgen
mcu_need /usr/bin/rustc rustc
mcu_need "/usr/src/rustc-$(/usr/bin/rustc --version 2>/dev/null | cut -d' ' -f2)/library/core/src/lib.rs" rust-src
mcu_need arm-none-eabi-gcc gcc-arm-none-eabi
mcu_need /usr/lib/arm-none-eabi/newlib/rdimon.specs libnewlib-arm-none-eabi
mcu_need qemu-system-arm qemu-system-arm
if [ "${#mcu_missing[@]}" -gt 0 ]; then
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    say "installing Debian's ${mcu_missing[*]} for the microcontroller tests"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
      --no-install-recommends "${mcu_missing[@]}" >/dev/null
  else
    say "${mcu_missing[*]} missing and apt-get is not available as root: the microcontroller tests that need them are skipped"
  fi
fi
# the tests start texsense in hundreds of child processes: its bytecode compiled once here
# (Python reads it even where PYTHONDONTWRITEBYTECODE keeps each process from writing it;
# about 0.2 s of every start)
say "compileall";            python -m compileall -q -j 0 python/texsense >/dev/null
# the slow checks (types, stubs, clippy, the Rust tests: ~4 CPU-minutes from a clean clone) run
# one after the other beside pytest, at a lower priority: pytest's workers spend much of their
# time waiting on a child process, a server or a browser, and these fill that time. Their
# output is kept and shown after pytest; any failure fails the command.
CHECKS="$(mktemp -d "${TMPDIR:-/tmp}/texsense-checks.XXXXXX")"
checks=(mypy stubtest clippy cargo-test)
run_check() {  # NAME: run one check, its output and exit status into $CHECKS
  local rc=0 start=$SECONDS
  case "$1" in
    mypy) mypy ;;
    stubtest) MYPYPATH=python python -m mypy.stubtest texsense._core ;;
    clippy) cargo clippy --quiet --all-targets -- -D warnings ;;
    cargo-test) cargo test --quiet -p texsense-core -p texsense-kernels -p texsense-mcu ;;
  esac >"$CHECKS/$1.log" 2>&1 || rc=$?
  echo "$rc" >"$CHECKS/$1.rc"
  echo "$((SECONDS - start))" >"$CHECKS/$1.s"
}
say "beside pytest: ${checks[*]} (reported at the end)"
( renice -n 10 "$BASHPID" >/dev/null; for c in "${checks[@]}"; do run_check "$c"; done ) &
checks_pid=$!
# two workers side by side (pytest-xdist; TEXSENSE_TEST_JOBS to change): much of a test's
# time is waiting on a child process, a server or a browser. Grouped tests stay together.
say "pytest"
pytest_rc=0
python -m pytest -q --durations=25 -n "${TEXSENSE_TEST_JOBS:-2}" --dist loadgroup "$@" \
  || pytest_rc=$?
say "waiting for the checks beside pytest"
wait "$checks_pid" || true
failed=()
for c in "${checks[@]}"; do
  rc="$(cat "$CHECKS/$c.rc" 2>/dev/null || echo "did not run")"
  if [ "$rc" = 0 ]; then
    say "$c: ok ($(cat "$CHECKS/$c.s") s)"
  else
    say "$c FAILED (exit $rc):"; cat "$CHECKS/$c.log" >&2; failed+=("$c")
  fi
done
rm -rf "$CHECKS"
if [ "$pytest_rc" != 0 ] || [ "${#failed[@]}" -gt 0 ]; then
  say "FAILED: ${failed[*]}${failed[*]:+ }$([ "$pytest_rc" != 0 ] && echo "pytest (exit $pytest_rc)")"
  exit 1
fi
