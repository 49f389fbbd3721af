//! The Gauss-Newton normal equations `J^T J` and `J^T r` for LM, from moments,
//! without forming the dense Jacobian.
//!
//! Columns of parameters that act everywhere ("global": constant bias,
//! gain, start, ...) are computed explicitly as in [`super::jacobian`]. A
//! parameter that acts only on a stretch of steps (a segment bias) has, at
//! every GPS row after its stretch, a Jacobian entry that is linear in a fixed
//! 9-vector `y_c = [U_c; V_c; D_c]` of its prefix sums:
//!
//! ```text
//! J[o, c] = h_o . y_c,   h_o = w_o (row_a(-[p]x), -e_a, e_a)    (observation o: axis a of p at its row)
//! ```
//!
//! so for segments `b < b'` the block `sum_o J_ob^T J_ob'` splits into the rows
//! inside `b'` (explicit) and the rows after it, `Y_b^T (sum_{o after b'} h_o^T h_o) Y_b'`,
//! a suffix sum of 9x9 moments. Building `J^T J` then costs O(N + S^2) instead
//! of O(rows x P^2): for a 30-minute ride with 5 s segments (1,080 bias
//! parameters) that is the difference between seconds and milliseconds.

use faer::linalg::solvers::Solve;
use nalgebra::{DMatrix, DVector, SMatrix, SVector, Vector3};
use std::sync::Arc;

use super::Model;
use super::noise::Link;
use super::observe::Whitener;
use crate::effects::PriorRows;

pub(crate) type V9 = SVector<f64, 9>;
type M9 = SMatrix<f64, 9, 9>;

/// `A = J^T J`, `g = J^T r` and the cost, over the free parameters.
#[derive(Clone, Debug)]
pub struct NormalEquations {
    pub a: DMatrix<f64>,
    pub g: DVector<f64>,
    pub cost: f64,
    /// Parameter index of each row/column of `a`.
    pub columns: Vec<usize>,
}

/// The linearised residuals of a model whose local parameters (segment
/// biases) act on disjoint stretches of steps, kept in the form that both the
/// dense normal equations and the O(N) chain solver ([`super::chain`]) use:
/// per observation `o` the residual `r_o`, and the derivative of its path
/// value `x_o` as the 9-vector `h_o`, its global row and its explicit row for
/// the block it lies in; per block parameter `y_c`. The residual's row is
/// `slope_o dx_o + back_o dx_prev(o)` (see [`super::noise`]: `back` is 0
/// without GPS error correlation).
#[derive(Clone, Debug)]
pub(crate) struct ChainLinearisation {
    /// The path's derivatives, shared: a noise likelihood reweighs the same
    /// derivatives under another setting, and copying them (1.5 MB on a
    /// 30-minute ride) was a twentieth of its time. Written through
    /// [`std::ops::DerefMut`], which copies them first where they are shared.
    pub derivatives: Arc<ChainDerivatives>,
    /// The path value `x_o` (component of `at`) it compares.
    pub x: Vec<f64>,
    /// Residuals of the observations (whitened, through the robust loss).
    pub r: DVector<f64>,
    /// `(d r_o / d x_o, d r_o / d z_prev)`.
    pub slope: Vec<(f64, f64)>,
    /// How each observation is linked to the one before it (GPS error correlation).
    pub links: Vec<Link>,
    /// Prior rows (entries of free parameters only).
    pub prior: PriorRows,
    /// Cost of observations and priors.
    pub cost: f64,
}

/// The parts of a [`ChainLinearisation`] that do not depend on the noise
/// settings: which parameters are free, and the derivatives of the path at
/// each observation.
#[derive(Clone, Debug)]
pub(crate) struct ChainDerivatives {
    /// Free parameters, in parameter order.
    pub columns: Vec<usize>,
    /// Free parameters acting everywhere.
    pub globals: Vec<usize>,
    /// Blocks of local parameters, sorted by first step, disjoint.
    pub blocks: Vec<Block>,
    /// `y_c = [U_c; V_c; D_c]` of each block's parameters once the block is complete.
    pub y: Vec<Vec<V9>>,
    /// `h_o = (row_a(-[p]x), -e_a, e_a)`: `d x_o = h_o . y_c` for a block complete before `o`.
    pub h: Vec<V9>,
    /// Where on the path observation `o` looks (`p`).
    pub at: Vec<Vector3<f64>>,
    /// Row in whose step observation `o` is evaluated.
    pub rows: Vec<usize>,
    /// Rows of the global parameters (observations x globals).
    pub jg: DMatrix<f64>,
    /// Block an observation lies in (`u32::MAX`: none) and its entries there.
    pub jb: Vec<(u32, BlockEntries)>,
    /// Rows swept by the model.
    pub horizon: usize,
}

