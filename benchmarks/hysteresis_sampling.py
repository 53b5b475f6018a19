"""How finely must a record be sampled for a Preisach model? The model of a calibration
record at each rate, run on the validation cycles (§4.5) at each rate: RMSE, and how many
turning points of the validation input fall between samples
(texsense.compensation.hysteresis.sampling).

Run:  .venv/bin/python benchmarks/hysteresis_sampling.py
"""

from __future__ import annotations

import numpy as np

from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.hysteresis.sampling import _nice_rate, coarse_turns
from texsense.sim.protocols import run_protocol

RATES = (10.0, 20.0, 50.0, 100.0)


def main() -> None:
    models = {}
    for hz in (10.0, 50.0):
        cal = run_protocol("calibration", "textile-6mm", seed=1, sample_hz=hz)
        u, y = cal.labels["compression_mm"], cal.labels["pressure_ncm2"]
        models[hz] = (HysteresisModel().fit(u, y), coarse_turns(u, cal.times))
    print("textile-6mm, seed 1; validation: 50 cycles 0-10-1.3-10-0-1.3-0 N/cm² at 50 mm/min\n")
    print(
        "| calibration | validation | RMSE (N/cm²) | turning points between samples "
        "| warning names |"
    )
    print("|---:|---:|---:|---:|---:|")
    for cal_hz, (model, cal_turns) in models.items():
        assert cal_turns.unresolved == 0, cal_turns  # the calibration curves turn slowly
        for hz in RATES:
            val = run_protocol("validation", "textile-6mm", seed=1, sample_hz=hz)
            u, y = val.labels["compression_mm"], val.labels["pressure_ncm2"]
            rmse = float(np.sqrt(np.nanmean((model.predict(u) - y) ** 2)))
            c = coarse_turns(u, val.times, span=model.u_max_ - model.u_min_)
            named = f"{_nice_rate(c.needed_hz):g} Hz" if c.unresolved else "–"
            print(
                f"| {cal_hz:g} Hz | {hz:g} Hz | {rmse:.4f} | {c.unresolved} of {c.turns} | "
                f"{named} |"
            )


if __name__ == "__main__":
    main()
