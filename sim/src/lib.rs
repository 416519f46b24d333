//! Deterministic procedural scenes scanned by a simulated spinning lidar.
//!
//! Output is a [`ScanGraph`] whose points are in the sensor frame, so the
//! graph2tree transform puts them in the world. Reproducibility: everything is
//! derived from the seed with our own SplitMix64 (no crate whose stream may
//! change), each lidar column gets its own random stream (results do not
//! depend on the rayon thread count), and only IEEE-exact operations are used
//! (+, -, *, /, sqrt, floor, round; sin/cos are our own polynomials), so the
//! bytes are the same on every platform.

use rayon::prelude::*;

use octolinear::formats::graph::ScanGraph;
use octolinear::geometry::{Point3, PointCloud, Pose6D, Quaternion};

/// SplitMix64: tiny, fast, and its stream is fixed by definition.
#[derive(Clone, Debug)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        finalize(self.0)
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// Uniform integer in `0..n` (n > 0).
    pub fn below(&mut self, n: u32) -> u32 {
        (((self.next_u64() >> 32) * n as u64) >> 32) as u32
    }

    /// Approximately standard normal: Irwin–Hall sum of four uniforms (bounded at ±2√3).
    pub fn normalish(&mut self) -> f64 {
        let s = self.next_f64() + self.next_f64() + self.next_f64() + self.next_f64();
        (s - 2.0) * 1.732_050_807_568_877_2
    }
}