impl std::ops::Deref for ChainLinearisation {
    type Target = ChainDerivatives;

    fn deref(&self) -> &ChainDerivatives {
        &self.derivatives
    }
}

impl std::ops::DerefMut for ChainLinearisation {
    fn deref_mut(&mut self) -> &mut ChainDerivatives {
        Arc::make_mut(&mut self.derivatives)
    }
}

/// What one chunk of [`Model::chain_linearisation`]'s sweep gathered: from
/// observation `first` on, each one's point, global row (row-major) and
/// partial block row.
#[derive(Default)]
struct Gathered {
    first: Option<usize>,
    at: Vec<Vector3<f64>>,
    jg: Vec<f64>,
    jb: Vec<(u32, BlockEntries)>,
}

/// An observation's derivatives in the parameters of its block, in the
/// block's order: inline for a segment's three biases, on the heap only
/// for a block that holds a gyro stop's turns too.
pub(crate) type BlockEntries = smallvec::SmallVec<[f64; 3]>;

/// A group of local columns acting within one stretch of steps, from
/// `first` to `last`; each of its parameters on all of it or on a part
/// (a stop's turns inside a segment).
#[derive(Clone, Debug)]
pub(crate) struct Block {
    pub first: usize,
    pub last: usize,
    pub params: Vec<usize>,
}

/// `groups` (local parameters by the stretch they act on) sorted by their
/// first step, those whose stretches overlap merged into one block: the
/// chain's blocks follow one another. A segment's bias and the turns of a
/// gyro stop inside it (or across its end) act on overlapping stretches;
/// in one block their columns are open together, each parameter's
/// derivative its own (its prefix sums are zero before it acts, final
/// after). Stretches past the ride's end (`first` = `usize::MAX`) stay
/// apart.
fn merged(mut groups: Vec<Block>) -> Vec<Block> {
    groups.sort_by_key(|b| b.first);
    let mut out: Vec<Block> = Vec::with_capacity(groups.len());
    for g in groups {
        match out.last_mut() {
            Some(b) if g.first != usize::MAX && g.first <= b.last => {
                b.last = b.last.max(g.last);
                b.params.extend(g.params);
            }
            _ => out.push(g),
        }
    }
    out
}

impl Model {
    /// Normal equations at `theta` over the parameters where `free` is true.
    ///
    /// Falls back to `J^T J` of the dense Jacobian for a model without
    /// local parameters and for whitened (coupled) rows.
    pub fn normal_equations(&self, theta: &[f64], free: &[bool]) -> NormalEquations {
        self.structured_normal_equations(theta, free)
            .unwrap_or_else(|| {
                // Dense: models without segments, and whitened (coupled) rows.
                let lin = self.linearise(theta, free);
                let jt = lin.jacobian.transpose();
                NormalEquations {
                    a: &jt * &lin.jacobian,
                    g: &jt * &lin.residuals,
                    cost: lin.cost,
                    columns: lin.columns,
                }
            })
    }

