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

use nalgebra::{DMatrix, DMatrixView, DVector, Vector3};

use super::noise::next_in_chain;
use super::normal::{ChainLinearisation, V9};

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

/// The rows of the path whose covariance [`ChainSystem::marginals`] prepares.
#[derive(Clone, Copy, Debug)]
pub(crate) enum PathRows<'a> {
    None,
    All,
    /// These rows (sorted).
    Only(&'a [usize]),
}

impl PathRows<'_> {
    /// Whether any of the rows is in `first..end`.
    fn wants(&self, first: usize, end: usize) -> bool {
        match self {
            PathRows::None => false,
            PathRows::All => true,
            PathRows::Only(r) => r
                .get(r.partition_point(|&x| x < first))
                .is_some_and(|&x| x < end),
        }
    }
}

/// Marginal covariances of the free parameters and of the path (see [`ChainSystem::marginals`]).
pub struct Marginals {
    /// Variance of every free column (its parameter's internal units).
    pub var: Vec<f64>,
    /// By first row: the covariance of what moves the path in each state the rows are seen in.
    stages: Vec<StageCov>,
}

/// What moves the path at the rows of one state of the forward pass, and its covariance.
struct StageCov {
    first_row: usize,
    /// The origin `c` of `T` in this state.
    origin: Vector3<f64>,
    cols: Vec<StageCol>,
    /// Per block among `cols`: its first and last row, first column, columns.
    spans: Vec<(usize, usize, usize, usize)>,
    /// A square root of the covariance of `cols`.
    l: DMatrix<f64>,
}

/// A column of a [`StageCov`]: a parameter (with `1 / sqrt(D)`: the unknown is scaled) or `s`.
#[derive(Clone, Copy, Debug)]
enum StageCol {
    Param(usize, f64),
    S(usize),
}

impl Marginals {
    /// The covariance of the path at `row` (at `p`): `H P H^T = |H L|^2` with `H` the
    /// path's derivative with respect to the unknowns of the state it is seen
    /// in, `dp/dU = [e_k x (p - c)]`, `dp/dT = I` for `s` (every block complete
    /// before the row), `dp(i)` (the caller's `d p / d theta_i` there) for its
    /// own block's and the global parameters. As `[var east, var north, var up, cov east-north]`.
    pub fn path_covariance(
        &self,
        row: usize,
        p: &Vector3<f64>,
        dp: impl Fn(usize) -> Vector3<f64>,
    ) -> [f64; 4] {
        let at = self.stages.partition_point(|s| s.first_row <= row);
        let Some(st) = at.checked_sub(1).and_then(|k| self.stages.get(k)) else {
            return [f64::NAN; 4];
        };
        // Columns of blocks the row does not lie in stay zero.
        let mut skip = vec![false; st.cols.len()];
        for &(first, last, c0, m) in &st.spans {
            if row < first || row > last {
                skip[c0..c0 + m].fill(true);
            }
        }
        let rel = p - st.origin;
        let h: Vec<Vector3<f64>> = st
            .cols
            .iter()
            .zip(&skip)
            .map(|(c, &skip)| match *c {
                _ if skip => Vector3::zeros(),
                StageCol::Param(i, inv) => dp(i) * inv,
                StageCol::S(k) if k < 3 => Vector3::ith(k, 1.0).cross(&rel),
                StageCol::S(k) => Vector3::ith(k - 3, 1.0),
            })
            .collect();
        // H L, one column at a time: [var east, var north, var up, cov east-north].
        let mut out = [0.0; 4];
        for c in 0..st.l.ncols() {
            let mut hl = Vector3::zeros();
            for (r, hr) in h.iter().enumerate() {
                hl += hr * st.l[(r, c)];
            }
            out[0] += hl.x * hl.x;
            out[1] += hl.y * hl.y;
            out[2] += hl.z * hl.z;
            out[3] += hl.x * hl.y;
        }
        out
    }
}

/// An unknown of the backward pass: a block's column, a component of `s`, a
/// global, an observation's wander.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Var {
    Block(usize, usize),
    S(usize),
    G(usize),
    Z(usize),
}

/// The covariance `P = L L^T` of the unknowns of one moment of the backward
/// pass, kept as a square root `L` (one row per unknown): the changes act on
/// the rows as they act on a draw of the unknowns, so the rounding grows as it
/// does for back-substitution. Carried as `P` itself it does not: on a 6-hour
/// ride the cancellations in `s_old = s_new - Y x_b` made `P` indefinite a
/// thousand blocks from the end and its entries reach 1e60 by the start.
struct CovWalk {
    labels: Vec<Var>,
    l: DMatrix<f64>,
}

impl CovWalk {
    fn index(&self, v: Var) -> Option<usize> {
        self.labels.iter().position(|&l| l == v)
    }

    /// The variance of unknown `k`.
    fn var(&self, k: usize) -> f64 {
        self.l.row(k).norm_squared()
    }

    /// `L <- A L` for `v_old = A v_new`, `A = I + sum (dst, src, a) e_dst e_src^T`
    /// (no `dst` is a `src`).
    fn transform(&mut self, terms: &[(Var, Var, f64)]) -> Option<()> {
        for &(d, s, a) in terms {
            let (d, s) = (self.index(d)?, self.index(s)?);
            for c in 0..self.l.ncols() {
                let v = self.l[(s, c)];
                self.l[(d, c)] += a * v;
            }
        }
        Some(())
    }

