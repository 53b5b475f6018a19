//! A mat in the caller's memory: a header, then the states of every stage in the blob's
//! order, then the scratch of a frame. Everything has a fixed size per element ([`Memory`]);
//! the layout is recomputed from the blob (a walk over its stage headers) at every call, so
//! the mat holds no pointer into itself.

use core::mem::{align_of, size_of};
use core::slice;

use texsense_kernels::blob::{Model, StageView};
use texsense_kernels::detect::{self, codes, Limits};
use texsense_kernels::drift;
use texsense_kernels::preisach::{self, Head};
use texsense_kernels::repair::repair_frame;
use texsense_kernels::stage as rules;

use crate::{blob_status, TS_ERR_STATE, TS_OK};

/// "TSMT": a mat that [`Mat::init`] set up.
const MAGIC: u32 = 0x544d_5354;

/// A reading invalid on input that no detect stage has coded yet.
const UNSET: u8 = u8::MAX;

/// The memory a mat needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Memory {
    /// Bytes of state per element, all stages together.
    pub state_per_element: usize,
    /// Bytes of scratch per element (a frame's work array and codes).
    pub scratch_per_element: usize,
    /// Bytes that do not grow with the elements (header, per-stage scratch, alignment).
    pub fixed: usize,
    /// Number of elements.
    pub n: usize,
}

impl Memory {
    /// All of it: what `ts_mem_size` reports.
    pub fn total(&self) -> usize {
        self.fixed + self.n * (self.state_per_element + self.scratch_per_element)
    }
}

/// Types that are plain data for every bit pattern (the states carved out of raw memory).
///
/// # Safety
/// Every bit pattern of the type's size must be a valid value.
unsafe trait Pod: Copy {}
// SAFETY: floats, integers and repr(C) structs of them (no padding bytes are read as
// anything but bytes)
unsafe impl Pod for f32 {}
// SAFETY: as above
unsafe impl Pod for u8 {}
// SAFETY: as above
unsafe impl Pod for [f32; 2] {}
// SAFETY: repr(C) { u32, f32, f32 }
unsafe impl Pod for Head<f32> {}
// SAFETY: repr(C) { f32, u32, f32 }
unsafe impl Pod for detect::Element<f32> {}
// SAFETY: repr(C) { f32, f32, f32, u32 }
unsafe impl Pod for drift::Element<f32> {}

/// Hands out consecutive, aligned, disjoint arrays of a region (or, without one, counts
/// the bytes they would take).
struct Carver<'m> {
    rest: &'m mut [u8],
    used: usize,
}

impl<'m> Carver<'m> {
    fn counting() -> Self {
        Carver {
            rest: &mut [],
            used: 0,
        }
    }

    fn take<T: Pod>(&mut self, count: usize) -> &'m mut [T] {
        let pad = (align_of::<T>() - self.used % align_of::<T>()) % align_of::<T>();
        let bytes = pad + count * size_of::<T>();
        self.used += bytes;
        if self.rest.len() < bytes {
            // counting (or a region too small, which `ts_init` rules out)
            self.rest = &mut [];
            return &mut [];
        }
        let rest = core::mem::take(&mut self.rest);
        let (head, tail) = rest.split_at_mut(bytes);
        self.rest = tail;
        if count == 0 {
            return &mut [];
        }
        let p = head[pad..].as_mut_ptr();
        debug_assert_eq!(p as usize % align_of::<T>(), 0);
        // SAFETY: `head[pad..]` is `count * size_of::<T>()` bytes of this region, aligned for
        // T (the region starts 8-aligned and `used` tracks the offset), not handed out
        // before (split off), and every bit pattern is a T (Pod)
        unsafe { slice::from_raw_parts_mut(p.cast::<T>(), count) }
    }
}

