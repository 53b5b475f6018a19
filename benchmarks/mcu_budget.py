"""Budgets of texsense on a mat's own microcontroller (docs/embedded.md): flash, RAM per
element and per mat, and instructions per element per frame counted on an emulated Cortex-M4.

Run:  .venv/bin/python benchmarks/mcu_budget.py [--frames 200]

- mats: the thesis seat (96 elements, the README's calibration: detect, convert, hysteresis,
  eq. 6.14 repair; with a drift stage on the time clock, eq. 5.8; and on the rest clock) and
  a 32 x 32 bed mat (1024 elements, the same stages), calibrated as a user would on the
  virtual sensor, each run over a loaded session with the thesis's failure rates;
- instructions: ``qemu-system-arm -M mps2-an386 -icount shift=0`` advances its clock one
  nanosecond per instruction, so SysTick (25 MHz) counts one tick per 40 instructions; the
  test program checks that on a loop of 2,000,000 known instructions in the same run;
- cycles: a Cortex-M4 takes one cycle for most integer and float instructions, 2 for a load,
  2-4 for a taken branch, 14 for a float division; we state cycles = 1.5 x instructions
  (and show 2.0 x as the pessimistic case: flash wait states at 64 MHz without a cache);
- flash: the blob, and the library's code (a program calling every ts_ function, minus the
  same program without the calls, both linked with --gc-sections);
- RAM: what ts_mem_size asks for (state per element, a frame's scratch, a fixed part).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "mcu"))
import build  # noqa: E402

from texsense._core import mcu_blob_info  # noqa: E402
from texsense.calibration.workflows import calibrate_virtual_mat  # noqa: E402
from texsense.compensation.drift import DriftModel  # noqa: E402
from texsense.compensation.drift_kernels import log_kernel  # noqa: E402
from texsense.compensation.pipeline import Pipeline  # noqa: E402
from texsense.compensation.stages import Drift, StageChain  # noqa: E402
from texsense.data.layout import Layout  # noqa: E402
from texsense.sim.mat import SEAT_PITCH_CM, VirtualMat  # noqa: E402
from texsense.sim.seated import SEAT_FAILURES  # noqa: E402

CLOCK_HZ = 64e6
RAM = 64 * 1024
CPI, CPI_SLOW = 1.5, 2.0


def session(mat: VirtualMat, frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A load that comes and goes on the mat (with its failures), every 0.1 s: readings,
    validity, dt. Its peaks while loaded shrink slowly, so each element nests minor loops
    in its Preisach memory: the demanding case for a bounded memory."""
    times = np.arange(frames) * 0.1
    xy = mat.layout.xy_cm
    on = (np.sin(times / 1.6) > -0.4)[:, None]
    spread = 0.05 * np.ptp(xy[:, 0]) ** 2 + 40
    load = on * (0.3 + 2.4 * np.exp(-np.sum((xy - xy.mean(0)) ** 2, axis=1) / spread))[None, :]
    load = load * (1 + 0.25 * np.sin(times / 0.41))[:, None]
    rec = mat.scan(times, load).capacitance
    return np.asarray(rec.frames, np.float32), rec.valid, np.diff(times, prepend=0.0)


def write_case(folder: Path, blob: bytes, cap: np.ndarray, valid: np.ndarray, dt: np.ndarray):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "mat.bin").write_bytes(blob)
    t, n = cap.shape
    with (folder / "frames.bin").open("wb") as f:
        f.write(b"TXSNFRM1" + np.array([n, t], "<u4").tobytes())
        for k in range(t):
            f.write(np.float32(dt[k]).tobytes() + cap[k].astype("<f4").tobytes())
            f.write(valid[k].astype(np.uint8).tobytes())


def instructions(arm: build.Built, folder: Path) -> tuple[float, float]:
    """(instructions per frame, instructions of ts_init) counted by QEMU."""
    out = build.run_program(arm, folder, icount=True, timeout=3600)
    m = re.search(r"ticks init (\d+) step (\d+) calibration (\d+) per 2000000", out)
    frames = re.search(r"(\d+) elements, (\d+) frames", out)
    if m is None or frames is None or "ALL CHECKS PASSED" not in out:
        raise RuntimeError(out)
    per_tick = 2_000_000 / int(m.group(3))  # instructions per SysTick tick, measured
    return int(m.group(2)) * per_tick / int(frames.group(2)), int(m.group(1)) * per_tick


