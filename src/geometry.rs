//! Points, quaternions and 6-DoF poses with OctoMap's `octomath` float behaviour.
//!
//! Every operation repeats OctoMap 1.10's arithmetic step by step (same
//! precision, same evaluation order) so results are bit-identical. OctoMap
//! stores vectors *and* quaternions as `float`; only the Euler conversions,
//! norms and dot products use `double` intermediates. Do not "simplify" the
//! formulas below: signed zeros and roundings depend on the exact sequence.
//!
//! The Euler conversions call `sin`/`cos`/`atan2` of the platform libm, like
//! OctoMap does, so they are only as reproducible as that libm.

use std::ops::{Add, AddAssign, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A point in metres, single precision like OctoMap's `point3d`. Laid
/// out as three consecutive floats (the vectorised ray set-up loads
/// points as a float array).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct Point3 {
    /// x coordinate, metres.
    pub x: f32,
    /// y coordinate, metres.
    pub y: f32,
    /// z coordinate, metres.
    pub z: f32,
}

impl Point3 {
    /// A point from its three coordinates (`point3d(x, y, z)`).
    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }

    /// The coordinates as `[x, y, z]`.
    pub const fn to_array(self) -> [f32; 3] {
        [self.x, self.y, self.z]
    }

    /// A point from `[x, y, z]`.
    pub const fn from_array(a: [f32; 3]) -> Self {
        Self::new(a[0], a[1], a[2])
    }

    /// `Vector3::cross`, float arithmetic.
    pub fn cross(self, o: Self) -> Self {
        Self::new(self.y * o.z - self.z * o.y, self.z * o.x - self.x * o.z, self.x * o.y - self.y * o.x)
    }

    /// `Vector3::dot`: summed in float, returned widened to double.
    pub fn dot(self, o: Self) -> f64 {
        (self.x * o.x + self.y * o.y + self.z * o.z) as f64
    }

    /// `Vector3::norm_sq`: summed in float, widened.
    pub fn norm_sq(self) -> f64 {
        (self.x * self.x + self.y * self.y + self.z * self.z) as f64
    }

    /// `Vector3::norm`: double sqrt of the float sum.
    pub fn norm(self) -> f64 {
        self.norm_sq().sqrt()
    }

    /// `Vector3::normalize`: divides by the norm rounded to float; zero stays zero.
    pub fn normalize(&mut self) -> &mut Self {
        let len = self.norm();
        if len > 0.0 {
            *self /= len as f32;
        }
        self
    }

    /// A normalised copy (see [`Point3::normalize`]); a zero vector stays zero.
    pub fn normalized(self) -> Self {
        let mut r = self;
        r.normalize();
        r
    }

    /// `Vector3::distance`: per-axis float differences, summed in double.
    pub fn distance(self, o: Self) -> f64 {
        let dx = (self.x - o.x) as f64;
        let dy = (self.y - o.y) as f64;
        let dz = (self.z - o.z) as f64;
        (dx * dx + dy * dy + dz * dz).sqrt()
    }

    /// `Vector3::distanceXY`.
    pub fn distance_xy(self, o: Self) -> f64 {
        let dx = (self.x - o.x) as f64;
        let dy = (self.y - o.y) as f64;
        (dx * dx + dy * dy).sqrt()
    }

    /// `Vector3::angleTo` (uses libm `acos`).
    pub fn angle_to(self, o: Self) -> f64 {
        let d = self.dot(o);
        (d / (self.norm() * o.norm())).acos()
    }

    /// `Vector3::rotate_IP` (pitch, then yaw, then roll) as the released
    /// binaries compute it. GCC's SLP vectoriser (-O2 since GCC 12, -O3 before)
    /// drops two of the source's float roundings: the new x after the pitch
    /// step is used unrounded for the final x, and y after the yaw step is
    /// used unrounded in the roll step. Verified bit for bit against Debian's
    /// liboctomath 1.9.7 and GCC 12 -O3 builds of 1.10 on 20000 random
    /// inputs; [`Point3::rotate_ip_as_written`] follows the source instead.
    pub fn rotate_ip(&mut self, roll: f64, pitch: f64, yaw: f64) -> &mut Self {
        let (sp, cp) = (pitch.sin(), pitch.cos());
        let (sy, cy) = (yaw.sin(), yaw.cos());
        let (sr, cr) = (roll.sin(), roll.cos());
        let (x, y, z) = (self.x as f64, self.y as f64, self.z as f64);
        let x1 = z * sp + x * cp;
        let z1 = (z * cp - x * sp) as f32 as f64;
        let y2 = (x1 as f32 as f64) * sy + y * cy;
        self.x = (x1 * cy - y * sy) as f32;
        self.y = (y2 * cr - z1 * sr) as f32;
        self.z = (y2 * sr + z1 * cr) as f32;
        self
    }

    /// `Vector3::rotate_IP` exactly as its source reads (every step rounded
    /// to float), i.e. what an unvectorised build computes.
    pub fn rotate_ip_as_written(&mut self, roll: f64, pitch: f64, yaw: f64) -> &mut Self {
        let (x, z) = (self.x as f64, self.z as f64);
        self.x = (z * pitch.sin() + x * pitch.cos()) as f32;
        self.z = (z * pitch.cos() - x * pitch.sin()) as f32;
        let (x, y) = (self.x as f64, self.y as f64);
        self.x = (x * yaw.cos() - y * yaw.sin()) as f32;
        self.y = (x * yaw.sin() + y * yaw.cos()) as f32;
        let (y, z) = (self.y as f64, self.z as f64);
        self.y = (y * roll.cos() - z * roll.sin()) as f32;
        self.z = (y * roll.sin() + z * roll.cos()) as f32;
        self
    }

    /// True when all three coordinates are finite (no NaN, no infinity).
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }

    /// Bit patterns, for exact comparisons (distinguishes -0 and NaN payloads).
    pub fn to_bits(self) -> [u32; 3] {
        [self.x.to_bits(), self.y.to_bits(), self.z.to_bits()]
    }
}

