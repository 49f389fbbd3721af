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
    /// Whether `other` is this stage under other noise settings: the same
    /// rows, unknowns, blocks and origin.
    fn blends_with(&self, other: &StageCov) -> bool {
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
            && self.first_row == other.first_row
            && self.spans == other.spans
            && self.origin == other.origin
            && self.l.nrows() == self.cols.len()
            && other.l.nrows() == other.cols.len()
    }

    /// See [`Marginals::blend`] (the two [`StageCov::blends_with`] each other).
    fn blend(a: &StageCov, wa: f64, b: &StageCov, wb: f64) -> StageCov {
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
        StageCov {
            first_row: a.first_row,
            origin: a.origin,
            cols,
            spans: a.spans.clone(),
            l: r.transpose(),
        }
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
    /// model (the same stages, unknowns and blocks; only the noise differs),
    /// each stage's square root the triangle of the QR of
    /// `[sqrt(wa) S_a L_a | sqrt(wb) S_b L_b]^T` (`S` the unknowns' scaling,
    /// taken out so that the two share one): `R^T R` is their weighted sum,
    /// and the path's covariance at a row then costs what one setting's
    /// does. The two are consumed stage by stage (on a 6-hour ride each
    /// holds some 60 MB); handed back where they differ in structure.
    pub fn blend(
        a: Marginals,
        wa: f64,
        b: Marginals,
        wb: f64,
    ) -> Result<Marginals, (Marginals, Marginals)> {
        let same = a.stages.len() == b.stages.len()
            && a.var.len() == b.var.len()
            && a.stages
                .iter()
                .zip(&b.stages)
                .all(|(x, y)| x.blends_with(y));
        if !same {
            return Err((a, b));
        }
        let var = a
            .var
            .iter()
            .zip(&b.var)
            .map(|(p, q)| wa * p + wb * q)
            .collect();
        let stages = a
            .stages
            .into_iter()
            .zip(b.stages)
            .map(|(x, y)| StageCov::blend(&x, wa, &y, wb))
            .collect();
        Ok(Marginals { var, stages })
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
        self.compress();
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
        self.compress();
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