    /// The linearisation in chain form (see [`ChainLinearisation`]), or `None`
    /// for a model without local parameters (no segments free).
    pub(crate) fn chain_linearisation(
        &self,
        theta: &[f64],
        free: &[bool],
    ) -> Option<ChainLinearisation> {
        let sig = &self.signals;
        let np = self.n_params();
        let columns = super::free_columns(&free[..np]);
        // Classify the free parameters.
        let mut globals: Vec<usize> = Vec::new();
        let mut blocks: Vec<Block> = Vec::new();
        // Index among the global columns, for free global parameters.
        let mut global_of = vec![usize::MAX; np];
        for (e, effect) in self.effects.iter().enumerate() {
            for k in 0..effect.n_params() {
                let i = self.offsets[e] + k;
                if !free[i] {
                    continue;
                }
                match effect.param_steps(k) {
                    None => {
                        global_of[i] = globals.len();
                        globals.push(i);
                    }
                    Some((first, last)) => {
                        let b = match blocks
                            .iter()
                            .position(|b| b.first == first && b.last == last)
                        {
                            Some(b) => b,
                            None => {
                                blocks.push(Block {
                                    first,
                                    last,
                                    params: Vec::new(),
                                });
                                blocks.len() - 1
                            }
                        };
                        blocks[b].params.push(i);
                    }
                }
            }
        }
        if blocks.is_empty() {
            return None;
        }
        let blocks = merged(blocks);
        let mut block_at = vec![u32::MAX; self.horizon()];
        for (b, block) in blocks.iter().enumerate() {
            if block.first < self.horizon() {
                for entry in &mut block_at[block.first..=block.last.min(self.horizon() - 1)] {
                    *entry = b as u32;
                }
            }
        }
        let ng = globals.len();

        // Forward sweep, chunk by chunk side by side: per observation, h_o,
        // the global row and the partial block row, each chunk's derivatives
        // its own steps' (see `Model::prefix_sweep_chunked`).
        let obs = &self.observations;
        let no = obs.len();
        let plan = self.obs_plan(theta);
        let chunked = self.prefix_sweep_chunked(
            theta,
            free,
            &plan.row,
            None,
            |_| Gathered::default(),
            |out, row, p_row, delta, sums| {
                let mut k = plan.row.partition_point(|&r| r < row);
                if out.first.is_none() {
                    out.first = Some(k);
                }
                while k < no && plan.row[k] == row {
                    let a = obs[k].axis;
                    let beta = plan.beta[k];
                    let p = plan.position(k, p_row, delta);
                    out.at.push(p);
                    for &i in &globals {
                        out.jg.push(sums.dp_at(i, &p, beta)[a]);
                    }
                    let at = out.jg.len() - ng;
                    plan.for_extra(k, a, delta, sig.dt[row], |i, d| {
                        if let Some(&g) = global_of.get(i).filter(|&&g| g != usize::MAX) {
                            out.jg[at + g] += d;
                        }
                    });
                    let b = block_at[row];
                    let vals: BlockEntries = match blocks.get(b as usize) {
                        Some(block) => block
                            .params
                            .iter()
                            .map(|&i| sums.dp_at(i, &p, beta)[a])
                            .collect(),
                        None => BlockEntries::new(),
                    };
                    out.jb.push((b, vals));
                    k += 1;
                }
            },
        );
        let mut h = vec![V9::zeros(); no];
        let mut at = vec![Vector3::zeros(); no];
        let mut xs = vec![0.0; no];
        let mut jg = DMatrix::<f64>::zeros(no, ng);
        let mut jb: Vec<(u32, BlockEntries)> = vec![(u32::MAX, BlockEntries::new()); no];
        let mut r = DVector::<f64>::zeros(no);
        let mut slope = vec![(1.0, 0.0); no];
        let mut white = Whitener::new(&plan, obs);
        let mut last_row = None;
        let total = chunked.each_with_before(np, |c, before, gathered| {
            let Some(first) = gathered.first else {
                return;
            };
            for (n, p) in gathered.at.iter().enumerate() {
                let k = first + n;
                let a = obs[k].axis;
                at[k] = *p;
                xs[k] = p[a];
                let v = white.value(k, p[a]);
                r[k] = v.r;
                slope[k] = (v.slope, v.back);
                // h_o: (row a of -[p]x, -e_a, e_a).
                let mut hv = V9::zeros();
                match a {
                    0 => {
                        hv[1] = p.z;
                        hv[2] = -p.y;
                    }
                    1 => {
                        hv[0] = -p.z;
                        hv[2] = p.x;
                    }
                    _ => {
                        hv[0] = p.y;
                        hv[1] = -p.x;
                    }
                }
                hv[3 + a] = -1.0;
                hv[6 + a] = 1.0;
                h[k] = hv;
                // The chunks before this one: their sums act on every later point.
                let earlier = |i: usize| if c == 0 { 0.0 } else { before.dp(i, p)[a] };
                for (g, &i) in globals.iter().enumerate() {
                    jg[(k, g)] = gathered.jg[n * ng + g] + earlier(i);
                }
                let (b, mut vals) = gathered.jb[n].clone();
                if b != u32::MAX {
                    for (kk, &i) in blocks[b as usize].params.iter().enumerate() {
                        vals[kk] += earlier(i);
                    }
                }
                jb[k] = (b, vals);
                last_row = Some(plan.row[k]);
            }
        });
        // y_c of the blocks that ended before the last observed row: their
        // sums are final there (a block's parameters act on its steps only).
        let y: Vec<Vec<V9>> = blocks
            .iter()
            .map(|b| {
                b.params
                    .iter()
                    .map(|&i| {
                        if last_row.is_some_and(|row| b.last < row) {
                            V9::from_iterator(
                                total.u[i]
                                    .iter()
                                    .chain(total.v[i].iter())
                                    .chain(total.d[i].iter())
                                    .copied(),
                            )
                        } else {
                            V9::zeros()
                        }
                    })
                    .collect()
            })
            .collect();

        let cost = r.norm_squared();
        let mut prior = self.prior_rows(theta);
        let prior_cost = prior.residuals.iter().map(|x| x * x).sum::<f64>();
        prior.entries.retain(|&(_, col, _)| free[col]);
        Some(ChainLinearisation {
            derivatives: Arc::new(ChainDerivatives {
                columns,
                globals,
                blocks,
                y,
                h,
                at,
                rows: plan.row,
                jg,
                jb,
                horizon: self.horizon(),
            }),
            x: xs,
            r,
            slope,
            links: plan.links,
            prior,
            cost: cost + prior_cost,
        })
    }

