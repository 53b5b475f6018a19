"""``texsense design``: the design rules for a textile capacitive sensor."""

from __future__ import annotations

import argparse
import json

from texsense.commands import HELP
from texsense.sensor.design import design_report


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``design`` command."""
    p = sub.add_parser(
        "design",
        help=HELP["design"],
        description="Apply the thesis's design rules (§2.3.2, §7.2) to a sensor specification.",
    )
    p.add_argument("--thickness-mm", type=float, default=3.0, help="spacer thickness (3)")
    p.add_argument("--electrode-cm", type=float, default=2.0, help="electrode side (2)")
    p.add_argument("--target-pf", type=float, default=2.0, help="minimal capacitance (2 pF)")
    p.add_argument("--rows", type=int, default=15, help="rows of elements (15)")
    p.add_argument("--cols", type=int, default=16, help="columns of elements (16)")
    p.add_argument(
        "--spacing-mm", type=float, default=7.0, help="spacing between electrodes for lines (7)"
    )
    p.add_argument(
        "--line-distance-mm",
        type=float,
        default=2.0,
        help="distance lines keep to each neighbour (2)",
    )
    p.add_argument("--update-hz", type=float, default=0.625, help="frame rate wanted (0.625)")
    p.add_argument("--converters", type=int, default=1, help="parallel converters (1)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run ``texsense design``."""
    r = design_report(
        thickness_mm=args.thickness_mm,
        electrode_side_cm=args.electrode_cm,
        target_pF=args.target_pf,
        spacing_mm=args.spacing_mm,
        line_distance_mm=args.line_distance_mm,
        rows=args.rows,
        cols=args.cols,
        update_hz=args.update_hz,
        converters=args.converters,
    )
    if args.json:
        print(json.dumps(r.as_dict(), indent=2))
        return 0
    layers = (
        "none (fits between the electrodes)"
        if r.routing_layers == 0
        else ("no line fits: widen the spacing" if r.routing_layers < 0 else str(r.routing_layers))
    )
    print(f"""sensor: {r.rows} x {r.cols} electrodes of {r.electrode_side_cm} cm on a \
{r.thickness_mm} mm spacer
  capacitance           {r.capacitance_unloaded_pF:.2f} pF unloaded, \
{r.capacitance_70pct_pF:.2f} pF at 70 % compression
  smallest electrode    {r.min_side_physics_cm * 10:.1f} mm for {args.target_pf} pF \
(plate + edge field + stray); thesis rule A/d > 1.9 cm: {r.min_side_thesis_rule_cm * 10:.1f} mm
  grid pitch            >= {r.min_pitch_mm:.1f} mm (electrode + 2 mm embroidery spacing)
  connections           {r.connections_single} (single electrodes + common), \
{r.connections_stripes} (perpendicular stripes)
  lines between         {r.lines_between} per gap; extra routing layers: {layers}
  frame time            {r.frame_time_s:.2f} s with {r.converters} converter(s)
  elements at rate      {r.max_elements_at_update} at {args.update_hz} Hz""")
    return 0
