//! The C ABI from Rust: a chain compiled by texsense-core (f64) written as a blob and run
//! through `ts_*` (f32) gives the same codes and values within float32's precision; the
//! memory it asks for is what it uses; a damaged blob is refused.

use texsense_core::chain::{Chain, Stage};
use texsense_core::detect::{DetectorParams, FailureDetector};
use texsense_core::drift::{DriftBank, Kernel};
use texsense_core::repair::{LocalRepair, Method};
use texsense_core::{Compensation, Converter, Curve, Everett, Neighbours, PreisachBank};
use texsense_mcu::*;

const ROWS: usize = 6;
const COLS: usize = 7;
const N: usize = ROWS * COLS;

fn noise(k: usize) -> f64 {
    let x = (k as u64 + 1).wrapping_mul(6_364_136_223_846_793_005);
    ((x >> 11) % 1_000_000) as f64 / 1e6
}

fn chain() -> Chain {
    let k = 25;
    let mut table = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..i {
            let d = (i - j) as f64 / (k - 1) as f64;
            table[i * k + j] = 0.5 * d * d + 0.1 * d;
        }
    }
    let everett = Everett::new(k, 0.0, 2.4, table).unwrap();
    let preisach = PreisachBank::new(everett, N, 8)
        .and_then(|p| p.with_output(-0.05, 1.0))
        .unwrap();
    let kernel = Kernel::new(vec![0.3, 0.4, 0.5], vec![0.5, 20.0, 900.0]).unwrap();
    let drift = DriftBank::new(kernel, -0.03, N)
        .and_then(|d| d.with_rest_rate(0.2, 0.5))
        .unwrap();
    let params = DetectorParams {
        min_pf: 0.05,
        low_share: 0.5,
        high_share: 1.2,
        stuck_frames: 5,
        stuck_pf: 1e-4,
        neighbour_change_pf: 0.05,
        stuck_floor_pf: f64::NEG_INFINITY,
    };
    let nb = Neighbours::grid4(ROWS, COLS);
    let detector = FailureDetector::new(
        params,
        nb.clone(),
        vec![3.0; N],
        Some(vec![10.0; N]),
        Some(vec![15.0; N]),
    )
    .unwrap();
    let curve = Curve::new(vec![10.0, 11.0, 12.5, 15.0], vec![0.0, 0.8, 1.6, 2.4]).unwrap();
    let offset = (0..N).map(|i| 0.1 * noise(i)).collect();
    let gain = (0..N).map(|i| 0.9 + 0.2 * noise(i + 99)).collect();
    let stages = vec![
        Stage::Detect(detector),
        Stage::Convert(Converter::new(offset, gain, Some(curve)).unwrap()),
        Stage::Compensation(Compensation::new(preisach, Some(drift)).unwrap()),
        Stage::Repair(LocalRepair::new(Method::NeighbourMean(nb), N).unwrap()),
    ];
    Chain::new(N, stages).unwrap()
}

/// 4-byte aligned copy of a blob.
fn aligned(blob: &[u8]) -> Vec<u32> {
    blob.chunks(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[test]
fn the_c_abi_runs_the_chain_in_f32_as_the_core_runs_it_in_f64() {
    let mut reference = chain();
    let blob = reference.mcu_blob().unwrap();
    let words = aligned(&blob);
    let (bp, bl) = (words.as_ptr().cast::<u8>(), blob.len());
    let mut need = 0usize;
    // SAFETY: a live, aligned blob and a writable size
    assert_eq!(unsafe { ts_mem_size(bp, bl, &mut need) }, TS_OK);
    let mut mem = vec![0u64; need / 8 + 1];
    let mut mat: *mut ts_mat = std::ptr::null_mut();
    let mp = mem.as_mut_ptr().cast::<u8>();
    // SAFETY: memory and blob live for the whole test
    unsafe {
        assert_eq!(
            ts_init(mp, need - 1, bp, bl, N as u32, &mut mat),
            TS_ERR_MEMORY
        );
        assert_eq!(
            ts_init(mp, need, bp, bl, N as u32 + 1, &mut mat),
            TS_ERR_ELEMENTS
        );
        assert_eq!(ts_init(mp, need, bp, bl, N as u32, &mut mat), TS_OK);
        assert_eq!(ts_n_elements(mat), N as u32);
    }
    let (t, mut worst) = (300, 0.0f64);
    for k in 0..t {
        let dt = if k == 0 { 0.0 } else { 0.1 };
        let r: Vec<f64> = (0..N)
            .map(|i| {
                let x = 10.5 + 3.5 * noise(k * N + i) * (1.0 + (k as f64 / 9.0).sin()) / 2.0;
                if noise(k * N + i + 3) < 0.03 {
                    0.0
                } else {
                    x as f32 as f64
                }
            })
            .collect();
        let valid: Vec<bool> = (0..N).map(|i| noise(k * N + i + 7) > 0.02).collect();
        let (mut want, mut want_codes) = (vec![0.0; N], vec![0u8; N]);
        reference
            .run(&[dt], &r, &valid, &mut want, &mut want_codes)
            .unwrap();
        let r32: Vec<f32> = r.iter().map(|&v| v as f32).collect();
        let v8: Vec<u8> = valid.iter().map(|&v| u8::from(v)).collect();
        let (mut got, mut codes) = (vec![0.0f32; N], vec![0u8; N]);
        // SAFETY: arrays of N elements
        let s = unsafe {
            ts_step(
                mat,
                r32.as_ptr(),
                v8.as_ptr(),
                dt as f32,
                got.as_mut_ptr(),
                codes.as_mut_ptr(),
            )
        };
        assert_eq!(s, TS_OK);
        assert_eq!(codes, want_codes, "frame {k}");
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.is_nan(), w.is_nan(), "frame {k}");
            if w.is_finite() {
                worst = worst.max((f64::from(*g) - w).abs() / w.abs().max(0.1));
            }
        }
    }
    assert!(worst < 2e-5, "worst relative difference {worst}");
    // a flipped bit anywhere in the blob: refused, nothing initialised
    for at in [20, bl / 3, bl - 2] {
        let mut bad = blob.clone();
        bad[at] ^= 1;
        let w = aligned(&bad);
        // SAFETY: as above
        let s = unsafe { ts_init(mp, need, w.as_ptr().cast(), bl, N as u32, &mut mat) };
        assert!(
            s == TS_ERR_CHECKSUM || s == TS_ERR_FORMAT,
            "flip at {at}: {s}"
        );
    }
}