def code_bytes() -> tuple[int, dict[str, int]]:
    """Flash of the library's code: a program that calls every ts_ function minus the same
    program without the calls (newlib's nosys stubs, --gc-sections); and the code and
    read-only data of the first by where it comes from."""
    arm = build.build_arm()
    gcc = build.tool("arm-none-eabi-gcc", "gcc-arm-none-eabi")
    size = build.tool("arm-none-eabi-size", "binutils-arm-none-eabi")
    src = (
        '#include "texsense.h"\n'
        "extern const uint8_t blob[]; const uint8_t blob[64] = {0};\n"
        "static uint64_t mem[64];\n"
        "int main(void) {\n#ifndef BASELINE\n  size_t need; ts_mat *m; float r[1], v[1];\n"
        "  ts_mem_size(blob, 64, &need);\n"
        "  ts_init((uint8_t *)mem, sizeof mem, blob, 64, 1, &m);\n"
        "  ts_step(m, r, 0, 0.1f, v, 0); ts_reset(m); return (int)ts_n_elements(m);\n"
        "#else\n  return (int)mem[0] + blob[0];\n#endif\n}\n"
    )
    sizes = []
    with tempfile.TemporaryDirectory() as tmp:
        c = Path(tmp) / "size.c"
        c.write_text(src)
        for extra in ([], ["-DBASELINE"]):
            elf = Path(tmp) / "size.elf"
            flags = [f for f in build.ARM_CFLAGS if not f.startswith("--specs")]
            subprocess.run(
                [gcc, *flags, "--specs=nosys.specs", "-O2", "-ffunction-sections",
                 "-Wl,--gc-sections", "-I", ROOT / "crates/mcu/include", *extra, c,
                 arm.library, "-lm", "-o", elf],
                check=True, capture_output=True,
            )  # fmt: skip
            text = subprocess.run([size, "-A", elf], capture_output=True, text=True, check=True)
            if not extra:
                parts = origins(elf)
            sizes.append(
                sum(
                    int(line.split()[1])
                    for line in text.stdout.splitlines()
                    if line.startswith((".text", ".rodata", ".ARM.exidx"))
                )
            )
    return sizes[0] - sizes[1], parts


def origins(elf: Path) -> dict[str, int]:
    """Bytes of code and read-only data of a program by origin: texsense's kernels and C ABI,
    Rust's core and compiler_builtins (mostly the formatting of panic messages), newlib."""
    nm = build.tool("arm-none-eabi-nm", "binutils-arm-none-eabi")
    out = subprocess.run([nm, "-S", "-C", str(elf)], capture_output=True, text=True, check=True)
    parts = {"texsense": 0, "Rust core": 0, "newlib (libm, libc)": 0}
    for line in out.stdout.splitlines():
        f = line.split(maxsplit=3)
        if len(f) < 4 or f[2].lower() not in ("t", "r", "w"):
            continue
        name, size = f[3], int(f[1], 16)
        if "texsense" in name:
            parts["texsense"] += size
        elif name.startswith(("core::", "<", "compiler_builtins")) or "core::" in name:
            parts["Rust core"] += size
        elif name not in ("main", "blob", "vectors"):
            parts["newlib (libm, libc)"] += size
    return parts


def chains(frames: int) -> list[tuple[str, VirtualMat, StageChain, int]]:
    """(name, mat, chain, elements) of every case."""
    seat_chain = calibrate_virtual_mat(VirtualMat.seat(seed=0))
    base = seat_chain.without("drift")
    model = seat_chain["drift"].model_
    time_clock = Drift.of(DriftModel(model.gamma, log_kernel(), "log"))
    rest = Drift.of(DriftModel(model.gamma, log_kernel(), "log", rest_rate=0.1))
    bed_layout = Layout.grid(32, 32, pitch_cm=SEAT_PITCH_CM, element_size_cm=2.0)
    bed_chain = calibrate_virtual_mat(VirtualMat(bed_layout, "textile-3mm", seed=1))
    seat = VirtualMat.seat(seed=0, failures=SEAT_FAILURES)
    bed = VirtualMat(bed_layout, "textile-3mm", seed=1, failures=SEAT_FAILURES)
    return [
        ("seat, no drift (README)", seat, base, 96),
        ("seat, drift on time (eq. 5.8)", seat, StageChain([*base.stages, time_clock]), 96),
        ("seat, drift on the rest clock", seat, StageChain([*base.stages, rest]), 96),
        ("bed, no drift", bed, bed_chain.without("drift"), 1024),
        ("bed, drift on time (eq. 5.8)", bed,
         StageChain([*bed_chain.without("drift").stages, time_clock]), 1024),
    ]  # fmt: skip


