"""The compiled pipeline runs any chain the stage contract allows, as written: chains of every
allowed shape (up to four stages of detect, convert, linear, hysteresis, drift, QLV drift and
the repairs, in any order StageChain accepts) give, compiled, the numbers of their stages run
one after the other in Python, to the bit; a stage without a compiled kernel is refused in one
line naming it. And a pipeline's state continues a stream in another pipeline to the bit."""

from __future__ import annotations

import copy
import itertools

import numpy as np
import pytest

from texsense.calibration.workflows import material_record
from texsense.compensation.drift import DriftModel, log_kernel
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stage import STAGES, Stage
from texsense.compensation.stages import (
    Convert,
    Drift,
    FailureDetector,
    Hysteresis,
    Linear,
    Repair,
    StageChain,
)
from texsense.exceptions import ParameterError
from texsense.sim import protocols
from texsense.sim.failures import FailureModel
from texsense.sim.mat import VirtualMat


@pytest.fixture(scope="module")
def world():
    """A 16-element virtual mat: its stages fitted (one of each kind, and the variants), and a
    session with failures as capacitance, compression and pressure."""
    mat = VirtualMat.prototype(16, "textile-3mm", seed=4)
    lay, n = mat.layout, mat.layout.n_elements
    ft = mat.cdc.frame_time_s(n)
    base = mat.scan(np.arange(8) * ft, np.zeros((8, n))).capacitance
    uni = mat.scan((8 + np.arange(8)) * ft, np.full((8, n), 1.0)).capacitance
    material = material_record(
        protocols.run_protocol("calibration", "textile-3mm", seed=9, sample_hz=None)
    )
    convert = Convert(3.0).fit(material, base, uni)
    lo, hi = convert.expected_range_pF()
    detect = FailureDetector(lay, stuck_frames=6).fit(lo, hi)
    # the thesis's identification on a small grid: fitted in milliseconds
    hyst = Hysteresis("thesis", grid=30).fit(material["compression_mm"], material["pressure_ncm2"])
    model = hyst.model_
    stages = {
        "D": detect,
        "C": convert,
        # capacitance -> compression in one straight line per element (a linear calibration)
        "L": Linear("capacitance", "pF", "compression", "mm").fit(lo, (hi - lo) / model.u_max_),
        "P": Linear("pressure", "N/cm2").fit(np.zeros(n), np.full(n, 0.98)),
        "H": hyst,
        "T": Drift.of(DriftModel(-0.03, log_kernel(), "log", rest_rate=0.2)),
        "Q": Drift.of(
            DriftModel(-0.03, log_kernel(), level="backbone", backbone=model.backbone_curve())
        ),
        "R": Repair(lay, "idw8").fit(),
        "Z": Repair(lay, "harmonic").fit(),
    }
    session = VirtualMat.prototype(
        16, "textile-3mm", seed=4, failures=FailureModel(onset_per_hour=400.0)
    )
    times = np.arange(60) * ft * 8
    load = 1.4 + np.sin(times / 3.0)[:, None] * np.linspace(0.3, 1.1, n)[None, :]
    cap = session.scan(times, np.clip(load, 0, None)).capacitance
    flagged = np.random.default_rng(1).random(cap.frames.shape) < 0.02
    cap = cap._with(valid=cap.valid & ~flagged)
    compression = StageChain([detect, convert]).reset().run(cap)
    pressure = StageChain([hyst]).reset().run(compression)
    inputs = {"capacitance": cap, "compression": compression, "pressure": pressure}
    return stages, inputs, lay


#: Chains with the harmonic repair (which solves in scipy between compiled passes, frame by
#: frame: slow, so not in every position of every shape)
HARMONIC = ("Z", "ZDCH", "DCZHT", "DCHZ", "DZCRHQ", "HZT")


def allowed_chains(stages):
    """Every sequence of up to four stages (the harmonic repair aside) that StageChain
    accepts, and the chains of :data:`HARMONIC`."""
    local = [k for k in stages if k != "Z"]
    shapes = itertools.chain.from_iterable(
        itertools.product(local, repeat=length) for length in range(1, 5)
    )
    for names in itertools.chain(shapes, HARMONIC):
        try:
            yield "".join(names), StageChain([stages[k] for k in names])
        except ParameterError:
            assert names not in HARMONIC
            continue


def input_of(chain, inputs):
    """The recording a chain reads (what its first stage that names a quantity reads)."""
    for s in chain.stages:
        if s.reads[0]:
            return inputs[s.reads[0]]
    return inputs["pressure"]


def by_stages(stages, rec):
    """The stages run one after the other in Python: StageChain's own batch path, on a chain
    built without its check of quantities (the detector a linear calibration implies reads
    whatever that calibration reads, not only capacitance)."""
    chain = object.__new__(StageChain)
    chain.stages, chain._last_t = [copy.deepcopy(s) for s in stages], None
    return chain._arrays(rec.frames, rec.valid, rec.times)