impl Add for Point3 {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl Sub for Point3 {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl Neg for Point3 {
    type Output = Self;
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}

impl Mul<f32> for Point3 {
    type Output = Self;
    fn mul(self, s: f32) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
}

impl AddAssign for Point3 {
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}

impl SubAssign for Point3 {
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}

impl MulAssign<f32> for Point3 {
    fn mul_assign(&mut self, s: f32) {
        *self = *self * s;
    }
}

impl DivAssign<f32> for Point3 {
    fn div_assign(&mut self, s: f32) {
        self.x /= s;
        self.y /= s;
        self.z /= s;
    }
}

/// OctoMap's `octomath::Quaternion`: four `float`s, scalar part `u` first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quaternion {
    /// Scalar (real) part, OctoMap's `u`.
    pub u: f32,
    /// First imaginary component.
    pub x: f32,
    /// Second imaginary component.
    pub y: f32,
    /// Third imaginary component.
    pub z: f32,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self::IDENTITY
    }
}

/// `std::max(0., v)`: returns 0 for NaN, like the C++ template.
fn max0(v: f64) -> f64 {
    if 0.0 < v {
        v
    } else {
        0.0
    }
}

impl Quaternion {
    /// The identity rotation `(1, 0, 0, 0)`.
    pub const IDENTITY: Self = Self::new(1.0, 0.0, 0.0, 0.0);

    /// A quaternion from its components, scalar part `u` first (OctoMap's argument order).
    pub const fn new(u: f32, x: f32, y: f32, z: f32) -> Self {
        Self { u, x, y, z }
    }

    /// The components as `[u, x, y, z]`.
    pub const fn to_array(self) -> [f32; 4] {
        [self.u, self.x, self.y, self.z]
    }

    /// A quaternion from `[u, x, y, z]`.
    pub const fn from_array(a: [f32; 4]) -> Self {
        Self::new(a[0], a[1], a[2], a[3])
    }

    /// `Quaternion(roll, pitch, yaw)`: via a double rotation matrix, then the
    /// four magnitudes rounded to float and signed from the matrix.
    pub fn from_euler(roll: f64, pitch: f64, yaw: f64) -> Self {
        let (sr, sp, sy) = (roll.sin(), pitch.sin(), yaw.sin());
        let (cr, cp, cy) = (roll.cos(), pitch.cos(), yaw.cos());
        let m00 = cy * cp;
        let m01 = cy * sp * sr - sy * cr;
        let m02 = cy * sp * cr + sy * sr;
        let m10 = sy * cp;
        let m11 = sy * sp * sr + cy * cr;
        let m12 = sy * sp * cr - cy * sr;
        let m20 = -sp;
        let m21 = cp * sr;
        let m22 = cp * cr;
        let u = (max0(1.0 + m00 + m11 + m22).sqrt() / 2.0) as f32;
        let x = (max0(1.0 + m00 - m11 - m22).sqrt() / 2.0) as f32;
        let y = (max0(1.0 - m00 + m11 - m22).sqrt() / 2.0) as f32;
        let z = (max0(1.0 - m00 - m11 + m22).sqrt() / 2.0) as f32;
        let signed = |v: f32, d: f64| if d >= 0.0 { v.abs() } else { -v.abs() };
        Self::new(u, signed(x, m21 - m12), signed(y, m02 - m20), signed(z, m10 - m01))
    }