    /// An eliminated unknown (its columns `new`) back, from its rows
    /// `[R_bb | R_rest | z]` over (`new`, `rest`): `x_b = G v_rest + R_bb^-1 xi`,
    /// so its rows of `L` are `G L_rest` and, in `m` new columns (`xi`), `R_bb^-1`.
    fn eliminated(&mut self, new: &[Var], rows: &DMatrix<f64>, rest: &[Var]) -> Option<()> {
        let m = new.len();
        let rest_idx: Vec<usize> = rest.iter().map(|&v| self.index(v)).collect::<Option<_>>()?;
        let rbb_inv = rows
            .view((0, 0), (m, m))
            .into_owned()
            .solve_upper_triangular(&DMatrix::identity(m, m))?;
        let g = -(&rbb_inv * rows.view((0, m), (m, rest.len())));
        let (n, k) = self.l.shape();
        let l_rest = DMatrix::from_fn(rest.len(), k, |r, c| self.l[(rest_idx[r], c)]);
        let mut l = DMatrix::zeros(n + m, k + m);
        l.view_mut((0, 0), (n, k)).copy_from(&self.l);
        l.view_mut((n, 0), (m, k)).copy_from(&(&g * l_rest));
        l.view_mut((n, k), (m, m)).copy_from(&rbb_inv);
        self.l = l;
        self.labels.extend_from_slice(new);
        self.compress();
        Some(())
    }

    /// Keep only the unknowns where `keep` holds (the others marginalised out).
    fn retain(&mut self, keep: impl Fn(&Var) -> bool) {
        let idx: Vec<usize> = (0..self.labels.len())
            .filter(|&k| keep(&self.labels[k]))
            .collect();
        if idx.len() == self.labels.len() {
            return;
        }
        self.l = self.l.select_rows(&idx);
        self.labels = idx.iter().map(|&k| self.labels[k]).collect();
        self.compress();
    }

    /// `L` with no more columns than rows: `L^T = Q R` gives `L L^T = R^T R`.
    fn compress(&mut self) {
        self.l = square_root(&self.l);
    }

    /// A square root of the covariance of the unknowns at `idx`.
    fn select(&self, idx: &[usize]) -> DMatrix<f64> {
        square_root(&self.l.select_rows(idx))
    }
}

/// `S` (rows x rows at most) with `S S^T = L L^T`.
fn square_root(l: &DMatrix<f64>) -> DMatrix<f64> {
    if l.ncols() <= l.nrows() {
        return l.clone();
    }
    l.transpose().qr().r().transpose()
}

/// What the forward pass finds: `ln det` of the information matrix, and what
/// it leaves for a backward pass.
struct Solved {
    log_det: f64,
    forward: Forward,
}

/// What the forward pass leaves for the backward pass.
struct Forward {
    /// The final triangle `[R | z]` over (`front`, `s`, globals).
    rows: DMatrix<f64>,
    front: Vec<Unknown>,
    ops: Vec<Op>,
    /// Column scaling `sqrt(D)` of the unknowns.
    scale: Vec<f64>,
    /// Where the state changed between rows of the path (only when tracked).
    stages: Vec<StageMark>,
    /// `ops.len()` when each block was opened.
    open_at: Vec<usize>,
    /// `ops.len()` when each observation's wander was added (`usize::MAX`: never).
    wander_at: Vec<usize>,
    /// The origin of `T` at the end.
    origin: Vector3<f64>,
}

/// The first row of the path seen after `ops` changes of the forward pass.
struct StageMark {
    first_row: usize,
    ops: usize,
}

/// How far the forward pass has gone along the blocks and the rows.
#[derive(Default)]
struct Cursor {
    opened: usize,
    completed: usize,
    /// `ops.len()` when each opened block was opened.
    open_at: Vec<usize>,
    next_row: usize,
    stages: Vec<StageMark>,
}

/// An unknown of the array ahead of `s`: a block, or the filtered GPS
/// wander `z_o` an observation passes on to the next (see [`super::noise`]).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Unknown {
    Block(usize),
    /// The wander of observation `o`.
    Wander(usize),
}

/// A change made during the forward pass, undone in reverse by the backward pass.
enum Op {
    /// The origin of `T` moved by `dc`.
    Shift(Vector3<f64>),
    /// Block `b` ended: `s += sum_x y6[x] x_b[x]`.
    Complete { block: usize, y6: Vec<[f64; 6]> },
    /// An unknown was eliminated: `rows = [R_uu | R_rest | z]` over (`what`,
    /// then `rest`, `s`, globals).
    Eliminate {
        what: Unknown,
        rows: DMatrix<f64>,
        rest: Vec<Unknown>,
    },
}

/// The information array of the forward pass.
struct Work {
    /// Wander unknowns in column order (first in the array, at most one per
    /// linked axis at a time), with the observation each belongs to.
    wander: Vec<usize>,
    /// Open blocks in column order (after the wander), with their number of columns.
    open: Vec<(usize, usize)>,
    ng: usize,
    /// Rows of `[R | z]`, `n + 1` columns.
    rows: DMatrix<f64>,
    /// Rows waiting to be folded in.
    pending: Vec<Vec<f64>>,
    origin: Vector3<f64>,
}

impl Work {
    fn front_cols(&self) -> usize {
        self.wander.len() + self.open.iter().map(|&(_, m)| m).sum::<usize>()
    }

    fn n(&self) -> usize {
        self.front_cols() + 6 + self.ng
    }

    fn s0(&self) -> usize {
        self.front_cols()
    }

    fn g0(&self) -> usize {
        self.front_cols() + 6
    }

    /// First column of open block `b`.
    fn col_of(&self, b: usize) -> Option<usize> {
        let mut c = self.wander.len();
        for &(ob, m) in &self.open {
            if ob == b {
                return Some(c);
            }
            c += m;
        }
        None
    }

