//! The reachable workspace as a shape a 3D viewer can draw as a translucent envelope.
//!
//! - The EezyBot ([`eezybot_envelope`]): the tool point moves in a vertical plane that
//!   the base turns about z, so its workspace is a solid of revolution, a
//!   [`Envelope::Lathe`]: the outline of the reachable (r, z) set swept over the base's
//!   yaw range. The outline comes from dense joint-space sampling within every limit
//!   (the arm's own [`JointLimits::check`](crate::JointLimits::check), the one the
//!   closed-form IK applies), an occupancy grid, its outer contour and a Douglas–Peucker
//!   simplification.
//! - Any other arm ([`chain_envelope`]): a cloud of tool positions of random
//!   configurations within the limits, an [`Envelope::Points`].
//!
//! Both are pure and deterministic; compute them once (at node start) and send the
//! result as JSON (`{"kind":"lathe","profile":[[r,z],…],"yaw":[a,b]}` or
//! `{"kind":"points","points":[[x,y,z],…]}`).
//!
//! # Examples
//! ```
//! use eezybot_kinematics::{Arm, envelope::{eezybot_envelope, Envelope}};
//! let arm = Arm::default();
//! let Envelope::Lathe { profile, yaw } = eezybot_envelope(&arm, 0.004) else {
//!     panic!("the EezyBot's envelope is a lathe");
//! };
//! assert!(profile.len() >= 3 && profile.len() <= 200);
//! // ROBOT.md: tool radius 0.100–0.279 m, height 0.052–0.279 m
//! let r_max = profile.iter().map(|p| p[0]).fold(f64::MIN, f64::max);
//! assert!((r_max - 0.279).abs() < 0.008);
//! assert_eq!(yaw, [-45f64.to_radians(), 45f64.to_radians()]);
//! ```

use crate::chain::SerialChain;
use crate::rng::SplitMix64;
use crate::{Arm, ArmJoints};
use serde::Serialize;

/// A workspace shape for a viewer, in the arm's base frame (`base_link`, metres).
///
/// Serialised with a `kind` tag: `{"kind":"lathe","profile":[[r,z],…],"yaw":[a,b]}`,
/// `{"kind":"points","points":[[x,y,z],…]}`.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Envelope {
    /// A solid of revolution about the base's z axis: the point (r, z) of `profile` at
    /// yaw θ is (r·cos θ, r·sin θ, z), for θ over `yaw`.
    Lathe {
        /// Closed outer boundary of the reachable (r, z) set, counter-clockwise with r
        /// along the first axis and z along the second, the last point not repeating the
        /// first. r is the tool's coordinate along the arm's vertical plane (its
        /// distance from the z axis where r ≥ 0, as everywhere with the default limits).
        profile: Vec<[f64; 2]>,
        /// The base joint's range `[min, max]` (rad) about z; 0 = +x.
        yaw: [f64; 2],
    },
    /// Tool positions `[x, y, z]` of sampled configurations within the limits.
    Points {
        /// The positions (m).
        points: Vec<[f64; 3]>,
    },
}

/// Smallest grid cell (m) [`eezybot_envelope`] uses: finer requests are raised to it.
pub const MIN_CELL_M: f64 = 0.0005;

/// Largest grid cell (m) [`eezybot_envelope`] uses: coarser requests are lowered to it.
pub const MAX_CELL_M: f64 = 0.1;

/// Most cells along a side of the occupancy grid: the cell grows for very long links.
pub const MAX_GRID_CELLS: usize = 1200;

/// Most points of a lathe profile: the simplification tolerance grows until it fits.
pub const MAX_PROFILE_POINTS: usize = 200;

/// Joint-space sampling step, as a fraction of a cell, of the tool's largest motion.
const SAMPLES_PER_CELL: f64 = 4.0;