fn finalize(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Derives an independent stream seed from a seed and a list of indices.
fn mix(seed: u64, parts: &[u64]) -> u64 {
    parts.iter().fold(finalize(seed ^ 0x6A09_E667_F3BC_C909), |h, &p| {
        finalize(h ^ finalize(p.wrapping_add(0x9E37_79B9_7F4A_7C15)))
    })
}

/// sin and cos from fixed polynomials, identical on every platform (libm is not).
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    const PIO2_HI: f64 = 1.570_796_326_734_125_6;
    const PIO2_LO: f64 = 6.077_100_506_506_192e-11;
    let k = (x * std::f64::consts::FRAC_2_PI).round();
    let r = (x - k * PIO2_HI) - k * PIO2_LO;
    let r2 = r * r;
    let mut s = 0.0;
    let mut c = 0.0;
    // Taylor series to degree 17/16; |r| <= pi/4 keeps the error below 1e-16.
    let mut fact = 1.0f64;
    let mut sc = [0.0f64; 9];
    let mut cc = [0.0f64; 9];
    for i in 0..9 {
        let n = 2 * i as u32;
        if i > 0 {
            fact *= ((n - 1) * n) as f64;
        }
        cc[i] = if i % 2 == 0 { 1.0 / fact } else { -1.0 / fact };
        let fs = fact * (n + 1) as f64;
        sc[i] = if i % 2 == 0 { 1.0 / fs } else { -1.0 / fs };
    }
    for i in (0..9).rev() {
        s = s * r2 + sc[i];
        c = c * r2 + cc[i];
    }
    s *= r;
    match (k as i64).rem_euclid(4) {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

type V3 = [f64; 3];

fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// What a ray hit; lets tests check that points land on sensible surfaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Surface {
    Floor,
    Ceiling,
    Wall,
    Furniture,
    Terrain,
    Building,
    Trunk,
    Crown,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f64,
    pub surface: Surface,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneKind {
    /// Rooms off a corridor, doors, furniture boxes; floor and ceiling.
    Indoor,
    /// Height-field terrain, box buildings, trees (cylinder trunk + sphere crown).
    Outdoor,
}

#[derive(Clone, Copy, Debug)]
enum Shape {
    Box {
        min: V3,
        max: V3,
    },
    /// Vertical cylinder with caps.
    Cylinder {
        c: [f64; 2],
        r: f64,
        z0: f64,
        z1: f64,
    },
    Sphere {
        c: V3,
        r: f64,
    },
}

/// Rays starting on a surface must not hit it again.
const EPS: f64 = 1e-9;

#[derive(Clone, Copy, Debug)]
struct Prim {
    shape: Shape,
    surface: Surface,
}

impl Prim {
    fn xy_bounds(&self) -> ([f64; 2], [f64; 2]) {
        match self.shape {
            Shape::Box { min, max } => ([min[0], min[1]], [max[0], max[1]]),
            Shape::Cylinder { c, r, .. } => ([c[0] - r, c[1] - r], [c[0] + r, c[1] + r]),
            Shape::Sphere { c, r } => ([c[0] - r, c[1] - r], [c[0] + r, c[1] + r]),
        }
    }

    /// First intersection with t in (EPS, tmax]; hits from inside are ignored.
    fn intersect(&self, o: V3, d: V3, tmax: f64) -> Option<f64> {
        match self.shape {
            Shape::Box { min, max } => {
                let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                for a in 0..3 {
                    if d[a] == 0.0 {
                        if o[a] < min[a] || o[a] > max[a] {
                            return None;
                        }
                    } else {
                        let ta = (min[a] - o[a]) / d[a];
                        let tb = (max[a] - o[a]) / d[a];
                        let (ta, tb) = if ta < tb { (ta, tb) } else { (tb, ta) };
                        t0 = t0.max(ta);
                        t1 = t1.min(tb);
                    }
                }
                (t0 <= t1 && t0 > EPS && t0 <= tmax).then_some(t0)
            }
            Shape::Cylinder { c, r, z0, z1 } => {
                let mut best = None::<f64>;
                let mut take = |t: f64| {
                    if t > EPS && t <= tmax && best.is_none_or(|b| t < b) {
                        best = Some(t);
                    }
                };
                let (fx, fy) = (o[0] - c[0], o[1] - c[1]);
                let a = d[0] * d[0] + d[1] * d[1];
                let cc = fx * fx + fy * fy - r * r;
                if a > 0.0 && cc > 0.0 {
                    let b = fx * d[0] + fy * d[1];
                    let disc = b * b - a * cc;
                    if disc >= 0.0 {
                        let t = (-b - disc.sqrt()) / a;
                        let z = o[2] + d[2] * t;
                        if z >= z0 && z <= z1 {
                            take(t);
                        }
                    }
                }
                if d[2] != 0.0 {
                    for zc in [z0, z1] {
                        let t = (zc - o[2]) / d[2];
                        let (x, y) = (fx + d[0] * t, fy + d[1] * t);
                        if x * x + y * y <= r * r {
                            take(t);
                        }
                    }
                }
                best
            }
            Shape::Sphere { c, r } => {
                let f = [o[0] - c[0], o[1] - c[1], o[2] - c[2]];
                let a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                let b = f[0] * d[0] + f[1] * d[1] + f[2] * d[2];
                let cc = f[0] * f[0] + f[1] * f[1] + f[2] * f[2] - r * r;
                let disc = b * b - a * cc;
                if cc <= 0.0 || disc < 0.0 || a == 0.0 {
                    return None;
                }
                let t = (-b - disc.sqrt()) / a;
                (t > EPS && t <= tmax).then_some(t)
            }
        }
    }

    /// Distance from `p` to the primitive's surface.
    fn surface_distance(&self, p: V3) -> f64 {
        match self.shape {
            Shape::Box { min, max } => {
                let mut out = 0.0f64;
                let mut inside = f64::INFINITY;
                for a in 0..3 {
                    let e = (min[a] - p[a]).max(p[a] - max[a]);
                    if e > 0.0 {
                        out += e * e;
                    }
                    inside = inside.min(-e);
                }
                if out > 0.0 {
                    out.sqrt()
                } else {
                    inside.max(0.0)
                }
            }
            Shape::Cylinder { c, r, z0, z1 } => {
                let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
                let radial = (dx * dx + dy * dy).sqrt() - r;
                let axial = (z0 - p[2]).max(p[2] - z1);
                if radial > 0.0 || axial > 0.0 {
                    let (a, b) = (radial.max(0.0), axial.max(0.0));
                    (a * a + b * b).sqrt()
                } else {
                    (-radial).min(-axial)
                }
            }
            Shape::Sphere { c, r } => {
                let f = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                ((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt() - r).abs()
            }
        }
    }
}

/// Uniform 2-D grid of cells of side `cell` starting at `origin`.
#[derive(Clone, Debug)]
struct Grid2 {
    origin: [f64; 2],
    cell: f64,
    n: [usize; 2],
}

impl Grid2 {
    /// Visits the cells the ray crosses for t in [0, tmax] with their entry and
    /// exit parameters, in order, until `visit` returns true.
    fn walk(&self, o: V3, d: V3, tmax: f64, mut visit: impl FnMut(usize, usize, f64, f64) -> bool) {
        let (mut t0, mut t1) = (0.0f64, tmax);
        for a in 0..2 {
            let lo = self.origin[a];
            let hi = lo + self.cell * self.n[a] as f64;
            if d[a] == 0.0 {
                if o[a] < lo || o[a] > hi {
                    return;
                }
            } else {
                let ta = (lo - o[a]) / d[a];
                let tb = (hi - o[a]) / d[a];
                let (ta, tb) = if ta < tb { (ta, tb) } else { (tb, ta) };
                t0 = t0.max(ta);
                t1 = t1.min(tb);
            }
        }
        if t0 > t1 {
            return;
        }
        let mut idx = [0usize; 2];
        for a in 0..2 {
            let p = o[a] + d[a] * t0;
            let i = ((p - self.origin[a]) / self.cell).floor();
            idx[a] = (i.max(0.0) as usize).min(self.n[a] - 1);
        }
        let next = |a: usize, i: usize| -> f64 {
            if d[a] > 0.0 {
                (self.origin[a] + self.cell * (i + 1) as f64 - o[a]) / d[a]
            } else if d[a] < 0.0 {
                (self.origin[a] + self.cell * i as f64 - o[a]) / d[a]
            } else {
                f64::INFINITY
            }
        };
        let mut t = t0;
        loop {
            let (nx, ny) = (next(0, idx[0]), next(1, idx[1]));
            let t_exit = nx.min(ny).min(t1);
            if visit(idx[0], idx[1], t, t_exit.max(t)) || t_exit >= t1 {
                return;
            }
            let a = if nx < ny { 0 } else { 1 };
            if d[a] > 0.0 {
                idx[a] += 1;
                if idx[a] >= self.n[a] {
                    return;
                }
            } else {
                if idx[a] == 0 {
                    return;
                }
                idx[a] -= 1;
            }
            t = t_exit.max(t);
        }
    }
}

/// Bilinear height field on a regular vertex grid.
#[derive(Clone, Debug)]
struct Terrain {
    grid: Grid2,
    /// (n+1) x (n+1) vertex heights, row major in y.
    h: Vec<f64>,
    /// Highest vertex per cell, to skip cells the ray passes above.
    cell_max: Vec<f64>,
    max_h: f64,
}

impl Terrain {
    fn vertex(&self, ix: usize, iy: usize) -> f64 {
        self.h[iy * (self.grid.n[0] + 1) + ix]
    }

    /// Height at (x, y), `None` outside the grid.
    fn height(&self, x: f64, y: f64) -> Option<f64> {
        let g = &self.grid;
        let fx = (x - g.origin[0]) / g.cell;
        let fy = (y - g.origin[1]) / g.cell;
        if !(fx >= 0.0 && fy >= 0.0 && fx <= g.n[0] as f64 && fy <= g.n[1] as f64) {
            return None;
        }
        let ix = (fx.floor() as usize).min(g.n[0] - 1);
        let iy = (fy.floor() as usize).min(g.n[1] - 1);
        let (u, v) = (fx - ix as f64, fy - iy as f64);
        let (h00, h10) = (self.vertex(ix, iy), self.vertex(ix + 1, iy));
        let (h01, h11) = (self.vertex(ix, iy + 1), self.vertex(ix + 1, iy + 1));
        Some(h00 * (1.0 - u) * (1.0 - v) + h10 * u * (1.0 - v) + h01 * (1.0 - u) * v + h11 * u * v)
    }

    /// Marches the cells along the ray and solves the bilinear patch of each
    /// exactly (a quadratic in t).
    fn intersect(&self, o: V3, d: V3, tmax: f64) -> Option<f64> {
        let mut hit = None;
        let g = &self.grid;
        g.walk(o, d, tmax, |ix, iy, ta, tb| {
            let (za, zb) = (o[2] + d[2] * ta, o[2] + d[2] * tb);
            if za.min(zb) > self.cell_max[iy * g.n[0] + ix] {
                // Above this cell; going up above everything ends the march.
                return d[2] >= 0.0 && za > self.max_h;
            }
            let x0 = g.origin[0] + g.cell * ix as f64;
            let y0 = g.origin[1] + g.cell * iy as f64;
            let (h00, h10) = (self.vertex(ix, iy), self.vertex(ix + 1, iy));
            let (h01, h11) = (self.vertex(ix, iy + 1), self.vertex(ix + 1, iy + 1));
            let (e1, e2, e3) = (h10 - h00, h01 - h00, h00 - h10 - h01 + h11);
            let (au, bu) = ((o[0] - x0) / g.cell, d[0] / g.cell);
            let (av, bv) = ((o[1] - y0) / g.cell, d[1] / g.cell);
            // f(t) = z(t) - h(t) = qa t^2 + qb t + qc
            let qa = -e3 * bu * bv;
            let qb = d[2] - e1 * bu - e2 * bv - e3 * (au * bv + av * bu);
            let qc = o[2] - h00 - e1 * au - e2 * av - e3 * au * av;
            let f = |t: f64| (qa * t + qb) * t + qc;
            if f(ta) < 0.0 {
                return false; // starts below the surface (not a visible hit)
            }
            let (lo, hi) = (ta.max(EPS), tb);
            let mut roots = [f64::NAN; 2];
            if qa.abs() < 1e-12 {
                if qb != 0.0 {
                    roots[0] = -qc / qb;
                }
            } else {
                let disc = qb * qb - 4.0 * qa * qc;
                if disc >= 0.0 {
                    let s = disc.sqrt();
                    let q = -0.5 * (qb + if qb >= 0.0 { s } else { -s });
                    roots = [q / qa, if q != 0.0 { qc / q } else { f64::NAN }];
                }
            }
            let best = roots
                .into_iter()
                .filter(|t| *t >= lo - 1e-9 && *t <= hi + 1e-9 && *t > EPS)
                .fold(f64::INFINITY, f64::min);
            if best.is_finite() {
                hit = Some(best);
                true
            } else {
                false
            }
        });
        hit
    }
}

/// Piecewise-linear sensor path, walked back and forth (open) or around (closed).
#[derive(Clone, Debug)]
struct Path {
    points: Vec<[f64; 2]>,
    closed: bool,
}

impl Path {
    /// Position and unit heading at arc length `s`.
    fn at(&self, s: f64) -> ([f64; 2], [f64; 2]) {
        let mut pts = self.points.clone();
        if self.closed {
            pts.push(pts[0]);
        }
        let segs: Vec<(usize, f64)> = pts
            .windows(2)
            .enumerate()
            .map(|(i, w)| {
                let (dx, dy) = (w[1][0] - w[0][0], w[1][1] - w[0][1]);
                (i, (dx * dx + dy * dy).sqrt())
            })
            .filter(|&(_, l)| l > 0.0)
            .collect();
        let total: f64 = segs.iter().map(|s| s.1).sum();
        if total <= 0.0 {
            return (pts[0], [1.0, 0.0]);
        }
        let (mut s, backwards) = if self.closed {
            (s - (s / total).floor() * total, false)
        } else {
            let period = 2.0 * total;
            let s = s - (s / period).floor() * period;
            if s > total {
                (period - s, true)
            } else {
                (s, false)
            }
        };
        for &(i, l) in &segs {
            if s <= l || i == segs.last().map_or(0, |x| x.0) {
                let (a, b) = (pts[i], pts[i + 1]);
                let u = (s / l).min(1.0);
                let p = [a[0] + (b[0] - a[0]) * u, a[1] + (b[1] - a[1]) * u];
                let mut h = [(b[0] - a[0]) / l, (b[1] - a[1]) / l];
                if backwards {
                    h = [-h[0], -h[1]];
                }
                return (p, h);
            }
            s -= l;
        }
        (pts[0], [1.0, 0.0])
    }
}

/// A generated world: primitives, optional terrain and the sensor path.
#[derive(Clone, Debug)]
pub struct Scene {
    pub kind: SceneKind,
    prims: Vec<Prim>,
    /// Primitives too large for the grid (floor, ceiling), tested for every ray.
    global: Vec<usize>,
    grid: Grid2,
    cells: Vec<Vec<u32>>,
    terrain: Option<Terrain>,
    path: Path,
    /// Metres of path between consecutive scans.
    spacing: f64,
    sensor_height: f64,
}

fn rect_overlap(a0: [f64; 2], a1: [f64; 2], b0: [f64; 2], b1: [f64; 2], gap: f64) -> bool {
    a0[0] < b1[0] + gap && b0[0] < a1[0] + gap && a0[1] < b1[1] + gap && b0[1] < a1[1] + gap
}

fn boxp(min: V3, max: V3, surface: Surface) -> Prim {
    Prim { shape: Shape::Box { min, max }, surface }
}

impl Scene {
    /// Builds the scene for `kind` from `seed` (deterministic).
    pub fn generate(kind: SceneKind, seed: u64) -> Self {
        match kind {
            SceneKind::Indoor => Self::indoor(seed),
            SceneKind::Outdoor => Self::outdoor(seed),
        }
    }

    fn indoor(seed: u64) -> Self {
        let mut rng = SplitMix64(mix(seed, &[1]));
        let rooms = 3 + rng.below(3) as usize;
        let widths: Vec<f64> = (0..rooms).map(|_| rng.range(4.0, 7.0)).collect();
        let half_corridor = rng.range(0.9, 1.2);
        let depth = [rng.range(4.0, 6.0), rng.range(4.0, 6.0)];
        let height = rng.range(2.5, 3.0);
        let wt = 0.12;
        let mut xs = vec![0.0];
        for w in &widths {
            xs.push(xs.last().copied().unwrap_or(0.0) + w);
        }
        let len = xs[rooms];
        let y_out = [half_corridor + depth[0], -(half_corridor + depth[1])];
        let mut prims = Vec::new();
        let wall = |x0: f64, x1: f64, y0: f64, y1: f64| boxp([x0, y0, 0.0], [x1, y1, height], Surface::Wall);
        // Shell.
        prims.push(wall(-wt, len + wt, y_out[0], y_out[0] + wt));
        prims.push(wall(-wt, len + wt, y_out[1] - wt, y_out[1]));
        prims.push(wall(-wt, 0.0, y_out[1] - wt, y_out[0] + wt));
        prims.push(wall(len, len + wt, y_out[1] - wt, y_out[0] + wt));
        let door_x: Vec<f64> = (0..rooms).map(|i| (xs[i] + xs[i + 1]) / 2.0).collect();
        let mut path = vec![[0.8, 0.0]];
        for (side, &room_depth) in depth.iter().enumerate() {
            let sign = if side == 0 { 1.0 } else { -1.0 };
            // Corridor wall on this side, y in [inner, inner + wt] (mirrored), with doors.
            let (y0, y1) =
                if side == 0 { (half_corridor, half_corridor + wt) } else { (-half_corridor - wt, -half_corridor) };
            let mut x = 0.0;
            for &dx in &door_x {
                prims.push(wall(x, dx - 0.5, y0, y1));
                x = dx + 0.5;
            }
            prims.push(wall(x, len, y0, y1));
            // Partitions between rooms.
            let (py0, py1) = if side == 0 { (half_corridor + wt, y_out[0]) } else { (y_out[1], -half_corridor - wt) };
            for &xp in &xs[1..rooms] {
                prims.push(wall(xp - wt / 2.0, xp + wt / 2.0, py0, py1));
            }
            // Furniture, kept off the walk from the door to the room centre.
            let yc = sign * (half_corridor + room_depth / 2.0);
            for i in 0..rooms {
                let (rx0, rx1) = (xs[i] + wt, xs[i + 1] - wt);
                let (ry0, ry1) = (py0.min(py1) + 0.05, py0.max(py1) - 0.05);
                let (ky0, ky1) = if side == 0 { (half_corridor, yc + 0.9) } else { (yc - 0.9, -half_corridor) };
                let (keep0, keep1) = ([door_x[i] - 0.9, ky0], [door_x[i] + 0.9, ky1]);
                let wanted = 2 + rng.below(4);
                let mut placed: Vec<([f64; 2], [f64; 2])> = Vec::new();
                for _ in 0..wanted {
                    for _try in 0..20 {
                        let (mut sx, mut sy, sz) = match rng.below(3) {
                            0 => (rng.range(0.8, 1.6), rng.range(0.6, 1.0), rng.range(0.72, 0.78)),
                            1 => (rng.range(0.4, 0.6), rng.range(0.8, 2.0), rng.range(1.2, 2.1)),
                            _ => (rng.range(0.8, 2.0), rng.range(0.8, 2.0), rng.range(0.4, 0.6)),
                        };
                        if rng.below(2) == 1 {
                            std::mem::swap(&mut sx, &mut sy);
                        }
                        if rx1 - rx0 <= sx || ry1 - ry0 <= sy {
                            continue;
                        }
                        let x0 = rng.range(rx0, rx1 - sx);
                        let y0 = rng.range(ry0, ry1 - sy);
                        let (a0, a1) = ([x0, y0], [x0 + sx, y0 + sy]);
                        if rect_overlap(a0, a1, keep0, keep1, 0.0)
                            || placed.iter().any(|&(b0, b1)| rect_overlap(a0, a1, b0, b1, 0.2))
                        {
                            continue;
                        }
                        placed.push((a0, a1));
                        prims.push(boxp([x0, y0, 0.0], [x0 + sx, y0 + sy, sz], Surface::Furniture));
                        break;
                    }
                }
            }
        }
        for &dx in &door_x {
            for (sign, room_depth) in [(1.0, depth[0]), (-1.0, depth[1])] {
                path.push([dx, 0.0]);
                path.push([dx, sign * (half_corridor + room_depth / 2.0)]);
            }
            path.push([dx, 0.0]);
        }
        path.push([len - 0.8, 0.0]);
        let margin = 0.5;
        let lo = [-wt - margin, y_out[1] - wt - margin];
        let hi = [len + wt + margin, y_out[0] + wt + margin];
        let global = vec![prims.len(), prims.len() + 1];
        prims.push(boxp([lo[0], lo[1], -0.2], [hi[0], hi[1], 0.0], Surface::Floor));
        prims.push(boxp([lo[0], lo[1], height], [hi[0], hi[1], height + 0.2], Surface::Ceiling));
        Self::assemble(SceneKind::Indoor, prims, global, None, Path { points: path, closed: false }, 0.25, 1.0, 1.0)
    }

    fn outdoor(seed: u64) -> Self {
        let mut rng = SplitMix64(mix(seed, &[2]));
        let n = 128usize;
        let spacing = 2.0;
        let origin = [-(n as f64) * spacing / 2.0; 2];
        let octaves = [(64.0, 4.0), (16.0, 1.5), (8.0, 0.4)];
        let noise_seed = rng.next_u64();
        let lattice = |o: usize, ix: i64, iy: i64| -> f64 {
            let h = mix(noise_seed, &[o as u64, ix as u64, iy as u64]);
            (h >> 11) as f64 * (2.0 / (1u64 << 53) as f64) - 1.0
        };
        let mut h = Vec::with_capacity((n + 1) * (n + 1));
        for iy in 0..=n {
            for ix in 0..=n {
                let (x, y) = (ix as f64 * spacing, iy as f64 * spacing);
                let mut z = 0.0;
                for (o, &(period, amp)) in octaves.iter().enumerate() {
                    let (fx, fy) = (x / period, y / period);
                    let (gx, gy) = (fx.floor(), fy.floor());
                    let smooth = |t: f64| t * t * (3.0 - 2.0 * t);
                    let (u, v) = (smooth(fx - gx), smooth(fy - gy));
                    let (gx, gy) = (gx as i64, gy as i64);
                    let a = lattice(o, gx, gy) * (1.0 - u) + lattice(o, gx + 1, gy) * u;
                    let b = lattice(o, gx, gy + 1) * (1.0 - u) + lattice(o, gx + 1, gy + 1) * u;
                    z += amp * (a * (1.0 - v) + b * v);
                }
                h.push(z);
            }
        }
        let mut cell_max = Vec::with_capacity(n * n);
        for iy in 0..n {
            for ix in 0..n {
                let v = |x: usize, y: usize| h[y * (n + 1) + x];
                cell_max.push(v(ix, iy).max(v(ix + 1, iy)).max(v(ix, iy + 1)).max(v(ix + 1, iy + 1)));
            }
        }
        let terrain = Terrain {
            grid: Grid2 { origin, cell: spacing, n: [n, n] },
            max_h: h.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            h,
            cell_max,
        };
        let ground = |x: f64, y: f64| terrain.height(x, y).unwrap_or(0.0);
        let road = rng.range(45.0, 70.0);
        let road_dist = |x: f64, y: f64| ((x * x + y * y).sqrt() - road).abs();
        let mut prims = Vec::new();
        let mut footprints: Vec<([f64; 2], [f64; 2])> = Vec::new();
        for _ in 0..8 + rng.below(10) {
            for _try in 0..50 {
                let (sx, sy) = (rng.range(8.0, 25.0), rng.range(8.0, 25.0));
                let (cx, cy) = (rng.range(-110.0, 110.0), rng.range(-110.0, 110.0));
                let half_diag = (sx * sx + sy * sy).sqrt() / 2.0;
                let (a0, a1) = ([cx - sx / 2.0, cy - sy / 2.0], [cx + sx / 2.0, cy + sy / 2.0]);
                if road_dist(cx, cy) < half_diag + 6.0
                    || footprints.iter().any(|&(b0, b1)| rect_overlap(a0, a1, b0, b1, 4.0))
                {
                    continue;
                }
                let corners = [ground(a0[0], a0[1]), ground(a1[0], a0[1]), ground(a0[0], a1[1]), ground(a1[0], a1[1])];
                let base = corners.iter().copied().fold(f64::INFINITY, f64::min) - 1.0;
                let top = corners.iter().copied().fold(f64::NEG_INFINITY, f64::max) + rng.range(5.0, 20.0);
                footprints.push((a0, a1));
                prims.push(boxp([a0[0], a0[1], base], [a1[0], a1[1], top], Surface::Building));
                break;
            }
        }
        let mut trees: Vec<([f64; 2], f64)> = Vec::new();
        for _ in 0..60 + rng.below(100) {
            for _try in 0..30 {
                let (x, y) = (rng.range(-120.0, 120.0), rng.range(-120.0, 120.0));
                let (tr, th, cr) = (rng.range(0.15, 0.35), rng.range(2.0, 4.0), rng.range(1.2, 3.0));
                let (p0, p1) = ([x - cr, y - cr], [x + cr, y + cr]);
                if road_dist(x, y) < cr + 3.0
                    || footprints.iter().any(|&(b0, b1)| rect_overlap(p0, p1, b0, b1, 1.0))
                    || trees.iter().any(|&(c, r)| {
                        let (dx, dy) = (c[0] - x, c[1] - y);
                        dx * dx + dy * dy < (r + cr) * (r + cr)
                    })
                {
                    continue;
                }
                let base = ground(x, y) - 0.3;
                let top = base + 0.3 + th;
                trees.push(([x, y], cr));
                prims.push(Prim {
                    shape: Shape::Cylinder { c: [x, y], r: tr, z0: base, z1: top },
                    surface: Surface::Trunk,
                });
                prims.push(Prim { shape: Shape::Sphere { c: [x, y, top + 0.6 * cr], r: cr }, surface: Surface::Crown });
                break;
            }
        }
        let steps = 256;
        let path: Vec<[f64; 2]> = (0..steps)
            .map(|i| {
                let (s, c) = sin_cos(std::f64::consts::TAU * i as f64 / steps as f64);
                [road * c, road * s]
            })
            .collect();
        Self::assemble(
            SceneKind::Outdoor,
            prims,
            Vec::new(),
            Some(terrain),
            Path { points: path, closed: true },
            1.0,
            1.8,
            8.0,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn assemble(
        kind: SceneKind,
        prims: Vec<Prim>,
        global: Vec<usize>,
        terrain: Option<Terrain>,
        path: Path,
        spacing: f64,
        sensor_height: f64,
        cell: f64,
    ) -> Self {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (i, p) in prims.iter().enumerate() {
            if global.contains(&i) {
                continue;
            }
            let (a, b) = p.xy_bounds();
            for k in 0..2 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
            }
        }
        if lo[0] > hi[0] {
            (lo, hi) = ([0.0; 2], [cell; 2]);
        }
        let n = [0, 1].map(|k| (((hi[k] - lo[k]) / cell).ceil() as usize).max(1));
        let grid = Grid2 { origin: lo, cell, n };
        let mut cells = vec![Vec::new(); n[0] * n[1]];
        for (i, p) in prims.iter().enumerate() {
            if global.contains(&i) {
                continue;
            }
            let (a, b) = p.xy_bounds();
            let idx = |v: f64, k: usize| (((v - lo[k]) / cell).floor().max(0.0) as usize).min(n[k] - 1);
            for iy in idx(a[1], 1)..=idx(b[1], 1) {
                for ix in idx(a[0], 0)..=idx(b[0], 0) {
                    cells[iy * n[0] + ix].push(i as u32);
                }
            }
        }
        Self { kind, prims, global, grid, cells, terrain, path, spacing, sensor_height }
    }

    /// Closest hit along `origin + t * dir` for t in (0, max_t]. `dir` need not be unit
    /// length; `t` is in units of `dir`.
    pub fn raycast(&self, origin: [f64; 3], dir: [f64; 3], max_t: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let consider = |p: &Prim, best: &mut Option<Hit>| {
            let tmax = best.map_or(max_t, |h| h.t);
            if let Some(t) = p.intersect(origin, dir, tmax) {
                if best.is_none_or(|h| t < h.t) {
                    *best = Some(Hit { t, surface: p.surface });
                }
            }
        };
        for &i in &self.global {
            consider(&self.prims[i], &mut best);
        }
        if let Some(ter) = &self.terrain {
            let tmax = best.map_or(max_t, |h| h.t);
            if let Some(t) = ter.intersect(origin, dir, tmax) {
                best = Some(Hit { t, surface: Surface::Terrain });
            }
        }
        self.grid.walk(origin, dir, best.map_or(max_t, |h| h.t), |ix, iy, _, t_exit| {
            for &i in &self.cells[iy * self.grid.n[0] + ix] {
                consider(&self.prims[i as usize], &mut best);
            }
            best.is_some_and(|h| h.t <= t_exit)
        });
        best
    }

    /// The surface nearest to `p` if it is within `tol` metres (for sanity checks).
    pub fn surface_near(&self, p: [f64; 3], tol: f64) -> Option<Surface> {
        let mut best: Option<(f64, Surface)> = None;
        for prim in &self.prims {
            let d = prim.surface_distance(p);
            if d <= tol && best.is_none_or(|b| d < b.0) {
                best = Some((d, prim.surface));
            }
        }
        if let Some(h) = self.terrain.as_ref().and_then(|t| t.height(p[0], p[1])) {
            let d = (p[2] - h).abs();
            if d <= tol && best.is_none_or(|b| d < b.0) {
                best = Some((d, Surface::Terrain));
            }
        }
        best.map(|b| b.1)
    }

    /// Sensor poses for `scans` scans: along the path, heading forward, with a
    /// slight roll/pitch wobble. Built without libm so it is platform-exact.
    pub fn trajectory(&self, scans: usize) -> Vec<Pose6D> {
        (0..scans)
            .map(|i| {
                let s = i as f64 * self.spacing;
                let (p, h) = self.path.at(s);
                let ground = self.terrain.as_ref().and_then(|t| t.height(p[0], p[1])).unwrap_or(0.0);
                let z = ground + self.sensor_height;
                let roll = 0.03 * sin_cos(0.7 * s).0;
                let pitch = 0.02 * sin_cos(1.3 * s + 1.0).0;
                // Half-angle of the heading via sqrt only.
                let cy = (0.5 * (1.0 + h[0])).max(0.0).sqrt();
                let sy = (0.5 * (1.0 - h[0])).max(0.0).sqrt();
                let sy = if h[1] < 0.0 { -sy } else { sy };
                let (sp, cp) = sin_cos(pitch / 2.0);
                let (sr, cr) = sin_cos(roll / 2.0);
                // q = yaw * pitch * roll (z, y, x), as OctoMap's Euler convention.
                let q = [
                    cy * cp * cr + sy * sp * sr,
                    cy * cp * sr - sy * sp * cr,
                    cy * sp * cr + sy * cp * sr,
                    sy * cp * cr - cy * sp * sr,
                ];
                let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
                Pose6D::new(
                    Point3::new(p[0] as f32, p[1] as f32, z as f32),
                    Quaternion::new((q[0] / n) as f32, (q[1] / n) as f32, (q[2] / n) as f32, (q[3] / n) as f32),
                )
            })
            .collect()
    }
}

/// Spinning multi-beam lidar (VLP-16-like by default).
#[derive(Clone, Debug, PartialEq)]
pub struct LidarConfig {
    /// Vertical channels.
    pub beams: u32,
    /// Firings per revolution.
    pub horizontal_steps: u32,
    /// Returns closer than this are dropped (metres).
    pub min_range: f64,
    /// Returns beyond this are dropped (metres).
    pub max_range: f64,
    /// Lowest and highest beam elevation in degrees.
    pub vertical_fov: (f64, f64),
    /// Standard deviation of the range noise (metres).
    pub noise_sigma: f64,
    /// Probability that a return is lost.
    pub dropout: f64,
}

impl Default for LidarConfig {
    fn default() -> Self {
        Self::indoor()
    }
}

impl LidarConfig {
    pub fn indoor() -> Self {
        Self {
            beams: 16,
            horizontal_steps: 360,
            min_range: 0.3,
            max_range: 30.0,
            vertical_fov: (-15.0, 15.0),
            noise_sigma: 0.01,
            dropout: 0.01,
        }
    }

    /// Longer range for open scenes.
    pub fn outdoor() -> Self {
        Self { max_range: 100.0, noise_sigma: 0.02, ..Self::indoor() }
    }

    fn validate(&self) -> Result<(), SimError> {
        let bad = |field: &'static str, value: String| Err(SimError::InvalidConfig { field, value });
        if self.beams == 0 {
            return bad("beams", self.beams.to_string());
        }
        if self.horizontal_steps == 0 {
            return bad("horizontal_steps", self.horizontal_steps.to_string());
        }
        if !(self.min_range >= 0.0 && self.min_range.is_finite()) {
            return bad("min_range", self.min_range.to_string());
        }
        if !(self.max_range > self.min_range && self.max_range.is_finite()) {
            return bad("max_range", self.max_range.to_string());
        }
        let (lo, hi) = self.vertical_fov;
        if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo >= -90.0 && hi <= 90.0) {
            return bad("vertical_fov", format!("{lo}..{hi}"));
        }
        if !(self.noise_sigma >= 0.0 && self.noise_sigma.is_finite()) {
            return bad("noise_sigma", self.noise_sigma.to_string());
        }
        if !(0.0..=1.0).contains(&self.dropout) {
            return bad("dropout", self.dropout.to_string());
        }
        Ok(())
    }

    /// Unit directions in the sensor frame, column-major (azimuth, then beam bottom-up).
    fn directions(&self) -> Vec<V3> {
        let deg = std::f64::consts::PI / 180.0;
        let (lo, hi) = self.vertical_fov;
        let elev: Vec<(f64, f64)> = (0..self.beams)
            .map(|b| {
                let f = if self.beams == 1 { 0.5 } else { b as f64 / (self.beams - 1) as f64 };
                sin_cos((lo + (hi - lo) * f) * deg)
            })
            .collect();
        let mut dirs = Vec::with_capacity(self.beams as usize * self.horizontal_steps as usize);
        for col in 0..self.horizontal_steps {
            let (sa, ca) = sin_cos(std::f64::consts::TAU * col as f64 / self.horizontal_steps as f64);
            for &(se, ce) in &elev {
                dirs.push([ce * ca, ce * sa, se]);
            }
        }
        dirs
    }
}

/// Rays one scan may cast: their directions are held in memory (24 bytes
/// each), and the largest real lidars cast a few hundred thousand.
pub const MAX_RAYS_PER_SCAN: u64 = 1 << 24;

/// Rays of all scans together: every point is held in memory (12 bytes
/// each, so at most 3 GiB) until the graph is returned.
pub const MAX_RAYS: u64 = 1 << 28;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("invalid lidar config: {field} = {value}")]
    InvalidConfig { field: &'static str, value: String },
    #[error("{beams} beams × {steps} steps = {rays} rays per scan exceeds the limit of {MAX_RAYS_PER_SCAN} (2^24)")]
    TooManyRaysPerScan { beams: u32, steps: u32, rays: u64 },
    #[error(
        "{scans} scans × {per_scan} rays = {total} rays exceeds the limit of {MAX_RAYS} \
         (2^28: every point is held in memory, 12 bytes each)"
    )]
    TooManyRays { scans: usize, per_scan: u64, total: u128 },
}

