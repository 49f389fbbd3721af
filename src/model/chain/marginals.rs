//! The posterior covariances of the chain (Bierman's square-root information
//! smoother): every free column's variance, and the path's covariance at the
//! rows asked for, from the forward pass's changes walked backwards.

use nalgebra::{DMatrix, Vector3};

use super::forward::{Op, Unknown};
use super::*;

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
    pub(super) fn wants(&self, first: usize, end: usize) -> bool {
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
    pub(super) stages: Vec<StageCov>,
}

/// What moves the path at the rows of one state of the forward pass, and its covariance.
#[derive(Clone)]
pub(super) struct StageCov {
    pub(super) first_row: usize,
    /// The origin `c` of `T` in this state.
    pub(super) origin: Vector3<f64>,
    pub(super) cols: Vec<StageCol>,
    /// Per block among `cols`: its first and last row, first column, columns.
    pub(super) spans: Vec<(usize, usize, usize, usize)>,
    /// A square root of the covariance of `cols`.
    pub(super) l: DMatrix<f64>,
}

impl StageCov {
    /// Whether `other` moves the path through the same unknowns in the same
    /// order (the same blocks, `s` and globals), each with a full square root.
    fn same_unknowns(&self, other: &StageCov) -> bool {
        let same_cols = self.cols.len() == other.cols.len()
            && self
                .cols
                .iter()
                .zip(&other.cols)
                .all(|(p, q)| match (p, q) {
                    (StageCol::Param(i, _), StageCol::Param(j, _)) => i == j,
                    (StageCol::S(i), StageCol::S(j)) => i == j,
                    _ => false,
                });
        same_cols
            && self.spans == other.spans
            && self.l.nrows() == self.cols.len()
            && other.l.nrows() == other.cols.len()
    }

    /// This stage with `T` taken about `origin` instead of its own `c`: the
    /// path moves by `U x (p - c) + T = U x (p - c') + T'`, so
    /// `T' = T + U x (c' - c) = T - [c' - c]_x U`, and the rows of `T` in the
    /// square root gain `-[c' - c]_x` times those of `U`. `None` where a
    /// component of `s` is not among its unknowns (the backward pass keeps all six).
    fn about(&self, origin: Vector3<f64>) -> Option<StageCov> {
        let mut out = self.clone();
        let row = |k: usize| {
            self.cols
                .iter()
                .position(|c| matches!(*c, StageCol::S(j) if j == k))
        };
        let rows: Vec<usize> = (0..6).map(row).collect::<Option<_>>()?;
        let m = -(origin - self.origin).cross_matrix();
        for j in 0..3 {
            for k in 0..3 {
                for c in 0..out.l.ncols() {
                    out.l[(rows[3 + j], c)] += m[(j, k)] * self.l[(rows[k], c)];
                }
            }
        }
        out.origin = origin;
        Some(out)
    }

    /// The stage whose covariance is `wa P_a + wb P_b` (see
    /// [`Marginals::mix`]), seen from `first_row` on, at `a`'s origin. Over
    /// the same unknowns, one square root: the triangle of the QR of
    /// `[sqrt(wa) S_a L_a | sqrt(wb) S_b L_b]^T` (`S` the unknowns' scaling,
    /// taken out so that the two share one), so that `R^T R` is the weighted
    /// sum and a row's covariance costs what one setting's does. Over other
    /// unknowns (the two passes changed state at other moments), the two
    /// side by side: `diag(sqrt(wa) L_a, sqrt(wb) L_b)` over `a`'s unknowns
    /// and then `b`'s, whose `H L` has both parts' columns.
    fn mix(a: &StageCov, wa: f64, b: &StageCov, wb: f64, first_row: usize) -> Option<StageCov> {
        let moved;
        let b = if b.origin == a.origin {
            b
        } else {
            moved = b.about(a.origin)?;
            &moved
        };
        if !a.same_unknowns(b) {
            let (ka, kb) = (a.cols.len(), b.cols.len());
            let (na, nb) = (a.l.ncols(), b.l.ncols());
            let mut l = DMatrix::<f64>::zeros(a.l.nrows() + b.l.nrows(), na + nb);
            l.view_mut((0, 0), (a.l.nrows(), na))
                .copy_from(&(&a.l * wa.sqrt()));
            l.view_mut((a.l.nrows(), na), (b.l.nrows(), nb))
                .copy_from(&(&b.l * wb.sqrt()));
            let spans = a
                .spans
                .iter()
                .copied()
                .chain(b.spans.iter().map(|&(f, e, c0, m)| (f, e, c0 + ka, m)))
                .collect();
            debug_assert_eq!(l.nrows(), ka + kb);
            return Some(StageCov {
                first_row,
                origin: a.origin,
                cols: a.cols.iter().chain(&b.cols).copied().collect(),
                spans,
                l,
            });
        }
        let k = a.cols.len();
        let scale = |c: &StageCol| match *c {
            StageCol::Param(_, inv) => inv,
            StageCol::S(_) => 1.0,
        };
        let (na, nb) = (a.l.ncols(), b.l.ncols());
        // The stacked square roots, transposed: rows are columns of `S L`.
        let mut stacked = DMatrix::<f64>::zeros(na + nb, k);
        for (r, (ca, cb)) in a.cols.iter().zip(&b.cols).enumerate() {
            let (sa, sb) = (wa.sqrt() * scale(ca), wb.sqrt() * scale(cb));
            for c in 0..na {
                stacked[(c, r)] = sa * a.l[(r, c)];
            }
            for c in 0..nb {
                stacked[(na + c, r)] = sb * b.l[(r, c)];
            }
        }
        let r = if na + nb >= k {
            stacked.qr().r()
        } else {
            stacked
        };
        let cols = a
            .cols
            .iter()
            .map(|c| match *c {
                StageCol::Param(i, _) => StageCol::Param(i, 1.0),
                other => other,
            })
            .collect();
        Some(StageCov {
            first_row,
            origin: a.origin,
            cols,
            spans: a.spans.clone(),
            l: r.transpose(),
        })
    }
}