    /// `lin` (made by a model on the same ride with the same effects and
    /// segments, at the same `theta`) with this model's noise: the
    /// derivatives of the path are unchanged, only the residuals, their
    /// slopes and links and the prior rows are this model's. O(fixes), not
    /// O(rows): what a search over noise settings needs.
    pub(crate) fn reweighted(&self, lin: &ChainLinearisation, theta: &[f64]) -> ChainLinearisation {
        let mut out = lin.clone();
        self.reweigh(&mut out, theta);
        out
    }

    /// `lin` (derivatives of this model's observations at `theta`, made
    /// elsewhere: see [`Model::chain_system_from_coarse`]) with the
    /// residuals, slopes and priors of this model at `theta`, where its
    /// observed values are `observed` (an evaluation's,
    /// [`super::Evaluation::observed`]). `None` if the counts disagree.
    pub(crate) fn moved(
        &self,
        mut lin: ChainLinearisation,
        theta: &[f64],
        observed: &[f64],
    ) -> Option<ChainLinearisation> {
        if observed.len() != lin.x.len() || observed.len() != self.observations.len() {
            return None;
        }
        lin.x.copy_from_slice(observed);
        self.reweigh(&mut lin, theta);
        Some(lin)
    }

    /// [`Model::reweighted`] in place.
    fn reweigh(&self, lin: &mut ChainLinearisation, theta: &[f64]) {
        let plan = self.obs_plan(theta);
        let mut white = Whitener::new(&plan, &self.observations);
        for (k, &x) in lin.x.iter().enumerate() {
            let v = white.value(k, x);
            lin.r[k] = v.r;
            lin.slope[k] = (v.slope, v.back);
        }
        lin.links = plan.links;
        let mut prior = self.prior_rows(theta);
        let prior_cost = prior.residuals.iter().map(|x| x * x).sum::<f64>();
        let free: std::collections::HashSet<usize> = lin.columns.iter().copied().collect();
        prior.entries.retain(|(_, col, _)| free.contains(col));
        lin.cost = lin.r.norm_squared() + prior_cost;
        lin.prior = prior;
    }

