//! The rows of the AA-pattern sweep: the node fields a sweep reads, the odd-step links between
//! rows, the ghost entries that stand for the periodic neighbours in x, and the even- and
//! odd-step row kernels, generic over the vector type. (The sweep over every row is
//! [`super::step`].)

use super::collision::{collide, collide_unforced};
use super::d3q19::{OPPOSITE, Q, SHIFTED_SLOTS, VELOCITIES};
use super::geometry::LatticeGeometry;
use super::numbers::{Stored, Vector};

/// Read-only node fields and boundary data of one sweep.
pub(super) struct Fields<'a> {
    pub(super) fx: &'a [f64],
    pub(super) fy: &'a [f64],
    pub(super) fz: &'a [f64],
    pub(super) omega: &'a [f64],
    pub(super) default_omega: f64,
    pub(super) row_forced: &'a [bool],
    pub(super) row_special_omega: &'a [u32],
    pub(super) geometry: LatticeGeometry,
    pub(super) row_links: &'a [RowLinks],
    pub(super) stride: usize,
}

/// After an even step: the ghost an odd-step gather of slot p reads past the run's end (p moves
/// in +x: the right ghost stands for x = 0; in −x: the left ghost for x = nx − 1).
#[inline]
pub(super) fn fill_ghosts<S: Stored>(row: &mut [S], nx: usize, stride: usize) {
    for (p, cx) in SHIFTED_SLOTS {
        let run = p * stride;
        if cx > 0 {
            row[run + nx + 1] = row[run + 1];
        } else {
            row[run] = row[run + nx];
        }
    }
}

/// The population buffer shared by the threads of an odd step. Sound because every slot is
/// read and written by exactly one node (see the `lattice` module docs), and only through raw
/// pointers.
pub(super) struct SharedBuffer<S> {
    ptr: *mut S,
    len: usize,
}

// SAFETY: the threads of an odd step access disjoint slots (`lattice` module docs), so sharing
// the pointer is race-free.
unsafe impl<S: Send> Sync for SharedBuffer<S> {}

impl<S> SharedBuffer<S> {
    /// The buffer `f`, shared by the threads of one odd step.
    pub(super) fn new(f: &mut [S]) -> Self {
        Self {
            ptr: f.as_mut_ptr(),
            len: f.len(),
        }
    }
}

/// One link of an odd step: the start of a slot run (its left ghost), the x shift
/// (`x_source = x − shift`, `x_target = x + shift`) and an additive wall term.
#[derive(Debug, Clone, Copy)]
struct Link {
    run: usize,
    shift: i64,
    add: f64,
}

/// Where the nodes of a row gather their 19 populations from and scatter them to in an odd
/// step.
#[derive(Debug, Clone, Copy)]
pub(super) struct RowLinks {
    from: [Link; Q],
    to: [Link; Q],
}

pub(super) fn row_links(
    g: &LatticeGeometry,
    stride: usize,
    wall_terms: &[[f64; Q]; 2],
    r: usize,
) -> RowLinks {
    let (y, z) = (r % g.ny, r / g.ny);
    let walls = !g.z_periodic();
    let from = std::array::from_fn(|q| {
        let c = VELOCITIES[q];
        let zs = z as i64 - c[2] as i64;
        if walls && (zs < 0 || zs >= g.nz as i64) {
            // Reflected by the wall: the node's own f*_q̄, kept in its slot q.
            Link {
                run: (r * Q + q) * stride,
                shift: 0,
                add: wall_terms[usize::from(zs >= 0)][q],
            }
        } else {
            let row = wrap(zs, g.nz) * g.ny + wrap(y as i64 - c[1] as i64, g.ny);
            Link {
                run: (row * Q + OPPOSITE[q]) * stride,
                shift: c[0] as i64,
                add: 0.0,
            }
        }
    });
    let to = std::array::from_fn(|q| {
        let c = VELOCITIES[q];
        let zd = z as i64 + c[2] as i64;
        if walls && (zd < 0 || zd >= g.nz as i64) {
            // Leaving through a wall: comes back as q̄ at this node.
            let p = OPPOSITE[q];
            Link {
                run: (r * Q + p) * stride,
                shift: 0,
                add: wall_terms[usize::from(zd >= 0)][p],
            }
        } else {
            let row = wrap(zd, g.nz) * g.ny + wrap(y as i64 + c[1] as i64, g.ny);
            Link {
                run: (row * Q + q) * stride,
                shift: c[0] as i64,
                add: 0.0,
            }
        }
    });
    RowLinks { from, to }
}

/// `i` wrapped into `0..n` for `−n ≤ i < 2n` (no division).
#[inline(always)]
pub(super) fn wrap(i: i64, n: usize) -> usize {
    let n = n as i64;
    (if i < 0 {
        i + n
    } else if i >= n {
        i - n
    } else {
        i
    }) as usize
}

/// A node field (force component, relaxation rate) for the nodes `x0 …` of the row starting at
/// node `node0` (a function rather than a closure, so that it is compiled with the kernel's
/// instruction set).
#[inline(always)]
fn node_field<V: Vector>(field: &[f64], node0: usize, x0: usize, nx: usize, full: bool) -> V {
    if full {
        V::load(&field[node0 + x0..])
    } else {
        V::gather(|l| field[node0 + (x0 + l).min(nx - 1)])
    }
}