    /// `Quaternion(const Vector3&)`: the vector's float components as roll, pitch, yaw.
    pub fn from_euler_vector(rpy: Point3) -> Self {
        Self::from_euler(rpy.x as f64, rpy.y as f64, rpy.z as f64)
    }

    /// `Quaternion(axis, angle)`: axis is not normalised (as in OctoMap).
    pub fn from_axis_angle(axis: Point3, angle: f64) -> Self {
        let sa = (angle / 2.0).sin();
        let ca = (angle / 2.0).cos();
        Self::new(ca as f32, (axis.x as f64 * sa) as f32, (axis.y as f64 * sa) as f32, (axis.z as f64 * sa) as f32)
    }

    /// `Quaternion::norm`: float squares summed in double, sqrt rounded to float.
    pub fn norm(self) -> f32 {
        let mut n = 0.0f64;
        for c in self.to_array() {
            n += (c * c) as f64;
        }
        n.sqrt() as f32
    }

    /// `Quaternion::normalize`: divides each float by the float norm if positive.
    pub fn normalize(&mut self) -> &mut Self {
        let len = self.norm() as f64;
        if len > 0.0 {
            *self /= len as f32;
        }
        self
    }

    /// A normalised copy (see [`Quaternion::normalize`]).
    pub fn normalized(self) -> Self {
        let mut r = self;
        r.normalize();
        r
    }

    /// Conjugate (`Quaternion::inv`); equals the inverse only for unit quaternions.
    #[inline]
    pub fn inv(self) -> Self {
        Self::new(self.u, -self.x, -self.y, -self.z)
    }

    /// `Quaternion::inv_IP`.
    pub fn inv_in_place(&mut self) -> &mut Self {
        *self = self.inv();
        self
    }

    /// `Quaternion * Vector3`: the vector as pure quaternion `(0, v)`.
    #[inline]
    pub fn mul_vec(self, v: Point3) -> Self {
        self * Self::new(0.0, v.x, v.y, v.z)
    }

    /// `q * v * q.inv()`, keeping the vector part.
    #[inline]
    pub fn rotate(self, v: Point3) -> Point3 {
        let q = self.mul_vec(v) * self.inv();
        Point3::new(q.x, q.y, q.z)
    }

    /// Shared double-precision rotation matrix of `toEuler` / `toRotMatrix`.
    fn matrix(self) -> [[f64; 3]; 3] {
        let n = self.norm() as f64;
        let s = if n > 0.0 { 2.0 / (n * n) } else { 0.0 };
        let (u, x, y, z) = (self.u as f64, self.x as f64, self.y as f64, self.z as f64);
        let (xs, ys, zs) = (x * s, y * s, z * s);
        let (ux, uy, uz) = (u * xs, u * ys, u * zs);
        let (xx, xy, xz) = (x * xs, x * ys, x * zs);
        let (yy, yz, zz) = (y * ys, y * zs, z * zs);
        [[1.0 - (yy + zz), xy - uz, xz + uy], [xy + uz, 1.0 - (xx + zz), yz - ux], [xz - uy, yz + ux, 1.0 - (xx + yy)]]
    }

    /// `Quaternion::toRotMatrix`, row major.
    pub fn to_rot_matrix(self) -> [[f64; 3]; 3] {
        self.matrix()
    }

    /// `Quaternion::toEuler`: (roll, pitch, yaw) as floats.
    pub fn to_euler(self) -> Point3 {
        let m = self.matrix();
        let roll = m[2][1].atan2(m[2][2]) as f32;
        let pitch = (-m[2][0]).atan2((m[2][1] * m[2][1] + m[2][2] * m[2][2]).sqrt()) as f32;
        let yaw = m[1][0].atan2(m[0][0]) as f32;
        Point3::new(roll, pitch, yaw)
    }