    /// `lin` (made by a model on the same ride, effects and segments at the
    /// same `theta`) restricted to the observations where `kept` is true,
    /// which must be this model's, under this model's noise. The path's
    /// derivatives at an observation do not depend on which others are
    /// observed, so a fold of a validation that withholds fixes starts from
    /// the full ride's linearisation instead of a sweep of its own: the same
    /// numbers, O(fixes) instead of O(rows). `None` if the counts disagree.
    pub(crate) fn restricted_to(
        &self,
        lin: &ChainLinearisation,
        theta: &[f64],
        kept: &[bool],
    ) -> Option<ChainLinearisation> {
        let take: Vec<usize> = (0..kept.len()).filter(|&o| kept[o]).collect();
        if kept.len() != lin.x.len() || take.len() != self.observations.len() {
            return None;
        }
        // The residuals, slopes, links, prior rows and cost are this model's:
        // `reweigh` writes them over the picked ones.
        let mut sub = ChainLinearisation {
            derivatives: Arc::new(ChainDerivatives {
                columns: lin.columns.clone(),
                globals: lin.globals.clone(),
                blocks: lin.blocks.clone(),
                y: lin.y.clone(),
                h: take.iter().map(|&o| lin.h[o]).collect(),
                at: take.iter().map(|&o| lin.at[o]).collect(),
                rows: take.iter().map(|&o| lin.rows[o]).collect(),
                jg: lin.jg.select_rows(take.iter()),
                jb: take.iter().map(|&o| lin.jb[o].clone()).collect(),
                horizon: lin.horizon,
            }),
            x: take.iter().map(|&o| lin.x[o]).collect(),
            r: DVector::from_iterator(take.len(), take.iter().map(|&o| lin.r[o])),
            slope: take.iter().map(|&o| lin.slope[o]).collect(),
            links: take.iter().map(|&o| lin.links[o]).collect(),
            prior: lin.prior.clone(),
            cost: lin.cost,
        };
        self.reweigh(&mut sub, theta);
        Some(sub)
    }

    /// The moment form, for rows that each see one observation (no GPS error correlation).
    fn structured_normal_equations(&self, theta: &[f64], free: &[bool]) -> Option<NormalEquations> {
        let c = self.chain_linearisation(theta, free)?;
        if c.is_coupled() {
            return None;
        }
        Some(c.normal_equations(self.n_params()))
    }
}

impl ChainLinearisation {
    /// What the derivatives of `coarse` (a coarse ride's linearisation,
    /// `Signals::coarse`) missed of `self`'s (the ride's own, at the same
    /// point): `self` with `J - J_c` in place of its derivatives (`jg`, the
    /// block entries, `h`, `at` and `y`), for [`ChainLinearisation::corrected`].
    /// `None` where the two do not share their parameters, blocks and
    /// observations.
    pub(crate) fn missed_by(self, coarse: &Self) -> Option<Self> {
        self.plus_derivatives(coarse, -1.0)
    }

    /// This linearisation (of a coarse ride at some `theta`) with its
    /// derivatives corrected by what the coarse ride missed at an anchor
    /// `theta_a` (`missed`, [`ChainLinearisation::missed_by`] there):
    /// `J = J_c(theta) + J(theta_a) - J_c(theta_a)`. What is left is
    /// `(J - J_c)(theta) - (J - J_c)(theta_a)`, second order in how far
    /// `theta` moved and how coarse the ride is. `None` where the two do
    /// not share their shape.
    pub(crate) fn corrected(self, missed: &Self) -> Option<Self> {
        self.plus_derivatives(missed, 1.0)
    }

    /// `self` with `sign` times `other`'s derivatives (`jg`, the block
    /// entries, `h`, `at` and `y`) added to its own, entry by entry; `None`
    /// where the two do not share their shape.
    fn plus_derivatives(mut self, other: &Self, sign: f64) -> Option<Self> {
        if !self.same_shape(other) {
            return None;
        }
        // Copied once where shared, not checked again at every entry.
        let own = Arc::make_mut(&mut self.derivatives);
        own.jg += &other.jg * sign;
        for (o, (_, vals)) in own.jb.iter_mut().enumerate() {
            for (k, v) in vals.iter_mut().enumerate() {
                *v += sign * other.jb[o].1[k];
            }
        }
        for o in 0..own.h.len() {
            own.h[o] += other.h[o] * sign;
            own.at[o] += other.at[o] * sign;
        }
        for (b, ys) in own.y.iter_mut().enumerate() {
            for (k, y) in ys.iter_mut().enumerate() {
                *y += other.y[b][k] * sign;
            }
        }
        Some(self)
    }