/// The collision of the pack of nodes `x0 …` of row `r`.
#[inline(always)]
fn collide_pack<V: Vector>(fields: &Fields, r: usize, x0: usize, f: &[V; Q], full: bool) -> [V; Q] {
    let nx = fields.geometry.nx;
    let node0 = r * nx;
    if !fields.row_forced[r] && fields.row_special_omega[r] == 0 {
        collide_unforced(f, V::splat(fields.default_omega))
    } else {
        collide(
            f,
            [
                node_field(fields.fx, node0, x0, nx, full),
                node_field(fields.fy, node0, x0, nx, full),
                node_field(fields.fz, node0, x0, nx, full),
            ],
            node_field(fields.omega, node0, x0, nx, full),
        )
    }
}

/// Load the pack `x0 …` of a run of `nx` values (lanes past the row's end repeat its last node;
/// they are never stored).
#[inline(always)]
fn load_run<V: Vector, S: Stored>(run: &[S], x0: usize, nx: usize, full: bool) -> V {
    if full {
        S::load::<V>(&run[x0..])
    } else {
        V::gather(|l| run[(x0 + l).min(nx - 1)].to_f64())
    }
}

#[inline(always)]
pub(super) fn even_row_with<V: Vector, S: Stored>(fields: &Fields, r: usize, row: &mut [S]) {
    let nx = fields.geometry.nx;
    let stride = fields.stride;
    let mut x0 = 0;
    while x0 < nx {
        let width = V::LANES.min(nx - x0);
        let full = width == V::LANES;
        macro_rules! load_all {
            ($($q:literal)*) => {
                [$(load_run::<V, S>(&row[$q * stride + 1..$q * stride + 1 + nx], x0, nx, full)),*]
            };
        }
        let f: [V; Q] = load_all!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18);
        let post = collide_pack(fields, r, x0, &f, full);
        for (q, p) in post.into_iter().enumerate() {
            S::store(p, &mut row[OPPOSITE[q] * stride + 1 + x0..], width);
        }
        x0 += V::LANES;
    }
    fill_ghosts(row, nx, stride);
}

/// How many rows ahead the odd step prefetches its gather runs.
const PREFETCH_ROWS: usize = 2;

/// Gather the pack `x0 …` of direction `link` in an odd step.
///
/// # Safety
/// `f` must be the buffer the links were built for, and no other thread may touch the slots
/// these nodes gather (guaranteed by the AA pattern).
#[inline(always)]
unsafe fn gather_pack<V: Vector, S: Stored>(
    f: &SharedBuffer<S>,
    link: &Link,
    x0: usize,
    nx: usize,
    full: bool,
) -> V {
    // x − shift lies in −1..=nx: the ghosts (run + 0 and run + nx + 1) hold the periodic
    // neighbours.
    let start = (link.run as i64 + 1 + x0 as i64 - link.shift) as usize;
    let v = if full {
        debug_assert!(start + V::LANES <= f.len);
        // SAFETY: the LANES slots lie in the buffer and are read only by these nodes.
        unsafe { S::load_ptr::<V>(f.ptr.add(start)) }
    } else {
        V::gather(|l| {
            // Lanes past the row's end repeat its last node; they are never stored.
            let i = start + l.min(nx - 1 - x0);
            debug_assert!(i < f.len);
            // SAFETY: in bounds, and read only by this node.
            unsafe { (*f.ptr.add(i)).to_f64() }
        })
    };
    if link.add != 0.0 {
        v + V::splat(link.add)
    } else {
        v
    }
}

#[inline(always)]
pub(super) fn odd_row_with<V: Vector, S: Stored>(fields: &Fields, f: &SharedBuffer<S>, r: usize) {
    let nx = fields.geometry.nx;
    let links = &fields.row_links[r];
    if let Some(ahead) = fields.row_links.get(r + PREFETCH_ROWS) {
        let line = 64 / std::mem::size_of::<S>();
        for link in &ahead.from {
            for x in (0..nx + 2).step_by(line).chain([nx + 1]) {
                debug_assert!(link.run + x < f.len);
                // SAFETY: the index lies inside the buffer; a prefetch reads nothing.
                V::prefetch(unsafe { f.ptr.add(link.run + x) });
            }
        }
    }
    let mut x0 = 0;
    while x0 < nx {
        let width = V::LANES.min(nx - x0);
        let full = width == V::LANES;
        macro_rules! gather_all {
            ($($q:literal)*) => {
                // SAFETY: the links belong to `f`; the AA pattern keeps other threads away.
                [$(unsafe { gather_pack::<V, S>(f, &links.from[$q], x0, nx, full) }),*]
            };
        }
        let f_in: [V; Q] = gather_all!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18);
        let post = collide_pack(fields, r, x0, &f_in, full);
        for (q, p) in post.into_iter().enumerate() {
            let link = links.to[q];
            let p = if link.add != 0.0 {
                p + V::splat(link.add)
            } else {
                p
            };
            // x + shift lies in −1..=nx: writes past the run's ends go to the ghosts, which
            // the fold pass moves onto the periodic neighbour.
            let start = (link.run as i64 + 1 + x0 as i64 + link.shift) as usize;
            if full {
                debug_assert!(start + V::LANES <= f.len);
                // SAFETY: the LANES slots lie in the buffer and are written only by these
                // nodes.
                unsafe { S::store_ptr::<V>(p, f.ptr.add(start)) };
            } else {
                let mut lanes = [0.0; 8];
                p.spill(&mut lanes);
                for (l, &value) in lanes.iter().enumerate().take(width) {
                    debug_assert!(start + l < f.len);
                    // SAFETY: in bounds, and written only by this node.
                    unsafe { *f.ptr.add(start + l) = S::from_f64(value) };
                }
            }
        }
        x0 += V::LANES;
    }
}