    /// Column of the wander of observation `o`.
    fn wander_col(&self, o: usize) -> Option<usize> {
        self.wander.iter().position(|&w| w == o)
    }

    /// The unknowns ahead of `s`, in column order.
    fn front(&self) -> Vec<Unknown> {
        self.wander
            .iter()
            .map(|&o| Unknown::Wander(o))
            .chain(self.open.iter().map(|&(b, _)| Unknown::Block(b)))
            .collect()
    }

    /// Fold the pending rows into an upper-triangular `n x (n + 1)` array.
    fn compress(&mut self) {
        let n = self.n();
        let nr = self.rows.nrows() + self.pending.len();
        let mut stack = DMatrix::<f64>::zeros(nr.max(n), n + 1);
        stack
            .view_mut((0, 0), (self.rows.nrows(), n + 1))
            .copy_from(&self.rows);
        for (i, row) in self.pending.drain(..).enumerate() {
            for (k, v) in row.into_iter().enumerate() {
                stack[(self.rows.nrows() + i, k)] = v;
            }
        }
        triangularise(&mut stack, n, self.rows.nrows());
        self.rows = stack.rows(0, n).into_owned();
    }

    /// Insert `m` zero columns at column `at` (the array and the pending rows).
    fn insert_cols(&mut self, at: usize, m: usize) {
        let old = std::mem::replace(&mut self.rows, DMatrix::zeros(0, 0));
        let n_old = old.ncols();
        let mut new = DMatrix::<f64>::zeros(old.nrows(), n_old + m);
        new.columns_mut(0, at).copy_from(&old.columns(0, at));
        new.columns_mut(at + m, n_old - at)
            .copy_from(&old.columns(at, n_old - at));
        self.rows = new;
        for row in &mut self.pending {
            row.splice(at..at, std::iter::repeat_n(0.0, m));
        }
    }

    /// Add `m` zero columns for block `b` after the open blocks.
    fn open_block(&mut self, b: usize, m: usize) {
        self.compress();
        self.insert_cols(self.s0(), m);
        self.open.push((b, m));
    }

    /// Add the wander of observation `o` as the first unknown. The array
    /// stays triangular once a row with an entry there is folded in (every
    /// row then moves down by one).
    fn open_wander(&mut self, o: usize) {
        self.insert_cols(0, 1);
        self.wander.insert(0, o);
    }

    /// `col(dst) += factor * col(src)` over all rows.
    fn axpy_col(&mut self, dst: usize, src: usize, factor: f64) {
        if factor == 0.0 {
            return;
        }
        for i in 0..self.rows.nrows() {
            let v = self.rows[(i, src)];
            self.rows[(i, dst)] += factor * v;
        }
    }

    /// Whether the first open block can be eliminated: finished (`s` has
    /// taken it in) and not the newest (the prior linking it to the next is in).
    fn first_done(&self, completed: usize) -> bool {
        matches!(self.open.first(), Some(&(b, _)) if self.open.len() > 1 && b < completed)
    }

    /// Eliminate the `m` columns from `start` (a few columns from the left):
    /// moved first and the array re-triangularised (only its first
    /// `start + m` rows change), their rows go to the backward pass.
    /// The array must be compressed.
    fn eliminate_cols(&mut self, start: usize, m: usize) -> DMatrix<f64> {
        let n = self.rows.ncols() - 1;
        if start > 0 {
            let order: Vec<usize> = (start..start + m)
                .chain(0..start)
                .chain(start + m..=n)
                .collect();
            self.rows = self.rows.select_columns(&order);
            let nr = self.rows.nrows();
            triangularise(&mut self.rows, n, nr);
        }
        let kept = self.rows.rows(0, m).into_owned();
        self.rows = self.rows.view((m, m), (n - m, n - m + 1)).into_owned();
        kept
    }

    /// Eliminate the first open block: its rows go to the backward pass.
    fn eliminate_first(&mut self) -> Op {
        self.compress();
        let start = self.wander.len();
        let (block, m) = self.open.remove(0);
        let rows = self.eliminate_cols(start, m);
        Op::Eliminate {
            what: Unknown::Block(block),
            rows,
            rest: self.front(),
        }
    }

    /// Hand the wander in column `c` on to observation `o` in place, given
    /// `o`'s residual row `r` (which reads the old wander in column `c`) and
    /// the heavy row `h` defining the new one, laid out over (old wander, the
    /// array's columns with column `c` the new wander, right-hand side).
    ///
    /// Only rows with an entry in column `c` involve the old wander: the
    /// triangle's rows `0..=c` (the wander columns come first), pending rows
    /// that read it, `r` and `h`. Their QR over (old wander, columns `0..=c`)
    /// gives the old wander's row for the backward pass, the triangle's new
    /// rows `0..=c` (the new wander now leads row `c`) and rows without any
    /// entry there, which wait in `pending`. So a fix costs O(c n) instead of
    /// a new column, a compression and a permuted copy of the whole array.
    fn pass_wander(&mut self, c: usize, o: usize, r: Vec<f64>, h: Vec<f64>) -> Op {
        let n = self.n();
        let (reading, rest): (Vec<_>, Vec<_>) = std::mem::take(&mut self.pending)
            .into_iter()
            .partition(|p| p[c] != 0.0);
        self.pending = rest;
        let nl = c + 1 + reading.len() + 2;
        let mut a = DMatrix::<f64>::zeros(nl, n + 2);
        let put = |a: &mut DMatrix<f64>, i: usize, at: &dyn Fn(usize) -> f64| {
            a[(i, 0)] = at(c);
            for k in (0..=n).filter(|&k| k != c) {
                a[(i, k + 1)] = at(k);
            }
        };
        for i in 0..=c {
            put(&mut a, i, &|k| self.rows[(i, k)]);
        }
        for (i, p) in reading.iter().chain([&r]).enumerate() {
            put(&mut a, c + 1 + i, &|k| p[k]);
        }
        for (k, v) in h.into_iter().enumerate() {
            a[(nl - 1, k)] = v;
        }
        triangularise(&mut a, c + 2, 0);
        for i in 0..=c {
            for k in 0..=n {
                self.rows[(i, k)] = a[(i + 1, k + 1)];
            }
        }
        for i in c + 2..nl {
            self.pending.push((0..=n).map(|k| a[(i, k + 1)]).collect());
        }
        let prev = std::mem::replace(&mut self.wander[c], o);
        Op::Eliminate {
            what: Unknown::Wander(prev),
            rows: a.rows(0, 1).into_owned(),
            rest: self.front(),
        }
    }