    /// The same free parameters, blocks, observations (each in the same
    /// block) and completed blocks' sums: derivatives that add entry by entry.
    fn same_shape(&self, other: &Self) -> bool {
        self.globals == other.globals
            && self.x.len() == other.x.len()
            && self.blocks.len() == other.blocks.len()
            && self
                .blocks
                .iter()
                .zip(&other.blocks)
                .all(|(p, q)| p.params == q.params)
            && self.jb.iter().zip(&other.jb).all(|(p, q)| p.0 == q.0)
            && self.y.iter().zip(&other.y).all(|(p, q)| {
                p.len() == q.len()
                    && p.iter()
                        .zip(q)
                        .all(|(u, v)| (u.norm() == 0.0) == (v.norm() == 0.0))
            })
    }

    /// Whether some residual row depends on more than its own observation (whitened GPS errors).
    pub fn is_coupled(&self) -> bool {
        self.links.iter().any(|l| l.prev.is_some())
    }

    /// `J delta` of every residual row, from `d x delta` of the observations
    /// (`dx[o]`): `slope_o dx_o + back_o dz_prev(o)`.
    pub fn combine(&self, dx: &[f64]) -> Vec<f64> {
        let mut dz = vec![0.0; dx.len()];
        (0..dx.len())
            .map(|o| {
                let (m, n) = self.slope[o];
                let l = self.links[o];
                let prev = l.prev.map_or(0.0, |j| dz[j]);
                dz[o] = l.alpha * prev + l.kappa * dx[o];
                m * dx[o] + n * prev
            })
            .collect()
    }

    /// `J^T J` and `J^T r` assembled densely from the moments (O(N + P^2)),
    /// for uncoupled rows (each row is `slope_o` times its observation's).
    fn normal_equations(mut self, np: usize) -> NormalEquations {
        let derivatives = Arc::make_mut(&mut self.derivatives);
        for (o, &(m, _)) in self.slope.iter().enumerate() {
            derivatives.h[o] *= m;
            derivatives.jg.row_mut(o).scale_mut(m);
            for v in &mut derivatives.jb[o].1 {
                *v *= m;
            }
        }
        let ChainDerivatives {
            columns,
            globals,
            blocks,
            y,
            h,
            rows,
            jg,
            jb,
            ..
        } = &*self.derivatives;
        let (r, prior) = (&self.r, &self.prior);
        let no = r.len();
        let ng = globals.len();
        // Suffix moments after each block: first observation past its last step.
        let nb = blocks.len();
        let after: Vec<usize> = blocks
            .iter()
            .map(|b| {
                if b.last == usize::MAX {
                    no
                } else {
                    rows.partition_point(|&row| row <= b.last)
                }
            })
            .collect();
        let mut h_after = vec![M9::zeros(); nb];
        let mut r_after = vec![V9::zeros(); nb];
        let mut f_after = vec![DMatrix::<f64>::zeros(ng, 9); nb];
        {
            let mut order: Vec<usize> = (0..nb).collect();
            order.sort_by_key(|&b| std::cmp::Reverse(after[b]));
            let mut hs = M9::zeros();
            let mut rs = V9::zeros();
            let mut fs = DMatrix::<f64>::zeros(ng, 9);
            let mut o = no;
            for b in order {
                while o > after[b] {
                    o -= 1;
                    hs += h[o] * h[o].transpose();
                    rs += h[o] * r[o];
                    for g in 0..ng {
                        let x = jg[(o, g)];
                        if x != 0.0 {
                            for c in 0..9 {
                                fs[(g, c)] += x * h[o][c];
                            }
                        }
                    }
                }
                h_after[b] = hs;
                r_after[b] = rs;
                f_after[b].copy_from(&fs);
            }
        }

        // Assemble in parameter order.
        let nf = columns.len();
        let mut pos = vec![usize::MAX; np];
        for (c, &i) in columns.iter().enumerate() {
            pos[i] = c;
        }
        let mut a = DMatrix::<f64>::zeros(nf, nf);
        let mut g = DVector::<f64>::zeros(nf);
        // Global-global and global rhs.
        let jgt = jg.transpose();
        let agg = &jgt * jg;
        let gg = &jgt * r;
        for (x, &ix) in globals.iter().enumerate() {
            g[pos[ix]] += gg[x];
            for (z, &iz) in globals.iter().enumerate() {
                a[(pos[ix], pos[iz])] += agg[(x, z)];
            }
        }
        // Explicit rows inside each block: J_ob^T J_ob, J_G^T J_ob, J_ob^T r, and K_b = sum h^T J_ob.
        let mut kb: Vec<Vec<V9>> = blocks
            .iter()
            .map(|b| vec![V9::zeros(); b.params.len()])
            .collect();
        for o in 0..no {
            let (b, vals) = (jb[o].0, &jb[o].1);
            if b == u32::MAX {
                continue;
            }
            let block = &blocks[b as usize];
            for (x, &ix) in block.params.iter().enumerate() {
                g[pos[ix]] += vals[x] * r[o];
                kb[b as usize][x] += h[o] * vals[x];
                for (z, &iz) in block.params.iter().enumerate() {
                    a[(pos[ix], pos[iz])] += vals[x] * vals[z];
                }
                for (gi, &ig) in globals.iter().enumerate() {
                    let val = jg[(o, gi)] * vals[x];
                    a[(pos[ig], pos[ix])] += val;
                    a[(pos[ix], pos[ig])] += val;
                }
            }
        }
        // Complete parts: rows after each block.
        let mut z: Vec<Vec<V9>> = Vec::with_capacity(nb);
        for b in 0..nb {
            let block = &blocks[b];
            let zb: Vec<V9> = (0..block.params.len())
                .map(|x| kb[b][x] + h_after[b] * y[b][x])
                .collect();
            for (x, &ix) in block.params.iter().enumerate() {
                g[pos[ix]] += y[b][x].dot(&r_after[b]);
                for (zz, &iz) in block.params.iter().enumerate() {
                    a[(pos[ix], pos[iz])] += y[b][x].dot(&(h_after[b] * y[b][zz]));
                }
                let fy = &f_after[b] * y[b][x];
                for (gi, &ig) in globals.iter().enumerate() {
                    a[(pos[ig], pos[ix])] += fy[gi];
                    a[(pos[ix], pos[ig])] += fy[gi];
                }
            }
            z.push(zb);
        }
        // Cross blocks b < b2: Y_b^T Z_b2.
        for b2 in 0..nb {
            for b in 0..b2 {
                for (x, &ix) in blocks[b].params.iter().enumerate() {
                    for (x2, &ix2) in blocks[b2].params.iter().enumerate() {
                        let val = y[b][x].dot(&z[b2][x2]);
                        a[(pos[ix], pos[ix2])] += val;
                        a[(pos[ix2], pos[ix])] += val;
                    }
                }
            }
        }
        // Prior rows.
        let mut by_row: Vec<Vec<(usize, f64)>> = vec![Vec::new(); prior.residuals.len()];
        for &(row, col, val) in &prior.entries {
            if pos[col] != usize::MAX {
                by_row[row].push((pos[col], val));
            }
        }
        for (row, entries) in by_row.iter().enumerate() {
            let rv = prior.residuals[row];
            for &(c1, v1) in entries {
                g[c1] += v1 * rv;
                for &(c2, v2) in entries {
                    a[(c1, c2)] += v1 * v2;
                }
            }
        }
        NormalEquations {
            a,
            g,
            cost: self.cost,
            columns: columns.clone(),
        }
    }
}

