//! The forward pass of the chain solver: the square-root information array
//! reduced stage by stage (Householder QR), its log-determinant, and the
//! back substitution that gives the step.

use nalgebra::{DMatrix, DMatrixView, DVector, Vector3};

use super::*;

/// What the forward pass finds: `ln det` of the information matrix, and what
/// it leaves for a backward pass.
pub(super) struct Solved {
    pub(super) log_det: f64,
    /// `min ||A x - b||^2` over the whole damped array: the squared
    /// right-hand sides that the QR leaves below the triangle (rows with no
    /// unknown left), summed as they fall out (see [`Work::compress`]).
    pub(super) residual: f64,
    pub(super) forward: Forward,
}

/// What the forward pass leaves for the backward pass.
pub(super) struct Forward {
    /// The final triangle `[R | z]` over (`front`, `s`, globals).
    pub(super) rows: DMatrix<f64>,
    pub(super) front: Vec<Unknown>,
    pub(super) ops: Vec<Op>,
    /// Column scaling `sqrt(D)` of the unknowns.
    pub(super) scale: Vec<f64>,
    /// Where the state changed between rows of the path (only when tracked).
    pub(super) stages: Vec<StageMark>,
    /// `ops.len()` when each block was opened.
    pub(super) open_at: Vec<usize>,
    /// `ops.len()` when each observation's wander was added (`usize::MAX`: never).
    pub(super) wander_at: Vec<usize>,
    /// The origin of `T` at the end.
    pub(super) origin: Vector3<f64>,
}

/// The first row of the path seen after `ops` changes of the forward pass.
pub(super) struct StageMark {
    pub(super) first_row: usize,
    pub(super) ops: usize,
}

/// How far the forward pass has gone along the blocks and the rows.
#[derive(Default)]
pub(super) struct Cursor {
    pub(super) opened: usize,
    pub(super) completed: usize,
    /// `ops.len()` when each opened block was opened.
    pub(super) open_at: Vec<usize>,
    pub(super) next_row: usize,
    pub(super) stages: Vec<StageMark>,
}

/// An unknown of the array ahead of `s`: a block, or the filtered GPS
/// wander `z_o` an observation passes on to the next (see [`super::noise`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Unknown {
    Block(usize),
    /// The wander of observation `o`.
    Wander(usize),
}

/// A change made during the forward pass, undone in reverse by the backward pass.
pub(super) enum Op {
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

/// The changes of a forward pass, in order, for the backward pass; and the
/// log-determinant of the eliminated unknowns' rows as they go. A pass
/// whose caller wants only the likelihood ([`ChainSystem::fit_with_log_det`])
/// counts them without keeping them: a noise likelihood copied out and
/// later freed a row for every fix and axis it never read.
pub(super) struct Ops {
    pub(super) list: Vec<Op>,
    keep: bool,
    count: usize,
    /// `sum 2 ln |R_ii|` over the eliminated rows.
    pub(super) log_det: f64,
}

impl Ops {
    pub(super) fn new(keep: bool) -> Self {
        Self {
            list: Vec::new(),
            keep,
            count: 0,
            log_det: 0.0,
        }
    }

    /// Whether the changes are kept (or only counted).
    pub(super) fn keeps(&self) -> bool {
        self.keep
    }

    /// Changes made so far, kept or not.
    pub(super) fn len(&self) -> usize {
        self.count
    }

    pub(super) fn push(&mut self, op: Op) {
        if let Op::Eliminate { rows, .. } = &op {
            self.add_diagonal((0..rows.nrows()).map(|i| rows[(i, i)]));
        }
        self.count += 1;
        if self.keep {
            self.list.push(op);
        }
    }

    /// An elimination not kept, by the diagonal of its rows.
    pub(super) fn eliminated(&mut self, diagonal: impl Iterator<Item = f64>) {
        self.add_diagonal(diagonal);
        self.count += 1;
    }

