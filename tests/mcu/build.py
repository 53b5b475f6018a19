"""Build texsense's C ABI and its C test program (tests/mcu/test_mat.c), for the host (gcc,
the workspace's rustc) and for a Cortex-M4 (Debian's rustc and arm-none-eabi-gcc), and run
it (the Cortex-M4 one on QEMU's mps2-an386). Used by tests/test_mcu.py and
benchmarks/mcu_budget.py; alone: ``python tests/mcu/build.py [host|arm]``.

The Cortex-M build follows docs/embedded.md: ``core`` for thumbv7em-none-eabihf from Debian's
rust-src, ``compiler_builtins`` 0.1.73 (fetched with ``cargo vendor``), both with Debian's
rustc; the kernels and the C ABI as Rust 1.63 code. Everything is cached in
``target/mcu/`` under a key of the sources and the compilers, so a run builds ``core`` and
``compiler_builtins`` once and later runs reuse them.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
CACHE = ROOT / "target" / "mcu"
TARGET = "thumbv7em-none-eabihf"
COMPILER_BUILTINS = "0.1.73"
ARM_CFLAGS = [
    "-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16", "--specs=rdimon.specs",
]  # fmt: skip
CFLAGS = ["-O2", "-std=c11", "-Wall", "-Wextra", "-Werror"]


class MissingError(Exception):
    """A tool or package the build needs is not on this machine (the message names it)."""


@dataclass(frozen=True)
class Built:
    """A built test program and the static library in it."""

    program: Path
    library: Path
    kind: str  # "host" or "arm"


def run(cmd: list[str | Path], **kw: object) -> str:
    """Run a build command; a failure raises RuntimeError with its output."""
    p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, check=False, **kw)  # type: ignore[call-overload]
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed:\n{p.stdout}\n{p.stderr}")
    return str(p.stdout)


def tool(name: str, package: str) -> str:
    """The path of a program, or MissingError naming the Debian package that has it."""
    path = shutil.which(name)
    if path is None:
        raise MissingError(f"{name} (Debian package {package})")
    return path


def key(*parts: object) -> str:
    """A cache key of the sources of the kernels, the C ABI and the test program, and of
    ``parts`` (compiler versions)."""
    h = hashlib.sha256()
    files = sorted(
        [
            *(ROOT / "crates" / "kernels" / "src").rglob("*.rs"),
            *(ROOT / "crates" / "mcu" / "src").rglob("*.rs"),
            ROOT / "crates" / "mcu" / "include" / "texsense.h",
            Path(__file__),
            *HERE.rglob("*.c"),
            *HERE.rglob("*.ld"),
        ]
    )
    for f in files:
        h.update(str(f.relative_to(ROOT)).encode())
        h.update(f.read_bytes())
    for p in parts:
        h.update(str(p).encode())
    return h.hexdigest()[:16]


def rust_crates(rustc: str, out: Path, target: list[str], libs: list[Path], env: dict) -> Path:
    """The kernels (rlib) and the C ABI (static library, with its panic handler) into
    ``out``; returns the static library."""
    common = ["--edition", "2021", "-O", "-C", "panic=abort", *target]
    for lib in libs:
        common += ["-L", str(lib)]
    run([rustc, *common, "--crate-type", "rlib", "--crate-name", "texsense_kernels",
         ROOT / "crates/kernels/src/lib.rs", "--out-dir", out], env=env)  # fmt: skip
    run([rustc, *common, "--crate-type", "staticlib", "--crate-name", "texsense_mcu",
         "--cfg", 'feature="panic-handler"', "-L", out,
         "--extern", f"texsense_kernels={out / 'libtexsense_kernels.rlib'}",
         ROOT / "crates/mcu/src/lib.rs", "--out-dir", out], env=env)  # fmt: skip
    return out / "libtexsense_mcu.a"


def build_host() -> Built:
    """The host build: the workspace's rustc, gcc."""
    rustc, gcc = tool("rustc", "rustup's toolchain"), tool("gcc", "gcc")
    version = run([rustc, "--version"]) + run([gcc, "--version"]).splitlines()[0]
    out = CACHE / f"host-{key(version)}"
    program = out / "test_mat"
    if not program.exists():
        out.mkdir(parents=True, exist_ok=True)
        lib = rust_crates(rustc, out, [], [], dict(os.environ))
        run([gcc, *CFLAGS, "-I", ROOT / "crates/mcu/include", HERE / "test_mat.c", lib, "-lm",
             "-o", program])  # fmt: skip
    return Built(program, out / "libtexsense_mcu.a", "host")


def debian_rustc() -> tuple[str, Path]:
    """Debian's rustc and the core library source of its version (rust-src)."""
    rustc = "/usr/bin/rustc"
    if not os.access(rustc, os.X_OK):
        raise MissingError("Debian's rustc (/usr/bin/rustc, package rustc)")
    version = run([rustc, "--version"]).split()[1]
    src = Path(f"/usr/src/rustc-{version}/library/core/src/lib.rs")
    if not src.is_file():
        raise MissingError(f"the Rust source of rustc {version} ({src}, package rust-src)")
    return rustc, src


