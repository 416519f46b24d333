//! Procedural scenes: indoor floors of rooms and corridors, outdoor
//! terrain with buildings and trees, and the ray casting against them.

use crate::math::*;
use crate::random::*;
use octolinear::geometry::{Point3, Pose6D, Quaternion};

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

#[cfg(test)]
mod tests {
    use super::*;

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
