//! Shared helpers for the golden-vector tests: manifest access, file
//! loading (plain, gzip, digest-only), and dumps in the golden CSV formats.
#![allow(dead_code)]

use octolinear::sensor::{SensorModel, SensorProbabilities};
use octolinear::{BoundsRule, OccupancyTree, Point3};
use serde_json::Value;
use sha2::{Digest, Sha256};
use std::fmt::Write as _;
use std::io::Read;
use std::path::{Path, PathBuf};

pub struct Golden {
    pub root: PathBuf,
    pub manifest: Value,
}

/// The golden vectors (`tests/golden`, see [`octolinear_oracle::golden_dir`]
/// for where they are looked for); a test without them fails.
pub fn golden() -> Golden {
    let root = octolinear_oracle::golden_dir();
    let text = std::fs::read_to_string(root.join("manifest.json")).expect("manifest.json reads");
    let manifest = serde_json::from_str(&text).expect("manifest.json parses");
    Golden { root, manifest }
}

/// A file of a case: its digest, and its bytes when stored.
pub struct GoldenFile {
    pub name: String,
    pub sha256: String,
    pub bytes: u64,
    pub path: Option<PathBuf>,
}

impl Golden {
    pub fn cases(&self, command: &str) -> Vec<&Value> {
        self.manifest["cases"].as_array().unwrap().iter().filter(|c| c["command"] == command).collect()
    }

    pub fn case(&self, id: &str) -> &Value {
        self.manifest["cases"].as_array().unwrap().iter().find(|c| c["id"] == id).expect("case exists")
    }

    pub fn file(&self, case: &Value, name: &str) -> Option<GoldenFile> {
        let f = case["files"].as_array()?.iter().find(|f| f["name"] == name)?;
        let path = match f["stored"].as_str().unwrap() {
            "plain" | "gzip" => Some(self.root.join(f["path"].as_str().unwrap())),
            _ => f.get("same_content_as").and_then(|s| s.as_str()).and_then(|other| {
                if other.starts_with("cases/") {
                    Some(self.root.join(other))
                } else {
                    self.file(case, other).and_then(|g| g.path)
                }
            }),
        };
        Some(GoldenFile {
            name: name.to_string(),
            sha256: f["sha256"].as_str().unwrap().to_string(),
            bytes: f["bytes"].as_u64().unwrap(),
            path,
        })
    }

    /// The (decompressed) bytes of a stored file.
    pub fn load(&self, case: &Value, name: &str) -> Option<Vec<u8>> {
        let path = self.file(case, name)?.path?;
        Some(read_maybe_gz(&path))
    }

    pub fn load_text(&self, case: &Value, name: &str) -> Option<String> {
        self.load(case, name).map(|b| String::from_utf8(b).expect("utf-8 csv"))
    }

    pub fn input(&self, rel: &str) -> PathBuf {
        self.root.join(rel)
    }
}

pub fn read_maybe_gz(path: &Path) -> Vec<u8> {
    let raw = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    if path.extension().is_some_and(|e| e == "gz") {
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(&raw[..]).read_to_end(&mut out).expect("gzip");
        out
    } else {
        raw
    }
}

pub fn sha256_hex(bytes: &[u8]) -> String {
    let d = Sha256::digest(bytes);
    d.iter().map(|b| format!("{b:02x}")).collect()
}

/// Collects failures so that one run reports every mismatch.
#[derive(Default)]
pub struct Failures(pub Vec<String>);

impl Failures {
    pub fn check(&mut self, ok: bool, what: impl FnOnce() -> String) {
        if !ok {
            self.0.push(what());
        }
    }

    /// Compares bytes we produced with a golden file by digest.
    pub fn check_digest(&mut self, g: &Golden, case: &Value, name: &str, ours: &[u8]) {
        let id = case["id"].as_str().unwrap();
        match g.file(case, name) {
            None => self.0.push(format!("{id}: golden file {name} missing from the manifest")),
            Some(f) => {
                if sha256_hex(ours) != f.sha256 {
                    let detail = f
                        .path
                        .as_ref()
                        .map(|p| first_difference(&read_maybe_gz(p), ours))
                        .unwrap_or_else(|| format!("{} bytes vs {} expected", ours.len(), f.bytes));
                    self.0.push(format!("{id}: {name} differs ({detail})"));
                }
            }
        }
    }