    /// Bit patterns of `[u, x, y, z]`, for exact comparisons.
    pub fn to_bits(self) -> [u32; 4] {
        self.to_array().map(f32::to_bits)
    }
}

impl Mul for Quaternion {
    type Output = Self;
    /// Hamilton product in float, in OctoMap's term order.
    #[inline]
    fn mul(self, o: Self) -> Self {
        let (a, b) = (self, o);
        Self::new(
            a.u * b.u - a.x * b.x - a.y * b.y - a.z * b.z,
            a.y * b.z - b.y * a.z + a.u * b.x + b.u * a.x,
            a.z * b.x - b.z * a.x + a.u * b.y + b.u * a.y,
            a.x * b.y - b.x * a.y + a.u * b.z + b.u * a.z,
        )
    }
}

impl DivAssign<f32> for Quaternion {
    fn div_assign(&mut self, s: f32) {
        self.u /= s;
        self.x /= s;
        self.y /= s;
        self.z /= s;
    }
}

/// OctoMap's `Pose6D`: float translation and float quaternion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose6D {
    /// Translation in metres (`Pose6D::trans`).
    pub translation: Point3,
    /// Orientation (`Pose6D::rot`).
    pub rotation: Quaternion,
}

impl Pose6D {
    /// Zero translation and the identity rotation.
    pub const IDENTITY: Self = Self { translation: Point3::new(0.0, 0.0, 0.0), rotation: Quaternion::IDENTITY };

    /// A pose from a translation and a rotation (the quaternion is used as given).
    pub const fn new(translation: Point3, rotation: Quaternion) -> Self {
        Self { translation, rotation }
    }

    /// `Pose6D(float x, y, z, double roll, pitch, yaw)`.
    pub fn from_euler(x: f32, y: f32, z: f32, roll: f64, pitch: f64, yaw: f64) -> Self {
        Self::new(Point3::new(x, y, z), Quaternion::from_euler(roll, pitch, yaw))
    }

    /// The translation, OctoMap's `Pose6D::trans`.
    pub fn trans(&self) -> Point3 {
        self.translation
    }

    /// The rotation, OctoMap's `Pose6D::rot`.
    pub fn rot(&self) -> Quaternion {
        self.rotation
    }

    /// Roll (rotation about x) in radians from [`Quaternion::to_euler`], OctoMap's `Pose6D::roll`.
    pub fn roll(&self) -> f64 {
        self.rotation.to_euler().x as f64
    }

    /// Pitch (rotation about y) in radians from [`Quaternion::to_euler`], OctoMap's `Pose6D::pitch`.
    pub fn pitch(&self) -> f64 {
        self.rotation.to_euler().y as f64
    }

    /// Yaw (rotation about z) in radians from [`Quaternion::to_euler`], OctoMap's `Pose6D::yaw`.
    pub fn yaw(&self) -> f64 {
        self.rotation.to_euler().z as f64
    }

    /// `rot.rotate(v) + trans`.
    #[inline]
    pub fn transform(&self, v: Point3) -> Point3 {
        self.rotation.rotate(v) + self.translation
    }

    /// [`Self::transform`] of every point of `points`, in place. Blocks of
    /// points are taken apart into one array per axis, so that the compiler
    /// runs the same float operations on several points at once (a point's
    /// three coordinates alone fill no vector): the same bits, about three
    /// times faster with AVX-512 (sixteen points an instruction), where the
    /// processor has it.
    pub fn transform_all(&self, points: &mut [Point3]) {
        #[cfg(target_arch = "x86_64")]
        if let Some(avx512) = crate::arch::avx512::Avx512::detect() {
            return avx512.transform_all(self, points);
        }
        self.transform_blocks(points);
    }

    /// [`Self::transform_all`]'s loop, inlined into each instruction set's
    /// copy.
    #[inline(always)]
    pub(crate) fn transform_blocks(&self, points: &mut [Point3]) {
        const BLOCK: usize = 16;
        let mut blocks = points.chunks_exact_mut(BLOCK);
        for block in &mut blocks {
            let (mut x, mut y, mut z) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
            for (i, p) in block.iter().enumerate() {
                (x[i], y[i], z[i]) = (p.x, p.y, p.z);
            }
            for i in 0..BLOCK {
                let t = self.transform(Point3::new(x[i], y[i], z[i]));
                (x[i], y[i], z[i]) = (t.x, t.y, t.z);
            }
            for (i, p) in block.iter_mut().enumerate() {
                *p = Point3::new(x[i], y[i], z[i]);
            }
        }
        for p in blocks.into_remainder() {
            *p = self.transform(*p);
        }
    }

