#!/usr/bin/env bash
# The main job: set up .venv, then a short end-to-end run on real data (until the live
# monitor exists): summarise the PhysioNet PMD tree and one subject, convert the subject to
# HDF5 and plot its peak frame. Output goes to out/.
source "$(dirname "${BASH_SOURCE[0]}")/_bootstrap.sh"
DATA="${TEXSENSE_SHARED_DATA:-$ROOT/../shared/data}"
mkdir -p out
say "texsense info $DATA/pmd/experiment-i"
texsense info "$DATA/pmd/experiment-i"
say "texsense convert (PMD subject S1 -> out/pmd-S1.h5)"
texsense convert "$DATA/pmd/experiment-i/S1" out/pmd-S1.h5
say "texsense plot out/pmd-S1.h5 -o out/pmd-S1.png"
texsense plot out/pmd-S1.h5 -o out/pmd-S1.png
say "texsense plot (Tekscan F-Scan walk) -o out/fscan.png"
texsense plot "$DATA/vendor-formats/fscan_testL.asf" -o out/fscan.png --unit kPa
say "done: see out/pmd-S1.png and out/fscan.png"