    /// Eliminate the wander of observation `o` once nothing ahead depends on it.
    fn eliminate_wander(&mut self, o: usize) -> Option<Op> {
        let at = self.wander_col(o)?;
        self.compress();
        self.wander.remove(at);
        let rows = self.eliminate_cols(at, 1);
        Some(Op::Eliminate {
            what: Unknown::Wander(o),
            rows,
            rest: self.front(),
        })
    }
}

/// Householder QR of the first `n` columns of `a` in place (rows below `n`
/// end up zero). The first `tri` rows are the triangle of an earlier
/// compression: where a column is zero below the diagonal inside them (always,
/// unless blocks were opened in between), its reflection only touches the
/// diagonal row and the rows after `tri`, and skips the others. Columns are
/// contiguous slices, so the inner loops vectorise.
fn triangularise(a: &mut DMatrix<f64>, n: usize, tri: usize) {
    let nr = a.nrows();
    let nc = a.ncols();
    let data = a.as_mut_slice();
    let mut v = vec![0.0; nr];
    for j in 0..n.min(nr) {
        let (head, tail) = data.split_at_mut((j + 1) * nr);
        let col = &head[j * nr..];
        // Rows the reflection touches: j and `from..nr` ...
        let from = if j + 1 < tri && col[j + 1..tri].iter().all(|&x| x == 0.0) {
            tri
        } else {
            j + 1
        };
        // ... up to the last one that is not zero (a few rows when columns
        // near the left were moved first).
        let to = from
            + col[from..]
                .iter()
                .rposition(|&x| x != 0.0)
                .map_or(0, |p| p + 1);
        if to == from {
            // Nothing below the diagonal: the row stays as it is.
            continue;
        }
        let norm = (col[j] * col[j] + dot(&col[from..to], &col[from..to])).sqrt();
        if norm == 0.0 {
            continue;
        }
        let alpha = if col[j] > 0.0 { -norm } else { norm };
        let vj = col[j] - alpha;
        v[from..to].copy_from_slice(&col[from..to]);
        let vv = vj * vj + dot(&v[from..to], &v[from..to]);
        if vv == 0.0 {
            continue;
        }
        let two_over_vv = 2.0 / vv;
        let col = &mut head[j * nr..];
        col[j] = alpha;
        col[j + 1..].fill(0.0);
        for k in j + 1..nc {
            let c = &mut tail[(k - j - 1) * nr..(k - j) * nr];
            let d = vj * c[j] + dot(&v[from..to], &c[from..to]);
            if d == 0.0 {
                continue;
            }
            let f = d * two_over_vv;
            c[j] -= f * vj;
            for (ci, vi) in c[from..to].iter_mut().zip(&v[from..to]) {
                *ci -= f * vi;
            }
        }
    }
}