    pub fn finish(self, what: &str) {
        if !self.0.is_empty() {
            let limit = if std::env::var_os("GOLDEN_SHOW_ALL").is_some() { usize::MAX } else { 40 };
            let shown: Vec<_> = self.0.iter().take(limit).cloned().collect();
            panic!("{what}: {} failures\n{}", self.0.len(), shown.join("\n"));
        }
    }
}

fn first_difference(expected: &[u8], ours: &[u8]) -> String {
    let pos = expected.iter().zip(ours).position(|(a, b)| a != b).unwrap_or(expected.len().min(ours.len()));
    let line = expected[..pos].iter().filter(|&&b| b == b'\n').count() + 1;
    let ctx = |b: &[u8]| {
        let start = pos.saturating_sub(40);
        String::from_utf8_lossy(&b[start..(pos + 40).min(b.len())]).replace('\n', "⏎")
    };
    format!(
        "first difference at byte {pos} (line {line}), {} vs {} bytes; expected …{}… got …{}…",
        expected.len(),
        ours.len(),
        ctx(expected),
        ctx(ours)
    )
}

pub fn f32hex(v: f32) -> String {
    format!("{:08x}", v.to_bits())
}

pub fn f64hex(v: f64) -> String {
    format!("{:016x}", v.to_bits())
}

pub fn parse_f32hex(s: &str) -> f32 {
    f32::from_bits(u32::from_str_radix(s, 16).unwrap_or_else(|_| panic!("bad f32 hex {s}")))
}

pub fn parse_f64hex(s: &str) -> f64 {
    f64::from_bits(u64::from_str_radix(s, 16).unwrap_or_else(|_| panic!("bad f64 hex {s}")))
}

/// The sensor model a case was built with.
pub fn case_sensor(case: &Value) -> SensorModel {
    let s = &case["params"]["sensor"];
    if !s.is_object() {
        return SensorModel::default();
    }
    let p = SensorProbabilities {
        hit: s["prob_hit"].as_f64().unwrap(),
        miss: s["prob_miss"].as_f64().unwrap(),
        clamping_min: s["clamping_thres_min"].as_f64().unwrap(),
        clamping_max: s["clamping_thres_max"].as_f64().unwrap(),
        occupancy_threshold: 0.5,
    };
    let how = s["how_set"].as_str().unwrap_or("");
    let model = SensorModel::from_probabilities(&p).unwrap();
    if how.starts_with("graph2tree style") {
        // probabilities read back from a fresh tree, then set again
        let back = model.probabilities();
        SensorModel::from_probabilities(&SensorProbabilities { occupancy_threshold: 0.5, ..back }).unwrap()
    } else {
        model
    }
}

/// `leaves.csv`: `kx,ky,kz,depth,logodds` per leaf in iteration order.
pub fn leaves_csv(tree: &OccupancyTree, max_depth: u8) -> String {
    let mut s = String::from("kx,ky,kz,depth,logodds\n");
    for n in tree.leaves(max_depth) {
        let [x, y, z] = n.key.0;
        writeln!(s, "{x},{y},{z},{},{}", n.depth, f32hex(n.value)).unwrap();
    }
    s
}

/// `nodes.csv`: `kx,ky,kz,depth,is_leaf,logodds` per node.
pub fn nodes_csv(tree: &OccupancyTree) -> String {
    let mut s = String::from("kx,ky,kz,depth,is_leaf,logodds\n");
    for n in tree.nodes(0) {
        let [x, y, z] = n.key.0;
        writeln!(s, "{x},{y},{z},{},{},{}", n.depth, u8::from(n.is_leaf), f32hex(n.value)).unwrap();
    }
    s
}