/// `wa a + wb b`, element by element.
fn mixed_var(a: &[f64], wa: f64, b: &[f64], wb: f64) -> Vec<f64> {
    a.iter().zip(b).map(|(p, q)| wa * p + wb * q).collect()
}

/// Mixes a second setting's stages, as its backward pass hands them over
/// (last first), into a first setting's (see [`Marginals::mix`]): each row
/// is seen in the stage of each that it lies in, so the mixed stages start
/// wherever either does, each pairing the two stages that hold from there.
/// The first setting's stages are let go as they are passed, so the two
/// settings take about one's memory (a 6-hour ride's hold some 60 MB).
pub(super) struct Mixer {
    /// The first setting's stages not yet passed, in row order.
    a: Vec<StageCov>,
    wa: f64,
    wb: f64,
    /// Mixed stages, last first.
    out: Vec<StageCov>,
    failed: bool,
}

impl Mixer {
    pub(super) fn new(a: Vec<StageCov>, wa: f64, wb: f64) -> Self {
        let out = Vec::with_capacity(a.len());
        Self {
            a,
            wa,
            wb,
            out,
            failed: false,
        }
    }

    /// The second setting's next stage (each earlier than the one before).
    pub(super) fn take(&mut self, b: &StageCov) {
        while let Some(a) = self.a.last() {
            let first = a.first_row.max(b.first_row);
            let Some(mixed) = StageCov::mix(a, self.wa, b, self.wb, first) else {
                self.failed = true;
                return;
            };
            if a.first_row < b.first_row {
                self.out.push(mixed);
                return;
            }
            let same = a.first_row == b.first_row;
            // The first setting's stage is passed: let go.
            self.a.pop();
            self.out.push(mixed);
            if same {
                return;
            }
        }
    }

    /// The mixed stages in row order.
    pub(super) fn finish(self) -> Option<Vec<StageCov>> {
        let mut out = self.out;
        out.reverse();
        (!self.failed).then_some(out)
    }
}

/// A column of a [`StageCov`]: a parameter (with `1 / sqrt(D)`: the unknown is scaled) or `s`.
#[derive(Clone, Copy, Debug)]
pub(super) enum StageCol {
    Param(usize, f64),
    S(usize),
}

impl Marginals {
    /// `wa P_a + wb P_b`: the marginals of a mixture of two settings of one
    /// model (the same free columns; only the noise differs), stage by stage
    /// (see [`StageCov::mix`]): the path's covariance at a row then costs
    /// what one setting's does. `None` where the columns differ.
    pub fn mix(a: Marginals, wa: f64, b: Marginals, wb: f64) -> Option<Marginals> {
        if a.var.len() != b.var.len() {
            return None;
        }
        let var = mixed_var(&a.var, wa, &b.var, wb);
        let mut mixer = Mixer::new(a.stages, wa, wb);
        for st in b.stages.iter().rev() {
            mixer.take(st);
        }
        Some(Marginals {
            var,
            stages: mixer.finish()?,
        })
    }

