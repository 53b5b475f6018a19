"""Sub-commands of the ``texsense`` CLI; each module defines ``register(subparsers)`` and
sets ``run`` as the parser's default function.

:data:`COMMANDS` names every command, the module that registers it and its one-line help, so
``texsense --help`` lists them all without importing any (the CLI imports a command's module
only when that command runs, :mod:`texsense.cli`).
"""

#: Every command: (module of texsense.commands, one-line help), in the order of ``--help``.
COMMANDS: dict[str, tuple[str, str]] = {
    "info": ("info", "summarise a recording (shape, timing, unit, labels, load and peak)"),
    "convert": (
        "convert",
        "convert a recording to HDF5 (.h5), wide CSV (.csv) or Tekscan ASCII (.asf)",
    ),
    "plot": (
        "plot",
        "plot the map of a frame (default: the peak frame) and load / centre of force",
    ),
    "simulate": ("simulate", "run a test-machine protocol on the virtual textile sensor"),
    "seat-sessions": (
        "simulate",
        "write capacitance sessions of the virtual seat and its calibration",
    ),
    "design": (
        "design",
        "design rules: capacitance, smallest electrode, connections, routing, rates",
    ),
    "hysteresis": ("hysteresis", "identify and apply Preisach hysteresis models"),
    "drift": ("drift", "identify drift from step-and-hold records"),
    "calibrate": ("pipeline", "calibrate a whole mat (zeroing, equilibration, spacer model)"),
    "process": (
        "pipeline",
        "raw capacitance -> pressure maps (detect, convert, hysteresis, drift, repair); "
        "one file, or a whole archive on Dask",
    ),
    "repair": ("pipeline", "fill elements marked invalid"),
    "health": ("pipeline", "failure report per element of a capacitance recording"),
    "posture": ("posture", "posture classification: leave-one-subject-out evaluation, training"),
    "study": (
        "posture",
        "error-modelling study (noise, hysteresis, drift, failures) with an HTML report",
    ),
    "monitor": ("monitor", "live pressure map, posture and pressure-injury alerts in the browser"),
    "station": ("station", "a ward station: many mats over MQTT, alerts, an overview page"),
    "stocking": (
        "stocking",
        "compression stockings: pressure at B, B1, C, D, gradient, class, hours of wear",
    ),
    "muscle": ("muscle", "muscle activity from a sensor sleeve: onsets, count, relative intensity"),
    "report": (
        "report",
        "a PDF or HTML report of a recording (maps, charts, regions, events, health)",
    ),
    "record": ("record", "record raw frames from a mat (no calibration needed)"),
    "export": (
        "export",
        "export a calibration for a mat's own microcontroller (a model blob or a C array)",
    ),
    "rehash": (
        "models",
        "accept a deliberate edit of a model file (write the hash of its content)",
    ),
}

#: The one-line help of every command (what its module registers it with).
HELP: dict[str, str] = {name: text for name, (_, text) in COMMANDS.items()}