/// Solve `(A + lambda D) x = b` by Cholesky, `D = diag(A)` floored at
/// `1e-9 max(diag)` (and at 1e-12 absolute) so directions the data cannot see keep a finite step.
pub fn damped_solve(a: &DMatrix<f64>, b: &DVector<f64>, lambda: f64) -> Option<DVector<f64>> {
    let n = a.nrows();
    let max_diag = (0..n).map(|i| a[(i, i)]).fold(0.0f64, f64::max);
    let floor = (1e-9 * max_diag).max(1e-12);
    let mut m = a.clone();
    for i in 0..n {
        m[(i, i)] += lambda * a[(i, i)].max(floor) + 1e-15 * max_diag;
    }
    // faer's blocked, multi-threaded Cholesky: about 4x nalgebra's on 1,000+ parameters.
    let fm = faer::Mat::<f64>::from_fn(n, n, |i, j| m[(i, j)]);
    let llt = fm.as_ref().llt(faer::Side::Lower).ok()?;
    let mut rhs = faer::Mat::<f64>::from_fn(n, 1, |i, _| b[i]);
    llt.solve_in_place(&mut rhs);
    let x = DVector::from_fn(n, |i, _| rhs[(i, 0)]);
    x.iter().all(|v| v.is_finite()).then_some(x)
}