/// One stage's parameters (in the blob) and state (in the mat's memory).
enum Slot<'a> {
    Detect {
        params: detect::Params<f32>,
        jump: &'a [f32],
        baseline: Option<&'a [f32]>,
        max: Option<&'a [f32]>,
        graph: texsense_kernels::graph::Graph<'a>,
        el: &'a mut [detect::Element<f32>],
    },
    Convert {
        offset: &'a [f32],
        gain: &'a [f32],
        curve: Option<texsense_kernels::convert::Curve<'a, f32>>,
    },
    Loading(texsense_kernels::convert::Curve<'a, f32>),
    Hysteresis {
        everett: texsense_kernels::everett::Everett<'a, f32>,
        capacity: usize,
        output: preisach::Output<f32>,
        heads: &'a mut [Head<f32>],
        stacks: &'a mut [[f32; 2]],
    },
    Drift {
        settings: drift::Settings<'a, f32>,
        level: Option<texsense_kernels::convert::Curve<'a, f32>>,
        el: &'a mut [drift::Element<f32>],
        z: &'a mut [f32],
        z_time: &'a mut [f32],
        decay: &'a mut [f32],
    },
    Repair {
        method: texsense_kernels::repair::Method<'a, f32>,
        last: &'a mut [f32],
    },
}

impl Slot<'_> {
    fn elementwise(&self) -> bool {
        !matches!(self, Slot::Detect { .. } | Slot::Repair { .. })
    }

    /// Every element at its initial state.
    fn reset(&mut self) {
        match self {
            Slot::Detect { el, .. } => el.iter_mut().for_each(|e| *e = Default::default()),
            Slot::Hysteresis {
                everett,
                capacity,
                heads,
                stacks,
                ..
            } => {
                for (h, s) in heads.iter_mut().zip(stacks.chunks_exact_mut(*capacity + 1)) {
                    preisach::start(h, s, everett.u_min());
                }
            }
            Slot::Drift { el, z, z_time, .. } => {
                el.iter_mut().for_each(|e| *e = Default::default());
                z.iter_mut().chain(z_time.iter_mut()).for_each(|v| *v = 0.0);
            }
            Slot::Repair { last, .. } => last.iter_mut().for_each(|v| *v = f32::NAN),
            Slot::Convert { .. } | Slot::Loading(_) => {}
        }
    }
}

/// The scratch of a frame.
struct Scratch<'a> {
    work: &'a mut [f32],
    neighbours: &'a mut [f32],
    codes: &'a mut [u8],
}

/// The slots of every stage and the scratch, carved in this order from `carver`.
fn carve<'a>(
    model: &Model<'a>,
    carver: &mut Carver<'a>,
    slots: &mut [Option<Slot<'a>>; texsense_kernels::blob::MAX_STAGES],
) -> Result<Scratch<'a>, i32> {
    let n = model.n_elements();
    let mut max_degree = 0;
    for (slot, view) in slots.iter_mut().zip(model.stages()) {
        *slot = Some(match view.map_err(blob_status)? {
            StageView::Detect {
                params,
                jump,
                baseline,
                max,
                graph,
            } => {
                max_degree = max_degree.max(graph.max_degree());
                Slot::Detect {
                    params,
                    jump,
                    baseline,
                    max,
                    graph,
                    el: carver.take(n),
                }
            }
            StageView::Convert {
                offset,
                gain,
                curve,
            } => Slot::Convert {
                offset,
                gain,
                curve,
            },
            StageView::Loading(c) => Slot::Loading(c),
            StageView::Hysteresis {
                everett,
                capacity,
                output,
            } => Slot::Hysteresis {
                everett,
                capacity,
                output,
                heads: carver.take(n),
                stacks: carver.take(n * (capacity + 1)),
            },
            StageView::Drift { settings, level } => {
                let k = settings.terms();
                let clocks = if settings.has_time_states() { n * k } else { 0 };
                Slot::Drift {
                    settings,
                    level,
                    el: carver.take(n),
                    z: carver.take(n * k),
                    z_time: carver.take(clocks),
                    decay: carver.take(k),
                }
            }
            StageView::Repair(method) => Slot::Repair {
                method,
                last: carver.take(n),
            },
        });
    }
    Ok(Scratch {
        work: carver.take(n),
        neighbours: carver.take(max_degree),
        codes: carver.take(n),
    })
}