/// `x . y` with four partial sums (so that it vectorises).
fn dot(x: &[f64], y: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (xc, yc) = (x.chunks_exact(4), y.chunks_exact(4));
    let (xr, yr) = (xc.remainder(), yc.remainder());
    for (a, b) in xc.zip(yc) {
        for i in 0..4 {
            acc[i] += a[i] * b[i];
        }
    }
    let tail: f64 = xr.iter().zip(yr).map(|(a, b)| a * b).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Solve the upper-triangular `r x = z`; `None` if singular or not finite.
fn solve_upper(r: DMatrixView<f64>, z: &DVector<f64>) -> Option<Vec<f64>> {
    let x = r.solve_upper_triangular(z)?;
    x.iter()
        .all(|v| v.is_finite())
        .then(|| x.as_slice().to_vec())
}

/// `(U, T)` of a 9-vector `y = [U; V; D]` about origin `c`: `T = U x c + D - V`.
fn six(y: &V9, c: &Vector3<f64>) -> [f64; 6] {
    let u = Vector3::new(y[0], y[1], y[2]);
    let t = u.cross(c) + Vector3::new(y[6] - y[3], y[7] - y[4], y[8] - y[5]);
    [u.x, u.y, u.z, t.x, t.y, t.z]
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
            // dz of the block's parameters at its own observations.
            let mut z = vec![[0.0; 3]; hi - lo];
            for o in lo..hi {
                let (m, n) = lin.slope[o];
                let l = links[o];
                let zp = match l.prev {
                    Some(j) if j >= lo => z[j - lo],
                    _ => [0.0; 3],
                };
                let dx = if lin.jb[o].0 == b as u32 {
                    lin.jb[o].1
                } else {
                    [0.0; 3]
                };
                for (x, &i) in block.params.iter().enumerate() {
                    diag[pos[i]] += (m * dx[x] + n * zp[x]).powi(2);
                    z[o - lo][x] = l.alpha * zp[x] + l.kappa * dx[x];
                }
            }
            for &j in &straddling[b] {
                for (x, &i) in block.params.iter().enumerate() {
                    let y = &lin.y[b][x];
                    let zj = if j >= lo { z[j - lo][x] } else { 0.0 };
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
        let mut prior_rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); lin.prior.residuals.len()];
        for &(row, col, val) in &lin.prior.entries {
            if pos[col] != usize::MAX {
                prior_rows[row].push((pos[col], val));
                diag[pos[col]] += val * val;
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

    pub fn cost(&self) -> f64 {
        self.lin.cost
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
        let solved = self.run(lambda, false)?;
        Some((self.backward(&solved.forward)?, solved.log_det))
    }

    /// The marginal covariances of the posterior `N(theta, (J^T J + J_p^T J_p)^-1)`
    /// under the fit's own noise model, from one forward pass at zero damping
    /// and a backward pass over its changes (Bierman's square-root information
    /// smoother), never a dense inverse; O(N + S (9 + G)^3).
    ///
    /// The backward pass carries the covariance `P` of the unknowns of the
    /// moment (open blocks, `s`, globals), as a square root (see [`CovWalk`]),
    /// starting from the final triangle's `P = R^-1 R^-T`, and undoes each
    /// change of the forward pass:
    /// - a change of variables `v_old = A v_new` (`s <- s + Y x_b`, a move of
    ///   the origin of `T`): `P <- A P A^T`;
    /// - an eliminated block with rows `R_bb x_b + R_br v_rest = xi`:
    ///   `x_b = G v_rest + R_bb^-1 xi`, `G = -R_bb^-1 R_br`, with `xi` independent
    ///   of `v_rest`, so `Cov(x_b, v) = G P_rest,v` and
    ///   `Var(x_b) = G P_rest,rest G^T + R_bb^-1 R_bb^-T`;
    /// - a block not yet opened at the moment is dropped (marginalised).
    ///
    /// Every free column's variance comes out of it; for `rows` also, for
    /// every state they are seen in, `P` over what moves the path there (its
    /// block, `s`, the globals): see [`Marginals::path_covariance`]. About
    /// 2.5 kB per state: 29 MB for every row of a 6-hour ride, a few MB for
    /// the few thousand rows a view draws.
    pub(crate) fn marginals(&self, rows: PathRows) -> Option<Marginals> {
        let solved = self.run(0.0, !matches!(rows, PathRows::None))?;
        let f = &solved.forward;
        let lin = &self.lin;
        let blocks = &lin.blocks;
        let n = f.rows.nrows();
        let rinv = f
            .rows
            .view((0, 0), (n, n))
            .into_owned()
            .solve_upper_triangular(&DMatrix::identity(n, n))?;
        let mut walk = CovWalk {
            labels: Vec::with_capacity(n),
            l: rinv,
        };
        let vars = |u: &Unknown| -> Vec<Var> {
            match *u {
                Unknown::Block(b) => (0..blocks[b].params.len())
                    .map(|x| Var::Block(b, x))
                    .collect(),
                Unknown::Wander(o) => vec![Var::Z(o)],
            }
        };
        for u in &f.front {
            walk.labels.extend(vars(u));
        }
        walk.labels.extend((0..6).map(Var::S));
        walk.labels.extend((0..lin.globals.len()).map(Var::G));
        let mut var = vec![f64::NAN; lin.columns.len()];
        let keep_var = |walk: &CovWalk, var: &mut [f64]| {
            for (k, l) in walk.labels.iter().enumerate() {
                let i = match *l {
                    Var::Block(b, x) => blocks[b].params[x],
                    Var::G(g) => lin.globals[g],
                    Var::S(_) | Var::Z(_) => continue,
                };
                let c = self.pos[i];
                if var[c].is_nan() {
                    var[c] = walk.var(k) / (f.scale[c] * f.scale[c]);
                }
            }
        };
        keep_var(&walk, &mut var);
        let mut stages: Vec<StageCov> = Vec::with_capacity(f.stages.len());
        let mut origin = f.origin;
        let mut mark = f.stages.len();
        let mut store = |walk: &CovWalk, at: usize, origin: Vector3<f64>, mark: &mut usize| {
            while *mark > 0 && f.stages[*mark - 1].ops >= at {
                *mark -= 1;
                let st = &f.stages[*mark];
                let end = f.stages.get(*mark + 1).map_or(lin.horizon, |n| n.first_row);
                if st.ops == at && rows.wants(st.first_row, end) {
                    stages.push(self.stage_cov(walk, st.first_row, end, origin, &f.scale));
                }
            }
        };
        store(&walk, f.ops.len(), origin, &mut mark);
        for (i, op) in f.ops.iter().enumerate().rev() {
            match op {
                Op::Shift(dc) => {
                    // T_old = T_new + dc x U.
                    let k = dc.cross_matrix();
                    let mut terms = Vec::with_capacity(9);
                    for r in 0..3 {
                        for c in 0..3 {
                            terms.push((Var::S(3 + r), Var::S(c), k[(r, c)]));
                        }
                    }
                    walk.transform(&terms)?;
                    origin -= dc;
                }
                Op::Complete { block, y6 } => {
                    // s_old = s_new - Y x_b.
                    let mut terms = Vec::with_capacity(6 * y6.len());
                    for (x, v) in y6.iter().enumerate() {
                        for (k, &yk) in v.iter().enumerate() {
                            terms.push((Var::S(k), Var::Block(*block, x), -yk));
                        }
                    }
                    walk.transform(&terms)?;
                }
                Op::Eliminate { what, rows, rest } => {
                    let mut rest_vars: Vec<Var> = rest.iter().flat_map(vars).collect();
                    rest_vars.extend((0..6).map(Var::S));
                    rest_vars.extend((0..lin.globals.len()).map(Var::G));
                    walk.eliminated(&vars(what), rows, &rest_vars)?;
                    keep_var(&walk, &mut var);
                }
            }
            // Blocks opened after change `i` are not unknowns before it.
            walk.retain(|l| match l {
                Var::Block(b, _) => f.open_at.get(*b).is_some_and(|&at| at <= i),
                Var::Z(o) => f.wander_at.get(*o).is_some_and(|&at| at <= i),
                _ => true,
            });
            store(&walk, i, origin, &mut mark);
        }
        stages.reverse();
        var.iter()
            .all(|v| v.is_finite())
            .then_some(Marginals { var, stages })
    }

    /// The covariance of what moves the path at rows `first..end` (all seen
    /// in one state): the blocks those rows lie in, `s` and the globals.
    fn stage_cov(
        &self,
        walk: &CovWalk,
        first: usize,
        end: usize,
        origin: Vector3<f64>,
        scale: &[f64],
    ) -> StageCov {
        let lin = &self.lin;
        let mut cols: Vec<StageCol> = Vec::new();
        let mut idx: Vec<usize> = Vec::new();
        let mut spans = Vec::new();
        for (k, l) in walk.labels.iter().enumerate() {
            match *l {
                Var::Block(b, x) => {
                    let block = &lin.blocks[b];
                    if block.first < end && block.last >= first {
                        if x == 0 {
                            spans.push((block.first, block.last, cols.len(), block.params.len()));
                        }
                        let i = block.params[x];
                        cols.push(StageCol::Param(i, 1.0 / scale[self.pos[i]]));
                        idx.push(k);
                    }
                }
                Var::S(_) | Var::G(_) | Var::Z(_) => {}
            }
        }
        for k in 0..6 {
            if let Some(at) = walk.index(Var::S(k)) {
                cols.push(StageCol::S(k));
                idx.push(at);
            }
        }
        for (g, &i) in lin.globals.iter().enumerate() {
            if let Some(at) = walk.index(Var::G(g)) {
                cols.push(StageCol::Param(i, 1.0 / scale[self.pos[i]]));
                idx.push(at);
            }
        }
        StageCov {
            first_row: first,
            origin,
            cols,
            spans,
            l: walk.select(&idx),
        }
    }

    /// The forward pass (see the module docs); the step is its back-substitution.
    fn run(&self, lambda: f64, track: bool) -> Option<Solved> {
        let lin = &self.lin;
        let ng = lin.globals.len();
        let scale: Vec<f64> = self.diag.iter().map(|d| d.sqrt()).collect();
        let damping: Vec<f64> = self
            .diag
            .iter()
            .map(|d| (lambda + 1e-15 * self.max_diag / d).sqrt())
            .collect();
        let global_col: Vec<usize> = lin.globals.iter().map(|&i| self.pos[i]).collect();
        let mut work = Work {
            wander: Vec::new(),
            open: Vec::new(),
            ng,
            rows: DMatrix::zeros(0, 7 + ng),
            pending: Vec::new(),
            origin: Vector3::zeros(),
        };
        let mut ops: Vec<Op> = Vec::new();
        // Heavy rows defining a wander (each adds exactly its weight squared to the determinant).
        let mut constraint_log_det = 0.0;
        let mut wander_at = vec![usize::MAX; lin.r.len()];
        // s = 0 exactly, and the globals' damping and priors.
        for k in 0..6 {
            let mut row = vec![0.0; 7 + ng];
            row[k] = PIN;
            work.pending.push(row);
        }
        for (g, &c) in global_col.iter().enumerate() {
            let mut row = vec![0.0; 7 + ng];
            row[6 + g] = damping[c];
            work.pending.push(row);
        }
        self.add_priors(&mut work, 0, &scale);

        let blocks = &lin.blocks;
        let nb = blocks.len();
        let open = |work: &mut Work, b: usize| {
            let m = blocks[b].params.len();
            work.open_block(b, m);
            let c0 = work.col_of(b).unwrap_or(0);
            for (x, &i) in blocks[b].params.iter().enumerate() {
                let mut row = vec![0.0; work.n() + 1];
                row[c0 + x] = damping[self.pos[i]];
                work.pending.push(row);
            }
            self.add_priors(work, b + 1, &scale);
        };
        let eliminate = |work: &mut Work, ops: &mut Vec<Op>, completed: usize| {
            while work.first_done(completed) {
                ops.push(work.eliminate_first());
            }
        };
        let complete = |work: &mut Work, ops: &mut Vec<Op>, b: usize| {
            work.compress();
            let c0 = work.col_of(b).unwrap_or(0);
            let s0 = work.s0();
            let y6: Vec<[f64; 6]> = blocks[b]
                .params
                .iter()
                .enumerate()
                .map(|(x, &i)| {
                    let mut v = six(&lin.y[b][x], &work.origin);
                    for e in &mut v {
                        *e /= scale[self.pos[i]];
                    }
                    v
                })
                .collect();
            // s_old = s_new - Y x_b: col(b) -= col(s) Y.
            for (x, v) in y6.iter().enumerate() {
                for (k, &yk) in v.iter().enumerate() {
                    work.axpy_col(c0 + x, s0 + k, -yk);
                }
            }
            ops.push(Op::Complete { block: b, y6 });
        };
        // Blocks opened and completed so far: every block ending before `row`
        // completed, every block starting by it open.
        let mut cursor = Cursor::default();
        let open_next = |work: &mut Work, ops: &mut Vec<Op>, cursor: &mut Cursor| {
            cursor.open_at.push(ops.len());
            open(work, cursor.opened);
            cursor.opened += 1;
            eliminate(work, ops, cursor.completed);
        };
        let advance = |work: &mut Work, ops: &mut Vec<Op>, cursor: &mut Cursor, row: usize| loop {
            while cursor.completed < cursor.opened && blocks[cursor.completed].last < row {
                complete(work, ops, cursor.completed);
                cursor.completed += 1;
            }
            if cursor.opened < nb && blocks[cursor.opened].first <= row {
                open_next(work, ops, cursor);
                continue;
            }
            break;
        };
        // With `track`, the state each row of the path is seen in: as if every
        // row were an observation (the order of the changes does not change the solution).
        let track_to = |work: &mut Work, ops: &mut Vec<Op>, cursor: &mut Cursor, end: usize| {
            while track && cursor.next_row < end {
                advance(work, ops, cursor, cursor.next_row);
                if cursor.stages.last().is_none_or(|s| s.ops != ops.len()) {
                    cursor.stages.push(StageMark {
                        first_row: cursor.next_row,
                        ops: ops.len(),
                    });
                }
                cursor.next_row += 1;
            }
        };
        for o in 0..lin.r.len() {
            let row = lin.rows[o];
            track_to(&mut work, &mut ops, &mut cursor, row + 1);
            advance(&mut work, &mut ops, &mut cursor, row);
            let p = lin.at[o];
            if (p - work.origin).norm() > RECENTRE_M {
                work.compress();
                let dc = p - work.origin;
                let s0 = work.s0();
                // T_old = T_new + dc x U: col(U_j) += sum_i col(T_i) [dc]x_ij.
                let k = dc.cross_matrix();
                for j in 0..3 {
                    for i in 0..3 {
                        work.axpy_col(s0 + j, s0 + 3 + i, k[(i, j)]);
                    }
                }
                work.origin = p;
                ops.push(Op::Shift(dc));
            }
            // The row of d x_o in the current unknowns: (U x (p - c) + T)_a,
            // its block's explicit entries and the globals.
            let n = work.n();
            let mut r = vec![0.0; n + 1];
            let h = &lin.h[o];
            // h = (x x e_a, -e_a, e_a): the axis is where the last three entries are non-zero.
            if let Some(a) = (0..3).find(|&a| h[6 + a] != 0.0) {
                let rel = p - work.origin;
                let mut e = Vector3::zeros();
                e[a] = 1.0;
                let ru = rel.cross(&e);
                let s0 = work.s0();
                for k in 0..3 {
                    r[s0 + k] = ru[k];
                }
                r[s0 + 3 + a] = 1.0;
            }
            let (b, vals) = lin.jb[o];
            if b != u32::MAX
                && let Some(c0) = work.col_of(b as usize)
            {
                for (x, &i) in blocks[b as usize].params.iter().enumerate() {
                    r[c0 + x] = vals[x] / scale[self.pos[i]];
                }
            }
            let g0 = work.g0();
            for (g, &c) in global_col.iter().enumerate() {
                r[g0 + g] = lin.jg[(o, g)] / scale[c];
            }
            // The residual's row: slope_o dx_o + back_o z_prev, with the
            // previous observation's wander an unknown of its own.
            let (m, back) = lin.slope[o];
            let link = lin.links[o];
            let prev_col = link.prev.and_then(|j| work.wander_col(j));
            // This observation's wander, for the next one linked to it:
            // z_o = alpha_o z_prev + kappa_o dx_o, held by a heavy row (over
            // the columns after the wander's, which goes first) that is
            // heavy against the row that will read it: a constraint, not a prior.
            let wander = self.next_in_chain[o].map(|next| {
                let w = WANDER_PIN * (1.0 + lin.slope[next].1.abs());
                let mut c = vec![0.0; n + 2];
                c[0] = w;
                for (k, d) in r[..n].iter().enumerate() {
                    c[k + 1] = -w * link.kappa * d;
                }
                if let Some(p) = prev_col {
                    c[p + 1] -= w * link.alpha;
                }
                (c, w)
            });
            for v in &mut r {
                *v *= m;
            }
            if let Some(c) = prev_col {
                r[c] += back;
            }
            r[n] = -lin.r[o];
            if let Some((_, w)) = &wander {
                wander_at[o] = ops.len();
                constraint_log_det += 2.0 * w.ln();
            }
            match (prev_col, wander) {
                // The common case, in place: the previous wander's column
                // becomes this one's (see `Work::pass_wander`).
                (Some(p), Some((mut c, _))) if work.rows.nrows() > p => {
                    c.swap(0, p + 1);
                    ops.push(work.pass_wander(p, o, r, c));
                }
                (_, wander) => {
                    work.pending.push(r);
                    if let Some((c, _)) = wander {
                        work.open_wander(o);
                        work.pending.push(c);
                    }
                    // The previous wander: nothing ahead depends on it any more.
                    if let Some(j) = link.prev
                        && let Some(op) = work.eliminate_wander(j)
                    {
                        ops.push(op);
                    }
                }
            }
            if work.pending.len() >= 2 * work.n() {
                work.compress();
            }
        }
        track_to(&mut work, &mut ops, &mut cursor, lin.horizon);
        while cursor.opened < nb {
            while cursor.completed < cursor.opened && blocks[cursor.completed].last < lin.horizon {
                complete(&mut work, &mut ops, cursor.completed);
                cursor.completed += 1;
            }
            open_next(&mut work, &mut ops, &mut cursor);
        }
        work.compress();

        let mut log_det =
            self.diag.iter().map(|d| d.ln()).sum::<f64>() - 12.0 * PIN.ln() - constraint_log_det;
        for op in &ops {
            if let Op::Eliminate { rows, .. } = op {
                for i in 0..rows.nrows() {
                    log_det += 2.0 * rows[(i, i)].abs().ln();
                }
            }
        }
        for i in 0..work.rows.nrows() {
            log_det += 2.0 * work.rows[(i, i)].abs().ln();
        }

        let forward = Forward {
            front: work.front(),
            rows: work.rows,
            ops,
            scale,
            stages: cursor.stages,
            open_at: cursor.open_at,
            wander_at,
            origin: work.origin,
        };
        Some(Solved { log_det, forward })
    }

    /// Columns of an unknown of the array.
    fn size(&self, u: &Unknown) -> usize {
        match *u {
            Unknown::Block(b) => self.lin.blocks[b].params.len(),
            Unknown::Wander(_) => 1,
        }
    }

    /// The backward pass: back-substitution through the final triangle and
    /// the eliminated blocks in reverse, undoing the changes of variables.
    fn backward(&self, f: &Forward) -> Option<DVector<f64>> {
        let lin = &self.lin;
        let blocks = &lin.blocks;
        let nb = blocks.len();
        let rhs = |rows: &DMatrix<f64>, m: usize| -> DVector<f64> {
            rows.column(rows.ncols() - 1).rows(0, m).into_owned()
        };
        let n = f.rows.nrows();
        let last = solve_upper(f.rows.view((0, 0), (n, n)), &rhs(&f.rows, n))?;
        let mut xb: Vec<Vec<f64>> = vec![Vec::new(); nb];
        let mut xz: Vec<f64> = vec![0.0; lin.r.len()];
        let mut c = 0;
        for u in &f.front {
            let m = self.size(u);
            match *u {
                Unknown::Block(b) => xb[b] = last[c..c + m].to_vec(),
                Unknown::Wander(o) => xz[o] = last[c],
            }
            c += m;
        }
        let mut s = [0.0; 6];
        s.copy_from_slice(&last[c..c + 6]);
        let xg = last[c + 6..].to_vec();
        for op in f.ops.iter().rev() {
            match op {
                Op::Shift(dc) => {
                    let u = Vector3::new(s[0], s[1], s[2]);
                    let t = Vector3::new(s[3], s[4], s[5]) + dc.cross(&u);
                    s[3] = t.x;
                    s[4] = t.y;
                    s[5] = t.z;
                }
                Op::Complete { block, y6 } => {
                    for (x, v) in y6.iter().enumerate() {
                        let xv = xb[*block].get(x).copied().unwrap_or(0.0);
                        for k in 0..6 {
                            s[k] -= v[k] * xv;
                        }
                    }
                }
                Op::Eliminate { what, rows, rest } => {
                    let m = self.size(what);
                    let mut known: Vec<f64> = Vec::new();
                    for u in rest {
                        match *u {
                            Unknown::Block(b) => known.extend_from_slice(&xb[b]),
                            Unknown::Wander(o) => known.push(xz[o]),
                        }
                    }
                    known.extend_from_slice(&s);
                    known.extend_from_slice(&xg);
                    let rest_cols = rows.ncols() - 1 - m;
                    let rhs =
                        rhs(rows, m) - rows.view((0, m), (m, rest_cols)) * DVector::from_vec(known);
                    let x = solve_upper(rows.view((0, 0), (m, m)), &rhs)?;
                    match *what {
                        Unknown::Block(b) => xb[b] = x,
                        Unknown::Wander(o) => xz[o] = x[0],
                    }
                }
            }
        }
        let nf = lin.columns.len();
        let mut delta = DVector::<f64>::zeros(nf);
        for (b, block) in blocks.iter().enumerate() {
            for (x, &i) in block.params.iter().enumerate() {
                let c = self.pos[i];
                delta[c] = xb[b].get(x).copied().unwrap_or(0.0) / f.scale[c];
            }
        }
        for (g, &i) in lin.globals.iter().enumerate() {
            let c = self.pos[i];
            delta[c] = xg[g] / f.scale[c];
        }
        delta.iter().all(|v| v.is_finite()).then_some(delta)
    }

    /// Prior rows of stage `stage` into the array, in scaled unknowns.
    fn add_priors(&self, work: &mut Work, stage: usize, scale: &[f64]) {
        for &row in &self.prior_at[stage] {
            let n = work.n();
            let mut r = vec![0.0; n + 1];
            for &(c, val) in &self.prior_rows[row] {
                let b = self.block_of[c];
                let col = if b == usize::MAX {
                    self.lin
                        .globals
                        .iter()
                        .position(|&i| self.pos[i] == c)
                        .map(|g| work.g0() + g)
                } else {
                    let x = self.lin.blocks[b]
                        .params
                        .iter()
                        .position(|&i| self.pos[i] == c);
                    work.col_of(b).zip(x).map(|(c0, x)| c0 + x)
                };
                if let Some(col) = col {
                    r[col] += val / scale[c];
                }
            }
            r[n] = -self.lin.prior.residuals[row];
            work.pending.push(r);
        }
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
            let (b, vals) = lin.jb[o];
            if b != u32::MAX {
                for (x, &i) in lin.blocks[b as usize].params.iter().enumerate() {
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
