"""Processing recordings in constant memory, and whole archives of them on Dask
(docs/pipeline.md, "Archives").

- :func:`process_file`: one recording through the compiled pipeline a block of frames at a
  time (every format is read block by block by its :mod:`texsense.io` reader, so the peak
  memory does not grow with the recording's length), written to a temporary name and renamed
  when complete (:func:`texsense.data.files.atomic_path`). The output's
  ``meta`` carries the calibration id and the SHA-256 of the input, so a second run skips a
  file whose output is already there for the same calibration and input.
- :func:`process_archive`: one task per file on a Dask cluster: local worker processes by
  default (one thread each), or any ``dask.distributed`` scheduler. A file that fails is
  reported at the end with its error and does not stop the others.

Examples
--------
>>> from texsense.compensation.archive import archive_jobs
>>> archive_jobs  # doctest: +ELLIPSIS
<function archive_jobs at ...>
"""

from __future__ import annotations

import glob
import hashlib
import logging
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from texsense._progress import progress
from texsense.compensation.pipeline import Pipeline, no_negative
from texsense.compensation.stages import StageChain, load_chain
from texsense.data.files import (
    atomic_path,
    check_not_input,
    json_loads,
    make_folder,
    open_regular,
    real_path,
    regular_files,
)
from texsense.data.layout import Layout
from texsense.data.modelfile import content_hash
from texsense.exceptions import FormatError, ParameterError

__all__ = [
    "FileReport",
    "ProcessOptions",
    "archive_jobs",
    "input_hash",
    "process_archive",
    "process_file",
]