/// The EezyBot's reachable workspace as a [`Envelope::Lathe`].
///
/// The shoulder and elbow are sampled within every limit row, the α/φ coupling
/// included, densely enough that the tool moves at most `cell_m / 4` between
/// neighbouring samples, the limit boundaries themselves included; each sample must pass
/// the arm's own limit check (so the set agrees with what [`Arm::solve_position`]
/// accepts) and its FK (r, z) marks a cell of an occupancy grid of side `cell_m`.
/// One-cell holes are closed, the outer contour is traced (marching squares at level ½
/// on the cell centres, diagonal neighbours joined, each boundary cell edge's point
/// being the sample of its cell farthest across the edge: a sample on the set's
/// boundary) and simplified by Douglas–Peucker at half a cell (more if needed to keep
/// at most [`MAX_PROFILE_POINTS`] points). Every configuration within the limits then
/// lies inside the outline or less than a cell outside it.
///
/// `cell_m` is kept within [`MIN_CELL_M`]…[`MAX_CELL_M`] (NaN counts as too small) and
/// grown if the grid would exceed [`MAX_GRID_CELLS`] a side. Limits that leave no
/// configuration give an empty profile. 0.004 m takes a few milliseconds (release build).
pub fn eezybot_envelope(arm: &Arm, cell_m: f64) -> Envelope {
    let yaw = [arm.limits.base_rad.0, arm.limits.base_rad.1];
    let g = &arm.geometry;
    let reach = (g.main_arm_m.abs() + g.forearm_m.abs()).max(f64::MIN_POSITIVE);
    let cell = if cell_m.is_nan() {
        MIN_CELL_M
    } else {
        cell_m.clamp(MIN_CELL_M, MAX_CELL_M)
    }
    .max(2.0 * reach / (MAX_GRID_CELLS - 4) as f64);
    if !cell.is_finite() || !g.tool_dx_m.is_finite() || !g.shoulder_height_m.is_finite() {
        return Envelope::Lathe {
            profile: Vec::new(),
            yaw,
        };
    }
    let mut grid = Grid::around(
        (g.tool_dx_m - reach, g.tool_dx_m + reach),
        (g.shoulder_height_m - reach, g.shoulder_height_m + reach),
        cell,
    );
    sample_plane(arm, cell / SAMPLES_PER_CELL, |r, z| grid.mark(r, z));
    grid.close_single_holes();
    let profile = grid
        .outer_contour()
        .map(|ring| simplify_closed(&ring, cell / 2.0, MAX_PROFILE_POINTS))
        .unwrap_or_default();
    Envelope::Lathe { profile, yaw }
}

/// Calls `visit(r, z)` with the FK of joint configurations within every limit of `arm`,
/// spaced so that the tool moves at most about `step_m` between neighbours. The limit
/// boundaries are sampled too (clamped a hair inside, as [`crate::JointLimits::clamp`]
/// does), and every sample passes [`crate::JointLimits::check`].
fn sample_plane(arm: &Arm, step_m: f64, mut visit: impl FnMut(f64, f64)) {
    let l = &arm.limits;
    let g = &arm.geometry;
    // a base angle within its limits for the check; the FK is taken at yaw 0 (x = r)
    let base_rad = 0f64.max(l.base_rad.0).min(l.base_rad.1);
    let Some((s_lo, s_hi)) = l.feasible_shoulder_rad() else {
        return;
    };
    // The tool moves by at most |shoulder → wrist| ≤ L2 + L3 per radian of shoulder (the
    // elbow held) and by L3 per radian of elbow.
    let (l2, l3) = (g.main_arm_m.abs(), g.forearm_m.abs());
    let steps = |span: f64, lever: f64| -> usize {
        let n = (span * lever / step_m).ceil();
        // NaN and negative spans give 1; cap for absurd geometry
        if n >= 1.0 {
            (n as usize).min(1 << 16)
        } else {
            1
        }
    };
    let n_s = steps(s_hi - s_lo, l2 + l3);
    for i in 0..=n_s {
        let shoulder_rad = s_lo + (s_hi - s_lo) * (i as f64 / n_s as f64);
        let e_lo = l.elbow_rad.0.max(l.forearm_elevation_rad.0 - shoulder_rad);
        let e_hi = l.elbow_rad.1.min(l.forearm_elevation_rad.1 - shoulder_rad);
        if e_lo.is_nan() || e_hi.is_nan() || e_lo > e_hi {
            continue;
        }
        let n_e = steps(e_hi - e_lo, l3);
        for j in 0..=n_e {
            let elbow_rad = e_lo + (e_hi - e_lo) * (j as f64 / n_e as f64);
            let q = l.clamp(&ArmJoints {
                base_rad,
                shoulder_rad,
                elbow_rad,
            });
            if l.check(&q).is_err() {
                continue;
            }
            let p = arm.forward(&ArmJoints { base_rad: 0.0, ..q });
            if p.x.is_finite() && p.z.is_finite() {
                visit(p.x, p.z);
            }
        }
    }
}