/// The memory a mat of this (parsed) blob needs.
pub fn memory(model: &Model<'_>) -> Memory {
    let count = |n: usize| {
        // the layout of the same stages with n elements (linear in n)
        let mut c = Carver::counting();
        c.used = size_of::<Header>();
        carve_n(model, n, &mut c);
        c.used
    };
    let n = model.n_elements();
    let (one, two) = (count(1), count(2));
    let per_element = two - one;
    let scratch = size_of::<f32>() + size_of::<u8>();
    Memory {
        state_per_element: per_element - scratch,
        scratch_per_element: scratch,
        // alignment padding varies with n: take the real count for the total
        fixed: count(n) - n * per_element,
        n,
    }
}

/// [`carve`] as if the model had `n` elements (for counting only; a parsed model).
fn carve_n(model: &Model<'_>, n: usize, carver: &mut Carver<'_>) {
    let mut max_degree = 0;
    for view in model.stages().flatten() {
        match view {
            StageView::Detect { graph, .. } => {
                max_degree = max_degree.max(graph.max_degree());
                carver.take::<detect::Element<f32>>(n);
            }
            StageView::Hysteresis { capacity, .. } => {
                carver.take::<Head<f32>>(n);
                carver.take::<[f32; 2]>(n * (capacity + 1));
            }
            StageView::Drift { settings, .. } => {
                let k = settings.terms();
                carver.take::<drift::Element<f32>>(n);
                carver.take::<f32>(n * k);
                carver.take::<f32>(if settings.has_time_states() { n * k } else { 0 });
                carver.take::<f32>(k);
            }
            StageView::Repair(_) => {
                carver.take::<f32>(n);
            }
            StageView::Convert { .. } | StageView::Loading(_) => {}
        }
    }
    carver.take::<f32>(n);
    carver.take::<f32>(max_degree);
    carver.take::<u8>(n);
}

/// The start of a mat's memory.
#[repr(C)]
struct Header {
    magic: u32,
    n: u32,
    blob: *const u8,
    blob_len: usize,
    mem_len: usize,
}

pub(crate) struct Mat;

impl Mat {
    /// Set up a mat (blob checked, memory large enough and 8-aligned: `ts_init`).
    ///
    /// # Safety
    /// As `ts_init`, after its checks.
    pub(crate) unsafe fn init(
        mem: *mut u8,
        mem_len: usize,
        blob: *const u8,
        blob_len: usize,
    ) -> *mut u8 {
        // SAFETY: the caller's checks: the blob parsed, mem is 8-aligned and large enough
        let bytes = unsafe { slice::from_raw_parts(blob, blob_len) };
        let model = Model::parse_trusted(bytes).expect("checked by ts_init");
        let header = Header {
            magic: MAGIC,
            n: model.n_elements() as u32,
            blob,
            blob_len,
            mem_len,
        };
        // SAFETY: mem is 8-aligned, writable and at least a header long
        unsafe { core::ptr::write(mem.cast::<Header>(), header) };
        // SAFETY: as above
        let status = unsafe {
            Self::with(mem, |slots, _| {
                for s in slots.iter_mut().flatten() {
                    s.reset();
                }
            })
        };
        debug_assert_eq!(status, TS_OK);
        mem
    }

