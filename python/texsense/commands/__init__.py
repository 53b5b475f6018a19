"""Sub-commands of the ``texsense`` CLI; each module defines ``register(subparsers)`` and
sets ``run`` as the parser's default function."""

from texsense.commands import (
    convert,
    design,
    drift,
    hysteresis,
    info,
    models,
    monitor,
    muscle,
    pipeline,
    plot,
    posture,
    simulate,
    station,
    stocking,
)

COMMANDS = (
    info, convert, plot, simulate, design, hysteresis, drift, pipeline, posture, monitor, station,
    stocking, muscle, models,
)  # fmt: skip