/// An occupancy grid in (r, z): cell (i, j) covers
/// `[(i0 + i)·cell, (i0 + i + 1)·cell) × [(j0 + j)·cell, (j0 + j + 1)·cell)`. Each
/// marked cell also keeps its samples of least and greatest r and z (their positions
/// within the cell, in 1/255 of a cell).
struct Grid {
    cell: f64,
    i0: f64,
    j0: f64,
    nr: usize,
    nz: usize,
    marked: Vec<bool>,
    /// The samples of least r, greatest r, least z, greatest z in each cell.
    extremes: Vec<[[u8; 2]; 4]>,
}

impl Grid {
    /// A grid covering `r` × `z` with an empty border at least one cell wide.
    fn around(r: (f64, f64), z: (f64, f64), cell: f64) -> Grid {
        let i0 = (r.0 / cell).floor() - 2.0;
        let j0 = (z.0 / cell).floor() - 2.0;
        let side = |lo: f64, hi: f64| (((hi - lo) / cell).ceil().max(0.0) as usize + 4).max(3);
        let (nr, nz) = (side(r.0, r.1), side(z.0, z.1));
        Grid {
            cell,
            i0,
            j0,
            nr,
            nz,
            marked: vec![false; nr * nz],
            extremes: vec![[[0; 2]; 4]; nr * nz],
        }
    }

    fn index(&self, i: usize, j: usize) -> usize {
        j * self.nr + i
    }

    /// Marks the cell holding (r, z); points outside the border are ignored.
    fn mark(&mut self, r: f64, z: f64) {
        let (u, v) = (r / self.cell - self.i0, z / self.cell - self.j0);
        let (i, j) = (u.floor(), v.floor());
        // (the border cells stay empty, so that every contour is closed)
        if i >= 1.0 && j >= 1.0 && i < (self.nr - 1) as f64 && j < (self.nz - 1) as f64 {
            let k = self.index(i as usize, j as usize);
            // (float to int casts saturate)
            let p = [
                ((u - i) * 255.0).round() as u8,
                ((v - j) * 255.0).round() as u8,
            ];
            let e = &mut self.extremes[k];
            if !self.marked[k] {
                *e = [p; 4];
                self.marked[k] = true;
            }
            if p[0] < e[0][0] {
                e[0] = p;
            }
            if p[0] > e[1][0] {
                e[1] = p;
            }
            if p[1] < e[2][1] {
                e[2] = p;
            }
            if p[1] > e[3][1] {
                e[3] = p;
            }
        }
    }

    fn is_marked(&self, i: usize, j: usize) -> bool {
        i < self.nr && j < self.nz && self.marked[self.index(i, j)]
    }

    /// Marks every empty cell whose four edge neighbours are all marked (it then has
    /// no boundary edge, so its extremes never matter).
    fn close_single_holes(&mut self) {
        let mut fill = Vec::new();
        for j in 1..self.nz - 1 {
            for i in 1..self.nr - 1 {
                if !self.is_marked(i, j)
                    && self.is_marked(i - 1, j)
                    && self.is_marked(i + 1, j)
                    && self.is_marked(i, j - 1)
                    && self.is_marked(i, j + 1)
                {
                    fill.push(self.index(i, j));
                }
            }
        }
        for k in fill {
            self.marked[k] = true;
        }
    }

