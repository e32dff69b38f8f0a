//! The residual's rows in factored form (`residual` module docs): the
//! rest-mesh data the residual sums per vertex.

use crate::mesh::{Point, Real};
use crate::operators::Operators;

/// One spoke `v → j` of a residual row (`residual` module docs).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct RowSpoke {
    /// `f_vj`.
    pub(super) f: Point,
    /// `c_vj`: the spoke of `v` (0 where `v`'s ring lacks `j`).
    pub(super) c_out: Real,
    /// `c_jv`: the spokes of `j` into `v`.
    pub(super) c_in: Real,
    /// `Lbar_vj`.
    pub(super) lbar: Real,
}

/// The residual's rows in factored form (`residual` module docs): per vertex the
/// union of its ring, the rings that hold it and `Lbar`'s and `L`'s row
/// (one and the same set on a manifold mesh), CSR.
#[derive(Debug, Clone, Default)]
pub(super) struct ResidualRows {
    pub(super) ptr: Vec<usize>,
    pub(super) nbr: Vec<u32>,
    pub(super) spoke: Vec<RowSpoke>,
    /// `L_vj` per spoke (the first pass's).
    pub(super) l: Vec<Real>,
    /// `o_v`.
    pub(super) own: Vec<Point>,
    pub(super) lbar_diag: Vec<Real>,
    pub(super) l_diag: Vec<Real>,
    /// `k_L λ2 k_b`.
    pub(super) kbl: Real,
    /// `k_a` (0 when the area term is off).
    pub(super) ka: Real,
}

impl ResidualRows {
    /// The rows of the spokes `ptr, nbr, c, e` (CSR over vertices), the
    /// bending weights `b` and the weights `kbl`, `ka` on `ops`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        ops: &Operators,
        (ptr, nbr): (&[usize], &[u32]),
        (c, e): (&[Real], &[Point]),
        b: &[Real],
        kbl: Real,
        ka: Real,
    ) -> Self {
        let n = ops.num_vertices();
        let x = &ops.positions;
        // per vertex: (j, spoke, L_vj); the ring first, in ring order
        let mut rows: Vec<Vec<(u32, RowSpoke, Real)>> = (0..n)
            .map(|v| {
                (ptr[v]..ptr[v + 1])
                    .map(|s| {
                        let sp = RowSpoke {
                            c_out: c[s],
                            ..RowSpoke::default()
                        };
                        (nbr[s], sp, 0.0)
                    })
                    .collect()
            })
            .collect();
        fn entry(row: &mut Vec<(u32, RowSpoke, Real)>, j: u32) -> &mut (u32, RowSpoke, Real) {
            let k = match row.iter().position(|e| e.0 == j) {
                Some(k) => k,
                None => {
                    row.push((j, RowSpoke::default(), 0.0));
                    row.len() - 1
                }
            };
            &mut row[k]
        }
        for i in 0..n {
            for s in ptr[i]..ptr[i + 1] {
                entry(&mut rows[nbr[s] as usize], i as u32).1.c_in += c[s];
            }
        }
        let (mut lbar_diag, mut l_diag) = (vec![0.0; n], vec![0.0; n]);
        for (v, row) in rows.iter_mut().enumerate() {
            if let Some(r) = ops.lbar.outer_view(v) {
                for (j, &w) in r.iter() {
                    if j == v {
                        lbar_diag[v] += w;
                    } else {
                        entry(row, j as u32).1.lbar += w;
                    }
                }
            }
            if let Some(r) = ops.l.outer_view(v) {
                for (j, &w) in r.iter() {
                    if j == v {
                        l_diag[v] += w;
                    } else {
                        entry(row, j as u32).2 += w;
                    }
                }
            }
        }
        let delta = |j: usize, w: Real| {
            let k = if kbl > 0.0 && b[j] > 0.0 {
                kbl * w
            } else {
                0.0
            };
            ops.delta[j].map(|d| k * d)
        };
        let own = (0..n)
            .map(|v| {
                let mut acc = [0.0; 3];
                for s in ptr[v]..ptr[v + 1] {
                    for a in 0..3 {
                        acc[a] += c[s] * e[s][a];
                    }
                }
                let d = delta(v, lbar_diag[v]);
                [acc[0] - d[0], acc[1] - d[1], acc[2] - d[2]]
            })
            .collect();
        let mut out = ResidualRows {
            ptr: vec![0],
            own,
            lbar_diag,
            l_diag,
            kbl,
            ka: ka.max(0.0),
            ..ResidualRows::default()
        };
        for (v, row) in rows.into_iter().enumerate() {
            for (j, mut sp, l) in row {
                let ju = j as usize;
                let d = delta(ju, sp.lbar);
                for a in 0..3 {
                    sp.f[a] = sp.c_in * (x[ju][a] - x[v][a]) - d[a];
                }
                out.nbr.push(j);
                out.spoke.push(sp);
                out.l.push(l);
            }
            out.ptr.push(out.nbr.len());
        }
        out
    }

    /// `Σ_j [j ∈ F̃] f_vj + [v ∈ F̃] o_v` per vertex for the rows `free`:
    /// the identity's part of the rotated terms (`residual` module docs).
    pub(super) fn rest_turn(&self, free: &[bool]) -> Vec<Point> {
        (0..free.len())
            .map(|v| {
                let mut acc = if free[v] { self.own[v] } else { [0.0; 3] };
                for s in self.ptr[v]..self.ptr[v + 1] {
                    if free[self.nbr[s] as usize] {
                        let f = self.spoke[s].f;
                        acc = [acc[0] + f[0], acc[1] + f[1], acc[2] + f[2]];
                    }
                }
                acc
            })
            .collect()
    }

    /// Memory held, in bytes.
    pub(super) fn memory_bytes(&self) -> usize {
        self.ptr.len() * 8
            + self.nbr.len() * 4
            + self.spoke.len() * std::mem::size_of::<RowSpoke>()
            + self.l.len() * 8
            + self.own.len() * 24
            + (self.lbar_diag.len() + self.l_diag.len()) * 8
    }
}
