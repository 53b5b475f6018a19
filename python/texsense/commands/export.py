"""``texsense export mcu CALIBRATION -o mat.bin|mat.c``: a mat's calibration as the model blob
its own microcontroller runs (docs/embedded.md)."""

from __future__ import annotations

import argparse
import re
import zlib
from pathlib import Path

from texsense._core import mcu_blob_info
from texsense.commands import HELP
from texsense.commands._applies import Rule, only_where, refuse_unless
from texsense.commands._options import add_accept_truncated
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.repair import Repair
from texsense.compensation.stages import Hysteresis, load_chain
from texsense.data.files import check_not_input, write_bytes, write_text
from texsense.data.layout import Layout
from texsense.exceptions import ParameterError

#: the local repairs a microcontroller runs (the harmonic ones solve sparse systems)
MCU_REPAIRS = ("zero", "last-value", "neighbour-mean", "idw8", "none")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``export`` command."""
    e = sub.add_parser(
        "export",
        help=HELP["export"],
        description="Export a calibration for another runtime.",
    )
    es = e.add_subparsers(dest="export_command", metavar="WHAT")
    es.required = True
    m = es.add_parser(
        "mcu",
        help="the model blob a mat's microcontroller runs (texsense-mcu, C ABI)",
        description="Compile a calibration chain as the pipeline runs it (its detect stage, "
        "conversion, hysteresis, drift, and a local repair) and write it as the model blob of "
        "texsense's C library: every parameter in float32, versioned and checksummed (CRC-32), "
        "read in place by the microcontroller. The output's suffix chooses the form: .bin "
        "(the blob) or .c (a C source with the blob as a 4-byte aligned array).",
    )
    m.add_argument("calibration", type=Path, help="calibration chain (JSON)")
    m.add_argument("-o", "--output", type=Path, required=True, help="mat.bin or mat.c")
    m.add_argument(
        "--repair",
        choices=MCU_REPAIRS,
        default="neighbour-mean",
        help="repair of failed readings after a chain without its own (default: "
        "neighbour-mean, eq. 6.14)",
    )
    m.add_argument(
        "--capacity",
        type=int,
        default=16,
        help="Preisach turning points kept per element (default 16; each costs 8 bytes of "
        "RAM per element; deeper, the innermost minor loop is forgotten)",
    )
    m.add_argument(
        "--like", type=Path, help="a recording of the mat, for its layout (if no stage has it)"
    )
    m.add_argument("--name", help="the C array's name (default: from the output file's name)")
    add_accept_truncated(m)
    m.set_defaults(run=run_export_mcu)
    only_where(m, [
        Rule("--name", lambda a: a.output.suffix.lower() == ".c", "a C source (-o NAME.c)"),
        Rule("--accept-truncated", lambda a: a.like is not None, "the recording of --like"),
    ])  # fmt: skip


def c_source(blob: bytes, name: str) -> str:
    """The blob as a C source: a 4-byte aligned array and its length."""
    rows = [
        "  " + ", ".join(f"0x{b:02x}" for b in blob[k : k + 16]) + ","
        for k in range(0, len(blob), 16)
    ]
    return (
        "/* A texsense model blob (texsense export mcu; docs/embedded.md): pass it to ts_init. */\n"
        "#include <stddef.h>\n#include <stdint.h>\n\n"
        f"_Alignas(4) const uint8_t {name}[{len(blob)}] = {{\n" + "\n".join(rows) + "\n};\n"
        f"const size_t {name}_len = {len(blob)};\n"
    )


def run_export_mcu(args: argparse.Namespace) -> int:
    """Run ``texsense export mcu``."""
    from texsense.io import load

    suffix = args.output.suffix.lower()
    if suffix not in (".bin", ".c"):
        raise ParameterError(f"{args.output}: the output must end in .bin (the blob) or .c")
    check_not_input(args.output, [args.calibration] + ([args.like] if args.like else []))
    chain = load_chain(args.calibration)
    layouts = [getattr(s, "layout", None) for s in chain.stages]
    layout = next((x for x in layouts if isinstance(x, Layout)), None)
    held = f"{args.calibration} holds the stages {', '.join(chain.names)}"
    refuse_unless(args, "--like", layout is None, "a calibration whose stages do not know the "
                  f"mat's layout; {held}, which do")  # fmt: skip
    refuse_unless(args, "--capacity", chain.find(Hysteresis) is not None,
                  "a calibration with a hysteresis stage", held)  # fmt: skip
    refuse_unless(args, "--repair", chain.find(Repair) is None or args.repair == "none",
                  "a calibration without a repair stage of its own (or --repair none, which "
                  "leaves it out)", held)  # fmt: skip
    if args.like is not None:
        layout = load(args.like, accept_truncated=args.accept_truncated).layout
    if layout is None:
        raise ParameterError(
            f"{args.calibration}: no stage knows the mat's layout; give --like RECORDING"
        )
    repair = None if args.repair == "none" else args.repair
    pipe = Pipeline(chain, layout, repair=repair, capacity=args.capacity)
    blob = pipe.compiled().mcu_blob()
    n, stages, memory, per_element, scratch, fixed = mcu_blob_info(blob)
    if suffix == ".c":
        name = args.name or re.sub(r"\W|^(?=\d)", "_", args.output.stem) + "_blob"
        if not re.fullmatch(r"[A-Za-z_]\w*", name):
            raise ParameterError(f"--name {name!r} is not a C name")
        write_text(args.output, c_source(blob, name))
    else:
        write_bytes(args.output, blob)
    print(
        f"wrote {args.output}: {n} elements, stages {', '.join(pipe.stage_names())}; "
        f"blob {len(blob):,} bytes (format version 1, CRC-32 {zlib.crc32(blob[:-4]):08x}); "
        f"RAM {memory:,} bytes = {per_element} bytes of state + {scratch} of scratch per "
        f"element + {fixed:,}"
    )
    assert len(stages) >= 1
    return 0