    fn add_diagonal(&mut self, diagonal: impl Iterator<Item = f64>) {
        for d in diagonal {
            self.log_det += 2.0 * d.abs().ln();
        }
    }
}

/// The information array of the forward pass.
pub(super) struct Work {
    /// Wander unknowns in column order (first in the array, at most one per
    /// linked axis at a time), with the observation each belongs to.
    pub(super) wander: Vec<usize>,
    /// Open blocks in column order (after the wander), with their number of columns.
    pub(super) open: Vec<(usize, usize)>,
    pub(super) ng: usize,
    /// Rows of `[R | z]`, `n + 1` columns.
    pub(super) rows: DMatrix<f64>,
    /// Rows waiting to be folded in.
    pub(super) pending: Vec<Vec<f64>>,
    pub(super) origin: Vector3<f64>,
    /// Squared right-hand sides of the rows that left the array with no
    /// unknown in them: the least-squares residual so far.
    pub(super) residual: f64,
    /// Buffers reused from fix to fix: allocating a fix's rows, arrays and
    /// vectors afresh was about a quarter of a noise likelihood's time.
    pub(super) scratch: Scratch,
}

/// Reused buffers of the forward pass ([`Work::pass_wander`], [`Work::compress`]).
#[derive(Default)]
pub(super) struct Scratch {
    /// The small array a wander is passed on in, column-major.
    array: Vec<f64>,
    /// The Householder vector of [`triangularise_in`].
    reflector: Vec<f64>,
    /// Pending rows that read the wander being passed on.
    reading: Vec<Vec<f64>>,
    /// Rows folded in, for the next rows to be written into.
    spare: Vec<Vec<f64>>,
    /// The array [`Work::compress`] triangularises, column-major.
    stack: Vec<f64>,
}

impl Work {
    pub(super) fn front_cols(&self) -> usize {
        self.wander.len() + self.open.iter().map(|&(_, m)| m).sum::<usize>()
    }

    pub(super) fn n(&self) -> usize {
        self.front_cols() + 6 + self.ng
    }

    pub(super) fn s0(&self) -> usize {
        self.front_cols()
    }

    pub(super) fn g0(&self) -> usize {
        self.front_cols() + 6
    }