    /// How many stages the path's covariance is kept for.
    #[cfg(test)]
    pub(crate) fn stage_count(&self) -> usize {
        self.stages.len()
    }

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
pub(super) enum Var {
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
pub(super) struct CovWalk {
    pub(super) labels: Vec<Var>,
    pub(super) l: DMatrix<f64>,
}

impl CovWalk {
    pub(super) fn index(&self, v: Var) -> Option<usize> {
        self.labels.iter().position(|&l| l == v)
    }

    /// The variance of unknown `k`.
    pub(super) fn var(&self, k: usize) -> f64 {
        self.l.row(k).norm_squared()
    }

    /// `L <- A L` for `v_old = A v_new`, `A = I + sum (dst, src, a) e_dst e_src^T`
    /// (no `dst` is a `src`).
    pub(super) fn transform(&mut self, terms: &[(Var, Var, f64)]) -> Option<()> {
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
    pub(super) fn eliminated(
        &mut self,
        new: &[Var],
        rows: &DMatrix<f64>,
        rest: &[Var],
    ) -> Option<()> {
        let m = new.len();
        let rest_idx: Vec<usize> = rest.iter().map(|&v| self.index(v)).collect::<Option<_>>()?;
        let rbb_inv = super::forward::block(rows, (0, 0), (m, m))
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
        self.compress_if_wide();
        Some(())
    }

    /// Keep only the unknowns where `keep` holds (the others marginalised out).
    pub(super) fn retain(&mut self, keep: impl Fn(&Var) -> bool) {
        let idx: Vec<usize> = (0..self.labels.len())
            .filter(|&k| keep(&self.labels[k]))
            .collect();
        if idx.len() == self.labels.len() {
            return;
        }
        self.l = self.l.select_rows(&idx);
        self.labels = idx.iter().map(|&k| self.labels[k]).collect();
        self.compress_if_wide();
    }

    /// [`Self::compress`] once `L` has grown to twice as many columns as
    /// rows: a QR after every change was 44 % of the backward pass, and
    /// the extra columns cost the changes less than the QRs they spare.
    fn compress_if_wide(&mut self) {
        if self.l.ncols() > 2 * self.l.nrows() {
            self.compress();
        }
    }

    /// `L` with no more columns than rows: `L^T = Q R` gives `L L^T = R^T R`.
    pub(super) fn compress(&mut self) {
        self.l = square_root(&self.l);
    }

    /// A square root of the covariance of the unknowns at `idx`.
    pub(super) fn select(&self, idx: &[usize]) -> DMatrix<f64> {
        square_root(&self.l.select_rows(idx))
    }
}

/// `S` (rows x rows at most) with `S S^T = L L^T`.
pub(super) fn square_root(l: &DMatrix<f64>) -> DMatrix<f64> {
    if l.ncols() <= l.nrows() {
        return l.clone();
    }
    l.transpose().qr().r().transpose()
}

impl ChainSystem {
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
        let mut stages = Vec::new();
        let var = self.walk_back(rows, &mut |st| stages.push(st))?;
        stages.reverse();
        Some(Marginals { var, stages })
    }

    /// [`Self::marginals`] of this setting mixed into `a`'s, another
    /// setting's of the same model (see [`Marginals::mix`]), stage by stage
    /// as the backward pass hands them over, so that this setting's are
    /// never all held. Also this setting's own variances. `None` as for
    /// `marginals`, or where the columns differ.
    pub(crate) fn marginals_mixed(
        &self,
        rows: PathRows,
        a: Marginals,
        wa: f64,
        wb: f64,
    ) -> Option<(Marginals, Vec<f64>)> {
        let mut mixer = Mixer::new(a.stages, wa, wb);
        let own = self.walk_back(rows, &mut |st| mixer.take(&st))?;
        if own.len() != a.var.len() {
            return None;
        }
        let var = mixed_var(&a.var, wa, &own, wb);
        let stages = mixer.finish()?;
        Some((Marginals { var, stages }, own))
    }

