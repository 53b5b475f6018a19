//! The Everett function of the Preisach model (thesis eq. 4.12) on a uniform `K x K` grid, and
//! the Everett terms of an input history (what identification fits the table to).
//!
//! `F(α, β) = (h_α - h_αβ) / 2` is tabulated over the identified input range
//! `[u_min, u_max]` (row = α, column = β, defined for β <= α). Between grid points it is
//! interpolated bilinearly; in the cells on the diagonal, whose upper half lies outside the
//! Preisach triangle, linearly on the lower triangle, so that `F(u, u) = 0` holds exactly.

use texsense_kernels::everett::{self as kernel, prepare_table};

use crate::error::{check_len, CoreError};

/// An Everett function on a uniform grid (its table owned; the kernel is
/// `texsense_kernels::everett`).
#[derive(Debug, Clone, PartialEq)]
pub struct Everett {
    pub(crate) k: usize,
    pub(crate) u_min: f64,
    pub(crate) u_max: f64,
    pub(crate) table: Vec<f64>,
    /// The table by cell for the SIMD path: the cell with lower corner (i, j), j <= i <=
    /// K - 2, at `4 (i (i + 1) / 2 + j)` as `F(i, j), F(i, j + 1), F(i + 1, j),
    /// F(i + 1, j + 1)` — one 32-byte load per lookup instead of four gathers. Empty for
    /// grids above [`CELL_GRID_MAX`] points (then the SIMD path gathers from `table`).
    pub(crate) cells: Vec<f64>,
}

/// The largest grid whose table is also kept by cell (`(K - 1) K / 2` cells of 32 bytes:
/// 4 MB at 512 points).
pub const CELL_GRID_MAX: usize = 512;

/// [`Everett::cells`] of a prepared `k x k` table (empty above [`CELL_GRID_MAX`]).
fn cells_of(k: usize, table: &[f64]) -> Vec<f64> {
    if k > CELL_GRID_MAX {
        return Vec::new();
    }
    let mut cells = Vec::with_capacity(2 * k * (k - 1));
    for i in 0..k - 1 {
        for j in 0..=i {
            let q = i * k + j;
            cells.extend_from_slice(&[table[q], table[q + 1], table[q + k], table[q + k + 1]]);
        }
    }
    cells
}

impl Everett {
    /// Build from a row-major `k x k` table (row α, column β; entries above the diagonal are
    /// ignored and the diagonal must be 0) over `[u_min, u_max]`.
    pub fn new(k: usize, u_min: f64, u_max: f64, table: Vec<f64>) -> Result<Self, CoreError> {
        if !(2..=1 << 20).contains(&k) {
            return Err(CoreError::Parameter {
                what: "everett",
                why: format!("the grid needs 2 ..= 2^20 points, got {k}"),
            });
        }
        check_len("everett table", table.len(), k * k)?;
        if !(u_min.is_finite() && u_max.is_finite() && u_max > u_min) {
            return Err(CoreError::Parameter {
                what: "input range",
                why: format!("need finite u_min < u_max, got {u_min} .. {u_max}"),
            });
        }
        let mut table = table;
        if let Some(q) = (0..k * k).find(|&q| q / k > q % k && !table[q].is_finite()) {
            return Err(CoreError::Parameter {
                what: "everett table",
                why: format!("entry ({}, {}) is not finite", q / k, q % k),
            });
        }
        prepare_table(k, &mut table)?;
        Self::view_of(k, u_min, u_max, &table)?;
        Ok(Self {
            k,
            u_min,
            u_max,
            cells: cells_of(k, &table),
            table,
        })
    }

    fn view_of(
        k: usize,
        u_min: f64,
        u_max: f64,
        table: &[f64],
    ) -> Result<kernel::Everett<'_, f64>, CoreError> {
        Ok(kernel::Everett::new(k, u_min, u_max, table)?)
    }

    /// The kernels' view (checked when the table was built).
    #[inline]
    pub fn view(&self) -> kernel::Everett<'_, f64> {
        Self::view_of(self.k, self.u_min, self.u_max, &self.table).expect("checked when built")
    }

    /// Grid size K.
    pub fn size(&self) -> usize {
        self.k
    }

    /// Lower end of the input range (the saturation input `m_0`).
    pub fn u_min(&self) -> f64 {
        self.u_min
    }

    /// Upper end of the input range.
    pub fn u_max(&self) -> f64 {
        self.u_max
    }

    /// The table (row α, column β; zero on and above the diagonal).
    pub fn table(&self) -> &[f64] {
        &self.table
    }

    /// The table by cell ([`Everett::cells`]; empty for large grids).
    pub(crate) fn cells(&self) -> &[f64] {
        &self.cells
    }

    /// The same function without its table by cell (the SIMD path then gathers from the
    /// table, as for grids above [`CELL_GRID_MAX`]; for tests of that path).
    #[cfg(test)]
    pub(crate) fn without_cells(mut self) -> Self {
        self.cells = Vec::new();
        self
    }

    /// `F(α, β)` for `u_min <= β <= α <= u_max` (interpolated; NaN for NaN).
    #[inline]
    pub fn value(&self, alpha: f64, beta: f64) -> f64 {
        self.view().value(alpha, beta)
    }
}