/// Checks what `scans` scans of `cfg` would hold against [`MAX_RAYS_PER_SCAN`]
/// and [`MAX_RAYS`] before anything is allocated for them.
pub fn check_size(scans: usize, cfg: &LidarConfig) -> Result<(), SimError> {
    let per_scan = u64::from(cfg.beams) * u64::from(cfg.horizontal_steps);
    if per_scan > MAX_RAYS_PER_SCAN {
        return Err(SimError::TooManyRaysPerScan { beams: cfg.beams, steps: cfg.horizontal_steps, rays: per_scan });
    }
    let total = scans as u128 * u128::from(per_scan);
    if total > u128::from(MAX_RAYS) {
        return Err(SimError::TooManyRays { scans, per_scan, total });
    }
    Ok(())
}

/// Generates `kind` from `seed` and scans it `scans` times along its path.
pub fn simulate(kind: SceneKind, scans: usize, seed: u64, cfg: &LidarConfig) -> Result<ScanGraph, SimError> {
    cfg.validate()?;
    check_size(scans, cfg)?;
    let scene = Scene::generate(kind, seed);
    let poses = scene.trajectory(scans);
    simulate_scene(&scene, &poses, seed, cfg)
}

/// Scans `scene` from each pose. Points are in the sensor frame (graph2tree
/// puts them in the world); rays without a return inside the range produce no
/// point. Parallel over scans and columns, identical for any thread count.
pub fn simulate_scene(scene: &Scene, poses: &[Pose6D], seed: u64, cfg: &LidarConfig) -> Result<ScanGraph, SimError> {
    cfg.validate()?;
    check_size(poses.len(), cfg)?;
    let dirs = cfg.directions();
    let beams = cfg.beams as usize;
    let clouds: Vec<PointCloud> = poses
        .par_iter()
        .enumerate()
        .map(|(scan, pose)| {
            let r = rotation_matrix(pose.rotation);
            let t = pose.translation;
            let o = [t.x as f64, t.y as f64, t.z as f64];
            let cols: Vec<Vec<Point3>> = dirs
                .par_chunks(beams)
                .enumerate()
                .map(|(col, col_dirs)| {
                    let mut rng = SplitMix64(mix(seed, &[3, scan as u64, col as u64]));
                    let mut out = Vec::with_capacity(col_dirs.len());
                    for &ds in col_dirs {
                        // Fixed number of draws per ray keeps streams aligned.
                        let (drop, noise) = (rng.next_f64(), rng.normalish());
                        let dw = [
                            r[0][0] * ds[0] + r[0][1] * ds[1] + r[0][2] * ds[2],
                            r[1][0] * ds[0] + r[1][1] * ds[1] + r[1][2] * ds[2],
                            r[2][0] * ds[0] + r[2][1] * ds[1] + r[2][2] * ds[2],
                        ];
                        let Some(hit) = scene.raycast(o, dw, cfg.max_range) else {
                            continue;
                        };
                        let range = hit.t + cfg.noise_sigma * noise;
                        if drop < cfg.dropout || range < cfg.min_range || range > cfg.max_range {
                            continue;
                        }
                        let p = scale(ds, range);
                        out.push(Point3::new(p[0] as f32, p[1] as f32, p[2] as f32));
                    }
                    out
                })
                .collect();
            cols.into_iter().flatten().collect()
        })
        .collect();
    let mut graph = ScanGraph::new();
    for (cloud, pose) in clouds.into_iter().zip(poses) {
        graph.add_node(cloud, *pose);
        graph.connect_previous();
    }
    Ok(graph)
}

