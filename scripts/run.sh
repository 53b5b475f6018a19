#!/usr/bin/env bash
# The main job: set up .venv, then start the live monitor (docs/monitor.md) on the virtual
# seat — a simulated person on the 96-element textile seat, 10x real time — and print the
# URL of its dashboard. Ctrl-C stops it. Extra arguments go to `texsense monitor`
# (e.g. --port 9000, --source replay:FILE, --speed 1).
source "$(dirname "${BASH_SOURCE[0]}")/_bootstrap.sh"
mkdir -p out
say "texsense monitor --speed 10 (open the URL below; Ctrl-C stops)"
exec texsense monitor --speed 10 --db out/monitor.sqlite --record-dir out/recordings "$@"