    /// The counter-clockwise contour of largest area around the marked cells, in
    /// metres, `None` when nothing is marked. Marching squares at level ½ on the cell
    /// centres, except that the point of each boundary edge of the marked region is
    /// not the edge's midpoint but the sample of its cell farthest across that edge
    /// (so the outline runs through samples on the set's boundary, in order along it,
    /// rather than up to a cell outside it).
    fn outer_contour(&self) -> Option<Vec<[f64; 2]>> {
        // Directed boundary edges between grid corners, the marked cell on the left:
        // bit d of out[corner] is the edge leaving that corner in direction DIRS[d].
        let (nr, nz) = (self.nr, self.nz);
        let corner = |i: usize, j: usize| j * (nr + 1) + i;
        let mut out = vec![0u8; (nr + 1) * (nz + 1)];
        for j in 0..nz {
            for i in 0..nr {
                if !self.is_marked(i, j) {
                    continue;
                }
                if j == 0 || !self.is_marked(i, j - 1) {
                    out[corner(i, j)] |= 1 << EAST;
                }
                if !self.is_marked(i + 1, j) {
                    out[corner(i + 1, j)] |= 1 << NORTH;
                }
                if !self.is_marked(i, j + 1) {
                    out[corner(i + 1, j + 1)] |= 1 << WEST;
                }
                if i == 0 || !self.is_marked(i - 1, j) {
                    out[corner(i, j + 1)] |= 1 << SOUTH;
                }
            }
        }
        let mut used = vec![0u8; out.len()];
        // (twice the area of the ring of edge midpoints, its edges as (corner, direction))
        let mut best: Option<(i64, Vec<(usize, usize)>)> = None;
        for start in 0..out.len() {
            for d0 in 0..4 {
                if out[start] & !used[start] & (1 << d0) == 0 {
                    continue;
                }
                let mut ring = Vec::new();
                let mut twice_area = 0i64;
                let (mut c, mut d) = (start, d0);
                loop {
                    used[c] |= 1 << d;
                    ring.push((c, d));
                    let (ci, cj) = ((c % (nr + 1)) as i64, (c / (nr + 1)) as i64);
                    let [di, dj] = DIRS[d];
                    let next = ((cj + dj) as usize) * (nr + 1) + (ci + di) as usize;
                    // right turn first: diagonal neighbours belong to one region
                    let Some(nd) = [(d + 3) % 4, d, (d + 1) % 4]
                        .into_iter()
                        .find(|nd| out[next] & (1 << nd) != 0)
                    else {
                        break; // cannot happen: every boundary corner has an exit
                    };
                    // shoelace term between this edge's midpoint and the next one's
                    // (doubled coordinates keep them integral)
                    let [ndi, ndj] = DIRS[nd];
                    let (a, b) = (
                        [2 * ci + di, 2 * cj + dj],
                        [2 * (ci + di) + ndi, 2 * (cj + dj) + ndj],
                    );
                    twice_area += a[0] * b[1] - b[0] * a[1];
                    (c, d) = (next, nd);
                    if c == start && d == d0 {
                        break;
                    }
                }
                if best.as_ref().is_none_or(|(a, _)| twice_area > *a) {
                    best = Some((twice_area, ring));
                }
            }
        }
        let (area, ring) = best?;
        if area <= 0 {
            return None;
        }
        let mut points: Vec<[f64; 2]> = ring
            .into_iter()
            .map(|(c, d)| {
                let (ci, cj) = (c % (nr + 1), c / (nr + 1));
                // the cell on the edge's left and which extreme faces across the edge
                let (i, j, which) = match d {
                    EAST => (ci, cj, 2),
                    NORTH => (ci - 1, cj, 1),
                    WEST => (ci - 1, cj - 1, 3),
                    _ => (ci, cj - 1, 0),
                };
                let [fu, fv] = self.extremes[self.index(i, j)][which];
                [
                    (self.i0 + i as f64 + fu as f64 / 255.0) * self.cell,
                    (self.j0 + j as f64 + fv as f64 / 255.0) * self.cell,
                ]
            })
            .collect();
        // (a sample can be the extreme across two edges of its cell)
        points.dedup();
        while points.len() > 1 && points.first() == points.last() {
            points.pop();
        }
        Some(points)
    }
}