/// Rotation matrix of the stored float quaternion (normalised in double), so
/// the simulated rays agree with what graph2tree will do with the points.
fn rotation_matrix(q: Quaternion) -> [[f64; 3]; 3] {
    let (mut w, mut x, mut y, mut z) = (q.u as f64, q.x as f64, q.y as f64, q.z as f64);
    let n = (w * w + x * x + y * y + z * z).sqrt();
    if n > 0.0 {
        (w, x, y, z) = (w / n, x / n, y / n, z / n);
    }
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_cos_matches_libm_closely() {
        for i in -2000..2000 {
            let x = i as f64 * 0.0123;
            let (s, c) = sin_cos(x);
            assert!((s - x.sin()).abs() < 1e-15, "{x}");
            assert!((c - x.cos()).abs() < 1e-15, "{x}");
        }
    }

    #[test]
    fn sizes_are_checked_before_anything_is_allocated() {
        let cfg = |beams, horizontal_steps| LidarConfig { beams, horizontal_steps, ..LidarConfig::indoor() };
        let err = simulate(SceneKind::Indoor, 1, 1, &cfg(100_000_000, 360)).unwrap_err();
        assert_eq!(
            err.to_string(),
            "100000000 beams × 360 steps = 36000000000 rays per scan exceeds the limit of 16777216 (2^24)"
        );
        let err = simulate(SceneKind::Indoor, 1, 1, &cfg(16, u32::MAX)).unwrap_err();
        assert!(matches!(err, SimError::TooManyRaysPerScan { rays: 68719476720, .. }), "{err}");
        let err = simulate(SceneKind::Indoor, usize::MAX, 1, &cfg(16, 360)).unwrap_err();
        assert!(err.to_string().starts_with(&format!("{} scans × 5760 rays = ", usize::MAX)), "{err}");
        assert!(err.to_string().contains("exceeds the limit of 268435456"), "{err}");
        // the limits themselves are allowed
        assert!(check_size(1, &cfg(1 << 12, 1 << 12)).is_ok());
        assert!(check_size(16, &cfg(1 << 12, 1 << 12)).is_ok());
        assert!(check_size(17, &cfg(1 << 12, 1 << 12)).is_err());
    }

    #[test]
    fn grid_walk_visits_cells_in_order() {
        let g = Grid2 { origin: [0.0, 0.0], cell: 1.0, n: [4, 4] };
        let mut seen = Vec::new();
        g.walk([0.5, 0.5, 0.0], [1.0, 1.0, 0.0], 10.0, |x, y, _, _| {
            seen.push((x, y));
            false
        });
        assert_eq!(seen.first(), Some(&(0, 0)));
        assert_eq!(seen.last(), Some(&(3, 3)));
        assert!(seen.windows(2).all(|w| w[0].0 + w[0].1 < w[1].0 + w[1].1 || w[0] == w[1]));
    }
}