    /// `Pose6D::inv`: normalised conjugate, translation rotated by the new rotation.
    pub fn inv(&self) -> Self {
        let rotation = self.rotation.inv().normalized();
        let translation = rotation.rotate(-self.translation);
        Self::new(translation, rotation)
    }

    /// `Pose6D::inv_IP` (same arithmetic as [`Pose6D::inv`]).
    pub fn inv_in_place(&mut self) -> &mut Self {
        *self = self.inv();
        self
    }

    /// `Pose6D::distance`: float differences summed in double.
    pub fn distance(&self, o: &Self) -> f64 {
        self.translation.distance(o.translation)
    }

    /// `Pose6D::transLength`: the float-argument `sqrt` overload, so a float result.
    pub fn trans_length(&self) -> f64 {
        let t = self.translation;
        (t.x * t.x + t.y * t.y + t.z * t.z).sqrt() as f64
    }
}

impl Mul for Pose6D {
    type Output = Self;
    /// `Pose6D::operator*`: the composed rotation is normalised.
    fn mul(self, o: Self) -> Self {
        let rot_new = self.rotation * o.rotation;
        let trans_new = self.rotation.rotate(o.translation) + self.translation;
        Self::new(trans_new, rot_new.normalized())
    }
}

impl MulAssign for Pose6D {
    /// `Pose6D::operator*=`: unlike `*`, the rotation is *not* normalised.
    fn mul_assign(&mut self, o: Self) {
        self.translation += self.rotation.rotate(o.translation);
        self.rotation = self.rotation * o.rotation;
    }
}

/// OctoMap's `Pointcloud`: a plain vector of float points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// The points, in insertion order.
    pub points: Vec<Point3>,
}

impl PointCloud {
    /// An empty cloud.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty cloud with room for `n` points.
    pub fn with_capacity(n: usize) -> Self {
        Self { points: Vec::with_capacity(n) }
    }

    /// Number of points (`Pointcloud::size`).
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when the cloud holds no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Appends a point (`Pointcloud::push_back`).
    pub fn push(&mut self, p: Point3) {
        self.points.push(p);
    }

    /// Iterates over the points in order.
    pub fn iter(&self) -> std::slice::Iter<'_, Point3> {
        self.points.iter()
    }

    /// The points as a slice.
    pub fn as_slice(&self) -> &[Point3] {
        &self.points
    }

    /// `Pointcloud::transform`: every point through `pose.transform`.
    pub fn transform(&mut self, pose: &Pose6D) {
        pose.transform_all(&mut self.points);
    }

    /// `Pointcloud::rotate`: [`Point3::rotate_ip`] on every point.
    pub fn rotate(&mut self, roll: f64, pitch: f64, yaw: f64) {
        for p in &mut self.points {
            p.rotate_ip(roll, pitch, yaw);
        }
    }

    /// Tight bounding box; `None` when empty. NaN coordinates are ignored.
    pub fn bounding_box(&self) -> Option<(Point3, Point3)> {
        let mut it = self.points.iter();
        let first = *it.next()?;
        let (mut lo, mut hi) = (first, first);
        for p in it {
            lo = Point3::new(lo.x.min(p.x), lo.y.min(p.y), lo.z.min(p.z));
            hi = Point3::new(hi.x.max(p.x), hi.y.max(p.y), hi.z.max(p.z));
        }
        Some((lo, hi))
    }

    /// `Pointcloud::calcBBX`: starts from ±1e6, so an empty cloud gives
    /// (1e6, -1e6) and far points are not clamped but near ones can be.
    pub fn calc_bbx(&self) -> (Point3, Point3) {
        let mut lo = Point3::new(1e6, 1e6, 1e6);
        let mut hi = Point3::new(-1e6, -1e6, -1e6);
        for p in &self.points {
            if p.x < lo.x {
                lo.x = p.x;
            }
            if p.y < lo.y {
                lo.y = p.y;
            }
            if p.z < lo.z {
                lo.z = p.z;
            }
            if p.x > hi.x {
                hi.x = p.x;
            }
            if p.y > hi.y {
                hi.y = p.y;
            }
            if p.z > hi.z {
                hi.z = p.z;
            }
        }
        (lo, hi)
    }

    /// `Pointcloud::crop`: keeps points with `lower <= p <= upper` (inclusive; NaN dropped).
    pub fn crop(&mut self, lower: Point3, upper: Point3) {
        self.points.retain(|p| {
            p.x >= lower.x && p.y >= lower.y && p.z >= lower.z && p.x <= upper.x && p.y <= upper.y && p.z <= upper.z
        });
    }

    /// `Pointcloud::minDist`: keeps points farther than `thres` from the
    /// origin. `sqrt` of a float argument picks C++'s float overload, so the
    /// distance is a float sqrt widened (checked against liboctomap).
    pub fn min_dist(&mut self, thres: f64) {
        self.points.retain(|p| (p.x * p.x + p.y * p.y + p.z * p.z).sqrt() as f64 > thres);
    }
}