@dataclass(frozen=True)
class ProcessOptions:
    """Pipeline settings of a processing run (see
    :class:`texsense.compensation.pipeline.Pipeline`)."""

    repair: str | None = "harmonic"
    hysteresis: bool = True
    drift: bool = True
    #: Frames per block; None: about 2^18 element-samples (2 MiB per float64 array).
    chunk_frames: int | None = None
    #: Read an input cut short up to its last complete frame (with a warning) instead of
    #: refusing it (``--accept-truncated``).
    accept_truncated: bool = False
    #: Correct the drift in use (stillness, an empty mat) instead of with the calibration's
    #: drift stage, where the calibration allows it (``--in-use-drift off``: laboratory only).
    in_use: bool = True
    #: Give every value a bound at this level (``--interval 0.95``): lower and upper maps
    #: beside the frames (docs/data-model.md).
    interval: float | None = None

    def pipeline(self, chain: StageChain, layout: Layout) -> Pipeline:
        """The compiled pipeline of ``chain`` for ``layout`` with these settings."""
        return Pipeline(
            chain,
            layout,
            hysteresis=self.hysteresis,
            drift=self.drift,
            repair=self.repair,
            in_use=self.in_use and self.drift,
            interval=self.interval,
        )

    def frames_per_block(self, n_elements: int) -> int:
        """The block length for a mat of ``n_elements``."""
        if self.chunk_frames is not None:
            return max(1, int(self.chunk_frames))
        return max(1, (1 << 18) // max(1, n_elements))


@dataclass(frozen=True)
class FileReport:
    """What happened to one file: ``done``, ``skipped`` (output already there for the same
    calibration and input) or ``failed`` (with the error)."""

    source: str
    output: str
    status: str
    frames: int = 0
    failed_share: float = 0.0
    error: str = ""
    #: the in-use drift correction at the end (:meth:`Pipeline.in_use_status`), if it ran
    in_use: dict[str, Any] | None = None


def input_hash(path: str | Path) -> str:
    """SHA-256 of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open_regular(path) as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _output_matches(
    dst: Path,
    calibration_id: str,
    digest: str,
    stages: list[str] | None = None,
    interval: float | None = None,
) -> bool:
    """True when ``dst`` is a complete output of the same calibration and input (and, given
    ``stages``, of the same stages)."""
    if not dst.is_file():
        return False
    from texsense.io.policy import open_hdf5  # the one HDF5 policy (loads h5py)

    try:
        with open_hdf5(dst) as f:
            meta = json_loads(f.attrs.get("meta", "{}"))
            complete = not int(f.attrs.get("open", 1))
    except (OSError, ValueError, TypeError):  # FormatError among them: not an output of ours
        return False
    return (
        complete
        and meta.get("calibration_id") == calibration_id
        and meta.get("input_sha256") == digest
        and (stages is None or meta.get("stages") == stages)
        and (meta.get("interval") or {}).get("level") == interval
    )


def process_file(
    src: str | Path,
    calibration: StageChain | str | Path,
    dst: str | Path,
    options: ProcessOptions | None = None,
) -> FileReport:
    """Process one recording block by block into ``dst`` (HDF5), atomically.

    Skips the work (status ``skipped``) when ``dst`` already holds the output of the same
    calibration for the same input bytes. Errors propagate; nothing is left at ``dst`` (nor
    at its temporary name) by a run that fails, and a previous ``dst`` is kept.

    Raises
    ------
    ParameterError
        If ``dst`` is the input (the raw data would be replaced by the output).
    """
    from texsense.io import open_reader
    from texsense.io.hdf5 import RecordingWriter

    opts = options or ProcessOptions()
    src, dst = Path(src), Path(dst)
    check_not_input(dst, [src])
    cal = load_chain(calibration) if isinstance(calibration, str | Path) else calibration
    digest = input_hash(src)
    with open_reader(src, accept_truncated=opts.accept_truncated) as reader:
        head = reader.header
        pipe = opts.pipeline(cal, head.layout)
        if _output_matches(dst, cal.id, digest, pipe.provenance()["stages"], opts.interval):
            return FileReport(str(src), str(dst), "skipped")
        quantity, unit = pipe.input_quantity
        if head.quantity != quantity:
            raise FormatError(src, f"holds {head.quantity}, the calibration reads {quantity}")
        out_quantity, out_unit = pipe.output_quantity
        meta = {**head.meta, **pipe.provenance(), "source": src.name, "input_sha256": digest}
        if opts.interval is not None:
            meta["interval"] = {"level": opts.interval, "method": "split conformal (issue 37)"}
        make_folder(dst.parent)
        frames, failed = 0, 0
        with (
            atomic_path(dst) as tmp,
            RecordingWriter(
                tmp,
                head.layout,
                out_quantity,
                out_unit,
                meta=meta,
                element_times=head.element_times,
                compress=True,
                live=False,
                bounds=opts.interval is not None,
            ) as writer,
        ):
            for block in reader.blocks(opts.frames_per_block(head.layout.n_elements)):
                values = block.to_unit(unit).frames if block.unit != unit else block.frames
                p, ok, codes = pipe.process(values, block.times, block.valid)
                lo, hi = pipe.bounds_ if pipe.bounds_ is not None else (None, None)
                p, lo = no_negative(p, lo)  # an empty element reads 0, not invalid
                writer.append(
                    p,
                    block.times,
                    valid=ok,
                    element_times=block.element_times,
                    labels=block.labels or None,
                    lower=lo,
                    upper=hi,
                )
                frames += block.n_frames
                failed += int(np.count_nonzero(codes))
            if frames == 0:
                raise FormatError(src, "the recording has no frames")
            if pipe.in_use:
                writer.update_meta({"in_use_drift": pipe.in_use_status()})
    share = failed / max(1, frames * head.layout.n_elements)
    status = pipe.in_use_status() if pipe.in_use else None
    return FileReport(str(src), str(dst), "done", frames, share, in_use=status)


def archive_jobs(
    inputs: Sequence[str | Path], out_dir: str | Path
) -> tuple[list[tuple[Path, Path]], list[Path]]:
    """(source, output) pairs of everything named by ``inputs``, and the files of the named
    folders that are not recordings (ignored).

    ``inputs`` are files, folders (searched recursively for files that a texsense reader
    recognises) and glob patterns. Outputs mirror the sources' paths below their folder (or
    the pattern's fixed part) in ``out_dir``, with the ending ``.h5``.
    """
    from texsense.io import sniff_format

    out = Path(out_dir)
    jobs: list[tuple[Path, Path]] = []
    ignored: list[Path] = []
    for spec in map(str, inputs):
        path = Path(spec)
        if path.is_dir():
            found, passed = regular_files(path, recursive=True)  # no link out, FIFO, device
            ignored += [p for p, _ in passed]
            for p in found:
                try:
                    sniff_format(p)
                except FormatError:
                    ignored.append(p)
                    continue
                jobs.append((p, out / p.relative_to(path).with_suffix(".h5")))
        elif path.is_file():
            jobs.append((path, out / path.with_suffix(".h5").name))
        elif glob.has_magic(spec):
            # outputs mirror the paths below the pattern's fixed folder
            prefix = spec[: min(i for i in (spec.find(c) for c in "*?[") if i >= 0)]
            base = Path(prefix) if prefix.endswith(("/", os.sep)) else Path(prefix).parent
            files = sorted(Path(p) for p in glob.glob(spec, recursive=True) if Path(p).is_file())
            jobs += [(p, out / p.relative_to(base).with_suffix(".h5")) for p in files]
        else:
            raise ParameterError(f"{spec}: no such file or folder, and not a glob pattern")
    seen: dict[Path, Path] = {}
    sources = {real_path(src): src for src, _ in jobs}
    for src, dst in jobs:
        if dst in seen and seen[dst] != src:
            raise ParameterError(f"{seen[dst]} and {src} would both be written to {dst}")
        seen[dst] = src
        if real_path(dst) in sources:  # the output would replace an input
            check_not_input(dst, [sources[real_path(dst)]])
    if not jobs:
        raise ParameterError(f"no recordings found in {', '.join(map(str, inputs))}")
    return jobs, ignored


#: Calibrations parsed on this worker, by their id (a task gets the JSON description).
_CALIBRATIONS: dict[str, StageChain] = {}


def _task(src: str, calibration: dict[str, Any], dst: str, options: dict[str, Any]) -> dict:
    """One file on a worker: the report as a dict; an expected failure (a bad file or
    parameter) is a ``failed`` report, anything else propagates to the driver."""
    key = content_hash(calibration)
    cal = _CALIBRATIONS.get(key)
    if cal is None:
        cal = _CALIBRATIONS[key] = StageChain.from_dict(calibration, "<calibration>")
    try:
        return asdict(process_file(src, cal, dst, ProcessOptions(**options)))
    except (OSError, ValueError) as e:  # FormatError, ParameterError, ShapeError among them
        return asdict(FileReport(src, dst, "failed", error=f"{type(e).__name__}: {e}"))


#: Inputs of fewer bytes than this, in all, are processed in this process when no scheduler
#: and no worker count is given: a local cluster's start (scheduler, worker processes that each
#: import texsense) costs ~1.5 s and ~5 CPU-s on the 2-core machine, more than such an archive
#: takes to process (two seat sessions, 0.6 MB: 0.7 CPU-s in this process).
IN_PROCESS_BYTES = 32 << 20


def process_archive(
    jobs: Sequence[tuple[Path, Path]],
    calibration: str | Path,
    options: ProcessOptions | None = None,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
) -> list[FileReport]:
    """Process every (source, output) pair, one Dask task per file.

    Parameters
    ----------
    jobs : sequence of (Path, Path)
        From :func:`archive_jobs`. Sources and outputs must be reachable by the workers
        under the same paths (a shared file system for a remote cluster).
    calibration : path
        The calibration file; it is read here and sent to the workers with each task.
    options : ProcessOptions, optional
        Pipeline settings (default: all stages, harmonic repair).
    scheduler : str, optional
        Address of a running ``dask.distributed`` scheduler (``tcp://host:8786``). Default:
        a local cluster of worker processes, one thread each.
    workers : int, optional
        Worker processes of the local cluster (default: one per core, at most one per file).
        ``1``, or neither this nor ``scheduler`` given and the inputs smaller than
        :data:`IN_PROCESS_BYTES` in all: the files are processed one after the other in this
        process, with the same reports.
    """
    # a bad file fails here, once, not in every task; the workers get the chain's content
    cal_dict = load_chain(calibration).to_dict()
    opts = asdict(options or ProcessOptions())
    if scheduler is None and (workers == 1 or (workers is None and _small(jobs))):
        reports = [
            _here(src, dst, cal_dict, opts)
            for src, dst in progress(jobs, total=len(jobs), desc="files", unit="file")
        ]
    else:
        reports = _on_dask(jobs, cal_dict, opts, scheduler, workers)
    order = {str(src): k for k, (src, _) in enumerate(jobs)}
    return sorted(reports, key=lambda r: order.get(r.source, 0))


def _here(src: Path, dst: Path, cal_dict: dict[str, Any], opts: dict[str, Any]) -> FileReport:
    """One file in this process; an unexpected error is that file's ``failed`` report, as
    a task's on a cluster is (the other files go on)."""
    try:
        return FileReport(**_task(str(src), cal_dict, str(dst), opts))
    except Exception as e:
        return FileReport(str(src), str(dst), "failed", error=f"{type(e).__name__}: {e}")


def _small(jobs: Sequence[tuple[Path, Path]]) -> bool:
    """One file, or inputs of fewer than :data:`IN_PROCESS_BYTES` in all."""
    if len(jobs) == 1:
        return True
    total = 0
    for src, _ in jobs:
        try:
            total += src.stat().st_size
        except OSError:  # the task reports it
            continue
        if total >= IN_PROCESS_BYTES:
            return False
    return True


def _on_dask(
    jobs: Sequence[tuple[Path, Path]],
    cal_dict: dict[str, Any],
    opts: dict[str, Any],
    scheduler: str | None,
    workers: int | None,
) -> list[FileReport]:
    """One Dask task per file, on the scheduler at ``scheduler`` or on a local cluster of
    ``workers`` processes (default: one per core, at most one per file)."""
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        n = workers or min(os.cpu_count() or 1, len(jobs))
        one_thread = {
            k: "1" for k in ("RAYON_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")
        }
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            env=one_thread,
            # a worker's heartbeat to a scheduler closing at the end is logged as an error
            # with a traceback on a loaded machine; a task's own failure comes back through
            # its future (a FileReport), so the cluster's logs stay quiet
            silence_logs=logging.CRITICAL,
        )
        client = Client(cluster)
    else:
        client = Client(scheduler)
    reports: list[FileReport] = []
    try:
        # the calibration goes to every worker once, not with every task
        cal_on_workers = client.scatter(cal_dict, broadcast=True)
        futures = {
            client.submit(_task, str(src), cal_on_workers, str(dst), opts, pure=False): (src, dst)
            for src, dst in jobs
        }
        for fut in progress(as_completed(futures), total=len(futures), desc="files", unit="file"):
            src, dst = futures[fut]
            try:
                reports.append(FileReport(**fut.result()))
            except Exception as e:  # a worker died or an unexpected error: report, go on
                reports.append(
                    FileReport(str(src), str(dst), "failed", error=f"{type(e).__name__}: {e}")
                )
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return reports
