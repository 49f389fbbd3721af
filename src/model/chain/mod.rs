//! The Levenberg-Marquardt step in O(N): the damped Gauss-Newton problem
//! solved along the ride as a chain (a square-root information smoother),
//! without forming the P x P normal equations.
//!
//! A segment bias `b` moves the path after its segment only through its prefix
//! sums (see [`super::jacobian`]), and of those only six numbers matter: the
//! rotation `U_b` and, about an origin `c`, the translation
//! `T_b = U_b x c + D_b - V_b`. So the linearised residual of observation `o`
//! (axis `a`, position `p_o`, slope `w_o`) is
//!
//! ```text
//! (J delta)_o = w_o (U x (p_o - c) + T)_a + J_o,in delta_in(o) + J_o,G delta_G
//! s = (U, T) = sum over blocks complete before o of Y_b delta_b
//! ```
//!
//! with `delta_in(o)` the block `o` lies in and `delta_G` the global parameters.
//! The state `s` grows by `Y_b delta_b` when block `b` ends, the bias prior
//! links neighbouring blocks only, so the LM problem
//!
//! ```text
//! min ||r + J delta||^2 + ||r_p + J_p delta||^2 + sum_i (lambda D_i + eps) delta_i^2,  D = diag(J^T J)
//! ```
//!
//! (exactly what [`super::normal::damped_solve`] solves densely) is a
//! linear smoothing problem over the blocks. It is solved by Householder QR
//! of an information array `[R | z]` over (open blocks, `s`, globals), updated
//! block by block as in Bierman's square-root information filter: a new block
//! adds columns, observations add rows, a finished block changes variables
//! `s <- s + Y_b delta_b` (a column operation), and a block no longer linked to
//! anything ahead is eliminated, its rows kept for the backward pass. Time and
//! memory are O(N + S (9 + G)^2) instead of the dense solve's O(S^3) and
//! O(S^2): a 6-hour ride has 13,000 bias parameters, whose dense normal
//! matrix alone would take 1.3 GB.
//!
//! `s` starts at exactly zero; the array holds that as rows `W s = 0` with `W`
//! far above every other row (Householder QR with the heavy rows on top keeps
//! the light rows' accuracy). Unknowns are scaled by `sqrt(D_i)` so that the
//! array's columns are of similar size.

use nalgebra::DVector;

use super::noise::{covariance_log_det, next_in_chain};
use super::normal::{ChainLinearisation, V9};

mod forward;
mod marginals;

pub use marginals::Marginals;
pub(crate) use marginals::PathRows;

/// Weight of the rows that pin the initial state `s` to zero.
const PIN: f64 = 1e8;

/// Weight of the rows that define a wander unknown, relative to the row that
/// reads it: heavy enough to be a constraint (1e-10 of the solution), light
/// enough to keep the light rows' digits through the QR (at 1e8 the step lost
/// them: 3e-6 from the dense one).
const WANDER_PIN: f64 = 1e5;

/// Re-centre the rotation terms when an observation is this far from the origin (m).
const RECENTRE_M: f64 = 50.0;

/// The damped least-squares problem of one LM iteration, in chain form.
#[derive(Clone, Debug)]
pub struct ChainSystem {
    lin: ChainLinearisation,
    /// `diag(J^T J)` floored, per free column.
    diag: Vec<f64>,
    max_diag: f64,
    /// Free-column index of each parameter (`usize::MAX`: not free).
    pos: Vec<usize>,
    /// Block of each free column (`usize::MAX`: global).
    block_of: Vec<usize>,
    /// Prior rows by the stage that adds them: 0 before any block, `b + 1` when block `b` opens.
    prior_at: Vec<Vec<usize>>,
    /// Prior entries grouped by row: `(free column, value)`.
    prior_rows: Vec<Vec<(usize, f64)>>,
    /// The observation linked to each (see [`next_in_chain`]).
    next_in_chain: Vec<Option<usize>>,
}