    /// `f(slots, scratch)` over the mat's stages (the blob re-read, the memory re-carved).
    ///
    /// # Safety
    /// `mem` comes from [`Mat::init`].
    unsafe fn with(mem: *mut u8, f: impl FnOnce(&mut [Option<Slot<'_>>], &mut Scratch<'_>)) -> i32 {
        // SAFETY: the caller's promise: a header at mem
        let header = unsafe { &*mem.cast::<Header>() };
        if header.magic != MAGIC {
            return TS_ERR_STATE;
        }
        // SAFETY: the blob given to ts_init, which must stay in place
        let bytes = unsafe { slice::from_raw_parts(header.blob, header.blob_len) };
        let model = match Model::parse_trusted(bytes) {
            Ok(m) if m.n_elements() == header.n as usize => m,
            _ => return TS_ERR_STATE,
        };
        let hb = size_of::<Header>();
        // SAFETY: the mat's memory after its header (mem_len checked by ts_init)
        let rest = unsafe { slice::from_raw_parts_mut(mem.add(hb), header.mem_len - hb) };
        let mut carver = Carver { rest, used: hb };
        let mut slots: [Option<Slot<'_>>; texsense_kernels::blob::MAX_STAGES] = Default::default();
        match carve(&model, &mut carver, &mut slots) {
            Ok(mut scratch) => {
                f(&mut slots[..model.n_stages()], &mut scratch);
                TS_OK
            }
            Err(_) => TS_ERR_STATE,
        }
    }

    /// `ts_reset`.
    ///
    /// # Safety
    /// `mem` comes from [`Mat::init`].
    pub(crate) unsafe fn reset(mem: *mut u8) -> i32 {
        // SAFETY: the caller's promise
        unsafe {
            Self::with(mem, |slots, _| {
                for s in slots.iter_mut().flatten() {
                    s.reset();
                }
            })
        }
    }

    /// `ts_n_elements`.
    ///
    /// # Safety
    /// `mem` comes from [`Mat::init`].
    pub(crate) unsafe fn n_elements(mem: *const u8) -> u32 {
        // SAFETY: the caller's promise
        let header = unsafe { &*mem.cast::<Header>() };
        if header.magic == MAGIC {
            header.n
        } else {
            0
        }
    }

    /// `ts_step` (dt checked).
    ///
    /// # Safety
    /// As `ts_step`.
    pub(crate) unsafe fn step(
        mem: *mut u8,
        readings: *const f32,
        valid: *const u8,
        dt: f32,
        values: *mut f32,
        codes: *mut u8,
    ) -> i32 {
        // SAFETY: the caller's promise
        let n = unsafe { Self::n_elements(mem) } as usize;
        if n == 0 {
            return TS_ERR_STATE;
        }
        // SAFETY: the caller's promise: N readings and values (they may be the same array:
        // the readings are copied into the values first and not read again)
        let out = unsafe {
            let out = slice::from_raw_parts_mut(values, n);
            core::ptr::copy(readings, out.as_mut_ptr(), n);
            out
        };
        // SAFETY: as above
        unsafe {
            Self::with(mem, |slots, scratch| {
                let codes_out: &mut [u8] = if codes.is_null() {
                    &mut *scratch.codes
                } else {
                    slice::from_raw_parts_mut(codes, n)
                };
                for (i, (c, &x)) in codes_out.iter_mut().zip(out.iter()).enumerate() {
                    let v = valid.is_null() || *valid.add(i) != 0;
                    *c = if v && x.is_finite() { codes::OK } else { UNSET };
                }
                let scratch = Scratch {
                    work: &mut *scratch.work,
                    neighbours: &mut *scratch.neighbours,
                    codes: &mut [],
                };
                frame(slots, scratch, dt, out, codes_out);
            })
        }
    }
}

/// One frame through every stage: `out` holds the readings in and the values out, `codes`
/// the validity (0: valid) in and the failure codes out.
fn frame(
    slots: &mut [Option<Slot<'_>>],
    scratch: Scratch<'_>,
    dt: f32,
    out: &mut [f32],
    codes: &mut [u8],
) {
    let Scratch {
        work, neighbours, ..
    } = scratch;
    let mut k = 0;
    while k < slots.len() {
        let elementwise = slots[k].as_ref().map_or(false, Slot::elementwise);
        if elementwise {
            let end = (k..slots.len())
                .find(|&j| !slots[j].as_ref().map_or(false, Slot::elementwise))
                .unwrap_or(slots.len());
            segment(&mut slots[k..end], dt, out, codes);
            k = end;
            continue;
        }
        match slots[k].as_mut() {
            Some(Slot::Detect {
                params,
                jump,
                baseline,
                max,
                graph,
                el,
            }) => {
                for ((w, e), &x) in work.iter_mut().zip(el.iter_mut()).zip(out.iter()) {
                    *w = detect::change(e, x);
                }
                for (i, e) in el.iter_mut().enumerate() {
                    let nbs = graph.of(i);
                    let nb_move = detect::neighbour_move(nbs, work, 0, neighbours);
                    let lim = Limits {
                        jump: jump[i],
                        baseline: baseline.map(|b| b[i]),
                        max: max.map(|m| m[i]),
                    };
                    let ok = codes[i] == codes::OK;
                    let found = detect::code(
                        params,
                        e,
                        lim,
                        out[i],
                        ok,
                        work[i],
                        nb_move,
                        !nbs.is_empty(),
                    );
                    if ok || codes[i] == UNSET {
                        codes[i] = found;
                    }
                }
            }
            Some(Slot::Repair { method, last }) => {
                let c: &[u8] = codes;
                repair_frame(method, last, out, |j| c[j] == codes::OK, work, None);
            }
            _ => {}
        }
        k += 1;
    }
    for c in codes.iter_mut() {
        if *c == UNSET {
            *c = codes::OUT_OF_RANGE;
        }
    }
}

/// A run of element-wise stages, element after element (the hysteresis stage's input kept
/// for a QLV drift right after it).
fn segment(slots: &mut [Option<Slot<'_>>], dt: f32, out: &mut [f32], codes: &mut [u8]) {
    for s in slots.iter_mut().flatten() {
        if let Slot::Drift {
            settings, decay, ..
        } = s
        {
            drift::frame(decay, settings.taus(), dt);
        }
    }
    for (i, (x_io, c)) in out.iter_mut().zip(codes.iter_mut()).enumerate() {
        let (mut x, mut ok) = (*x_io, *c == codes::OK);
        let mut u = f32::NAN;
        for s in slots.iter_mut().flatten() {
            (x, ok) = match s {
                Slot::Convert {
                    offset,
                    gain,
                    curve,
                } => rules::conversion(offset[i], gain[i], curve.as_ref(), x, ok),
                Slot::Loading(curve) => rules::loading(curve, x, ok),
                Slot::Hysteresis {
                    everett,
                    capacity,
                    output,
                    heads,
                    stacks,
                } => {
                    u = x;
                    let cap = *capacity;
                    let stack = &mut stacks[i * (cap + 1)..(i + 1) * (cap + 1)];
                    let (y, ok, _) =
                        rules::hysteresis(&mut heads[i], stack, cap, everett, *output, x, ok);
                    (y, ok)
                }
                Slot::Drift {
                    settings,
                    level,
                    el,
                    z,
                    z_time,
                    decay,
                } => {
                    let k = settings.terms();
                    let zs = &mut z[i * k..(i + 1) * k];
                    let zt: &mut [f32] = if z_time.is_empty() {
                        &mut []
                    } else {
                        &mut z_time[i * k..(i + 1) * k]
                    };
                    match level {
                        Some(curve) => rules::drift_on_level(
                            settings, &mut el[i], zs, zt, decay, dt, curve, u, x, ok,
                        ),
                        None => rules::drift(settings, &mut el[i], zs, zt, decay, dt, x, ok),
                    }
                }
                Slot::Detect { .. } | Slot::Repair { .. } => (x, ok),
            };
        }
        *x_io = x;
        if *c == codes::OK && !x.is_finite() {
            *c = codes::OUT_OF_RANGE;
        }
    }
}