/// The Everett terms behind the model's output along one input history, for identification.
///
/// The output of the numerical model is linear in the Everett function: with the extremum
/// stack `m_0, M_1, m_1, ...` (which depends on the input alone, eq. 4.18-4.22),
/// `h(t) = h(u_min) + 2 Σ_k [F(M_k, m_{k-1}) - F(M_k, m_k)] ± 2 F(branch now traced)`
/// (eq. 4.15/4.16). Sample `t` owns the terms `indptr[t] .. indptr[t + 1]`, each a point
/// `(alpha, beta)` with `alpha > beta` and a coefficient of ±2; a table on any grid turns
/// them into a design matrix by its interpolation weights. The stack is the evaluator's
/// (same turning and wiping-out rules, no capacity limit); inputs are clamped into
/// `[u_min, u_max]` and must not be NaN.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EverettTerms {
    /// Row pointer: sample `t` owns terms `indptr[t] .. indptr[t + 1]`.
    pub indptr: Vec<usize>,
    /// α of each term.
    pub alpha: Vec<f64>,
    /// β of each term.
    pub beta: Vec<f64>,
    /// Coefficient of each term (±2).
    pub coef: Vec<f64>,
}

impl EverettTerms {
    fn push(&mut self, alpha: f64, beta: f64, coef: f64) {
        if alpha > beta {
            self.alpha.push(alpha);
            self.beta.push(beta);
            self.coef.push(coef);
        }
    }
}

/// The Everett terms of every sample of `inputs` (see [`EverettTerms`]).
pub fn everett_terms(inputs: &[f64], u_min: f64, u_max: f64) -> Result<EverettTerms, CoreError> {
    if !(u_min.is_finite() && u_max.is_finite() && u_max > u_min) {
        return Err(CoreError::Parameter {
            what: "input range",
            why: format!("need finite u_min < u_max, got {u_min} .. {u_max}"),
        });
    }
    if let Some(t) = inputs.iter().position(|u| u.is_nan()) {
        return Err(CoreError::Parameter {
            what: "inputs",
            why: format!("sample {t} is NaN"),
        });
    }
    let mut out = EverettTerms {
        indptr: Vec::with_capacity(inputs.len() + 1),
        ..Default::default()
    };
    out.indptr.push(0);
    let mut stack = vec![u_min];
    let mut prev = u_min;
    for &u_in in inputs {
        let u = u_in.clamp(u_min, u_max);
        if u != prev {
            let rising = u > prev;
            if rising != (stack.len() % 2 == 1) {
                stack.push(prev);
            }
            if rising {
                while stack.len() >= 3 && u >= stack[stack.len() - 2] {
                    stack.truncate(stack.len() - 2);
                }
            } else {
                while stack.len() >= 3 && u <= stack[stack.len() - 2] {
                    stack.truncate(stack.len() - 2);
                }
                if stack.len() == 2 && u <= stack[0] {
                    stack.truncate(1);
                }
            }
            prev = u;
        }
        let len = stack.len();
        for q in (1..len).step_by(2) {
            out.push(stack[q], stack[q - 1], 2.0);
            if q + 1 < len {
                out.push(stack[q], stack[q + 1], -2.0);
            }
        }
        if len % 2 == 1 {
            out.push(u, stack[len - 1], 2.0);
        } else {
            out.push(stack[len - 1], u, -2.0);
        }
        out.indptr.push(out.alpha.len());
    }
    Ok(out)
}

/// A test table: `F(α, β) = (α - β)² / 2` on a `k x k` grid over `[0, u_max]` (scaled so that
/// `k = 21` over `[0, 1]` has steps of 1/20).
#[cfg(test)]
pub(crate) fn quadratic(k: usize, u_max: f64) -> Everett {
    let mut table = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..i {
            let d = (i - j) as f64 / (k - 1) as f64;
            table[i * k + j] = 0.5 * d * d;
        }
    }
    Everett::new(k, 0.0, u_max, table).unwrap()
}