/// Our statistics under the names of `stats.csv` (integers in decimal,
/// floats as hex bits). `const_cached` says whether OctoMap's const extent
/// getters would answer from the cache its non-const ones fill (see
/// [`StatsTracker`]).
pub fn stats(tree: &OccupancyTree, const_cached: bool) -> Vec<(&'static str, String)> {
    let const_rule = if const_cached { BoundsRule::MinPlusSize } else { BoundsRule::CenterHalfSize };
    let sensor = tree.sensor();
    let mut v: Vec<(&'static str, String)> = vec![
        ("resolution", f64hex(tree.resolution())),
        ("size", tree.size().to_string()),
        ("num_leaf_nodes", tree.num_leaves().to_string()),
        ("calc_num_nodes", tree.calc_num_nodes().to_string()),
        ("num_inner_nodes_iter", tree.nodes(0).filter(|n| !n.is_leaf).count().to_string()),
        ("memory_usage", tree.octomap_memory_usage().to_string()),
        ("memory_full_grid", tree.memory_full_grid(const_rule).to_string()),
        ("volume", f64hex(tree.volume())),
        ("clamping_thres_min_log", f32hex(sensor.clamping_min)),
        ("clamping_thres_max_log", f32hex(sensor.clamping_max)),
        ("prob_hit_log", f32hex(sensor.hit)),
        ("prob_miss_log", f32hex(sensor.miss)),
        ("occupancy_thres_log", f32hex(sensor.occupancy_threshold)),
    ];
    let leaves: Vec<f32> = tree.leaves(0).map(|n| n.value).collect();
    v.push(("leaves_occupied", leaves.iter().filter(|&&x| sensor.is_occupied(x)).count().to_string()));
    v.push(("leaves_free", leaves.iter().filter(|&&x| !sensor.is_occupied(x)).count().to_string()));
    v.push(("leaves_at_threshold", leaves.iter().filter(|&&x| sensor.is_at_threshold(x)).count().to_string()));
    v.push(("nodes_at_threshold", tree.nodes(0).filter(|n| sensor.is_at_threshold(n.value)).count().to_string()));
    if let Some(r) = tree.root_value() {
        v.push(("root_logodds", f32hex(r)));
    }
    let nc = tree.bounds(BoundsRule::MinPlusSize);
    let c = tree.bounds(const_rule);
    let axes = ["x", "y", "z"];
    const MIN: [&str; 3] = ["metric_min_x", "metric_min_y", "metric_min_z"];
    const MAX: [&str; 3] = ["metric_max_x", "metric_max_y", "metric_max_z"];
    const SIZE: [&str; 3] = ["metric_size_x", "metric_size_y", "metric_size_z"];
    const CMIN: [&str; 3] = ["const_metric_min_x", "const_metric_min_y", "const_metric_min_z"];
    const CMAX: [&str; 3] = ["const_metric_max_x", "const_metric_max_y", "const_metric_max_z"];
    for i in 0..axes.len() {
        v.push((MIN[i], f64hex(nc.min[i])));
        v.push((MAX[i], f64hex(nc.max[i])));
        v.push((SIZE[i], f64hex(nc.size()[i])));
        v.push((CMIN[i], f64hex(c.min[i])));
        v.push((CMAX[i], f64hex(c.max[i])));
    }
    v
}

/// Expected statistics per stage and name: from the case's `stats.csv`
/// when stored (it has the per-scan stages too), else from the manifest.
pub type StageStats = std::collections::HashMap<String, std::collections::HashMap<String, String>>;

pub fn expected_stats(g: &Golden, case: &Value) -> StageStats {
    let mut out = StageStats::new();
    if let Some(text) = g.load_text(case, "stats.csv") {
        for line in text.lines().skip(1) {
            let cols: Vec<&str> = line.split(',').collect();
            let want = if cols[3].is_empty() { cols[2] } else { cols[3] };
            out.entry(cols[0].to_string()).or_default().insert(cols[1].to_string(), want.to_string());
        }
        return out;
    }
    if let Some(stages) = case["stats"].as_object() {
        for (stage, names) in stages {
            let m = out.entry(stage.clone()).or_default();
            for (name, e) in names.as_object().unwrap() {
                let want = match e {
                    Value::Object(o) => o["hex"].as_str().unwrap().to_string(),
                    Value::Number(n) => n.to_string(),
                    Value::String(s) => s.clone(),
                    other => other.to_string(),
                };
                m.insert(name.clone(), want);
            }
        }
    }
    out
}

/// Models when OctoMap's const `getMetricMin/Max` (and so `memoryFullGrid`)
/// answer from the cache that the non-const overloads fill: the cache stays
/// valid until the tree's structure changes. The golden harness calls the
/// const overloads first at every stage, so a stage sees cached values
/// exactly when the node count did not change since the previous stage on
/// the same tree object.
#[derive(Default)]
pub struct StatsTracker {
    last_size: Option<usize>,
}

impl StatsTracker {
    /// Checks a stage (when `expected` has it) and records that the
    /// harness computed statistics on this tree.
    pub fn check(&mut self, f: &mut Failures, id: &str, expected: &StageStats, stage: &str, tree: &OccupancyTree) {
        let cached = self.last_size == Some(tree.size());
        match expected.get(stage) {
            Some(want) => {
                for (name, ours) in stats(tree, cached) {
                    if let Some(w) = want.get(name) {
                        f.check(*w == ours, || format!("{id} [{stage}] {name}: expected {w}, got {ours}"));
                    }
                }
            }
            None => f.0.push(format!("{id}: no stats stage {stage}")),
        }
        self.last_size = Some(tree.size());
    }