impl From<Vec<Point3>> for PointCloud {
    fn from(points: Vec<Point3>) -> Self {
        Self { points }
    }
}

impl FromIterator<Point3> for PointCloud {
    fn from_iter<I: IntoIterator<Item = Point3>>(iter: I) -> Self {
        Self { points: iter.into_iter().collect() }
    }
}

impl<'a> IntoIterator for &'a PointCloud {
    type Item = &'a Point3;
    type IntoIter = std::slice::Iter<'a, Point3>;
    fn into_iter(self) -> Self::IntoIter {
        self.points.iter()
    }
}

/// What `graph2tree` does to one scan node: returns the world-frame points and
/// the sensor origin passed to `insertPointCloud`.
///
/// The origin is `pose.transform(pose.inv().transform(pose.trans()))`, which
/// can differ from `pose.trans()` in the last bits when the rotation is not
/// the identity; OctoMap uses this round-tripped value, so we do too.
pub fn graph2tree_transform(pose: &Pose6D, scan: &PointCloud) -> (PointCloud, Point3) {
    graph2tree_in_place(pose, scan.clone())
}

/// [`graph2tree_transform`] of a scan given up for it: its points are
/// transformed where they are.
pub fn graph2tree_in_place(pose: &Pose6D, mut scan: PointCloud) -> (PointCloud, Point3) {
    let sensor_origin = pose.inv().transform(pose.translation);
    scan.transform(pose);
    (scan, pose.transform(sensor_origin))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every block path gives each point the bits of the point-by-point
    /// transform: rotations of every kind, special floats, a remainder.
    #[test]
    fn transform_all_equals_transform_bit_for_bit() {
        let specials = [0.0f32, -0.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MIN_POSITIVE, 1e-40, 3.0e38];
        let mut points = Vec::new();
        let mut state = 12345u32;
        for i in 0..1000 {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let r = |k: u32| ((state.rotate_left(k) >> 8) as f32 / (1 << 24) as f32 - 0.5) * 80.0;
            let mut p = Point3::new(r(0), r(7), r(13));
            if i % 37 == 0 {
                p.y = specials[i / 37 % specials.len()];
            }
            points.push(p);
        }
        let poses = [
            Pose6D::new(Point3::new(1.5, -2.25, 0.75), Quaternion::from_euler(0.3, -0.2, 2.9)),
            Pose6D::new(Point3::new(0.0, 0.0, 0.0), Quaternion::new(1.0, 0.0, 0.0, 0.0)),
            Pose6D::new(Point3::new(-1e3, 7.0, 1e-3), Quaternion::new(0.5, 0.5, -0.5, 0.5)),
            Pose6D::new(Point3::new(0.1, 0.2, 0.3), Quaternion::new(0.9, 0.1, 0.3, -0.2)),
        ];
        for pose in poses {
            let want: Vec<[u32; 3]> = points.iter().map(|&p| pose.transform(p).to_bits()).collect();
            for len in [points.len(), 999, 16, 15, 0] {
                let (mut all, mut blocks) = (points[..len].to_vec(), points[..len].to_vec());
                pose.transform_all(&mut all);
                pose.transform_blocks(&mut blocks);
                let bits = |v: &[Point3]| v.iter().map(|p| p.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&all), want[..len], "{pose:?}, {len} points");
                assert_eq!(bits(&blocks), want[..len], "{pose:?}, {len} points");
            }
        }
    }
}