def sysroot(rustc: str, core_src: Path) -> Path:
    """``core`` and ``compiler_builtins`` for the Cortex-M4, built once per compiler."""
    version = run([rustc, "--version"]).strip()
    sys_dir = CACHE / f"sys-{hashlib.sha256(version.encode()).hexdigest()[:12]}"
    done = sys_dir / "libcompiler_builtins.rlib"
    if done.exists():
        return sys_dir
    sys_dir.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, RUSTC_BOOTSTRAP="1")
    run([rustc, "--target", TARGET, "--crate-type", "rlib", "--crate-name", "core",
         "--edition", "2021", "-O", "-C", "panic=abort", core_src, "--out-dir", sys_dir],
        env=env)  # fmt: skip
    cb = vendored_compiler_builtins()
    run([rustc, "--target", TARGET, "--crate-type", "rlib", "--crate-name", "compiler_builtins",
         "--edition", "2015", "-O", "-C", "panic=abort", "--cfg", 'feature="unstable"',
         "--cfg", 'feature="compiler-builtins"', "--cfg", 'feature="mem"', "--cfg", "thumb",
         "-L", sys_dir, cb / "src" / "lib.rs", "--out-dir", sys_dir], env=env)  # fmt: skip
    return sys_dir


def vendored_compiler_builtins() -> Path:
    """compiler_builtins from the crates registry (``cargo vendor``, once)."""
    where = CACHE / "vendor"
    crate = where / "vendor" / f"compiler_builtins-{COMPILER_BUILTINS}"
    if (crate / "src" / "lib.rs").exists():
        return crate
    cargo = tool("cargo", "cargo")
    where.mkdir(parents=True, exist_ok=True)
    (where / "src").mkdir(exist_ok=True)
    (where / "src" / "lib.rs").write_text("")
    (where / "Cargo.toml").write_text(
        '[package]\nname = "fetch-compiler-builtins"\nversion = "0.0.0"\nedition = "2021"\n\n'
        f'[dependencies]\ncompiler_builtins = "={COMPILER_BUILTINS}"\n\n[workspace]\n'
    )
    try:
        run([cargo, "vendor", "--versioned-dirs", "--quiet", "vendor"], cwd=where)
    except RuntimeError as e:
        why = f"compiler_builtins {COMPILER_BUILTINS} from crates.io ({e})"
        raise MissingError(why) from None
    return crate


def build_arm() -> Built:
    """The Cortex-M4 build: Debian's rustc (1.63 on bookworm), arm-none-eabi-gcc, newlib."""
    rustc, core_src = debian_rustc()
    gcc = tool("arm-none-eabi-gcc", "gcc-arm-none-eabi")
    specs = run([gcc, "-print-file-name=rdimon.specs"]).strip()
    if not Path(specs).is_file():
        raise MissingError("newlib's rdimon.specs (Debian package libnewlib-arm-none-eabi)")
    version = run([rustc, "--version"]) + run([gcc, "--version"]).splitlines()[0]
    out = CACHE / f"arm-{key(version)}"
    program = out / "test_mat.elf"
    if not program.exists():
        sys_dir = sysroot(rustc, core_src)
        out.mkdir(parents=True, exist_ok=True)
        lib = rust_crates(rustc, out, ["--target", TARGET], [sys_dir], dict(os.environ))
        run([gcc, *ARM_CFLAGS, *CFLAGS, "-I", ROOT / "crates/mcu/include", "-T",
             HERE / "arm" / "link.ld", HERE / "arm" / "startup.c", HERE / "test_mat.c", lib,
             "-lm", "-o", program])  # fmt: skip
    return Built(program, out / "libtexsense_mcu.a", "arm")


def build(kind: str) -> Built:
    """The ``host`` or ``arm`` build, one process at a time (a lock on ``target/mcu``: two
    rustc runs into one folder remove each other's object files, e.g. two test workers)."""
    import fcntl

    CACHE.mkdir(parents=True, exist_ok=True)
    with open(CACHE / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return build_host() if kind == "host" else build_arm()


def qemu() -> str:
    """QEMU for Arm systems."""
    return tool("qemu-system-arm", "qemu-system-arm")


def run_program(built: Built, folder: Path, timeout: float = 600, icount: bool = False) -> str:
    """Run the test program on ``folder`` (host, or QEMU for the Cortex-M4); its output.
    With ``icount`` QEMU's clock counts instructions (one per ns: SysTick ticks are
    instructions / 40 at the board's 25 MHz; the program calibrates it)."""
    if built.kind == "host":
        cmd: list[str | Path] = [built.program, folder]
    else:
        cmd = [qemu(), "-M", "mps2-an386", "-nographic", "-monitor", "none",
               "-semihosting-config", f"enable=on,target=native,arg=test_mat,arg={folder}",
               "-kernel", built.program]  # fmt: skip
        if icount:
            cmd[1:1] = ["-icount", "shift=0"]
    p = subprocess.run(
        [str(c) for c in cmd], capture_output=True, text=True, timeout=timeout, check=False
    )
    return p.stdout + p.stderr + f"\nexit {p.returncode}\n"


if __name__ == "__main__":
    which = sys.argv[1:] or ["host", "arm"]
    for w in which:
        try:
            b = build(w)
            print(f"{w}: {b.program}")
        except MissingError as e:
            print(f"{w}: missing {e}")