    /// Records a stage whose statistics are not available to compare.
    pub fn skip(&mut self, tree: &OccupancyTree) {
        self.last_size = Some(tree.size());
    }
}

/// Reads `x y z` lines as float32 points.
pub fn read_xyz(text: &str) -> Vec<Point3> {
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f32> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            Point3::new(v[0], v[1], v[2])
        })
        .collect()
}

pub fn point_from_hex(cols: &[&str]) -> Point3 {
    Point3::new(parse_f32hex(cols[0]), parse_f32hex(cols[1]), parse_f32hex(cols[2]))
}

/// A greedy LZF compressor (liblzf's format, as PCL's `binary_compressed`
/// uses): literal runs and back references, for building test inputs.
pub fn lzf_compress(input: &[u8]) -> Vec<u8> {
    fn flush(out: &mut Vec<u8>, lit: &mut Vec<u8>) {
        for chunk in lit.chunks(32) {
            out.push((chunk.len() - 1) as u8);
            out.extend_from_slice(chunk);
        }
        lit.clear();
    }
    let (mut out, mut lit, mut i) = (Vec::new(), Vec::new(), 0);
    while i < input.len() {
        let mut best = (0, 0);
        for j in i.saturating_sub(8192)..i {
            let mut l = 0;
            while i + l < input.len() && l < 264 && input[j + l] == input[i + l] {
                l += 1;
            }
            if l > best.0 {
                best = (l, i - j - 1);
            }
        }
        if best.0 >= 3 {
            flush(&mut out, &mut lit);
            let (len, off) = (best.0 - 2, best.1);
            if len < 7 {
                out.push(((len << 5) | (off >> 8)) as u8);
            } else {
                out.push(((7 << 5) | (off >> 8)) as u8);
                out.push((len - 7) as u8);
            }
            out.push((off & 0xff) as u8);
            i += best.0;
        } else {
            lit.push(input[i]);
            i += 1;
        }
    }
    flush(&mut out, &mut lit);
    out
}

/// Deterministic randomness for the mutation tests (splitmix64).
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform-ish in `0..n`; 0 when `n` is 0.
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }

    /// A random byte.
    pub fn byte(&mut self) -> u8 {
        self.next() as u8
    }
}

/// A coloured scan: a wall, a floor and scattered points around `origin`,
/// many of them sharing voxels (so colours are blended) and whole blocks of
/// equal occupancy (so pruning merges coloured voxels). Colours come in
/// bands with a little noise; some are pure white (OctoMap's "unset").
pub fn colored_scan(
    rng: &mut octolinear_sim::SplitMix64,
    res: f64,
    origin: [f32; 3],
    n: usize,
) -> (Vec<[f32; 3]>, Vec<[u8; 3]>) {
    let wall = rng.range(1.0, 6.0);
    let floor = -rng.range(0.5, 2.0);
    let snap = rng.below(2) == 0;
    let palette: Vec<[u8; 3]> = (0..6).map(|_| [0, 1, 2].map(|_| rng.below(256) as u8)).collect();
    let (mut pts, mut cols) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for _ in 0..n {
        let u = rng.range(-3.0, 3.0);
        let v = rng.range(-1.5, 1.5);
        let mut p = match rng.below(10) {
            0..=4 => [wall, u, v + floor.abs() * 0.5],
            5..=7 => [rng.range(0.3, wall), u, floor],
            _ => {
                let d = rng.range(0.2, 9.0);
                let (a, b) = (rng.range(-3.2, 3.2), rng.range(-1.2, 1.2));
                [d * a.cos() * b.cos(), d * a.sin() * b.cos(), d * b.sin()]
            }
        };
        if snap {
            // voxel centres plus a small offset: many points per voxel
            for c in &mut p {
                *c = ((*c / res).floor() + 0.5 + rng.range(-0.3, 0.3)) * res;
            }
        }
        let band = ((u * 2.0).floor() as i64).rem_euclid(palette.len() as i64) as usize;
        let base = palette[band];
        let rgb = if rng.below(25) == 0 {
            [255, 255, 255]
        } else {
            base.map(|c| (i32::from(c) + rng.below(9) as i32 - 4).clamp(0, 255) as u8)
        };
        pts.push([p[0] as f32 + origin[0], p[1] as f32 + origin[1], p[2] as f32 + origin[2]]);
        cols.push(rgb);
    }
    (pts, cols)
}