const EAST: usize = 0;
const NORTH: usize = 1;
const WEST: usize = 2;
const SOUTH: usize = 3;
/// Unit steps in the order east, north, west, south (counter-clockwise turns: +1).
const DIRS: [[i64; 2]; 4] = [[1, 0], [0, 1], [-1, 0], [0, -1]];

/// Distance from `p` to the segment `a`–`b`.
fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// Douglas–Peucker on a closed ring at `tolerance`, raised by 25 % at a time until at
/// most `max_points` remain. Keeps the ring's order (and so its orientation).
fn simplify_closed(ring: &[[f64; 2]], tolerance: f64, max_points: usize) -> Vec<[f64; 2]> {
    let n = ring.len();
    if n <= 3 {
        return ring.to_vec();
    }
    // split at the lowest-left point and the point farthest from it
    let a = (0..n)
        .min_by(|x, y| {
            ring[*x]
                .partial_cmp(&ring[*y])
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .unwrap_or(0);
    let far = |k: &usize| (ring[*k][0] - ring[a][0]).hypot(ring[*k][1] - ring[a][1]);
    let b = (0..n)
        .max_by(|x, y| {
            far(x)
                .partial_cmp(&far(y))
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .unwrap_or(0);
    let mut tol = tolerance;
    loop {
        let mut keep = vec![false; n];
        keep[a] = true;
        keep[b] = true;
        // spans (from, to) along the ring, indices modulo n, to > from
        let mut stack = vec![
            (a, if b > a { b } else { b + n }),
            (b, if a > b { a } else { a + n }),
        ];
        while let Some((from, to)) = stack.pop() {
            let (p, q) = (ring[from % n], ring[to % n]);
            let worst = (from + 1..to)
                .map(|k| (k, segment_distance(ring[k % n], p, q)))
                .max_by(|x, y| x.1.partial_cmp(&y.1).unwrap_or(std::cmp::Ordering::Equal));
            if let Some((k, d)) = worst {
                if d > tol {
                    keep[k % n] = true;
                    stack.push((from, k));
                    stack.push((k, to));
                }
            }
        }
        let out: Vec<[f64; 2]> = (0..n).filter(|k| keep[*k]).map(|k| ring[k]).collect();
        if out.len() <= max_points || !tol.is_finite() {
            return out;
        }
        tol *= 1.25;
    }
}

/// Tool positions of `samples` random configurations of `chain` within its limits
/// ([`SerialChain::random_configuration`] from a [`SplitMix64`] seeded with `seed`), as
/// an [`Envelope::Points`]. The same chain, count and seed give the same points.
///
/// # Examples
/// ```
/// use eezybot_kinematics::{chain::SerialChain, envelope::{chain_envelope, Envelope},
///                          urdf::RobotModel};
/// let model = RobotModel::load(std::path::Path::new(concat!(
///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/jaco.urdf"))).unwrap();
/// let chain = SerialChain::from_model(&model, "base_link", "jaco_end_effector").unwrap();
/// let cloud = chain_envelope(&chain, 500, 7);
/// assert_eq!(cloud, chain_envelope(&chain, 500, 7));
/// let Envelope::Points { points } = cloud else { panic!("a point cloud") };
/// assert_eq!(points.len(), 500);
/// ```
pub fn chain_envelope(chain: &SerialChain, samples: usize, seed: u64) -> Envelope {
    let mut rng = SplitMix64::new(seed);
    let mut x = vec![0.0; chain.dof()];
    let points = (0..samples)
        .map(|_| {
            chain.random_into(&mut rng, &mut x);
            let p = chain.forward_unchecked(&x).translation.vector;
            [p.x, p.y, p.z]
        })
        .collect();
    Envelope::Points { points }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of 1 mm cells with the cells `(i, j)` marked by a sample at their centre.
    fn grid_with(cells: &[(usize, usize)]) -> Grid {
        let mut g = Grid::around((0.0, 0.010), (0.0, 0.010), 0.001);
        for (i, j) in cells {
            let r = (g.i0 + *i as f64 + 0.5) * g.cell;
            let z = (g.j0 + *j as f64 + 0.5) * g.cell;
            g.mark(r, z);
        }
        g
    }

    fn twice_area(ring: &[[f64; 2]]) -> f64 {
        let n = ring.len();
        (0..n)
            .map(|k| ring[k][0] * ring[(k + 1) % n][1] - ring[(k + 1) % n][0] * ring[k][1])
            .sum()
    }

    #[test]
    fn contour_of_a_block_runs_counter_clockwise_through_its_edge_cells() {
        let cells: Vec<(usize, usize)> = (3..6).flat_map(|i| (3..5).map(move |j| (i, j))).collect();
        let ring = grid_with(&cells).outer_contour().unwrap();
        // one point per boundary edge: 3 + 2 + 3 + 2, minus the corner cells' duplicates
        // (a lone centre sample is the extreme across both edges of a corner cell)
        assert_eq!(ring.len(), 10 - 4);
        assert!(twice_area(&ring) > 0.0);
    }

    #[test]
    fn diagonal_neighbours_are_one_region_and_holes_are_not_the_outline() {
        let g = grid_with(&[(3, 3), (4, 4)]);
        let ring = g.outer_contour().unwrap();
        // both cells' centres, one contour
        assert_eq!(ring.len(), 2);
        // a ring of 8 cells around an empty 2×2 block: the outer contour, not the hole's
        let mut cells = Vec::new();
        for i in 2..6 {
            for j in 2..6 {
                if !(3..5).contains(&i) || !(3..5).contains(&j) {
                    cells.push((i, j));
                }
            }
        }
        let ring = grid_with(&cells).outer_contour().unwrap();
        assert!(twice_area(&ring) > 0.0);
        let r_min = ring.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
        let g = grid_with(&cells);
        assert!((r_min - (g.i0 + 2.5) * g.cell).abs() < g.cell / 100.0);
    }

    #[test]
    fn single_holes_close() {
        let mut cells = Vec::new();
        for i in 2..5 {
            for j in 2..5 {
                if (i, j) != (3, 3) {
                    cells.push((i, j));
                }
            }
        }
        let mut g = grid_with(&cells);
        assert!(!g.is_marked(3, 3));
        g.close_single_holes();
        assert!(g.is_marked(3, 3));
        assert!(!g.is_marked(1, 3) && !g.is_marked(5, 3));
    }

    #[test]
    fn empty_grid_has_no_contour() {
        assert!(grid_with(&[]).outer_contour().is_none());
    }

    #[test]
    fn simplification_keeps_the_ring_within_tolerance_and_the_point_budget() {
        // a wavy circle of 2000 points, counter-clockwise
        let ring: Vec<[f64; 2]> = (0..2000)
            .map(|k| {
                let t = k as f64 / 2000.0 * std::f64::consts::TAU;
                let r = 1.0 + 0.01 * (40.0 * t).sin();
                [r * t.cos(), r * t.sin()]
            })
            .collect();
        let fine = simplify_closed(&ring, 0.001, 10_000);
        assert!(fine.len() > 200 && fine.len() < 2000, "{}", fine.len());
        for p in &ring {
            let d = (0..fine.len())
                .map(|k| segment_distance(*p, fine[k], fine[(k + 1) % fine.len()]))
                .fold(f64::INFINITY, f64::min);
            assert!(d <= 0.001 + 1e-12);
        }
        let capped = simplify_closed(&ring, 0.001, 200);
        assert!(capped.len() <= 200 && capped.len() >= 3);
        assert!(twice_area(&capped) > 0.0);
        // order (and so orientation) kept: the kept points are a subsequence
        let mut k = 0;
        for p in &capped {
            while ring[k] != *p {
                k += 1;
            }
        }
    }
}