impl ChainSystem {
    /// The chain form of `lin` over `np` parameters; `None` when a prior row
    /// links blocks that are not neighbours (the chain would not be a chain).
    pub(crate) fn new(lin: ChainLinearisation, np: usize) -> Option<Self> {
        let nf = lin.columns.len();
        let mut pos = vec![usize::MAX; np];
        for (c, &i) in lin.columns.iter().enumerate() {
            pos[i] = c;
        }
        let mut block_of = vec![usize::MAX; nf];
        for (b, block) in lin.blocks.iter().enumerate() {
            for &i in &block.params {
                block_of[pos[i]] = b;
            }
        }
        // diag(J^T J). A residual row is `slope_o dx_o + back_o dz_prev(o)`
        // with the filtered wander `dz_o = alpha_o dz_prev + kappa_o dx_o` (see
        // `noise`). A global's column is its rows combined. A block's
        // parameter (its `y`) moves the observations inside the block
        // explicitly and those after it by `dx_o = h_o . y`; there
        // `dz_o = hz_o . y + D_o`, with `hz` the filtered `h` and
        // `D_o = alpha_o D_prev` what the chain remembers of the block's own
        // rows, so `J_o = htilde_o . y + back_o Pi_o D_J` with
        // `htilde_o = slope_o h_o + back_o hz_prev`, `J` the chain's last
        // observation up to the block's end and `Pi_o` the alphas since.
        // Summed over the rows after the block that is
        // `y^T M y + sum_J (2 D_J Q_J . y + D_J^2 R_J)`: suffix moments `M` of
        // `htilde`, and `Q`, `R` run backwards along each chain.
        let mut diag = vec![0.0; nf];
        let no = lin.r.len();
        let links = &lin.links;
        for (g, &i) in lin.globals.iter().enumerate() {
            diag[pos[i]] = lin
                .combine(lin.jg.column(g).as_slice())
                .iter()
                .map(|v| v * v)
                .sum();
        }
        let next_in_chain = next_in_chain(links);
        let mut hz = vec![V9::zeros(); no];
        let mut htilde = vec![V9::zeros(); no];
        for o in 0..no {
            let (m, n) = lin.slope[o];
            let l = links[o];
            let prev = l.prev.map_or(V9::zeros(), |j| hz[j]);
            hz[o] = prev * l.alpha + lin.h[o] * l.kappa;
            htilde[o] = lin.h[o] * m + prev * n;
        }
        let mut q = vec![V9::zeros(); no];
        let mut r2 = vec![0.0; no];
        for j in (0..no).rev() {
            if let Some(s) = next_in_chain[j] {
                let (n, a) = (lin.slope[s].1, links[s].alpha);
                q[j] = htilde[s] * n + q[s] * a;
                r2[j] = n * n + a * a * r2[s];
            }
        }
        // Per block, the chains' last observations up to its end that a later one is linked to.
        let mut straddling: Vec<Vec<usize>> = vec![Vec::new(); lin.blocks.len()];
        for (s, l) in links.iter().enumerate() {
            if let Some(j) = l.prev {
                let from = lin.blocks.partition_point(|b| b.last < lin.rows[j]);
                for (b, block) in lin.blocks.iter().enumerate().skip(from) {
                    if block.last >= lin.rows[s] {
                        break;
                    }
                    straddling[b].push(j);
                }
            }
        }
        for (b, block) in lin.blocks.iter().enumerate() {
            let lo = lin.rows.partition_point(|&r| r < block.first);
            let hi = lin.rows.partition_point(|&r| r <= block.last);
            // dz of the block's parameters at its own observations, `w` a row.
            let w = block.params.len();
            let mut z = vec![0.0; (hi - lo) * w];
            for o in lo..hi {
                let (m, n) = lin.slope[o];
                let l = links[o];
                let own = lin.jb[o].0 == b as u32;
                for (x, &i) in block.params.iter().enumerate() {
                    let zp = match l.prev {
                        Some(j) if j >= lo => z[(j - lo) * w + x],
                        _ => 0.0,
                    };
                    let dx = if own { lin.jb[o].1[x] } else { 0.0 };
                    diag[pos[i]] += (m * dx + n * zp).powi(2);
                    z[(o - lo) * w + x] = l.alpha * zp + l.kappa * dx;
                }
            }
            for &j in &straddling[b] {
                for (x, &i) in block.params.iter().enumerate() {
                    let y = &lin.y[b][x];
                    let zj = if j >= lo { z[(j - lo) * w + x] } else { 0.0 };
                    let d = zj - hz[j].dot(y);
                    diag[pos[i]] += 2.0 * d * q[j].dot(y) + d * d * r2[j];
                }
            }
        }
        let mut next = no;
        let mut moments = nalgebra::SMatrix::<f64, 9, 9>::zeros();
        for (b, block) in lin.blocks.iter().enumerate().rev() {
            if block.last == usize::MAX {
                continue;
            }
            while next > 0 && lin.rows[next - 1] > block.last {
                let hv = htilde[next - 1];
                moments += hv * hv.transpose();
                next -= 1;
            }
            for (x, &i) in block.params.iter().enumerate() {
                diag[pos[i]] += lin.y[b][x].dot(&(moments * lin.y[b][x]));
            }
        }
        let (prior_rows, prior_at) = Self::prior_stages(&lin, &pos, &block_of)?;
        for &(_, col, val) in &lin.prior.entries {
            if pos[col] != usize::MAX {
                diag[pos[col]] += val * val;
            }
        }
        let max_diag = diag.iter().copied().fold(0.0f64, f64::max);
        let floor = (1e-9 * max_diag).max(1e-12);
        for d in &mut diag {
            *d = d.max(floor);
        }
        Some(Self {
            lin,
            diag,
            max_diag,
            pos,
            block_of,
            prior_at,
            prior_rows,
            next_in_chain,
        })
    }