    /// The backward pass of [`Self::marginals`]: every free column's
    /// variance, and each stage of `rows` handed to `sink` as it is reached
    /// (last first).
    fn walk_back(&self, rows: PathRows, sink: &mut dyn FnMut(StageCov)) -> Option<Vec<f64>> {
        let solved = self.run(0.0, !matches!(rows, PathRows::None), true)?;
        let f = &solved.forward;
        let lin = &self.lin;
        let blocks = &lin.blocks;
        let n = f.rows.nrows();
        let rinv = super::forward::block(&f.rows, (0, 0), (n, n))
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
        let mut origin = f.origin;
        let mut mark = f.stages.len();
        let mut store = |walk: &CovWalk, at: usize, origin: Vector3<f64>, mark: &mut usize| {
            while *mark > 0 && f.stages[*mark - 1].ops >= at {
                *mark -= 1;
                let st = &f.stages[*mark];
                let end = f.stages.get(*mark + 1).map_or(lin.horizon, |n| n.first_row);
                if st.ops == at && rows.wants(st.first_row, end) {
                    sink(self.stage_cov(walk, st.first_row, end, origin, &f.scale));
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
        var.iter().all(|v| v.is_finite()).then_some(var)
    }

    /// The covariance of what moves the path at rows `first..end` (all seen
    /// in one state): the blocks those rows lie in, `s` and the globals.
    pub(super) fn stage_cov(
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
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stage over `s` (and, with `param`, one parameter of a block over
    /// rows `0..=99`) about `origin`, with a full square root of numbers
    /// drawn from `seed`.
    fn stage(first_row: usize, origin: Vector3<f64>, param: bool, seed: f64) -> StageCov {
        let mut cols: Vec<StageCol> = (0..6).map(StageCol::S).collect();
        let mut spans = Vec::new();
        if param {
            spans.push((0, 99, 0, 1));
            cols.insert(0, StageCol::Param(0, 0.5));
        }
        let k = cols.len();
        let l = DMatrix::from_fn(k, k, |r, c| {
            if c > r {
                0.0
            } else {
                ((r * 7 + c * 3) as f64 + seed).sin() + if r == c { 2.0 } else { 0.0 }
            }
        });
        StageCov {
            first_row,
            origin,
            cols,
            spans,
            l,
        }
    }

    fn marginals(stages: Vec<StageCov>) -> Marginals {
        Marginals {
            var: vec![1.0],
            stages,
        }
    }

    /// The path's covariance at `row` (at a point that moves with the row).
    fn at(m: &Marginals, row: usize) -> [f64; 4] {
        let p = Vector3::new(3.0 + row as f64, -2.0, 0.5);
        m.path_covariance(row, &p, |_| Vector3::new(1.0, 0.3, -0.2))
    }

    /// Two settings whose passes changed state at other rows, over other
    /// unknowns and about other origins mix into `wa P_a + wb P_b` at every
    /// row: the mixed stages start wherever either setting's does and pair
    /// the two that hold there, side by side where their unknowns differ.
    #[test]
    fn mixed_stages_are_the_weighted_sum_at_every_row() {
        let o = |x: f64| Vector3::new(x, 1.0 - x, 0.2 * x);
        let a = || {
            marginals(vec![
                stage(0, o(0.0), false, 0.1),
                stage(10, o(0.0), true, 0.7),
                stage(30, o(4.0), true, 1.3),
            ])
        };
        let b = || {
            marginals(vec![
                stage(0, o(0.0), false, 2.1),
                stage(5, o(1.0), false, 2.9),
                stage(10, o(1.0), true, 3.3),
                stage(22, o(-3.0), true, 4.4),
            ])
        };
        let (wa, wb) = (0.3, 1.7);
        let (sa, sb) = (a(), b());
        let mixed = Marginals::mix(a(), wa, b(), wb).expect("same columns");
        assert_eq!(
            mixed.stages.iter().map(|s| s.first_row).collect::<Vec<_>>(),
            [0, 5, 10, 22, 30]
        );
        for row in 0..40 {
            let (pa, pb, got) = (at(&sa, row), at(&sb, row), at(&mixed, row));
            for k in 0..4 {
                let want = wa * pa[k] + wb * pb[k];
                assert!(
                    (got[k] - want).abs() <= 1e-10 * want.abs().max(1.0),
                    "row {row}, entry {k}: {} against {want}",
                    got[k]
                );
            }
        }
        assert!((mixed.var[0] - (wa + wb)).abs() < 1e-12);
    }

    /// Taken about another origin, a stage moves the path as before.
    #[test]
    fn a_stage_about_another_origin_moves_the_path_alike() {
        let st = stage(0, Vector3::new(1.0, 2.0, 3.0), true, 0.4);
        let moved = st.about(Vector3::new(-5.0, 0.5, 9.0)).expect("all of s");
        let (before, after) = (marginals(vec![st]), marginals(vec![moved]));
        for row in [0, 50, 99] {
            let (x, y) = (at(&before, row), at(&after, row));
            for k in 0..4 {
                assert!(
                    (x[k] - y[k]).abs() <= 1e-10 * x[k].abs().max(1.0),
                    "row {row}"
                );
            }
        }
    }
}