def accuracy(cases, sessions, tmp: Path) -> None:
    """float32 on the microcontroller (the host build of the same library: the same
    arithmetic, with glibc's expf/powf in place of newlib's) against the pipeline in
    float64 with the same memory of turning points; and that memory against the desktop's
    default (256), both in float64: the largest difference over the session."""
    host = build.build_host()
    print(
        "| mat and stages | float32 vs float64: max abs (N/cm²) | max relative where "
        "p > 0.1 N/cm² | codes that differ | capacity 4 / 8 / 16 vs 256: max abs (N/cm²) |"
    )
    print("|---|---:|---:|---:|---:|")  # fmt: skip
    for k, (name, mat, chain, n) in enumerate(cases):
        if n > 500:
            continue
        cap, valid, dt = sessions[id(mat)]
        times = np.cumsum(dt.astype(np.float32).astype(np.float64))
        x = cap.astype(np.float64)
        outs = {}
        for c in (4, 8, 16, 256):
            pipe = Pipeline(chain, mat.layout, repair="neighbour-mean", capacity=c)
            outs[c] = pipe.process(x, times, valid)
        folder = tmp / f"acc{k}"
        blob = Pipeline(chain, mat.layout, repair="neighbour-mean", capacity=16)
        write_case(folder, blob.compiled().mcu_blob(), cap, valid, np.diff(times, prepend=0.0))
        out = build.run_program(host, folder)
        assert "ALL CHECKS PASSED" in out, out
        raw = np.frombuffer((folder / "out.bin").read_bytes(), np.uint8).reshape(len(dt), 5 * n)
        got = raw[:, : 4 * n].copy().view("<f4").astype(np.float64)
        want, _, codes = outs[16]
        fin = np.isfinite(want) & np.isfinite(got)
        err = np.abs(got - want)[fin]
        big = np.abs(want[fin]) > 0.1
        rel = float(np.max(err[big] / np.abs(want[fin][big]))) if big.any() else 0.0
        diff = [np.nanmax(np.abs(outs[c][0] - outs[256][0])) for c in (4, 8, 16)]
        print(
            f"| {name} | {err.max():.1e} | {rel:.1e} | {int(np.sum(raw[:, 4 * n :] != codes))} "
            f"| {' / '.join(f'{d:.1e}' for d in diff)} |"
        )


def capacities(cases: list[tuple[str, VirtualMat, StageChain, int]]) -> None:
    """RAM per element (state and scratch) by the Preisach memory, and the largest mat that
    fits in 56 KiB."""
    caps = (4, 8, 16, 32)
    print("| stages | " + " | ".join(f"capacity {c}" for c in caps) + " |")
    print("|---|" + "---:|" * len(caps))
    for name, mat, chain, _ in cases[:2]:
        cells = []
        for c in caps:
            pipe = Pipeline(chain, mat.layout, repair="neighbour-mean", capacity=c)
            _, _, _, state, scratch, fixed = mcu_blob_info(pipe.compiled().mcu_blob())
            largest = (RAM - 8 * 1024 - fixed) // (state + scratch)
            cells.append(f"{state + scratch} B ({largest} elements)")
        print(f"| {name.split(', ', 1)[1]} | " + " | ".join(cells) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--capacity", type=int, default=16)
    args = ap.parse_args()
    arm = build.build_arm()
    code, parts = code_bytes()
    where = ", ".join(f"{k} {v:,}" for k, v in parts.items())
    print(f"library code (flash): {code:,} bytes (a program calling it: {where}); "
          f"capacity {args.capacity} turning points\n")  # fmt: skip
    print("| mat and stages | blob (flash) | RAM per element | RAM in all | fits 64 KiB | "
          "largest mat in 56 KiB | instructions per element per frame | "
          "cycles per frame (x1.5) | CPU at 10 Hz | CPU at 1 Hz |")  # fmt: skip
    print("|---|---:|---:|---:|---|---:|---:|---:|---:|---:|")
    cases = chains(args.frames)
    sessions: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, mat, chain, n) in enumerate(cases):
            pipe = Pipeline(chain, mat.layout, repair="neighbour-mean", capacity=args.capacity)
            blob = pipe.compiled().mcu_blob()
            _, _, memory, state, scratch, fixed = mcu_blob_info(blob)
            if id(mat) not in sessions:  # one session per mat (a virtual mat's clock runs on)
                sessions[id(mat)] = session(mat, args.frames if n < 500 else args.frames // 4)
            cap, valid, dt = sessions[id(mat)]
            folder = Path(tmp) / str(k)
            write_case(folder, blob, cap, valid, dt)
            per_frame, _ = instructions(arm, folder)
            per_el = per_frame / n
            cycles = CPI * per_frame
            fits = "yes" if memory <= RAM else f"no ({memory / RAM:.1f} x)"
            largest = (RAM - 8 * 1024 - fixed) // (state + scratch)
            print(
                f"| {name} | {len(blob) / 1024:.1f} KiB | {state + scratch} B | "
                f"{memory / 1024:.1f} KiB | {fits} | {largest} | {per_el:,.0f} | {cycles:,.0f} | "
                f"{10 * cycles / CLOCK_HZ:.1%} ({10 * CPI_SLOW * per_frame / CLOCK_HZ:.1%}) | "
                f"{cycles / CLOCK_HZ:.2%} |"
            )
        print(
            f"\nCPU: share of a {CLOCK_HZ / 1e6:.0f} MHz Cortex-M4 at CPI {CPI} (in brackets "
            f"CPI {CPI_SLOW}); RAM per element includes {scratch} bytes of a frame's scratch; "
            f"fixed part {fixed} bytes for the last mat; largest mat: 64 KiB less 8 KiB for "
            "the rest of the firmware.\n"
        )
        accuracy(cases, sessions, Path(tmp))
    print()
    capacities(cases)


if __name__ == "__main__":
    main()