    /// The chain form of `lin`, which has the columns, blocks and
    /// derivatives of `like`'s linearisation under other weights (a noise
    /// likelihood's setting, `Model::likelihood_system_like`), its unknowns
    /// scaled as `like`'s are. The scaling `S = sqrt(D)` only conditions the
    /// QR: the step and the cost do not depend on it, and the log-determinant
    /// adds back `sum ln D` for whichever `D` it used; only the floor
    /// `1e-15 max D / D` that keeps an undamped array regular moves, by 1e-15
    /// of the information. It saves the O(N) sums of `diag(J^T J)`, an eighth
    /// of a noise likelihood's time. `None` as [`ChainSystem::new`].
    pub(crate) fn scaled_like(lin: ChainLinearisation, like: &ChainSystem) -> Option<Self> {
        if lin.columns != like.lin.columns || lin.blocks.len() != like.lin.blocks.len() {
            return None;
        }
        let (prior_rows, prior_at) = Self::prior_stages(&lin, &like.pos, &like.block_of)?;
        Some(Self {
            next_in_chain: next_in_chain(&lin.links),
            lin,
            diag: like.diag.clone(),
            max_diag: like.max_diag,
            pos: like.pos.clone(),
            block_of: like.block_of.clone(),
            prior_at,
            prior_rows,
        })
    }