    /// First column of open block `b`.
    pub(super) fn col_of(&self, b: usize) -> Option<usize> {
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
    pub(super) fn wander_col(&self, o: usize) -> Option<usize> {
        self.wander.iter().position(|&w| w == o)
    }

    /// The unknowns ahead of `s`, in column order.
    pub(super) fn front(&self) -> Vec<Unknown> {
        self.wander
            .iter()
            .map(|&o| Unknown::Wander(o))
            .chain(self.open.iter().map(|&(b, _)| Unknown::Block(b)))
            .collect()
    }

    /// Fold the pending rows into an upper-triangular `n x (n + 1)` array.
    pub(super) fn compress(&mut self) {
        let n = self.n();
        let tri = self.rows.nrows();
        let nr = (tri + self.pending.len()).max(n);
        let Scratch {
            reflector,
            spare,
            stack,
            ..
        } = &mut self.scratch;
        stack.clear();
        stack.resize(nr * (n + 1), 0.0);
        for (k, col) in self.rows.column_iter().enumerate() {
            stack[k * nr..k * nr + tri].copy_from_slice(col.as_slice());
        }
        for (i, row) in self.pending.drain(..).enumerate() {
            for (k, &v) in row.iter().enumerate() {
                stack[k * nr + tri + i] = v;
            }
            spare.push(row);
        }
        triangularise_in(stack, nr, n, tri, reflector);
        // Rows past the `n` of the triangle have no unknown left: what their
        // right-hand side holds no step can fit.
        self.residual += dot(
            &stack[n * nr + n..(n + 1) * nr],
            &stack[n * nr + n..(n + 1) * nr],
        );
        self.rows = block_of(stack, nr, (0, 0), (n, n + 1));
    }

    /// A zero row of `len` entries, in a buffer folded in earlier where there is one.
    pub(super) fn row(&mut self, len: usize) -> Vec<f64> {
        let mut row = self.scratch.spare.pop().unwrap_or_default();
        row.clear();
        row.resize(len, 0.0);
        row
    }

    /// Insert `m` zero columns at column `at` (the array and the pending rows).
    pub(super) fn insert_cols(&mut self, at: usize, m: usize) {
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
    pub(super) fn open_block(&mut self, b: usize, m: usize) {
        self.compress();
        self.insert_cols(self.s0(), m);
        self.open.push((b, m));
    }

    /// Add the wander of observation `o` as the first unknown. The array
    /// stays triangular once a row with an entry there is folded in (every
    /// row then moves down by one).
    pub(super) fn open_wander(&mut self, o: usize) {
        self.insert_cols(0, 1);
        self.wander.insert(0, o);
    }

    /// `col(dst) += factor * col(src)` over all rows.
    pub(super) fn axpy_col(&mut self, dst: usize, src: usize, factor: f64) {
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
    pub(super) fn first_done(&self, completed: usize) -> bool {
        matches!(self.open.first(), Some(&(b, _)) if self.open.len() > 1 && b < completed)
    }

    /// Eliminate the `m` columns from `start` (a few columns from the left):
    /// moved first and the array re-triangularised (only its first
    /// `start + m` rows change), their rows go to the backward pass.
    /// The array must be compressed.
    pub(super) fn eliminate_cols(&mut self, start: usize, m: usize) -> DMatrix<f64> {
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
        let kept = block(&self.rows, (0, 0), (m, n + 1));
        self.rows = block(&self.rows, (m, m), (n - m, n - m + 1));
        kept
    }

    /// Eliminate the first open block: its rows go to the backward pass.
    pub(super) fn eliminate_first(&mut self) -> Op {
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
    pub(super) fn pass_wander(
        &mut self,
        c: usize,
        o: usize,
        r: Vec<f64>,
        h: Vec<f64>,
        ops: &mut Ops,
    ) {
        let n = self.n();
        let Scratch {
            array,
            reflector,
            reading,
            spare,
            ..
        } = &mut self.scratch;
        // The rows that read the old wander leave `pending` (the others keep
        // their order), and come back below with the new rows' contents.
        reading.clear();
        reading.extend(self.pending.extract_if(.., |p| p[c] != 0.0));
        reading.push(r);
        let nl = c + 1 + reading.len() + 1;
        let nc = n + 2;
        array.clear();
        array.resize(nl * nc, 0.0);
        // Row `i` of the column-major `a`, `a[(i, k)]` at `k * nl + i`, from
        // the entries `at(k)` over the array's columns: the old wander's first.
        fn put(a: &mut [f64], nl: usize, c: usize, i: usize, at: impl Iterator<Item = f64>) {
            for (k, v) in at.enumerate() {
                let to = if k == c { 0 } else { k + 1 };
                a[to * nl + i] = v;
            }
        }
        for i in 0..=c {
            put(array, nl, c, i, self.rows.row(i).iter().copied());
        }
        for (i, p) in reading.iter().enumerate() {
            put(array, nl, c, c + 1 + i, p.iter().copied());
        }
        for (k, &v) in h.iter().enumerate() {
            array[k * nl + nl - 1] = v;
        }
        spare.push(h);
        triangularise_in(array, nl, c + 2, 0, reflector);
        for i in 0..=c {
            for k in 0..=n {
                self.rows[(i, k)] = array[(k + 1) * nl + i + 1];
            }
        }
        for (i, mut row) in (c + 2..nl).zip(reading.drain(..)) {
            row.clear();
            row.extend((0..=n).map(|k| array[(k + 1) * nl + i]));
            self.pending.push(row);
        }
        let prev = std::mem::replace(&mut self.wander[c], o);
        if ops.keeps() {
            let rows = block_of(array, nl, (0, 0), (1, nc));
            ops.push(Op::Eliminate {
                what: Unknown::Wander(prev),
                rows,
                rest: self.front(),
            });
        } else {
            ops.eliminated(std::iter::once(array[0]));
        }
    }

    /// Eliminate the wander of observation `o` once nothing ahead depends on it.
    pub(super) fn eliminate_wander(&mut self, o: usize) -> Option<Op> {
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
pub(super) fn triangularise(a: &mut DMatrix<f64>, n: usize, tri: usize) {
    let nr = a.nrows();
    triangularise_in(a.as_mut_slice(), nr, n, tri, &mut Vec::new());
}

/// [`triangularise`] of the column-major `nr`-row array `data`, with the
/// Householder vector in `v` (a buffer the caller may reuse).
pub(super) fn triangularise_in(
    data: &mut [f64],
    nr: usize,
    n: usize,
    tri: usize,
    v: &mut Vec<f64>,
) {
    triangularise_with::<true>(data, nr, n, tri, v);
}

/// [`triangularise_in`], its reflections over up to eight rows unrolled
/// ([`Reflection::apply_short`]) where `SHORT`: the general loop alone is
/// what the tests compare it with, digit for digit.
fn triangularise_with<const SHORT: bool>(
    data: &mut [f64],
    nr: usize,
    n: usize,
    tri: usize,
    v: &mut Vec<f64>,
) {
    let nc = data.len() / nr.max(1);
    v.clear();
    v.resize(nr, 0.0);
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
        let reflection = Reflection {
            j,
            from,
            vj,
            two_over_vv,
        };
        let columns = &mut tail[..(nc - j - 1) * nr];
        match if SHORT { to - from } else { 0 } {
            1 => reflection.apply_short::<1>(columns, nr, v),
            2 => reflection.apply_short::<2>(columns, nr, v),
            3 => reflection.apply_short::<3>(columns, nr, v),
            4 => reflection.apply_short::<4>(columns, nr, v),
            5 => reflection.apply_short::<5>(columns, nr, v),
            6 => reflection.apply_short::<6>(columns, nr, v),
            7 => reflection.apply_short::<7>(columns, nr, v),
            8 => reflection.apply_short::<8>(columns, nr, v),
            _ => reflection.apply(columns, nr, &v[from..to]),
        }
    }
}

/// A Householder reflection `I - 2 u u^T / (u^T u)` of [`triangularise_in`]
/// over row `j` (where `u` is `vj`) and rows `from..` (where it is `v`).
struct Reflection {
    j: usize,
    from: usize,
    vj: f64,
    two_over_vv: f64,
}

impl Reflection {
    /// The reflection applied to each `nr`-row column of `columns`, `v`
    /// being `u` on rows `from..from + v.len()`. A column with nothing on
    /// those rows is left as it is.
    fn apply(&self, columns: &mut [f64], nr: usize, v: &[f64]) {
        let (j, from, to) = (self.j, self.from, self.from + v.len());
        for c in columns.chunks_exact_mut(nr) {
            let d = self.vj * c[j] + dot(v, &c[from..to]);
            if d == 0.0 {
                continue;
            }
            let f = d * self.two_over_vv;
            c[j] -= f * self.vj;
            for (ci, vi) in c[from..to].iter_mut().zip(v) {
                *ci -= f * vi;
            }
        }
    }

    /// [`Reflection::apply`] for `L` rows below the diagonal, with `u` in
    /// registers: nine in ten of a noise likelihood's column updates touch
    /// one to eight rows (a fix's wander handed on, a few pending rows),
    /// where the general loop spent its time on loop set-up and bounds
    /// checks. The same [`dot`], unrolled for its length, so the same digits.
    #[inline(always)]
    fn apply_short<const L: usize>(&self, columns: &mut [f64], nr: usize, v: &[f64]) {
        let (j, from) = (self.j, self.from);
        let u: [f64; L] = std::array::from_fn(|i| v[from + i]);
        for c in columns.chunks_exact_mut(nr) {
            let cj = c[j];
            let Ok(below) = <&mut [f64; L]>::try_from(&mut c[from..from + L]) else {
                return;
            };
            let d = self.vj * cj + dot(&u, below);
            if d == 0.0 {
                continue;
            }
            let f = d * self.two_over_vv;
            for (b, x) in below.iter_mut().zip(&u) {
                *b -= f * x;
            }
            c[j] -= f * self.vj;
        }
    }
}

/// The `size` block of `a` at `start`, copied a column slice at a time
/// (nalgebra's `view(..).into_owned()` copies element by element through an
/// iterator, which was a sixth of the chain solver's time).
pub(super) fn block(a: &DMatrix<f64>, start: (usize, usize), size: (usize, usize)) -> DMatrix<f64> {
    block_of(a.as_slice(), a.nrows(), start, size)
}

/// [`block`] of the column-major array `src` of `stride` rows.
pub(super) fn block_of(
    src: &[f64],
    stride: usize,
    start: (usize, usize),
    size: (usize, usize),
) -> DMatrix<f64> {
    let (r0, c0) = start;
    let (nr, nc) = size;
    let mut out = Vec::with_capacity(nr * nc);
    for j in c0..c0 + nc {
        out.extend_from_slice(&src[j * stride + r0..j * stride + r0 + nr]);
    }
    DMatrix::from_vec(nr, nc, out)
}

/// `x . y` with four partial sums (so that it vectorises).
#[inline(always)]
pub(super) fn dot(x: &[f64], y: &[f64]) -> f64 {
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
pub(super) fn solve_upper(r: DMatrixView<f64>, z: &DVector<f64>) -> Option<Vec<f64>> {
    let x = r.solve_upper_triangular(z)?;
    x.iter()
        .all(|v| v.is_finite())
        .then(|| x.as_slice().to_vec())
}

/// `(U, T)` of a 9-vector `y = [U; V; D]` about origin `c`: `T = U x c + D - V`.
pub(super) fn six(y: &V9, c: &Vector3<f64>) -> [f64; 6] {
    let u = Vector3::new(y[0], y[1], y[2]);
    let t = u.cross(c) + Vector3::new(y[6] - y[3], y[7] - y[4], y[8] - y[5]);
    [u.x, u.y, u.z, t.x, t.y, t.z]
}

impl ChainSystem {
    /// The forward pass (see the module docs); the step is its
    /// back-substitution. With `keep` false the changes are not kept
    /// (`forward.ops` is empty: no backward pass), only the log-determinant
    /// and the residual.
    pub(super) fn run(&self, lambda: f64, track: bool, keep: bool) -> Option<Solved> {
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
            residual: 0.0,
            scratch: Scratch::default(),
        };
        let mut ops = Ops::new(keep);
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
        let eliminate = |work: &mut Work, ops: &mut Ops, completed: usize| {
            while work.first_done(completed) {
                ops.push(work.eliminate_first());
            }
        };
        let complete = |work: &mut Work, ops: &mut Ops, b: usize| {
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
        let open_next = |work: &mut Work, ops: &mut Ops, cursor: &mut Cursor| {
            cursor.open_at.push(ops.len());
            open(work, cursor.opened);
            cursor.opened += 1;
            eliminate(work, ops, cursor.completed);
        };
        let advance = |work: &mut Work, ops: &mut Ops, cursor: &mut Cursor, row: usize| loop {
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
        let track_to = |work: &mut Work, ops: &mut Ops, cursor: &mut Cursor, end: usize| {
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
            let mut r = work.row(n + 1);
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
            let (b, vals) = &lin.jb[o];
            if *b != u32::MAX
                && let Some(c0) = work.col_of(*b as usize)
            {
                for (x, &i) in blocks[*b as usize].params.iter().enumerate() {
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
                let mut c = work.row(n + 2);
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
                    work.pass_wander(p, o, r, c, &mut ops);
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
            self.diag.iter().map(|d| d.ln()).sum::<f64>() - 12.0 * PIN.ln() - constraint_log_det
                + ops.log_det;
        for i in 0..work.rows.nrows() {
            log_det += 2.0 * work.rows[(i, i)].abs().ln();
        }

        let forward = Forward {
            front: work.front(),
            rows: work.rows,
            ops: ops.list,
            scale,
            stages: cursor.stages,
            open_at: cursor.open_at,
            wander_at,
            origin: work.origin,
        };
        Some(Solved {
            log_det,
            residual: work.residual,
            forward,
        })
    }

    /// Columns of an unknown of the array.
    pub(super) fn size(&self, u: &Unknown) -> usize {
        match *u {
            Unknown::Block(b) => self.lin.blocks[b].params.len(),
            Unknown::Wander(_) => 1,
        }
    }

    /// The backward pass: back-substitution through the final triangle and
    /// the eliminated blocks in reverse, undoing the changes of variables.
    pub(super) fn backward(&self, f: &Forward) -> Option<DVector<f64>> {
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
    pub(super) fn add_priors(&self, work: &mut Work, stage: usize, scale: &[f64]) {
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulation::rng::Rng;

    /// The unrolled short reflections give the general loop's digits, on
    /// arrays shaped as the forward pass makes them: a triangle on top
    /// (`tri` rows) and below it 1-12 sparse rows (some columns empty), so
    /// that reflections touch every length from one row up.
    #[test]
    fn short_reflections_give_the_general_loops_digits() {
        let mut rng = Rng::new(5);
        let mut lengths = std::collections::BTreeSet::new();
        for case in 0..300 {
            let n = 3 + case % 20;
            let tri = case % (n + 1);
            let below = 1 + case % 12;
            let nr = tri.max(n) + below;
            let nc = n + 1;
            let mut a = vec![0.0; nr * nc];
            for k in 0..nc {
                for i in 0..nr {
                    let in_triangle = i < tri && i <= k;
                    let below_triangle = i >= tri.max(n) && rng.uniform() < 0.6;
                    if in_triangle || below_triangle {
                        a[k * nr + i] = rng.normal();
                    }
                }
            }
            for j in 0..n.min(nr) {
                let last = (j + 1..nr).rev().find(|&i| a[j * nr + i] != 0.0);
                if let Some(last) = last {
                    lengths.insert(last - tri.max(j + 1) + 1);
                }
            }
            let (mut short, mut general) = (a.clone(), a);
            triangularise_with::<true>(&mut short, nr, n, tri, &mut Vec::new());
            triangularise_with::<false>(&mut general, nr, n, tri, &mut Vec::new());
            let same = short
                .iter()
                .zip(&general)
                .all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same, "case {case}: n {n}, tri {tri}, {below} rows below");
        }
        assert!((1..=9).all(|l| lengths.contains(&l)), "{lengths:?}");
    }
}