def test_every_allowed_chain_runs_compiled_as_written(world):
    stages, inputs, lay = world
    shapes = 0
    for names, chain in allowed_chains(stages):
        rec = input_of(chain, inputs)
        # nothing added: the default repair goes only to a chain without a repair stage
        own = any(isinstance(s, Repair) for s in chain.stages)
        pipe = Pipeline(chain, lay) if own else Pipeline(chain, lay, repair=None)
        # the plan is the chain as written (plus the implied detector of a chain that has
        # none, right before its conversion)
        written = [s.name for s in chain.stages]
        plan = [s.name for s in pipe.plan]
        if "detect" not in written and ("convert" in written or "linear" in written):
            first = next(i for i, s in enumerate(written) if s in ("convert", "linear"))
            written.insert(first, "detect")
        assert plan == written, names
        values, ok = by_stages(pipe.plan, rec)
        got, got_ok, _ = pipe.process(rec.frames, rec.times, rec.valid)
        np.testing.assert_array_equal(got_ok, ok, err_msg=names)
        np.testing.assert_array_equal(got, values, err_msg=names)
        # streaming is the same code with one frame
        if shapes % 15 == 0:
            pipe.reset()
            rows = [pipe.step(rec.frames[k], rec.valid[k], rec.times[k])[0] for k in range(30)]
            np.testing.assert_array_equal(rows, got[:30], err_msg=names)
        shapes += 1
    # each kind of stage in every position a chain allows it: hundreds of shapes
    assert shapes == 352 + len(HARMONIC), shapes


def test_a_stage_without_a_compiled_kernel_is_refused_naming_it(world):
    stages, _, lay = world

    class Smooth(Stage):
        """A stage added in one module (it registers itself by its name)."""

        name = "smooth"

        def __init__(self) -> None:
            pass

        def fit(self) -> Smooth:
            return self.set_fitted(width=3)

        def _block(self, values, valid, dt):
            return values, valid

        def _fitted_json(self):
            return {"width": self.width_}

    try:
        chain = StageChain([stages["C"], Smooth().fit(), stages["H"]])
        with pytest.raises(ParameterError, match=r"stage 2 of the chain .*\(smooth, Smooth\) has"):
            Pipeline(chain, lay)
    finally:
        del STAGES["smooth"]  # registered for this test only


def test_a_repair_in_the_chain_runs_where_it_stands(world):
    stages, inputs, lay = world
    chain = StageChain([stages[k] for k in "DCRH"])
    pipe = Pipeline(chain, lay)  # the default repair is not added to a chain with its own
    assert pipe.stage_names() == ["detect", "convert", "repair:idw8", "hysteresis"]
    rec = inputs["capacitance"]
    values, _ = by_stages(chain.stages, rec)
    np.testing.assert_array_equal(pipe.process(rec.frames, rec.times, rec.valid)[0], values)
    none = Pipeline(chain, lay, repair=None)
    assert none.stage_names() == ["detect", "convert", "hysteresis"]


@pytest.mark.parametrize("repair", ["neighbour-mean", "harmonic-temporal"])
def test_a_snapshot_continues_the_stream_in_a_fresh_pipeline_to_the_bit(world, repair):
    stages, inputs, lay = world
    chain = StageChain([stages[k] for k in "DCHT"])
    rec = inputs["capacitance"]
    whole = Pipeline(chain, lay, repair=repair).run(rec)
    half = rec.n_frames // 2
    first = Pipeline(chain, lay, repair=repair)
    first.run(rec.select(slice(0, half)))
    state = first.snapshot()
    second = Pipeline(copy.deepcopy(chain), lay, repair=repair).restore(state)
    rest = second.run(rec.select(slice(half, None)))
    np.testing.assert_array_equal(rest.frames, whole.frames[half:])
    np.testing.assert_array_equal(rest.valid, whole.valid[half:])
    # a frame earlier than the snapshot's last is refused, as in the first pipeline
    with pytest.raises(ParameterError, match="must not decrease"):
        Pipeline(chain, lay, repair=repair).restore(state).step(rec.frames[0], None, rec.times[0])


def test_a_state_that_does_not_fit_is_refused_and_changes_nothing(world):
    stages, inputs, lay = world
    chain = StageChain([stages[k] for k in "DCHT"])
    rec = inputs["capacitance"]
    pipe = Pipeline(chain, lay, repair="neighbour-mean")
    pipe.run(rec.select(slice(0, 20)))
    state = pipe.snapshot()
    before = pipe.snapshot()
    other = Pipeline(StageChain([stages[k] for k in "DCH"]), lay, repair="neighbour-mean")
    k = state.index(b"TXSNSNAP")  # the compiled chain's section
    cases = {
        "not a texsense pipeline state": b"hello",
        "calibration": other.snapshot(),
        "cut short or has bytes left over": state[:-5],
        "has bytes left over": state + b"\x00\x00",
        "version 9": state[:8] + (9).to_bytes(4, "little") + state[12:],
        "does not fit this pipeline: snapshot: not a texsense chain snapshot": (
            state[:k] + b"X" + state[k + 1 :]
        ),
    }
    for why, bad in cases.items():
        with pytest.raises(ParameterError, match=why):
            pipe.restore(bad)
        assert pipe.snapshot() == before
    # the same calibration processed with other stages switched
    no_drift = Pipeline(chain, lay, repair="neighbour-mean", drift=False)
    with pytest.raises(ParameterError, match="of the stages"):
        no_drift.restore(state)