    /// `lin`'s prior rows as (free column, value) entries, and the stage that
    /// adds each (0 before any block, `b + 1` when block `b` opens: the
    /// latest block it touches); `None` when a row links blocks that are not
    /// neighbours.
    #[allow(clippy::type_complexity)]
    fn prior_stages(
        lin: &ChainLinearisation,
        pos: &[usize],
        block_of: &[usize],
    ) -> Option<(Vec<Vec<(usize, f64)>>, Vec<Vec<usize>>)> {
        let mut prior_rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); lin.prior.residuals.len()];
        for &(row, col, val) in &lin.prior.entries {
            if pos[col] != usize::MAX {
                prior_rows[row].push((pos[col], val));
            }
        }
        let mut prior_at = vec![Vec::new(); lin.blocks.len() + 1];
        for (row, entries) in prior_rows.iter().enumerate() {
            let blocks: Vec<usize> = entries
                .iter()
                .map(|&(c, _)| block_of[c])
                .filter(|&b| b != usize::MAX)
                .collect();
            match (blocks.iter().min(), blocks.iter().max()) {
                (Some(&lo), Some(&hi)) if hi - lo > 1 => return None,
                (_, Some(&hi)) => prior_at[hi + 1].push(row),
                _ => prior_at[0].push(row),
            }
        }
        Some((prior_rows, prior_at))
    }

    pub fn cost(&self) -> f64 {
        self.lin.cost
    }

    /// `ln det` of the covariance of what the system weighs (see
    /// `Model::noise_log_det`), from its own links and prior rows: the
    /// model's at the point and settings it was made at, without the
    /// observation plan made again.
    pub fn noise_log_det(&self) -> f64 {
        covariance_log_det(&self.lin.links, &self.lin.prior, |_| true)
    }

    pub(crate) fn linearisation(&self) -> &ChainLinearisation {
        &self.lin
    }

    /// Parameter index of each entry of a step.
    pub fn columns(&self) -> &[usize] {
        &self.lin.columns
    }

    /// The LM step for damping `lambda`: the minimiser of the damped problem
    /// in the module docs, one entry per free column; `None` if not finite.
    pub fn solve(&self, lambda: f64) -> Option<DVector<f64>> {
        self.solve_with_log_det(lambda).map(|(x, _)| x)
    }

    /// The step and `ln det(J^T J + J_p^T J_p + lambda D)`, the log-determinant
    /// of the information matrix the step solves with (at `lambda = 0` the
    /// posterior precision a marginal likelihood needs). The QR gives it for
    /// free: the array is `R S^-1` in scaled unknowns `S x` (`S = sqrt(D)`),
    /// its diagonal from the eliminated blocks and the final rows, and the six
    /// rows pinning `s` contribute exactly `PIN^12` (the changes of variables
    /// `s <- s + Y x_b` have determinant 1).
    pub fn solve_with_log_det(&self, lambda: f64) -> Option<(DVector<f64>, f64)> {
        let solved = self.run(lambda, false, true)?;
        Some((self.backward(&solved.forward)?, solved.log_det))
    }

    /// What a marginal likelihood needs of the undamped system, without the
    /// step: the linearised cost at its minimum,
    /// `min_x ||r + J x||^2 + ||r_p + J_p x||^2`, and the log-determinant of
    /// [`solve_with_log_det`](Self::solve_with_log_det). The minimum is
    /// what the forward pass's QR leaves below its triangle, so neither the
    /// back substitution nor a sweep of `J x` is needed: they were a third
    /// of each noise likelihood's time. (The array also holds the rows that
    /// pin `s`, define each wander and keep the globals regular; at the
    /// minimum they add 1e-10 of the cost or less, the weights they are
    /// chosen with.)
    pub fn fit_with_log_det(&self) -> Option<(f64, f64)> {
        let solved = self.run(0.0, false, false)?;
        Some((solved.residual, solved.log_det))
    }

    /// Cost decrease that the linear model predicts for `delta`:
    /// `C - (||r + J delta||^2 + ||r_p + J_p delta||^2)`.
    pub fn predicted_decrease(&self, delta: &DVector<f64>) -> f64 {
        let lin = &self.lin;
        let mut s = V9::zeros();
        let mut next = 0;
        let mut dx = vec![0.0; lin.r.len()];
        for (o, dx) in dx.iter_mut().enumerate() {
            let row = lin.rows[o];
            while next < lin.blocks.len()
                && lin.blocks[next].last != usize::MAX
                && lin.blocks[next].last < row
            {
                for (x, &i) in lin.blocks[next].params.iter().enumerate() {
                    s += lin.y[next][x] * delta[self.pos[i]];
                }
                next += 1;
            }
            let mut jd = lin.h[o].dot(&s);
            let (b, vals) = &lin.jb[o];
            if *b != u32::MAX {
                for (x, &i) in lin.blocks[*b as usize].params.iter().enumerate() {
                    jd += vals[x] * delta[self.pos[i]];
                }
            }
            for (g, &i) in lin.globals.iter().enumerate() {
                jd += lin.jg[(o, g)] * delta[self.pos[i]];
            }
            *dx = jd;
        }
        let mut model: f64 = lin
            .combine(&dx)
            .iter()
            .zip(lin.r.iter())
            .map(|(jd, r)| (r + jd).powi(2))
            .sum();
        for (row, entries) in self.prior_rows.iter().enumerate() {
            let v = self.lin.prior.residuals[row]
                + entries.iter().map(|&(c, val)| val * delta[c]).sum::<f64>();
            model += v * v;
        }
        self.lin.cost - model
    }
}
