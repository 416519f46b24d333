//! End-to-end tests of the `octolinear` subcommands: outputs checked against
//! Debian's OctoMap tools where they exist (bytes of files, numbers they
//! print), by content otherwise, and every error path a user can hit.

#[path = "../../tests/common/mod.rs"]
mod common;
use common::lzf_compress;
use octolinear::formats::{bt, graph, ot};
use octolinear::{OccupancyTree, Point3};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_octolinear"))
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("binary runs")
}

/// Runs and requires success; returns stdout.
fn ok(args: &[&str]) -> String {
    let out = run(args);
    assert!(out.status.success(), "{args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("utf-8 stdout")
}

/// Runs and requires a failure with one clear line on stderr containing `needle`.
fn fail(args: &[&str], needle: &str) {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{args:?} succeeded: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    assert!(err.starts_with("octolinear: error: "), "{args:?}: {err}");
    assert!(err.contains(needle), "{args:?}: {err:?} lacks {needle:?}");
}

/// Fails in argument parsing (clap's own message, which has a usage block).
fn fail_usage(args: &[&str], needle: &str) {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert!(!err.contains("panicked"));
    assert!(err.lines().next().unwrap().starts_with("error:"), "{err}");
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
}

/// A Debian OctoMap tool. When it is not installed the test skips the part
/// that needs it (`None`, and a line saying so), or fails where `CI=true`
/// (see `octolinear_oracle::skip_without_octomap`).
fn tool(name: &str) -> Option<PathBuf> {
    let p = Path::new("/usr/bin").join(name);
    if p.exists() {
        return Some(p);
    }
    let test = std::thread::current().name().unwrap_or("cli").to_string();
    octolinear_oracle::skip_without_octomap(
        &test,
        &format!("{name} is not installed (apt-get install -y octomap-tools)"),
    );
    None
}

fn oracle(tool: &Path, args: &[&str]) -> String {
    let out = Command::new(tool).args(args).output().expect("tool runs");
    assert!(out.status.success(), "{tool:?} {args:?} failed");
    String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr)
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// A temp dir with a small simulated scan graph and the maps built from it.
struct Fixture {
    dir: tempfile::TempDir,
}

impl Fixture {
    fn new() -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let f = Fixture { dir };
        ok(&["simulate", "--scans", "6", "--beams", "8", "--steps", "120", "-o", f.p("s.graph")]);
        for out in ["a.bt", "a.ot"] {
            ok(&["build", f.p("s.graph"), "-o", f.p(out), "--res", "0.1"]);
        }
        f
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn p(&self, name: &str) -> &str {
        let p = self.dir.path().join(name);
        // leak: test-lifetime strings for argument lists
        Box::leak(p.into_os_string().into_string().unwrap().into_boxed_str())
    }

    fn write(&self, name: &str, bytes: impl AsRef<[u8]>) -> &str {
        std::fs::write(self.path(name), bytes).unwrap();
        self.p(name)
    }
}

fn read_tree(p: &str) -> OccupancyTree {
    let f = std::io::BufReader::new(std::fs::File::open(p).unwrap());
    if p.ends_with(".bt") {
        bt::read(f).unwrap()
    } else {
        ot::read(f).unwrap().into_occupancy().unwrap()
    }
}

fn json(text: &str) -> serde_json::Value {
    serde_json::from_str(text.trim()).unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// Voxels at depth `depth` below the leaves `want` selects.
fn voxel_count(t: &OccupancyTree, depth: u8, want: impl Fn(f32) -> bool) -> u64 {
    t.leaves(depth).filter(|l| want(l.value)).map(|l| 1u64 << (3 * u32::from(depth - l.depth))).sum()
}

// ----- help ------------------------------------------------------------------

#[test]
fn every_subcommand_has_help_with_an_example() {
    for cmd in [
        "simulate",
        "build",
        "info",
        "convert",
        "query",
        "compare",
        "crop",
        "edit",
        "to-points",
        "eval",
        "log2graph",
        "binvox",
        "raycast",
        "render",
        "mesh",
    ] {
        let out = ok(&[cmd, "--help"]);
        assert!(out.contains("Example: octolinear"), "{cmd}: {out}");
    }
}

// ----- compare -------------------------------------------------------------

#[test]
fn compare_counts_differences_and_kld_like_compare_octrees() {
    let f = Fixture::new();
    let same = json(&ok(&["compare", f.p("a.ot"), f.p("a.ot"), "--json"]));
    assert_eq!(same["occupancy_differs"], 0);
    assert_eq!(same["logodds_differ"], 0);
    assert_eq!(same["kld"], 0.0);
    assert_eq!(same["only_a"], 0);
    // a map with another sensor model: same voxels, other values
    ok(&["build", f.p("s.graph"), "-o", f.p("c.ot"), "--sensor", "0.3", "0.8"]);
    let text = ok(&["compare", f.p("a.ot"), f.p("c.ot")]);
    let j = json(&ok(&["compare", f.p("a.ot"), f.p("c.ot"), "--json"]));
    assert!(j["logodds_differ"].as_u64().unwrap() > 0);
    assert!(j["kld"].as_f64().unwrap() > 0.0);
    let a = read_tree(f.p("a.ot"));
    assert_eq!(j["voxels_a"].as_u64().unwrap(), voxel_count(&a, 16, |_| true));
    if let Some(t) = tool("compare_octrees") {
        let out = oracle(&t, &[f.p("a.ot"), f.p("c.ot")]);
        let line = |text: &str, key: &str| {
            text.lines().find(|l| l.starts_with(key)).unwrap_or_else(|| panic!("no {key} in {text}")).to_string()
        };
        assert_eq!(line(&text, "KLD:"), line(&out, "KLD:"));
        let leafs = line(&out, "Expanded num. leafs:");
        assert!(leafs.ends_with(&format!(" {}", j["voxels_a"])), "{leafs}");
    }
    // maps of different extent: voxels only in one
    ok(&["build", f.p("s.graph"), "-o", f.p("d.ot"), "--scans", "2"]);
    let j = json(&ok(&["compare", f.p("a.ot"), f.p("d.ot"), "--json"]));
    assert!(j["only_a"].as_u64().unwrap() > 0);
    assert_eq!(j["only_b"], 0);
    // resolution mismatch
    ok(&["build", f.p("s.graph"), "-o", f.p("r.bt"), "--res", "0.2", "--scans", "1"]);
    fail(&["compare", f.p("a.bt"), f.p("r.bt")], "resolutions don't match");
}

// ----- edit / crop -----------------------------------------------------------

#[test]
fn edit_matches_edit_octree_bytes() {
    let f = Fixture::new();
    for (ours, theirs) in
        [(vec![], vec![]), (vec!["--res", "0.05"], vec!["--res", "0.05"]), (vec!["--scale", "2"], vec!["--scale", "2"])]
    {
        let mut args = vec!["edit", f.p("a.bt"), f.p("e.bt")];
        args.extend(&ours);
        ok(&args);
        let t = read_tree(f.p("e.bt"));
        let expect = match ours.first() {
            Some(&"--res") => 0.05,
            Some(_) => 0.2,
            None => 0.1,
        };
        assert_eq!(t.resolution(), expect);
        if let Some(tool) = tool("edit_octree") {
            let mut args = vec!["-o", f.p("o.bt")];
            args.extend(&theirs);
            args.push(f.p("a.bt"));
            oracle(&tool, &args);
            assert_eq!(std::fs::read(f.path("e.bt")).unwrap(), std::fs::read(f.path("o.bt")).unwrap(), "edit {ours:?}");
        }
    }
    // expand keeps the voxels (in .ot); max-likelihood + prune gives the .bt tree
    ok(&["edit", f.p("a.ot"), f.p("x.ot"), "--expand"]);
    let (a, x) = (read_tree(f.p("a.ot")), read_tree(f.p("x.ot")));
    assert!(x.leaves(0).all(|l| l.depth == 16));
    assert_eq!(voxel_count(&a, 16, |_| true), x.num_leaves() as u64);
    ok(&["edit", f.p("x.ot"), f.p("ml.ot"), "--max-likelihood", "--prune"]);
    let mut ml = a.clone();
    ml.to_max_likelihood();
    ml.prune();
    let ours = read_tree(f.p("ml.ot"));
    assert_eq!(ours.num_leaves(), ml.num_leaves());

    fail(&["edit", f.p("a.bt"), f.p("e.bt"), "--res", "-1"], "--res must be a positive");
    fail(&["edit", f.p("a.bt"), f.p("e.bt"), "--scale", "0"], "--scale must be a positive");
    fail(&["edit", f.p("a.bt"), f.p("e.txt")], "unknown map format");
}

/// Smallest key of a node with centre key `key` covering `size` keys.
fn key_min(key: u16, size: i64) -> i64 {
    i64::from(key) - size / 2
}

#[test]
fn crop_keeps_exactly_the_voxels_in_the_box() {
    let f = Fixture::new();
    let (lo, hi) = ([-1.0f32, -1.5, 0.2], [2.0f32, 1.0, 1.3]);
    let args: Vec<String> = lo.iter().chain(&hi).map(|v| v.to_string()).collect();
    let a = read_tree(f.p("a.ot"));
    let keys = a.key_space();
    let kmin = keys.key(Point3::from_array(lo)).unwrap();
    let kmax = keys.key(Point3::from_array(hi)).unwrap();
    for out in ["c.ot", "c.bt"] {
        let mut cmd = vec!["crop", f.p("a.ot"), f.p(out), "--min"];
        cmd.extend(args[..3].iter().map(String::as_str));
        cmd.push("--max");
        cmd.extend(args[3..].iter().map(String::as_str));
        ok(&cmd);
    }
    let c = read_tree(f.p("c.ot"));
    assert!(c.num_leaves() > 100);
    // every kept leaf lies in the box and has the source's value
    for l in c.leaves(0) {
        let size = 1i64 << (16 - l.depth);
        for i in 0..3 {
            let k0 = key_min(l.key.0[i], size);
            assert!(k0 >= i64::from(kmin.0[i]) && k0 + size - 1 <= i64::from(kmax.0[i]));
        }
        let src = a.search(l.key, 16).expect("known in the source");
        assert_eq!(src.value.to_bits(), l.value.to_bits());
    }
    // and every voxel of the source inside the box is kept
    let inside: u64 = a
        .leaves(0)
        .map(|l| {
            let size = 1i64 << (16 - l.depth);
            (0..3)
                .map(|i| {
                    let k0 = key_min(l.key.0[i], size);
                    let lo = k0.max(i64::from(kmin.0[i]));
                    let hi = (k0 + size - 1).min(i64::from(kmax.0[i]));
                    (hi - lo + 1).max(0) as u64
                })
                .product::<u64>()
        })
        .sum();
    assert_eq!(voxel_count(&c, 16, |_| true), inside);
    // the .bt output is the cropped tree, maximum likelihood
    let cb = read_tree(f.p("c.bt"));
    let mut ml = c.clone();
    ml.to_max_likelihood();
    ml.prune();
    let mut x = Vec::new();
    bt::write(&ml, &mut x).unwrap();
    assert_eq!(std::fs::read(f.path("c.bt")).unwrap(), x);
    assert_eq!(cb.num_leaves(), ml.num_leaves());

    fail(&["crop", f.p("a.ot"), f.p("c.ot"), "--min", "1", "0", "0", "--max", "0", "1", "1"], "is above --max");
    fail(
        &["crop", f.p("a.ot"), f.p("c.ot"), "--min", "0", "0", "0", "--max", "1", "nan", "1"],
        "--max needs three finite numbers",
    );
    fail_usage(&["crop", f.p("a.ot"), f.p("c.ot"), "--min", "0", "0"], "--max");
}

// ----- to-points ---------------------------------------------------------------

#[test]
fn to_points_writes_every_occupied_voxel_centre() {
    let f = Fixture::new();
    let a = read_tree(f.p("a.bt"));
    let sensor = *a.sensor();
    let occupied = voxel_count(&a, 16, |v| sensor.is_occupied(v));
    ok(&["to-points", f.p("a.bt"), "-o", f.p("p.xyz")]);
    let pts = octolinear::formats::xyz::read_file(f.path("p.xyz")).unwrap();
    assert_eq!(pts.len() as u64, occupied);
    for p in &pts.points {
        let n = a.search_point(*p, 0).unwrap().unwrap();
        assert!(a.is_occupied(n.value));
        // a voxel centre
        let c = a.key_space().key_to_point(a.key(*p).unwrap());
        assert_eq!(c, *p);
    }
    let free = voxel_count(&a, 16, |v| !sensor.is_occupied(v));
    ok(&["to-points", f.p("a.bt"), "-o", f.p("f.ply"), "--free", "--ascii"]);
    let ply = std::fs::read_to_string(f.path("f.ply")).unwrap();
    assert!(ply.contains(&format!("element vertex {free}\n")));
    assert_eq!(ply.lines().count() as u64, 8 + free);
    // coarser level: one point per occupied depth-14 node
    let coarse = voxel_count(&a, 14, |v| sensor.is_occupied(v));
    assert!(coarse < occupied);
    ok(&["to-points", f.p("a.bt"), "-o", f.p("c.pcd"), "--depth", "14"]);
    let pcd = std::fs::read_to_string(f.path("c.pcd")).unwrap();
    assert!(pcd.starts_with("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"));
    assert!(pcd.contains(&format!("\nPOINTS {coarse}\nDATA ascii\n")));
    assert_eq!(pcd.lines().count() as u64, 11 + coarse);
    ok(&["to-points", f.p("a.bt"), "-o", f.p("b.ply")]);
    let b = std::fs::read(f.path("b.ply")).unwrap();
    let header = b"end_header\n";
    let at = b.windows(header.len()).position(|w| w == header).unwrap() + header.len();
    assert_eq!((b.len() - at) as u64, 12 * occupied);

    fail(&["to-points", f.p("a.bt"), "-o", f.p("p.obj")], "unknown format");
    fail(&["to-points", f.p("a.bt"), "-o", f.p("p.xyz"), "--depth", "17"], "--depth must be");
    fail(&["to-points", f.p("missing.bt"), "-o", f.p("p.xyz")], "cannot open");
}

// ----- eval ----------------------------------------------------------------------

fn counts_of(line: &str) -> [u64; 3] {
    let num = |key: &str| -> u64 {
        let rest = &line[line.find(key).unwrap() + key.len()..];
        rest.trim_start().split(|c: char| !c.is_ascii_digit()).next().unwrap().parse().unwrap()
    };
    [num("Voxels correct:"), num("#wrong:"), num("#unknown:")]
}

#[test]
fn eval_matches_eval_octree_accuracy() {
    let f = Fixture::new();
    for extra in [vec![], vec!["--max-range", "5"]] {
        let mut args = vec!["eval", f.p("s.graph")];
        args.extend(&extra);
        let text = ok(&args);
        args.push("--json");
        let j = json(&ok(&args));
        let fold = &j["folds"][0];
        assert_eq!(fold["scans"], 1); // scan 5 of 6
        let ours = [&fold["correct"], &fold["wrong"], &fold["unknown"]].map(|v| v.as_u64().unwrap());
        assert!(ours[0] > ours[1]);
        assert_eq!(counts_of(text.lines().next().unwrap()), ours);
        if let Some(t) = tool("eval_octree_accuracy") {
            let mut oargs = vec![f.p("s.graph")];
            if !extra.is_empty() {
                oargs.extend(["-m", "5"]);
            }
            let out = oracle(&t, &oargs);
            let line = out.lines().find(|l| l.starts_with("Voxels correct:")).unwrap();
            assert_eq!(counts_of(line), ours, "{extra:?}");
        }
    }
    // a given map on all scans; cross-validation covers every scan once
    let j = json(&ok(&["eval", f.p("a.bt"), f.p("s.graph"), "--json"]));
    assert_eq!(j["scans"], 6);
    assert_eq!(j["unknown"], 0); // the map was built from these scans
    assert!(j["accuracy"].as_f64().unwrap() > 0.9);
    let j = json(&ok(&["eval", f.p("s.graph"), "--folds", "3", "--json"]));
    assert_eq!(j["folds"].as_array().unwrap().len(), 3);
    assert_eq!(j["total"]["scans"], 6);

    fail(&["eval", f.p("s.graph"), "--holdout", "1"], "at least 2");
    fail(&["eval", f.p("s.graph"), "--res", "-0.1"], "--res: resolution -0.1 m is not a positive finite number");
    fail(&["eval", f.p("a.bt"), f.p("s.graph"), "--folds", "2"], "give only the .graph");
    fail(&["eval", f.p("a.bt")], "cannot read");
}

// ----- log2graph ---------------------------------------------------------------------

#[test]
fn log2graph_matches_octomap() {
    let f = Fixture::new();
    let one = f.write("one.log", "# one scan\nNODE 0.5 -1 0.25 0.1 0.2 0.3\n1 2 3\n4.5 5 -6\n0.1 0.2 0.3\n");
    ok(&["log2graph", one, f.p("one.graph")]);
    let mut text = String::from("# several\n");
    for n in 0..5 {
        text += &format!("NODE {} {} 0.2 0.01 -0.02 {}\n", n as f32 * 0.5, n as f32 * 0.1, n as f32 * 0.3);
        for i in 0..40 {
            text += &format!("{} {} {}\n", (i as f32) * 0.1 - 2.0, (n * i) as f32 * 0.01, 0.5);
        }
    }
    let many = f.write("many.log", &text);
    ok(&["log2graph", many, f.p("many.graph")]);
    let g = graph::read_file(f.path("many.graph")).unwrap();
    assert_eq!((g.nodes.len(), g.edges.len(), g.num_points()), (5, 4, 200));
    if let Some(t) = tool("log2graph") {
        oracle(&t, &[one, f.p("one_o.graph")]);
        assert_eq!(std::fs::read(f.path("one.graph")).unwrap(), std::fs::read(f.path("one_o.graph")).unwrap());
        // log2graph leaves node ids uninitialised: compare all else
        oracle(&t, &[many, f.p("many_o.graph")]);
        let o = graph::read_file(f.path("many_o.graph")).unwrap();
        assert_eq!(o.nodes.len(), g.nodes.len());
        for (a, b) in g.nodes.iter().zip(&o.nodes) {
            assert_eq!((a.pose, &a.scan), (b.pose, &b.scan));
        }
        for (a, b) in g.edges.iter().zip(&o.edges) {
            assert_eq!((a.constraint, a.weight), (b.constraint, b.weight));
        }
    }
    fail(&["log2graph", f.write("bad.log", "1 2 3\n"), f.p("x.graph")], "point before the first NODE");
    fail(&["log2graph", f.p("none.log"), f.p("x.graph")], "cannot open");
    fail(&["log2graph", one, "/nonexistent/dir/x.graph"], "cannot write /nonexistent/dir/x.graph");
}

// ----- binvox --------------------------------------------------------------------------

fn binvox(dim: [usize; 3], translate: &str, scale: &str, seed: u64) -> Vec<u8> {
    let mut state = seed;
    let mut next = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 33) as u32
    };
    let n = dim[0] * dim[1] * dim[2];
    let vals: Vec<u8> = (0..n).map(|_| u8::from(next() % 10 < 3)).collect();
    let mut out =
        format!("#binvox 1\ndim {} {} {}\ntranslate {translate}\nscale {scale}\ndata\n", dim[0], dim[1], dim[2])
            .into_bytes();
    let mut i = 0;
    while i < n {
        let mut k = 1;
        while i + k < n && vals[i + k] == vals[i] && k < 255 {
            k += 1;
        }
        out.extend([vals[i], k as u8]);
        i += k;
    }
    out
}

#[test]
fn binvox_matches_binvox2bt_bytes() {
    let f = Fixture::new();
    let input = f.write("t.binvox", binvox([12, 10, 8], "-0.37 0.11 1.5", "2.4", 1));
    let options: [&[&str]; 5] = [
        &[],
        &["--mark-free"],
        &["--rotate"],
        &["--offset", "1", "2", "-3"],
        &["--bb", "-0.2", "0", "1.6", "1", "1", "3"],
    ];
    for opts in options {
        let mut args = vec!["binvox", input, "-o", f.p("ours.bt"), "--json"];
        args.extend(opts);
        let j = json(&ok(&args));
        let res = j["resolution"].as_f64().unwrap();
        assert!((res - f64::from(2.4f32) / 12.0).abs() < 1e-15, "{res}");
        let t = read_tree(f.p("ours.bt"));
        assert!(t.num_leaves() > 0);
        if let Some(tool) = tool("binvox2bt") {
            let mut oargs = vec!["-o", f.p("theirs.bt")];
            oargs.extend(opts);
            oargs.push(input);
            oracle(&tool, &oargs);
            assert_eq!(
                std::fs::read(f.path("ours.bt")).unwrap(),
                std::fs::read(f.path("theirs.bt")).unwrap(),
                "{opts:?}"
            );
        }
    }
    // default output name: input + .bt
    ok(&["binvox", input]);
    assert!(f.path("t.binvox.bt").exists());

    let good = binvox([4, 5, 6], "0 0 0", "1", 2);
    fail(&["binvox", f.write("trunc.binvox", &good[..good.len() - 4])], "data ends after");
    fail(&["binvox", f.write("hdr.binvox", "#notbinvox 1\n")], "instead of \"#binvox\"");
    fail(&["binvox", f.write("nodim.binvox", "#binvox 1\nscale 1\ndata\n")], "no \"dim\"");
    fail(&["binvox", f.p("absent.binvox")], "cannot open");
    fail(&["binvox", input, "--bb", "1", "0", "0", "0", "1", "1"], "--bb needs");
}

// ----- a known scene: one wall ---------------------------------------------------------

/// Points on the plane x = 2.05 for y in [-1, 1], z in [0, 1]: a wall
/// one voxel thick seen from the origin.
fn wall(f: &Fixture) -> &str {
    let mut text = String::new();
    for iy in 0..=40 {
        for iz in 0..=20 {
            text += &format!("2.05 {} {}\n", -1.0 + 0.05 * f64::from(iy), 0.05 * f64::from(iz));
        }
    }
    let xyz = f.write("wall.xyz", text);
    ok(&["build", "--points", xyz, "-o", f.p("wall.bt"), "--res", "0.1"]);
    f.p("wall.bt")
}

#[test]
fn raycast_reports_outcomes() {
    let f = Fixture::new();
    let map = wall(&f);
    let j = json(&ok(&["raycast", map, "--origin", "0.05", "0.05", "0.05", "--direction", "1", "0", "0", "--json"]));
    assert_eq!(j["outcome"], "occupied");
    assert_eq!(j["hit"], true);
    let end = j["end"].as_array().unwrap();
    assert!((end[0].as_f64().unwrap() - 2.05).abs() < 1e-6);
    let j = json(&ok(&["raycast", map, "--origin", "0.05", "0.05", "0.05", "--direction", "-1", "0", "0", "--json"]));
    assert_eq!(j["outcome"], "unknown");
    let j = json(&ok(&[
        "raycast",
        map,
        "--origin",
        "0.05",
        "0.05",
        "0.05",
        "--direction",
        "-1",
        "0",
        "0",
        "--ignore-unknown",
        "--max-range",
        "3",
        "--json",
    ]));
    assert_eq!(j["outcome"], "max_range");
    let j = json(&ok(&[
        "raycast",
        map,
        "--origin",
        "0.05",
        "0.05",
        "0.05",
        "--direction",
        "1",
        "0",
        "0",
        "--max-range",
        "1",
        "--json",
    ]));
    assert_eq!(j["outcome"], "max_range");
    let text = ok(&["raycast", map, "--origin", "0.05", "0.05", "0.05", "--direction", "1", "0", "0"]);
    assert!(text.starts_with("occupied at 2.05 "), "{text}");

    fail(&["raycast", map, "--origin", "0", "0", "0", "--direction", "0", "0", "0"], "zero vector");
    fail(&["raycast", map, "--origin", "1e9", "0", "0", "--direction", "1", "0", "0"], "cannot cast the ray");
    fail(
        &["raycast", map, "--origin", "0", "0", "0", "--direction", "1", "0", "0", "--max-range", "-2"],
        "--max-range",
    );
}

fn png_pixels(path: &Path) -> (u32, u32, Vec<u8>) {
    let d = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = d.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

fn brightness(img: &(u32, u32, Vec<u8>), x: u32, y: u32) -> u32 {
    let i = 3 * (y * img.0 + x) as usize;
    img.2[i..i + 3].iter().map(|&c| u32::from(c)).max().unwrap()
}

#[test]
fn render_draws_the_wall() {
    let f = Fixture::new();
    let map = wall(&f);
    // top view with free space: frame = all known leaves
    ok(&["render", map, "-o", f.p("top.png"), "--free", "--width", "100", "--height", "100"]);
    let img = png_pixels(&f.path("top.png"));
    assert_eq!((img.0, img.1), (100, 100));
    let info = json(&ok(&["info", map, "--json"]));
    let (lo, hi) = (&info["bounds_min"], &info["bounds_max"]);
    let b = |v: &serde_json::Value, i: usize| v[i].as_f64().unwrap();
    let s = ((b(hi, 0) - b(lo, 0)) / 100.0).max((b(hi, 1) - b(lo, 1)) / 100.0);
    let (cx, cy) = ((b(lo, 0) + b(hi, 0)) / 2.0, (b(lo, 1) + b(hi, 1)) / 2.0);
    let pixel = |x: f64, y: f64| -> (u32, u32) { (((x - cx) / s + 50.0) as u32, ((cy - y) / s + 50.0) as u32) };
    let colour = |x: f64, y: f64| {
        let (px, py) = pixel(x, y);
        let i = 3 * (py * 100 + px) as usize;
        [img.2[i], img.2[i + 1], img.2[i + 2]]
    };
    // the wall column is lit in every row it spans
    for k in 0..20 {
        let y = -0.95 + 0.1 * f64::from(k);
        let c = colour(2.05, y);
        assert!(c.iter().any(|&v| v >= 200), "wall at y={y}: {c:?}");
    }
    assert_eq!(colour(1.0, 0.0), [70, 84, 110]); // free
    assert_eq!(colour(0.3, 0.9), [16, 16, 16]); // unknown
                                                // without --free only occupied pixels are lit
    ok(&["render", map, "-o", f.p("occ.png"), "--width", "40"]);
    let occ = png_pixels(&f.path("occ.png"));
    assert!(occ.1 > occ.0); // the wall is taller (in y) than wide
    for y in 0..occ.1 {
        assert!(brightness(&occ, occ.0 / 2, y) >= 200, "wall row {y}");
        assert_eq!(brightness(&occ, 0, y), 16);
        assert_eq!(brightness(&occ, occ.0 - 1, y), 16);
    }

    // perspective: looking at the wall from the origin
    ok(&[
        "render",
        map,
        "-o",
        f.p("p.png"),
        "--view",
        "perspective",
        "--camera",
        "0",
        "0",
        "0.5",
        "--look-at",
        "2",
        "0",
        "0.5",
        "--width",
        "64",
        "--height",
        "48",
    ]);
    let p = png_pixels(&f.path("p.png"));
    assert_eq!((p.0, p.1), (64, 48));
    // a block around the centre hits the wall face-on: bright
    for y in 20..28 {
        for x in 24..40 {
            assert!(brightness(&p, x, y) >= 100, "centre pixel {x},{y} dark");
        }
    }
    // above the wall top (z = 1.1) and beyond its sides: background
    for x in 0..64 {
        assert_eq!(brightness(&p, x, 0), 16, "top row {x}");
        assert_eq!(brightness(&p, x, 47), 16, "bottom row {x}");
    }
    for y in 0..48 {
        assert_eq!(brightness(&p, 0, y), 16);
        assert_eq!(brightness(&p, 63, y), 16);
    }
    // a coarser level draws bigger blocks: the lit area grows
    let lit_count =
        |img: &(u32, u32, Vec<u8>)| (0..img.0 * img.1).filter(|&i| brightness(img, i % img.0, i / img.0) > 16).count();
    let mut coarse_args = vec![
        "render",
        map,
        "-o",
        f.p("p12.png"),
        "--view",
        "perspective",
        "--camera",
        "0",
        "0",
        "0.5",
        "--look-at",
        "2",
        "0",
        "0.5",
        "--width",
        "64",
        "--height",
        "48",
        "--depth",
        "12",
    ];
    ok(&coarse_args);
    let c = png_pixels(&f.path("p12.png"));
    assert!(brightness(&c, 32, 24) >= 100);
    assert!(lit_count(&c) > lit_count(&p), "{} vs {}", lit_count(&c), lit_count(&p));
    coarse_args.push("--free");
    fail(&coarse_args, "--free applies to --view top only");
    // auto camera sees something
    ok(&["render", map, "-o", f.p("auto.png"), "--view", "perspective", "--width", "48"]);
    let a = png_pixels(&f.path("auto.png"));
    let lit = (0..a.0 * a.1).filter(|&i| brightness(&a, i % a.0, i / a.0) > 16).count();
    assert!(lit > 20, "{lit}");

    fail(&["render", map, "-o", f.p("x.jpg")], "unknown format");
    fail(&["render", map, "-o", f.p("x.png"), "--width", "0"], "--width and --height");
    fail(&["render", map, "-o", f.p("x.png"), "--view", "perspective", "--fov", "200"], "--fov");
    fail(
        &[
            "render",
            map,
            "-o",
            f.p("x.png"),
            "--view",
            "perspective",
            "--camera",
            "2",
            "0",
            "0.5",
            "--look-at",
            "2",
            "0",
            "0.5",
        ],
        "same point",
    );
    fail(&["render", map, "-o", "/nonexistent/dir/x.png"], "cannot write");
    fail_usage(&["render", map, "-o", f.p("x.png"), "--view", "side"], "side");
}

// ----- mesh ----------------------------------------------------------------------

fn ply_counts(path: &Path) -> (u64, u64) {
    let text = std::fs::read(path).unwrap();
    let text = String::from_utf8_lossy(&text);
    let count = |el: &str| -> u64 {
        let l = text.lines().find(|l| l.starts_with(&format!("element {el} "))).unwrap();
        l.rsplit(' ').next().unwrap().parse().unwrap()
    };
    (count("vertex"), count("face"))
}

#[test]
fn mesh_exports_cubes_with_hidden_faces_culled() {
    let f = Fixture::new();
    let one = f.write("one.xyz", "2.05 0.05 0.05\n");
    ok(&["build", "--points", one, "-o", f.p("one.bt")]);
    ok(&["mesh", f.p("one.bt"), "-o", f.p("one.ply"), "--ascii"]);
    assert_eq!(ply_counts(&f.path("one.ply")), (8, 6));
    let text = std::fs::read_to_string(f.path("one.ply")).unwrap();
    let body: Vec<&str> = text.split("end_header\n").nth(1).unwrap().lines().collect();
    assert_eq!(body.len(), 14);
    assert!(body[0].starts_with("2 0 0 ")); // corner (2.0, 0.0, 0.0)
    assert!(body[8].starts_with("4 0 4 6 2"));
    let two = f.write("two.xyz", "2.05 0.05 0.05\n2.05 0.15 0.05\n");
    ok(&["build", "--points", two, "-o", f.p("two.bt")]);
    ok(&["mesh", f.p("two.bt"), "-o", f.p("two.ply")]);
    assert_eq!(ply_counts(&f.path("two.ply")), (16, 10));
    ok(&["mesh", f.p("two.bt"), "-o", f.p("all.ply"), "--all-faces"]);
    assert_eq!(ply_counts(&f.path("all.ply")), (16, 12));
    // binary size: header + 15 bytes per vertex + 17 per face
    let b = std::fs::read(f.path("two.ply")).unwrap();
    let text = String::from_utf8_lossy(&b);
    let header = text.find("end_header\n").unwrap() + 11;
    assert_eq!(b.len() - header, 16 * 15 + 10 * 17);
    // the simulated map
    ok(&["mesh", f.p("a.bt"), "-o", f.p("a.ply"), "--depth", "15"]);
    let (v, faces) = ply_counts(&f.path("a.ply"));
    assert!(v > 0 && faces > 0);

    fail(&["mesh", f.p("a.bt"), "-o", f.p("a.stl")], "unknown format");
    fail(&["mesh", f.p("a.bt"), "-o", f.p("a.ply"), "--depth", "99"], "--depth must be");
}

// ----- build from point cloud files --------------------------------------------------------

/// Points exactly representable in every format (multiples of 1/8).
fn cloud() -> Vec<[f32; 3]> {
    let mut v = Vec::new();
    for i in 0..300u32 {
        let a = f64::from(i) * 0.37;
        let r = 2.0 + f64::from(i % 7) * 0.5;
        let q = |x: f64| ((x * 8.0).round() / 8.0) as f32;
        v.push([q(r * a.cos()), q(r * a.sin()), q(f64::from(i % 13) * 0.125 - 0.5)]);
    }
    v
}

fn write_cloud_files(f: &Fixture, pts: &[[f32; 3]]) -> Vec<PathBuf> {
    let n = pts.len();
    let mut files = Vec::new();
    let mut add = |name: &str, bytes: Vec<u8>| {
        f.write(name, bytes);
        files.push(f.path(name));
    };
    let text: String = pts.iter().map(|p| format!("{} {} {}\n", p[0], p[1], p[2])).collect();
    add("c.xyz", text.clone().into_bytes());
    // PLY ascii with an extra property and a face element after the vertices
    let mut ply = format!(
        "ply\nformat ascii 1.0\ncomment test\nelement vertex {n}\nproperty float x\nproperty float y\n\
         property float z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
    );
    for p in pts {
        ply += &format!("{} {} {} 7\n", p[0], p[1], p[2]);
    }
    ply += "3 0 1 2\n";
    add("c_ascii.ply", ply.into_bytes());
    // binary little endian, double coordinates, with an element before the vertices
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\nelement camera 1\nproperty list uchar float k\nproperty int id\n\
         element vertex {n}\nproperty uchar flag\nproperty double x\nproperty double y\nproperty double z\nend_header\n"
    )
    .into_bytes();
    b.push(2);
    b.extend(1.5f32.to_le_bytes());
    b.extend(2.5f32.to_le_bytes());
    b.extend(9i32.to_le_bytes());
    for p in pts {
        b.push(1);
        for c in p {
            b.extend(f64::from(*c).to_le_bytes());
        }
    }
    add("c_le.ply", b);
    let mut b = format!(
        "ply\nformat binary_big_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    )
    .into_bytes();
    for p in pts {
        for c in p {
            b.extend(c.to_be_bytes());
        }
    }
    add("c_be.ply", b);
    // PCD: ascii, binary with an extra field, binary_compressed
    let head = |fields: &str, size: &str, ty: &str, count: &str, data: &str| {
        format!(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {ty}\nCOUNT {count}\nWIDTH {n}\nHEIGHT 1\n\
             VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
        )
    };
    add("c_ascii.pcd", (head("x y z", "4 4 4", "F F F", "1 1 1", "ascii") + &text).into_bytes());
    let mut b = head("x y z rgb", "4 4 4 4", "F F F U", "1 1 1 1", "binary").into_bytes();
    for p in pts {
        for c in p {
            b.extend(c.to_le_bytes());
        }
        b.extend(0x00ff_8040u32.to_le_bytes());
    }
    add("c_bin.pcd", b);
    let mut raw = Vec::new();
    for axis in 0..3 {
        for p in pts {
            raw.extend(p[axis].to_le_bytes());
        }
    }
    let comp = lzf_compress(&raw);
    assert!(comp.len() < raw.len());
    let mut b = head("x y z", "4 4 4", "F F F", "1 1 1", "binary_compressed").into_bytes();
    b.extend((comp.len() as u32).to_le_bytes());
    b.extend((raw.len() as u32).to_le_bytes());
    b.extend(&comp);
    add("c_comp.pcd", b);
    // LAS and LAZ through the las crate
    for ext in ["las", "laz"] {
        let mut builder = las::Builder::from((1, 2));
        let t = las::Transform { scale: 0.125, offset: 0.0 };
        builder.transforms = las::Vector { x: t, y: t, z: t };
        let header = builder.into_header().unwrap();
        let path = f.path(&format!("c.{ext}"));
        let mut w = las::Writer::from_path(&path, header).unwrap();
        for p in pts {
            w.write_point(las::Point {
                x: f64::from(p[0]),
                y: f64::from(p[1]),
                z: f64::from(p[2]),
                ..Default::default()
            })
            .unwrap();
        }
        w.close().unwrap();
        drop(w);
        files.push(path);
    }
    files
}

/// Two damaged LAZ files found by mutating a small one: the laz crate once
/// reserved a chunk table of 2^32 entries (aborting the process) for the
/// first and panicked in its byte slicing on the second.
fn damaged_laz_files_fail_cleanly(f: &Fixture) {
    let mut builder = las::Builder::from((1, 2));
    let t = las::Transform { scale: 0.125, offset: 0.0 };
    builder.transforms = las::Vector { x: t, y: t, z: t };
    builder.point_format.is_compressed = true;
    let path = f.path("m.laz");
    let mut w = las::Writer::from_path(&path, builder.into_header().unwrap()).unwrap();
    for i in 0..50 {
        w.write_point(las::Point { x: f64::from(i), y: 1.0, z: 2.0, ..Default::default() }).unwrap();
    }
    w.close().unwrap();
    drop(w);
    let good = std::fs::read(&path).unwrap();
    assert_eq!(good.len(), 451, "the writer's output changed; find new damaging mutations");
    let mut chunks = good.clone();
    // the chunk table's offset is the first 8 bytes of the point data
    let data = u32::from_le_bytes(good[96..100].try_into().unwrap()) as usize;
    let table = i64::from_le_bytes(good[data..data + 8].try_into().unwrap()) as usize;
    chunks[table + 4..table + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    fail(&["build", "--points", f.write("chunks.laz", chunks), "-o", f.p("x.bt")], "chunk table announces");
    let mut sliced = good;
    (sliced[50], sliced[317]) = (153, 7);
    let out = run(&["build", "--points", f.write("sliced.laz", sliced), "-o", f.p("x.bt")]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.trim_end().lines().count() == 1, "{err}");
    assert!(err.contains("not a valid .laz file") && !err.contains("panicked"), "{err}");
}

#[test]
fn build_reads_point_cloud_formats_with_poses() {
    let f = Fixture::new();
    let pts = cloud();
    let files = write_cloud_files(&f, &pts);
    let pose = ["0.5", "-0.25", "0.125", "0", "0.25", "0.5"];
    // the reference: a .graph with the same scan and pose, via log2graph
    let mut log = format!("NODE {}\n", pose.join(" "));
    for p in &pts {
        log += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    ok(&["log2graph", f.write("c.log", log), f.p("c.graph")]);
    ok(&["build", f.p("c.graph"), "-o", f.p("ref.ot")]);
    let reference = std::fs::read(f.path("ref.ot")).unwrap();
    for file in &files {
        let mut args = vec!["build", "--points", s(file), "-o", f.p("p.ot"), "--pose"];
        args.extend(pose);
        ok(&args);
        assert!(std::fs::read(f.path("p.ot")).unwrap() == reference, "{}", file.display());
    }
    // a trajectory: one pose per file, same as a two-node graph
    let pose2 = ["-1", "0.5", "0", "0.125", "0", "-0.75"];
    f.write("traj.txt", format!("# x y z roll pitch yaw\n{}\n\n{}\n", pose.join(" "), pose2.join(" ")));
    let mut log2 = format!("NODE {}\n", pose.join(" "));
    for p in &pts {
        log2 += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    log2 += &format!("NODE {}\n", pose2.join(" "));
    for p in &pts[..100] {
        log2 += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    let part: String = pts[..100].iter().map(|p| format!("{} {} {}\n", p[0], p[1], p[2])).collect();
    let second = f.write("part.xyz", part);
    ok(&["log2graph", f.write("c2.log", log2), f.p("c2.graph")]);
    ok(&["build", f.p("c2.graph"), "-o", f.p("ref2.bt")]);
    let j = json(&ok(&[
        "build",
        "--points",
        s(&files[3]),
        second,
        "--trajectory",
        f.p("traj.txt"),
        "-o",
        f.p("t.bt"),
        "--json",
    ]));
    assert_eq!(j["scans"], 2);
    assert_eq!(j["points"], 400);
    assert_eq!(std::fs::read(f.path("t.bt")).unwrap(), std::fs::read(f.path("ref2.bt")).unwrap());
    // without a pose: identity, rays from the origin
    ok(&["build", "--points", s(&files[0]), "-o", f.p("id.bt")]);
    let t = read_tree(f.p("id.bt"));
    let p = Point3::from_array(pts[0]);
    assert!(t.is_occupied(t.search_point(p, 0).unwrap().unwrap().value));

    // errors
    fail(&["build", "--points", s(&files[0]), "-o", f.p("x.bt"), "--trajectory", f.p("traj.txt")], "has 2 poses for 1");
    fail(&["build", "--points", f.write("x.obj", "v 1 2 3\n"), "-o", f.p("x.bt")], "unknown format");
    let ply = std::fs::read(&files[2]).unwrap();
    fail(&["build", "--points", f.write("t.ply", &ply[..ply.len() - 5]), "-o", f.p("x.bt")], "data ends in vertex");
    fail(
        &["build", "--points", f.write("h.ply", "ply\nformat ascii 1.0\nelement vertex 1\n"), "-o", f.p("x.bt")],
        "no \"end_header\"",
    );
    fail(
        &[
            "build",
            "--points",
            f.write("n.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n"),
            "-o",
            f.p("x.bt"),
        ],
        "no y field",
    );
    let pcd = std::fs::read(&files[6]).unwrap();
    fail(
        &["build", "--points", f.write("t.pcd", &pcd[..pcd.len() - 7]), "-o", f.p("x.bt")],
        "compressed data is shorter",
    );
    let mut bad = pcd.clone();
    let at = bad.len() - 3;
    bad[at - 40] = 0xff; // a back reference before the start, or a wrong length
    let out = run(&["build", "--points", f.write("b.pcd", &bad), "-o", f.p("x.bt")]);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("panicked"));
    let bin = std::fs::read(&files[5]).unwrap();
    fail(&["build", "--points", f.write("tb.pcd", &bin[..bin.len() - 3]), "-o", f.p("x.bt")], "binary data holds");
    fail(
        &[
            "build",
            "--points",
            f.write("k.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA zip\n"),
            "-o",
            f.p("x.bt"),
        ],
        "unknown DATA kind",
    );
    fail(&["build", "--points", f.write("t.las", b"LASF-not-really"), "-o", f.p("x.bt")], "not a valid .las file");
    damaged_laz_files_fail_cleanly(&f);
    fail(&["build", "--points", f.p("missing.ply"), "-o", f.p("x.bt")], "cannot open");
    fail(
        &["build", "--points", s(&files[0]), "-o", f.p("x.bt"), "--pose", "0", "0", "0", "0", "0", "inf"],
        "six finite numbers",
    );
    fail(
        &["build", "--points", s(&files[0]), "-o", f.p("x.bt"), "--trajectory", f.write("tj.txt", "1 2 3\n")],
        "line 1",
    );
    fail_usage(&["build", f.p("s.graph"), "--points", s(&files[0]), "-o", f.p("x.bt")], "cannot be used with");
    fail_usage(&["build", "-o", f.p("x.bt")], "required");
}

fn colors_of(pts: &[[f32; 3]]) -> Vec<[u8; 3]> {
    (0..pts.len()).map(|i| [(i * 37 % 256) as u8, (i * 91 % 256) as u8, (i * 13 % 256) as u8]).collect()
}

/// The same coloured scan in every colour encoding `build --color` reads.
fn write_colored_files(f: &Fixture, pts: &[[f32; 3]], cols: &[[u8; 3]]) -> Vec<PathBuf> {
    let n = pts.len();
    let mut files = Vec::new();
    let mut add = |name: &str, bytes: Vec<u8>| {
        f.write(name, bytes);
        files.push(f.path(name));
    };
    // PLY ascii, uchar colours between other properties, a face element after
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty uchar blue\nproperty float y\n\
         property float z\nproperty uchar green\nproperty float nx\nproperty uchar red\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    );
    for (p, c) in pts.iter().zip(cols) {
        ply += &format!("{} {} {} {} {} 0.5 {}\n", p[0], c[2], p[1], p[2], c[1], c[0]);
    }
    ply += "3 0 1 2\n";
    add("k_ascii.ply", ply.into_bytes());
    // PLY big endian, ushort colours
    let mut b = format!(
        "ply\nformat binary_big_endian 1.0\nelement vertex {n}\nproperty ushort red\nproperty ushort green\n\
         property ushort blue\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    )
    .into_bytes();
    for (p, c) in pts.iter().zip(cols) {
        for v in c {
            b.extend(u16::from(*v).to_be_bytes());
        }
        for v in p {
            b.extend(v.to_be_bytes());
        }
    }
    add("k_be.ply", b);
    // PLY little endian, float colours in 0..1, a list before them
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty double x\nproperty double y\n\
         property double z\nproperty list uchar int idx\nproperty float red\nproperty float green\nproperty float blue\n\
         end_header\n"
    )
    .into_bytes();
    for (p, c) in pts.iter().zip(cols) {
        for v in p {
            b.extend(f64::from(*v).to_le_bytes());
        }
        b.push(2);
        b.extend(7i32.to_le_bytes());
        b.extend(8i32.to_le_bytes());
        for v in c {
            b.extend((f32::from(*v) / 255.0).to_le_bytes());
        }
    }
    add("k_le.ply", b);
    let packed =
        |c: &[u8; 3], alpha: u32| (alpha << 24) | (u32::from(c[0]) << 16) | (u32::from(c[1]) << 8) | u32::from(c[2]);
    let head = |fields: &str, size: &str, ty: &str, data: &str| {
        format!(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {ty}\nCOUNT 1 1 1 1\nWIDTH {n}\nHEIGHT 1\n\
             VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
        )
    };
    // PCD ascii: rgb as the float PCL prints (the packed bits), and as U
    let mut t = head("x y z rgb", "4 4 4 4", "F F F F", "ascii");
    let mut u = head("x y rgb z", "4 4 4 4", "F F U F", "ascii");
    for (p, c) in pts.iter().zip(cols) {
        t += &format!("{} {} {} {:e}\n", p[0], p[1], p[2], f32::from_bits(packed(c, 0)));
        u += &format!("{} {} {} {}\n", p[0], p[1], packed(c, 0x7f), p[2]);
    }
    add("k_f.pcd", t.into_bytes());
    add("k_u.pcd", u.into_bytes());
    // PCD binary, rgb typed F
    let mut b = head("x y z rgb", "4 4 4 4", "F F F F", "binary").into_bytes();
    for (p, c) in pts.iter().zip(cols) {
        for v in p {
            b.extend(v.to_le_bytes());
        }
        b.extend(packed(c, 0).to_le_bytes());
    }
    add("k_bin.pcd", b);
    // PCD binary_compressed, rgba with alpha
    let mut raw = Vec::new();
    for axis in 0..3 {
        for p in pts {
            raw.extend(p[axis].to_le_bytes());
        }
    }
    for c in cols {
        raw.extend(packed(c, 0xff).to_le_bytes());
    }
    let comp = lzf_compress(&raw);
    let mut b = head("x y z rgba", "4 4 4 4", "F F F U", "binary_compressed").into_bytes();
    b.extend((comp.len() as u32).to_le_bytes());
    b.extend((raw.len() as u32).to_le_bytes());
    b.extend(&comp);
    add("k_comp.pcd", b);
    files
}

#[test]
fn build_color_reads_ply_and_pcd_colours() {
    let f = Fixture::new();
    let pts = cloud();
    let cols = colors_of(&pts);
    let files = write_colored_files(&f, &pts, &cols);
    let pose = ["0.5", "-0.25", "0.125", "0", "0.25", "0.5"];
    // the reference, through the library: insertPointCloud, integrateNodeColor
    // per point, updateInnerOccupancy (graph2tree's sensor model, read back)
    let mut g = graph::ScanGraph::new();
    let cloud = octolinear::PointCloud { points: pts.iter().map(|p| Point3::from_array(*p)).collect() };
    let pose6 = octolinear::Pose6D::from_euler(0.5, -0.25, 0.125, 0.0, 0.25, 0.5);
    g.add_node(cloud, pose6);
    let (world, origin) = g.nodes[0].graph2tree();
    let sensor = octolinear::SensorModel::from_probabilities(&octolinear::SensorProbabilities {
        occupancy_threshold: 0.5,
        ..octolinear::SensorModel::default().probabilities()
    })
    .unwrap();
    let mut t = OccupancyTree::with_kind(0.1, sensor, octolinear::NodeKind::Color).unwrap();
    t.insert_point_cloud(&world.points, origin, &Default::default()).unwrap();
    for (p, c) in world.points.iter().zip(&cols) {
        let k = t.key(*p).unwrap();
        t.integrate_color(k, *c);
    }
    t.update_inner_occupancy();
    let mut reference = Vec::new();
    ot::write(&t, &mut reference).unwrap();
    assert!(reference.windows(16).any(|w| w == b"\nid ColorOcTree\n"));
    for file in &files {
        let mut args = vec!["build", "--color", "--points", s(file), "-o", f.p("k.ot"), "--pose"];
        args.extend(pose);
        let j = json(&ok(&[&args[..], &["--json"]].concat()));
        assert_eq!(j["tree_type"], "ColorOcTree");
        assert!(std::fs::read(f.path("k.ot")).unwrap() == reference, "{}", file.display());
    }
    // the colour of a lone point's voxel is the point's colour
    let lone = f.write(
        "lone.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n1.05 0.25 -0.35 12 200 7\n",
    );
    ok(&["build", "--color", "--points", lone, "-o", f.p("lone.ot")]);
    let t = read_tree(f.p("lone.ot"));
    let found = t.search_point(Point3::new(1.05, 0.25, -0.35), 0).unwrap().unwrap();
    assert!(t.is_occupied(found.value));
    assert_eq!(octolinear::tree::unpack_rgb(found.extra), [12, 200, 7]);
    // .ot (ColorOcTree) -> .olm -> .ot gives the same bytes; query shows colours
    ok(&["convert", f.p("k.ot"), f.p("k.olm")]);
    ok(&["verify", f.p("k.olm")]);
    ok(&["convert", f.p("k.olm"), f.p("k2.ot")]);
    assert!(std::fs::read(f.path("k2.ot")).unwrap() == reference);
    ok(&["build", "--color", "--points", s(&files[0]), "-o", f.p("direct.olm"), "--pose"]
        .iter()
        .chain(&pose)
        .copied()
        .collect::<Vec<_>>());
    assert_eq!(std::fs::read(f.path("direct.olm")).unwrap(), std::fs::read(f.path("k.olm")).unwrap());
    let q = f.write(
        "q.xyz",
        "1.05 0.25 -0.35
100 100 100
",
    );
    for map in ["lone.ot", "lone.olm"] {
        if map == "lone.olm" {
            ok(&["convert", f.p("lone.ot"), f.p("lone.olm")]);
        }
        let out = ok(&["query", f.p(map), "--points", q]);
        let lines: Vec<&str> = out.lines().collect();
        assert!(lines[0].starts_with("1.05,0.25,-0.35,occupied,") && lines[0].ends_with(",12,200,7"), "{map}: {out}");
        assert_eq!(lines[1], "100,100,100,unknown,,,,", "{map}");
    }
    // without --color the same files build the plain map
    ok(&["build", "--points", s(&files[0]), "-o", f.p("plain.ot")]);
    assert!(read_tree(f.p("plain.ot")).kind() == octolinear::NodeKind::Plain);

    // errors
    fail(&["build", "--color", "--points", s(&files[0]), "-o", f.p("k.bt")], "a colour map needs .ot or .olm");
    let xyz = f.write("k.xyz", "1 2 3\n");
    fail(&["build", "--color", "--points", xyz, "-o", f.p("k.ot")], "--color needs colours");
    let red_only = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                    property uchar red\nend_header\n1 2 3 4\n";
    fail(&["build", "--color", "--points", f.write("r.ply", red_only), "-o", f.p("k.ot")], "this file has none");
    let big = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
               property ushort red\nproperty ushort green\nproperty ushort blue\nend_header\n1 2 3 4 300 5\n";
    fail(&["build", "--color", "--points", f.write("big.ply", big), "-o", f.p("k.ot")], "vertex 0 green: colour 300");
    ok(&["build", "--points", f.p("big.ply"), "-o", f.p("k.ot")]);
    let fl = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
              property float red\nproperty float green\nproperty float blue\nend_header\n1 2 3 0.5 1.5 0\n";
    fail(
        &["build", "--color", "--points", f.write("fl.ply", fl), "-o", f.p("k.ot")],
        "float colour 1.5 is outside 0..1",
    );
    let short = "FIELDS x y z rgb\nSIZE 4 4 4 2\nTYPE F F F U\nPOINTS 1\nDATA ascii\n1 2 3 4\n";
    fail(&["build", "--color", "--points", f.write("s.pcd", short), "-o", f.p("k.ot")], "needs SIZE 4 COUNT 1");
    let nan = "FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nPOINTS 1\nDATA ascii\n1 2 3 nan\n";
    fail(&["build", "--color", "--points", f.write("n.pcd", nan), "-o", f.p("k.ot")], "point 0: cannot read rgb");
    fail(&["build", f.p("s.graph"), "--color", "-o", f.p("k.ot")], "--color needs --points");
}

// ----- errors shared by every map reader and the build flags ------------------------------------

#[test]
fn user_errors_are_one_line_without_panics() {
    let f = Fixture::new();
    let a = f.p("a.bt");
    // missing files and wrong extensions
    for cmd in ["info", "to-points", "mesh", "render"] {
        let mut args = vec![cmd, f.p("missing.bt")];
        match cmd {
            "to-points" => args.push(f.p("o.xyz")),
            "mesh" => args.extend(["-o", f.p("o.ply")]),
            "render" => args.extend(["-o", f.p("o.png")]),
            _ => {}
        }
        fail(&args, "cannot open");
    }
    fail(&["compare", a, f.p("missing.ot")], "cannot open");
    fail(&["compare", a, f.write("m.map", "x")], "unknown map format");
    fail(&["convert", a, f.p("out.pcd")], "unknown map format");
    // truncated and corrupt maps
    let bytes = std::fs::read(a).unwrap();
    let cut = f.write("cut.bt", &bytes[..bytes.len() / 2]);
    fail(&["info", cut], "not a valid .bt map");
    fail(&["compare", a, cut], "not a valid .bt map");
    fail(&["raycast", cut, "--origin", "0", "0", "0", "--direction", "1", "0", "0"], "not a valid .bt map");
    let ot_bytes = std::fs::read(f.path("a.ot")).unwrap();
    fail(&["edit", f.write("cut.ot", &ot_bytes[..ot_bytes.len() - 9]), f.p("e.ot")], "not a valid .ot map");
    fail(&["info", f.write("text.bt", "hello\n")], "not a valid .bt map");
    // build flag values
    let g = f.p("s.graph");
    fail(&["build", g, "-o", f.p("x.bt"), "--res", "-0.1"], "resolution");
    fail(&["build", g, "-o", f.p("x.bt"), "--clamping", "0.1", "1.5"], "clamping");
    fail(&["build", g, "-o", f.p("x.bt"), "--sensor", "0.8", "0.3"], "sensor model");
    fail(&["build", g, "-o", "/nonexistent/dir/out.bt"], "cannot write /nonexistent/dir/out.bt");
    fail(&["build", f.write("t.graph", &std::fs::read(g).unwrap()[..100]), "-o", f.p("x.bt")], "cannot read");
    fail_usage(&["build", g, "-o", f.p("x.bt"), "--res", "abc"], "abc");
    // unwritable outputs everywhere
    for args in [
        vec!["edit", a, "/nonexistent/dir/e.bt"],
        vec!["crop", a, "/nonexistent/dir/e.bt", "--min", "0", "0", "0", "--max", "1", "1", "1"],
        vec!["to-points", a, "/nonexistent/dir/p.xyz"],
        vec!["mesh", a, "-o", "/nonexistent/dir/m.ply"],
        vec!["convert", a, "/nonexistent/dir/c.ot"],
    ] {
        fail(&args, "cannot write /nonexistent/dir/");
    }
    // output to a directory path names no file
    fail(&["convert", a, f.dir.path().to_str().unwrap()], "unknown map format");
}

#[test]
fn olm_maps_convert_verify_and_answer_queries_like_the_source() {
    let f = Fixture::new();
    ok(&["convert", f.p("a.ot"), f.p("a.olm")]);
    assert!(ok(&["verify", f.p("a.olm")]).contains(": ok"));
    ok(&["convert", f.p("a.olm"), f.p("back.ot")]);
    assert_eq!(std::fs::read(f.path("a.ot")).unwrap(), std::fs::read(f.path("back.ot")).unwrap());
    let tree = read_tree(f.p("a.ot"));
    let mut pts = String::new();
    for (i, leaf) in tree.leaves(0).enumerate().filter(|(i, _)| i % 97 == 0) {
        let c = leaf.center_point();
        pts.push_str(&format!("{} {} {}\n", c.x, c.y, c.z + (i % 3) as f32 * 7.0));
        if i % 5 == 0 {
            pts.push_str("1e9 0 0\n"); // outside the map: unknown, between answered points
        }
    }
    let points = f.write("q.xyz", pts);
    let from_ot = ok(&["query", f.p("a.ot"), "--points", points]);
    // each line answers its own point, as one search after another would
    let cloud = octolinear::formats::xyz::read_file(std::path::Path::new(points)).unwrap();
    assert_eq!(from_ot.lines().count(), cloud.points.len());
    for (line, p) in from_ot.lines().zip(&cloud.points) {
        let expected = match tree.search_point(*p, 0) {
            Ok(Some(found)) if tree.is_occupied(found.value) => format!("occupied,{:08x}", found.value.to_bits()),
            Ok(Some(found)) => format!("free,{:08x}", found.value.to_bits()),
            _ => "unknown,".to_string(),
        };
        assert!(line.ends_with(&expected), "{line}: expected {expected}");
    }
    assert_eq!(ok(&["query", f.p("a.olm"), "--points", points]), from_ot);
    assert!(from_ot.contains(",occupied,") && from_ot.contains(",free,") && from_ot.contains(",unknown,"));
    // --search-blocks: a larger file that answers the same
    ok(&["convert", f.p("a.ot"), f.p("sb.olm"), "--search-blocks"]);
    assert!(ok(&["verify", f.p("sb.olm")]).contains(": ok"));
    assert!(std::fs::metadata(f.path("sb.olm")).unwrap().len() > std::fs::metadata(f.path("a.olm")).unwrap().len());
    assert_eq!(ok(&["query", f.p("sb.olm"), "--points", points]), from_ot);
    fail(&["convert", f.p("a.ot"), f.p("sb.bt"), "--search-blocks"], "--search-blocks applies to .olm output");
    // --ml: the maximum-likelihood variant, which answers as the .bt does
    ok(&["convert", f.p("a.bt"), f.p("ml.olm"), "--ml"]);
    assert!(ok(&["verify", f.p("ml.olm")]).contains(": ok"));
    let (full, ml) =
        (std::fs::metadata(f.path("a.olm")).unwrap().len(), std::fs::metadata(f.path("ml.olm")).unwrap().len());
    assert!(ml * 3 < full, "ML .olm {ml} bytes vs full {full}");
    assert_eq!(ok(&["query", f.p("ml.olm"), "--points", points]), ok(&["query", f.p("a.bt"), "--points", points]));
    ok(&["convert", f.p("ml.olm"), f.p("ml.bt")]);
    assert_eq!(std::fs::read(f.path("ml.bt")).unwrap(), std::fs::read(f.path("a.bt")).unwrap());
    fail(&["convert", f.p("a.ot"), f.p("x.bt"), "--ml"], "--ml applies to .olm output");
    let bytes = std::fs::read(f.path("a.olm")).unwrap();
    let truncated = f.write("cut.olm", &bytes[..bytes.len() / 2]);
    fail(&["verify", truncated], "not a valid .olm map");
    fail(&["query", truncated, "--points", points], "not a valid .olm map");
}

#[test]
fn counting_trees_convert_between_ot_and_olm_and_answer_counts() {
    let f = Fixture::new();
    // a counting tree of the fixture's occupied leaves, some counted twice
    let tree = read_tree(f.p("a.ot"));
    let mut counting = octolinear::CountingTree::new(tree.resolution()).unwrap();
    let centers: Vec<Point3> = tree.leaves(0).filter(|l| tree.is_occupied(l.value)).map(|l| l.center_point()).collect();
    for (i, c) in centers.iter().enumerate() {
        for _ in 0..1 + i % 2 {
            counting.update_point(*c).unwrap();
        }
    }
    let mut bytes = Vec::new();
    ot::write_counting(&counting, &mut bytes).unwrap();
    let src = f.write("c.ot", &bytes);
    ok(&["convert", src, f.p("c.olm")]);
    assert!(ok(&["verify", f.p("c.olm")]).contains(": ok"));
    ok(&["convert", f.p("c.olm"), f.p("c2.ot")]);
    assert_eq!(std::fs::read(f.path("c2.ot")).unwrap(), bytes, ".ot -> .olm -> .ot changed the bytes");
    fail(&["convert", src, f.p("c.bt")], "no .bt form");
    fail(&["convert", src, f.p("c.olm"), "--ml"], "no maximum-likelihood form");
    fail(&["info", src], "counting tree holds no occupancy");
    // queries: each point's count, as CountingOcTree::search gives it
    let mut pts = String::new();
    for c in centers.iter().step_by(7) {
        pts.push_str(&format!("{} {} {}\n", c.x, c.y, c.z));
    }
    pts.push_str("1e9 0 0\n");
    let points = f.write("q.xyz", pts);
    let from_ot = ok(&["query", src, "--points", points]);
    let cloud = octolinear::formats::xyz::read_file(Path::new(points)).unwrap();
    assert_eq!(from_ot.lines().count(), cloud.points.len());
    for (line, p) in from_ot.lines().zip(&cloud.points) {
        let want = match counting.key_space().key(*p).ok().and_then(|k| counting.count(k, 0)) {
            Some(c) => format!(",counted,{c}"),
            None => ",unknown,".to_string(),
        };
        assert!(line.ends_with(&want), "{line}: expected {want}");
    }
    assert!(from_ot.contains(",counted,2") && from_ot.contains(",counted,1") && from_ot.contains(",unknown,"));
    assert_eq!(ok(&["query", f.p("c.olm"), "--points", points]), from_ot);
}

// ----- reading commands: verify's report, convert's line, query's formats, numbers for people ------

#[test]
fn verify_reports_what_it_checked() {
    let f = Fixture::new();
    ok(&["convert", f.p("a.ot"), f.p("a.olm")]);
    let tree = read_tree(f.p("a.ot"));
    let size = std::fs::metadata(f.path("a.olm")).unwrap().len();
    let text = ok(&["verify", f.p("a.olm")]);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4, "{text}");
    assert_eq!(lines[0], format!("{}: ok", f.p("a.olm")));
    assert_eq!(lines[1], format!("map:         OcTree, full variant, resolution 0.1 m, {size} bytes"));
    assert!(lines[2].starts_with("checksums:   header and 3 sections (masks, rank, values): "), "{text}");
    let structure = format!(
        "structure:   zero padding, rank directory, one tree of {} nodes ({} inner, {} leaves), depth 16",
        tree.size(),
        tree.size() - tree.num_leaves(),
        tree.num_leaves()
    );
    assert_eq!(lines[3], structure);
    let j = json(&ok(&["verify", f.p("a.olm"), "--json"]));
    assert_eq!(
        (j["ok"].as_bool(), j["kind"].as_str(), j["variant"].as_str()),
        (Some(true), Some("OcTree"), Some("full"))
    );
    assert_eq!(j["nodes"].as_u64(), Some(tree.size() as u64));
    assert_eq!(j["leaves"].as_u64(), Some(tree.num_leaves() as u64));
    assert_eq!(j["file_bytes"].as_u64(), Some(size));
    let checked = j["checked_bytes"].as_u64().unwrap();
    assert!(checked <= size && checked > size * 9 / 10, "{checked} of {size}");
    assert!(lines[2].ends_with(&format!(": {checked} bytes")), "{text}");
    assert_eq!(j["sections"], serde_json::json!(["masks", "rank", "values"]));
    ok(&["convert", f.p("a.bt"), f.p("ml.olm"), "--ml"]);
    let j = json(&ok(&["verify", f.p("ml.olm"), "--json"]));
    assert_eq!(j["variant"].as_str(), Some("maximum-likelihood"));
    assert_eq!(j["nodes"].as_u64(), Some(read_tree(f.p("a.bt")).size() as u64));
    fail(&["verify", f.p("a.bt")], "verify checks .olm maps");
}

#[test]
fn convert_says_what_it_wrote() {
    let f = Fixture::new();
    // one line on stderr, nothing on stdout
    let line = |args: &[&str]| {
        let out = run(args);
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(out.status.success() && out.stdout.is_empty() && err.lines().count() == 1, "{args:?}: {err}");
        err.trim_end().to_string()
    };
    let size = |name: &str| std::fs::metadata(f.path(name)).unwrap().len();
    let nodes = read_tree(f.p("a.ot")).size();
    let ml_nodes = read_tree(f.p("a.bt")).size();
    assert!(ml_nodes < nodes);
    assert_eq!(
        line(&["convert", f.p("a.ot"), f.p("a.olm")]),
        format!("wrote {} (OcTree, {nodes} nodes, {} bytes)", f.p("a.olm"), size("a.olm"))
    );
    assert_eq!(
        line(&["convert", f.p("a.olm"), f.p("b.ot")]),
        format!("wrote {} (OcTree, {nodes} nodes, {} bytes)", f.p("b.ot"), size("b.ot"))
    );
    assert_eq!(
        line(&["convert", f.p("a.ot"), f.p("ml.olm"), "--ml"]),
        format!("wrote {} (OcTree, maximum likelihood, {ml_nodes} nodes, {} bytes)", f.p("ml.olm"), size("ml.olm"))
    );
    assert_eq!(
        line(&["convert", f.p("a.ot"), f.p("b.bt")]),
        format!("wrote {} (OcTree, maximum likelihood, {} bytes)", f.p("b.bt"), size("b.bt"))
    );
}

#[test]
fn query_decimal_format_prints_logodds_and_probability() {
    let f = Fixture::new();
    ok(&["convert", f.p("a.ot"), f.p("a.olm")]);
    let tree = read_tree(f.p("a.ot"));
    let mut pts: String =
        tree.leaves(0).step_by(53).map(|l| l.center_point()).map(|c| format!("{} {} {}\n", c.x, c.y, c.z)).collect();
    pts += "1e9 0 0\n";
    let points = f.write("q.xyz", pts);
    for map in [f.p("a.ot"), f.p("a.olm")] {
        let bits = ok(&["query", map, "--points", points]);
        assert_eq!(ok(&["query", map, "--points", points, "--format", "bits"]), bits);
        let decimal = ok(&["query", map, "--points", points, "--format", "decimal"]);
        assert_eq!(decimal.lines().count(), bits.lines().count());
        assert!(decimal.contains(",occupied,") && decimal.contains(",free,") && decimal.contains(",unknown,"));
        for (b, d) in bits.lines().zip(decimal.lines()) {
            let (b, d): (Vec<&str>, Vec<&str>) = (b.split(',').collect(), d.split(',').collect());
            assert_eq!((b.len(), d.len(), &b[..4]), (5, 6, &d[..4]), "{b:?} {d:?}");
            if b[3] == "unknown" {
                assert_eq!(&d[4..], ["", ""]);
                continue;
            }
            let logodds: f32 = d[4].parse().unwrap();
            assert_eq!(format!("{:08x}", logodds.to_bits()), b[4], "{d:?}");
            let probability = octolinear::sensor::probability(f64::from(logodds)) as f32;
            assert_eq!(d[5], probability.to_string(), "{d:?}");
        }
    }
    fail_usage(&["query", f.p("a.ot"), "--points", points, "--format", "hex"], "hex");
}

#[test]
fn reading_commands_help_names_every_map_format() {
    for cmd in ["info", "query", "convert", "compare"] {
        let help = ok(&[cmd, "--help"]);
        assert!(help.contains(".bt, .ot or .olm"), "{cmd}: {help}");
    }
    let help = ok(&["query", "--help"]);
    assert!(help.contains("--format") && help.contains("decimal") && help.contains("--no-verify"), "{help}");
    assert!(ok(&["verify", "--help"]).contains("--json"));
}

#[test]
fn numbers_for_people_are_printed_at_map_precision() {
    let f = Fixture::new();
    let text = ok(&["info", f.p("a.ot")]);
    let j = json(&ok(&["info", f.p("a.ot"), "--json"]));
    let field = |name: &str| {
        let line = text.lines().find(|l| l.starts_with(name)).unwrap_or_else(|| panic!("{name}: {text}"));
        line[name.len()..].trim().to_string()
    };
    assert_eq!(field("resolution:"), "0.1 m");
    // every number printed is the f32 of the full value, in its shortest form
    let full: Vec<f64> = ["bounds_min", "bounds_max"]
        .iter()
        .flat_map(|k| j[k].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
        .collect();
    let shown: String = full
        .chunks(3)
        .map(|p| format!("({}, {}, {})", p[0] as f32, p[1] as f32, p[2] as f32))
        .collect::<Vec<_>>()
        .join(" .. ");
    assert_eq!(field("bounds:"), format!("{shown} m"));
    assert!(full.iter().any(|v| v.to_string().len() > (*v as f32).to_string().len() + 5), "no noise to hide: {full:?}");
    let volume = |k: &str| (j[k].as_f64().unwrap() as f32).to_string();
    assert_eq!(
        field("volume:"),
        format!("{} m^3 occupied, {} m^3 free", volume("occupied_volume_m3"), volume("free_volume_m3"))
    ); // a resolution computed in f64 (0.1 x 3 = 0.30000000000000004)
    let out = run(&["edit", f.p("a.ot"), f.p("e.ot"), "--scale", "3"]);
    let line = String::from_utf8(out.stderr).unwrap();
    assert!(out.status.success() && line.trim_end().ends_with(" nodes, resolution 0.3)"), "{line}");
}

/// A map file truncated in place while `query` has it mapped: one error
/// line and exit code 1 instead of a death by SIGBUS. The points come
/// through a pipe, read after the map is opened, so the truncation falls
/// between the two. Replacing the file by a rename instead is harmless.
#[cfg(target_os = "linux")]
#[test]
fn a_map_changed_under_query_is_an_error_or_harmless() {
    use std::io::Write;
    use std::process::Stdio;
    let f = Fixture::new();
    let tree = read_tree(f.p("a.ot"));
    let points: String =
        tree.leaves(0).step_by(31).map(|l| l.center_point()).map(|c| format!("{} {} {}\n", c.x, c.y, c.z)).collect();
    let expected = ok(&["query", f.p("a.ot"), "--points", f.write("q.xyz", &points)]);
    let map = f.p("t.olm");
    // runs query with the map mapped and waiting for points, changes the map, then sends them
    let query_while = |change: &dyn Fn()| {
        ok(&["convert", f.p("a.ot"), map]);
        let real = std::fs::canonicalize(map).unwrap();
        let mut child = bin()
            .args(["query", map, "--points", "/dev/stdin"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let maps = format!("/proc/{}/maps", child.id());
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        while !std::fs::read_to_string(&maps).unwrap_or_default().contains(real.to_str().unwrap()) {
            assert!(std::time::Instant::now() < deadline, "query never mapped {map}");
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        change();
        let mut stdin = child.stdin.take().unwrap();
        // the process may already be gone (truncated during its check of the map)
        let _ = stdin.write_all(points.as_bytes());
        drop(stdin);
        child.wait_with_output().unwrap()
    };
    let truncated = query_while(&|| std::fs::OpenOptions::new().write(true).open(map).unwrap().set_len(0).unwrap());
    let err = String::from_utf8_lossy(&truncated.stderr);
    assert_eq!(truncated.status.code(), Some(1), "{err}");
    assert_eq!(
        err,
        format!(
            "octolinear: error: {map}: the file was truncated while memory-mapped \
             (replace files by renaming a new file over them, never in place)\n"
        )
    );
    let renamed = query_while(&|| {
        std::fs::write(f.path("new.olm"), b"not a map").unwrap();
        std::fs::rename(f.path("new.olm"), map).unwrap();
    });
    assert!(renamed.status.success(), "{}", String::from_utf8_lossy(&renamed.stderr));
    assert_eq!(String::from_utf8(renamed.stdout).unwrap(), expected);
}

// ----- threads, output arguments, messages ------------------------------------

/// Many more threads than scans, as a default run on a large machine has:
/// every run ends (a lost wakeup in the scan pipeline once hung some of
/// them) and gives the one-thread bytes. Each run has a deadline.
#[test]
fn builds_on_many_threads_always_finish() {
    let f = Fixture::new();
    let sample = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/indoor.graph");
    ok(&["build", sample, "-o", f.p("one.bt"), "--threads", "1"]);
    let expected = std::fs::read(f.path("one.bt")).unwrap();
    for run in 0..8 {
        let threads = ["256", "64", "1000", "32"][run % 4];
        let out = f.p("many.bt");
        let mut child = bin()
            .args(["build", sample, "-o", out, "--threads", threads])
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if std::time::Instant::now() > deadline {
                let _ = child.kill();
                panic!("run {run} on {threads} threads hung");
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        };
        assert!(status.success(), "run {run} on {threads} threads: {status}");
        assert!(std::fs::read(out).unwrap() == expected, "run {run} on {threads} threads");
    }
}

#[test]
fn commands_that_write_take_dash_o_or_a_last_positional() {
    let f = Fixture::new();
    let a = f.p("a.bt");
    ok(&["to-points", a, "-o", f.p("o.xyz")]);
    ok(&["to-points", a, f.p("p.xyz")]);
    assert_eq!(std::fs::read(f.path("o.xyz")).unwrap(), std::fs::read(f.path("p.xyz")).unwrap());
    ok(&["convert", a, "-o", f.p("c.ot")]);
    ok(&["edit", a, "--output", f.p("e.bt"), "--prune"]);
    ok(&["crop", a, "-o", f.p("r.bt"), "--min", "0", "0", "0", "--max", "1", "1", "1"]);
    fail_usage(&["to-points", a, f.p("x.xyz"), "-o", f.p("y.xyz")], "cannot be used with");
    fail_usage(&["convert", a], "--output");
}

/// `raycast` names its outcomes in `--help` as it prints them.
#[test]
fn raycast_help_names_the_outcomes_it_prints() {
    let help = ok(&["raycast", "--help"]);
    for outcome in ["occupied", "max_range", "unknown", "left_map"] {
        assert!(help.contains(outcome), "{outcome} missing from raycast --help");
    }
    let f = Fixture::new();
    let out = ok(&["raycast", f.p("a.bt"), "--origin", "0", "0", "0", "--direction", "0", "0", "-1"]);
    let printed = out.split_whitespace().next().unwrap();
    assert!(["occupied", "max_range", "unknown", "left_map"].contains(&printed), "{out}");
}

/// An error line says each cause once (no "(os error 2): No such file or
/// directory (os error 2)").
#[test]
fn error_lines_do_not_repeat_their_cause() {
    let f = Fixture::new();
    for args in [
        vec!["build", f.p("missing.graph"), "-o", f.p("x.bt")],
        vec!["info", f.p("missing.olm")],
        vec!["verify", f.p("missing.olm")],
        vec!["query", f.p("a.bt"), "--points", f.p("missing.xyz")],
    ] {
        let out = run(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert_eq!(err.matches("os error 2").count(), 1, "{args:?}: {err}");
    }
}

// ---- interrupted writes: no temporary file survives a signal ----

#[cfg(unix)]
mod interrupted_writes {
    use super::*;
    use std::os::unix::process::{CommandExt, ExitStatusExt};
    use std::process::{ExitStatus, Stdio};
    use std::time::{Duration, Instant};

    /// Jobs of growing size (16, 64 and 256 MB of `.graph`), tried until the
    /// write lasts long enough to be signalled while its temporary file exists.
    const SCANS: [&str; 3] = ["100", "400", "1600"];

    fn temp_files(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".out.graph.") && n.ends_with(".tmp"))
            .collect()
    }

    /// Starts `simulate` writing `dir/out.graph` (with `ignored` ignored, the
    /// other signals at their default action whatever this test inherited),
    /// sends `signal` once its temporary file appears and returns the exit
    /// status; `None` if the write was over before the signal could be sent.
    fn signal_during_write(dir: &Path, scans: &str, signal: i32, ignored: Option<i32>) -> Option<ExitStatus> {
        let mut cmd = bin();
        cmd.args(["simulate", "--scans", scans, "-o", s(&dir.join("out.graph"))]);
        cmd.stdout(Stdio::null()).stderr(Stdio::null());
        // SAFETY: signal() is async-signal-safe, as pre_exec requires.
        unsafe {
            cmd.pre_exec(move || {
                for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
                    libc::signal(sig, if Some(sig) == ignored { libc::SIG_IGN } else { libc::SIG_DFL });
                }
                Ok(())
            });
        }
        let mut child = cmd.spawn().expect("binary runs");
        let deadline = Instant::now() + Duration::from_secs(300);
        loop {
            if !temp_files(dir).is_empty() {
                // SAFETY: kill() of the child's pid, which stays reserved
                // until it is waited for below.
                assert_eq!(unsafe { libc::kill(child.id() as i32, signal) }, 0);
                let status = child.wait().unwrap();
                return (ignored.is_some() || !status.success()).then_some(status);
            }
            if let Some(status) = child.try_wait().unwrap() {
                assert!(status.success(), "simulate --scans {scans}: {status}");
                return None;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                panic!("simulate --scans {scans} neither wrote nor ended in 300 s");
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The first of [`SCANS`]'s jobs that `signal` reaches while it writes.
    fn signalled_write(dir: &Path, signal: i32, ignored: Option<i32>) -> ExitStatus {
        for scans in SCANS {
            if let Some(status) = signal_during_write(dir, scans, signal, ignored) {
                return status;
            }
        }
        panic!("no write of up to {} scans lasted until signal {signal}", SCANS[SCANS.len() - 1]);
    }

    #[test]
    fn polite_signals_remove_the_temporary_file_and_end_the_process_by_the_signal() {
        for signal in [libc::SIGTERM, libc::SIGINT, libc::SIGHUP] {
            let dir = tempfile::tempdir().unwrap();
            let status = signalled_write(dir.path(), signal, None);
            assert_eq!(status.signal(), Some(signal), "{status}");
            assert_eq!(temp_files(dir.path()), Vec::<String>::new(), "signal {signal}");
        }
    }

    #[test]
    fn an_ignored_signal_stays_ignored() {
        let dir = tempfile::tempdir().unwrap();
        let status = signalled_write(dir.path(), libc::SIGHUP, Some(libc::SIGHUP));
        assert!(status.success(), "{status}");
        assert!(graph::read_file(dir.path().join("out.graph")).is_ok());
        assert_eq!(temp_files(dir.path()), Vec::<String>::new());
    }

    #[test]
    fn the_next_write_removes_the_temporary_file_a_sigkill_left() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.graph");
        let left = SCANS.iter().find_map(|scans| {
            let status = signal_during_write(dir.path(), scans, libc::SIGKILL, None)?;
            assert_eq!(status.signal(), Some(libc::SIGKILL), "{status}");
            // killed after the rename: nothing left to observe, try a longer write
            let left = temp_files(dir.path());
            (!left.is_empty()).then_some(left)
        });
        let left = left.expect("a SIGKILL during a write leaves its temporary file");
        assert_eq!(left.len(), 1, "{left:?}");
        // another process's temporary file of the same output, still running: kept
        let live = format!(".out.graph.{}.0.tmp", std::process::id());
        std::fs::write(dir.path().join(&live), "live").unwrap();
        ok(&["simulate", "--scans", "2", "-o", s(&out)]);
        assert_eq!(temp_files(dir.path()), [live]);
        assert_eq!(graph::read_file(&out).unwrap().nodes.len(), 2);
    }
}

// ----- bounded sizes, streamed input, warnings ---------------------------------

/// Runs with `input` on standard input, written through a pipe by another
/// thread (a write the binary leaves unread is not an error).
fn run_with_stdin(args: &[&str], input: Vec<u8>) -> Output {
    use std::io::Write;
    use std::process::Stdio;
    let mut child =
        bin().args(args).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(&input);
    });
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    out
}

/// Requires a failure reported as one error line containing `needle`.
fn assert_one_error(args: &[&str], out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    assert!(err.starts_with("octolinear: error: ") && err.contains(needle), "{args:?}: {err:?} lacks {needle:?}");
}

/// Runs and requires success; returns stderr.
fn ok_stderr(args: &[&str]) -> String {
    let out = run(args);
    let err = String::from_utf8(out.stderr).expect("utf-8 stderr");
    assert!(out.status.success(), "{args:?} failed: {err}");
    err
}

#[test]
fn sizes_a_user_asks_for_are_bounded_by_what_they_imply() {
    let f = Fixture::new();
    let out = f.p("big.graph");
    fail(
        &["simulate", "--scans", "1", "--beams", "100000000", "-o", out],
        "100000000 beams × 360 steps = 36000000000 rays per scan exceeds the limit of 16777216",
    );
    fail(&["simulate", "--steps", "4000000000", "-o", out], "exceeds the limit of 16777216");
    fail(
        &["simulate", "--scans", "100000000", "-o", out],
        "100000000 scans × 5760 rays = 576000000000 rays exceeds the limit of 268435456",
    );
    assert!(!f.path("big.graph").exists());
    fail(&["eval", f.p("s.graph"), "--folds", "100000"], "--folds 100000 needs at least 100000 scans, only 6");
    fail(&["eval", f.p("s.graph"), "--holdout", "7"], "--holdout 7 needs at least 7 scans, only 6");
    fail(&["eval", f.p("s.graph"), "--scans", "3"], "the default --holdout 5 needs at least 5 scans, only 3");
    let j = json(&ok(&["eval", f.p("s.graph"), "--folds", "6", "--json"]));
    assert_eq!(j["total"]["scans"], 6);
    fail(
        &["render", f.p("a.bt"), "-o", f.p("v.png"), "--width", "16384", "--height", "16384"],
        "--width 16384 × --height 16384 = 268435456 pixels exceeds the limit of 67108864",
    );
    fail(
        &["render", f.p("a.bt"), "-o", f.p("v.png"), "--view", "perspective", "--width", "16384"],
        "--width 16384 × the default --height 12288 = 201326592 pixels exceeds the limit",
    );
    fail(&["build", f.p("s.graph"), "-o", f.p("t.bt"), "--threads", "100000"], "--threads must be between 1 and 1024");
    // a stream claiming four billion points in its first scan: read as the
    // data comes, it ends with an error, not an allocation abort
    let mut claim = 1u32.to_le_bytes().to_vec();
    claim.extend(u32::MAX.to_le_bytes());
    claim.extend(vec![0u8; 100]);
    let args = ["build", "-", "-o", f.p("t.bt")];
    assert_one_error(&args, &run_with_stdin(&args, claim), "input ends at byte offset 108 inside point 3 of node 0");
    assert!(!f.path("t.bt").exists());
}

#[test]
fn build_streams_graphs_from_pipes_fifos_and_standard_input() {
    let f = Fixture::new();
    let bytes = std::fs::read(f.path("s.graph")).unwrap();
    let expected = std::fs::read(f.path("a.bt")).unwrap();
    for input in ["-", "/dev/stdin"] {
        let args = ["build", input, "-o", f.p("p.bt"), "--res", "0.1"];
        let out = run_with_stdin(&args, bytes.clone());
        assert!(out.status.success(), "{input}: {}", String::from_utf8_lossy(&out.stderr));
        assert_eq!(std::fs::read(f.path("p.bt")).unwrap(), expected, "{input}");
        std::fs::remove_file(f.path("p.bt")).unwrap();
    }
    // the full tree and the first scans only
    let args = ["build", "-", "-o", f.p("p.ot"), "--scans", "2"];
    assert!(run_with_stdin(&args, bytes.clone()).status.success());
    ok(&["build", f.p("s.graph"), "-o", f.p("two.ot"), "--scans", "2"]);
    assert_eq!(std::fs::read(f.path("p.ot")).unwrap(), std::fs::read(f.path("two.ot")).unwrap());
    // a FIFO, and bash's process substitution (a pipe under /dev/fd)
    let fifo = f.path("scans.fifo");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let writer = {
        let (fifo, bytes) = (fifo.clone(), bytes.clone());
        std::thread::spawn(move || std::fs::write(fifo, bytes))
    };
    ok(&["build", f.p("scans.fifo"), "-o", f.p("fifo.bt")]);
    writer.join().unwrap().unwrap();
    assert_eq!(std::fs::read(f.path("fifo.bt")).unwrap(), expected);
    let script = format!(
        "{} build <(cat {}) -o {} >/dev/null",
        env!("CARGO_BIN_EXE_octolinear"),
        f.p("s.graph"),
        f.p("subst.bt")
    );
    let out = Command::new("bash").arg("-c").arg(&script).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(std::fs::read(f.path("subst.bt")).unwrap(), expected);
    // eval reads standard input too
    let args = ["eval", f.p("a.bt"), "-", "--json"];
    let out = run_with_stdin(&args, bytes.clone());
    assert!(out.status.success());
    assert_eq!(
        json(&String::from_utf8(out.stdout).unwrap()),
        json(&ok(&["eval", f.p("a.bt"), f.p("s.graph"), "--json"]))
    );
    // a stream cut inside a point, or inside the edge list: the error names
    // the scan and the byte offset, and no map is written
    let g = graph::read_file(f.path("s.graph")).unwrap();
    let node0 = 4 + 4 + 28 * g.nodes[0].scan.len() + 64 + 4;
    let cut = node0 + 4 + 28 * 3 + 10;
    let args = ["build", "-", "-o", f.p("cut.bt")];
    let out = run_with_stdin(&args, bytes[..cut].to_vec());
    assert_one_error(&args, &out, &format!("input ends at byte offset {cut} inside point 3 of node 1"));
    let out = run_with_stdin(&args, bytes[..bytes.len() - 10].to_vec());
    assert_one_error(&args, &out, "inside constraint of edge 4");
    assert!(!f.path("cut.bt").exists());
    // point files from standard input, recognised by their first bytes
    ok(&["to-points", f.p("a.bt"), f.p("occ.ply")]);
    ok(&["build", "--points", f.p("occ.ply"), "-o", f.p("ply.bt")]);
    let args = ["build", "--points", "-", "-o", f.p("ply_stdin.bt")];
    assert!(run_with_stdin(&args, std::fs::read(f.path("occ.ply")).unwrap()).status.success());
    assert_eq!(std::fs::read(f.path("ply_stdin.bt")).unwrap(), std::fs::read(f.path("ply.bt")).unwrap());
    fail(&["build", "--points", "-", "-", "-o", f.p("x.bt")], "standard input (-) more than once");
}

#[test]
fn meaningless_values_are_refused() {
    let f = Fixture::new();
    let (g, out) = (f.p("s.graph"), f.p("x.bt"));
    fail(
        &["build", g, "-o", out, "--res", "1e-40"],
        "--res: resolution 1e-40 m is below the smallest usable resolution 2.35",
    );
    fail(&["build", g, "-o", out, "--res", "1e40"], "above the largest usable resolution");
    fail(&["build", g, "-o", out, "--res", "NaN"], "--res: resolution NaN m is not a positive finite number");
    for range in ["-5", "-1", "0", "inf"] {
        fail(&["build", g, "-o", out, "--max-range", range], "--max-range must be a positive finite number");
        fail(&["eval", g, "--max-range", range], "--max-range must be a positive finite number");
    }
    fail(&["build", g, "-o", out, "--scans", "0"], "--scans must be at least 1");
    fail(&["eval", g, "--scans", "0"], "--scans must be at least 1");
    fail(&["simulate", "--scans", "0", "-o", f.p("z.graph")], "--scans must be at least 1");
    fail(&["render", f.p("a.bt"), "-o", f.p("v.png"), "--depth", "0"], "--depth must be between 1 and 16, got 0");
    fail(&["mesh", f.p("a.bt"), "-o", f.p("m.ply"), "--depth", "0"], "--depth must be between 1 and 16, got 0");
    fail(&["to-points", f.p("a.bt"), f.p("p.xyz"), "--depth", "0"], "--depth must be between 1 and 16, got 0");
    assert!(!f.path("x.bt").exists());
    // the documented ways: no --max-range for no limit, depth 1
    ok(&["mesh", f.p("a.bt"), "-o", f.p("m.ply"), "--depth", "1"]);
    let help = ok(&["build", "--help"]);
    assert!(help.contains("leave it out for no limit"), "{help}");
}

#[test]
fn build_says_what_it_dropped_and_stays_quiet_otherwise() {
    let f = Fixture::new();
    let total = json(&ok(&["build", f.p("s.graph"), "-o", f.p("q.bt"), "--json"]))["points"].as_u64().unwrap();
    // a piped run of a normal build: no progress, no warning
    assert_eq!(ok_stderr(&["build", f.p("s.graph"), "-o", f.p("q.bt")]), "");
    // every point outside a map of ±0.032768 m; the map (empty) is what
    // graph2tree writes, byte for byte
    let args = ["build", f.p("s.graph"), "-o", f.p("tiny.bt"), "--res", "1e-6"];
    let err = ok_stderr(&args);
    assert_eq!(
        err,
        format!(
            "octolinear: warning: {total} of {total} points lie outside the map, which spans ±0.032768 m at \
             --res 1e-6; they were not marked and cast no ray (beyond a --max-range cut), as in OctoMap\n"
        )
    );
    let j = json(&ok(&[&args[..], &["--json"]].concat()));
    assert_eq!(j["out_of_map_points"], total);
    if let Some(t) = tool("graph2tree") {
        Command::new(t).args(["-i", f.p("s.graph"), "-o", f.p("tiny_g.bt"), "-res", "1e-6"]).output().unwrap();
        assert_eq!(std::fs::read(f.path("tiny.bt")).unwrap(), std::fs::read(f.path("tiny_g.bt")).unwrap());
    }
    // one point 400 m away at 0.01 m, under each --out-of-map rule
    let xyz = f.write("far.xyz", "400 0 0\n1 0 0\n");
    let err = ok_stderr(&["build", "--points", xyz, "-o", f.p("far.bt"), "--res", "0.01"]);
    assert!(err.contains("warning: 1 of 2 points lie outside the map, which spans ±327.68 m at --res 0.01"), "{err}");
    let err = ok_stderr(&["build", "--points", xyz, "-o", f.p("far.bt"), "--res", "0.01", "--discretize"]);
    assert!(err.contains("1 of 2 points") && err.contains("wrapped around"), "{err}");
    let err = ok_stderr(&["build", "--points", xyz, "-o", f.p("far.bt"), "--res", "0.01", "--out-of-map", "skip"]);
    assert!(err.contains("1 of 2 points") && err.contains("were skipped (--out-of-map skip)"), "{err}");
    // NaN coordinates (a .graph can hold them)
    let mut nan = octolinear::ScanGraph::new();
    let cloud = [Point3::new(1.0, 0.0, 0.0), Point3::new(f32::NAN, 0.0, 0.0), Point3::new(0.0, 1.0, 0.0)];
    nan.add_node(cloud.into_iter().collect(), octolinear::Pose6D::IDENTITY);
    graph::write_file(&nan, f.path("nan.graph")).unwrap();
    let err = ok_stderr(&["build", f.p("nan.graph"), "-o", f.p("nan.bt")]);
    assert!(err.contains("warning: 1 of 3 points have NaN or infinite coordinates and were skipped"), "{err}");
    // empty inputs build empty maps, with a word
    graph::write_file(&octolinear::ScanGraph::new(), f.path("none.graph")).unwrap();
    let err = ok_stderr(&["build", f.p("none.graph"), "-o", f.p("none.bt")]);
    assert!(err.contains("none.graph holds no scans: the map is empty"), "{err}");
    assert!(f.path("none.bt").exists());
    let mut bare = octolinear::ScanGraph::new();
    for _ in 0..2 {
        bare.add_node(Default::default(), octolinear::Pose6D::IDENTITY);
    }
    graph::write_file(&bare, f.path("bare.graph")).unwrap();
    let err = ok_stderr(&["build", f.p("bare.graph"), "-o", f.p("bare.bt")]);
    assert!(err.contains("the 2 scans of") && err.contains("hold no points: the map is empty"), "{err}");
    let err = ok_stderr(&["build", f.p("s.graph"), "-o", f.p("q.bt"), "--scans", "10"]);
    assert!(err.contains("--scans 10 asks for more than the 6 scans of"), "{err}");
}

#[test]
fn xyz_points_with_comments_commas_and_semicolons() {
    let f = Fixture::new();
    let plain = f.write("plain.xyz", "2.05 0.05 0.05\n2.05 0.15 0.05\n-1 0.5 0.25\n");
    let other = f.write(
        "other.xyz",
        "# exported by a scanner\n\n2.05,0.05,0.05\n2.05, 0.15, 0.05 # second\n-1;0.5;0.25\r\n# end\n",
    );
    ok(&["build", "--points", plain, "-o", f.p("plain.bt")]);
    ok(&["build", "--points", other, "-o", f.p("other.bt")]);
    assert_eq!(std::fs::read(f.path("plain.bt")).unwrap(), std::fs::read(f.path("other.bt")).unwrap());
    let bad = f.write("bad.xyz", "# x,y,z\n1,2,3\n1,,3\n");
    fail(&["build", "--points", bad, "-o", f.p("bad.bt")], "line 3: \"\" is not a decimal number");
    let short = f.write("short.txt", "1;2;3\n4;5\n");
    fail(&["build", "--points", short, "-o", f.p("bad.bt")], "line 2: expected 3 numbers, found 2 values");
}

#[test]
fn build_help_lists_every_format_it_takes() {
    let help = ok(&["build", "--help"]);
    for format in [".bt", ".ot", ".olm", ".ply", ".pcd", ".las", ".laz", ".xyz", "standard input"] {
        assert!(help.contains(format), "build --help lacks {format}");
    }
    let f = Fixture::new();
    ok(&["build", f.p("s.graph"), "-o", f.p("m.olm")]);
    assert!(ok(&["verify", f.p("m.olm")]).contains(": ok"));
}

/// A map of eight free leaves just below the root holds 8 × 8^15 free
/// voxels: `to-points --free` refuses that before allocating, and gives
/// the coarse voxels at a depth that fits.
#[test]
fn to_points_refuses_more_points_than_it_can_hold() {
    let f = Fixture::new();
    let mut bytes = b"# Octomap OcTree binary file\n#\n#\nid OcTree\nsize 9\nres 0.1\ndata\n".to_vec();
    bytes.extend([0x55, 0x55]); // the root's eight children: free leaves
    let map = f.write("free.bt", bytes);
    fail(&["to-points", map, "-o", f.p("all.xyz"), "--free"], "exceed the limit of 268435456 (2^28) points");
    assert!(!f.path("all.xyz").exists());
    ok(&["to-points", map, "-o", f.p("coarse.xyz"), "--free", "--depth", "5"]);
    let written = std::fs::read_to_string(f.path("coarse.xyz")).unwrap();
    assert_eq!(written.lines().count(), 8 * 8usize.pow(4));
}

// ----- tile sets: tiled builds, builds in parts, memory caps -----------------------------------

/// Builds the fixture's graph to `out` with `flags`; returns the bytes
/// written (a file) or, for a tile set, its conversion to `as_ext`.
fn tiled_build_bytes(f: &Fixture, out: &str, flags: &[&str]) -> Vec<u8> {
    let mut args = vec!["build", f.p("s.graph"), "-o", out];
    args.extend(flags);
    ok(&args);
    std::fs::read(out).unwrap()
}

/// The bytes `convert SET OUT` writes.
fn converted(f: &Fixture, set: &str, out: &str) -> Vec<u8> {
    let out = f.p(out);
    ok(&["convert", set, out]);
    std::fs::read(out).unwrap()
}

#[test]
fn tiled_builds_convert_to_the_plain_build_bytes() {
    let f = Fixture::new();
    assert!(ok(&["tiles", "--help"]).contains("Example: octolinear tiles manifest"));
    ok(&["build", f.p("s.graph"), "-o", f.p("a.olm"), "--res", "0.1"]);
    for depth in ["1", "4", "9", "15"] {
        let set = f.p(&format!("d{depth}.tiles"));
        let out = ok(&["build", f.p("s.graph"), "-o", set, "--res", "0.1", "--tile-depth", depth]);
        assert!(out.contains(&format!("at depth {depth}")), "{out}");
        for plain in ["a.ot", "a.bt", "a.olm"] {
            let ext = plain.rsplit('.').next().unwrap();
            let want = std::fs::read(f.path(plain)).unwrap();
            assert!(converted(&f, set, &format!("d{depth}.{ext}")) == want, "depth {depth}: {ext} differs");
        }
        assert!(ok(&["verify", set]).contains(": ok"));
        let info = json(&ok(&["info", set, "--json"]));
        assert_eq!(info["tile_depth"], depth.parse::<u64>().unwrap());
        assert_eq!(info["nodes"].as_u64().unwrap() as usize, read_tree(f.p("a.ot")).size());
        // another build into the same set leaves no tile of the first behind
        ok(&["build", f.p("s.graph"), "-o", set, "--res", "0.1", "--tile-depth", depth, "--max-range", "2"]);
        let manifest = octolinear::tiles::read_manifest(&f.path(&format!("d{depth}.tiles/manifest"))).unwrap();
        let files = std::fs::read_dir(f.path(&format!("d{depth}.tiles"))).unwrap().count();
        assert_eq!(files, manifest.tiles.len() + 1, "depth {depth}");
    }
}

#[test]
fn queries_on_a_tile_set_answer_as_the_map_and_map_only_their_tiles() {
    let f = Fixture::new();
    let set = f.p("q.tiles");
    ok(&["build", f.p("s.graph"), "-o", set, "--res", "0.1", "--tile-depth", "12"]);
    let tree = read_tree(f.p("a.ot"));
    // the centre of every leaf, and points in unknown space
    let mut points: Vec<Point3> = tree.leaves(0).step_by(7).map(|l| l.center_point()).collect();
    points.extend([Point3::new(500.0, 3.0, 1.0), Point3::new(-0.05, 0.05, 40.0), Point3::new(1e9, 0.0, 0.0)]);
    let text: String = points.iter().map(|p| format!("{} {} {}\n", p.x, p.y, p.z)).collect();
    let pts = f.write("q.xyz", text);
    let want = ok(&["query", f.p("a.ot"), "--points", pts]);
    assert_eq!(ok(&["query", set, "--points", pts]), want);
    assert_eq!(ok(&["query", set, "--points", pts, "--no-verify"]), want);
    // a tile no point reaches may be gone; one a point reaches may not
    let manifest = octolinear::tiles::read_manifest(&f.path("q.tiles/manifest")).unwrap();
    let one = f.write("one.xyz", format!("{} {} {}\n", points[0].x, points[0].y, points[0].z));
    let keys = octolinear::KeySpace::new(0.1);
    let reached = octolinear::tiles::TileId::of_key(keys.key(points[0]).unwrap(), 12);
    let other = manifest.tiles.iter().find(|t| t.id != reached && !t.root.is_leaf).unwrap().id;
    std::fs::remove_file(f.path(&format!("q.tiles/{}", other.file_name()))).unwrap();
    ok(&["query", set, "--points", one]);
    fail(&["query", set, "--points", pts], &format!("tile {other}"));
    fail(&["verify", set], "is missing");
    fail(&["convert", set, f.p("q.ot")], &format!("tile {other}"));
}

#[test]
fn tile_sets_built_in_parts_combine_to_the_plain_build() {
    let f = Fixture::new();
    let flags =
        ["--res", "0.1", "--max-range", "6", "--discretize", "--sensor", "0.35", "0.8", "--clamping", "0.15", "0.95"];
    let want = tiled_build_bytes(&f, f.p("plain.ot"), &flags);
    let set = f.p("parts.tiles");
    for k in 0..3 {
        let task = format!("{k}/3");
        let mut args = vec!["build", f.p("s.graph"), "-o", set, "--tile-depth", "10", "--task", &task];
        args.extend(flags);
        let out = ok(&args);
        assert!(out.contains(&format!("task {k} of 3")), "{out}");
        if k == 0 {
            fail(&["convert", set, f.p("early.ot")], "manifest");
            fail(&["tiles", "manifest", set], "the part of task 1 of 3 is missing");
        }
    }
    assert!(!f.path("parts.tiles/manifest").exists());
    ok(&["tiles", "manifest", set]);
    assert!(!f.path("parts.tiles/task-0-of-3.manifest").exists());
    assert!(converted(&f, set, "parts.ot") == want);
    assert!(ok(&["verify", set]).contains(": ok"));
    fail(&["tiles", "manifest", set], "holds no task parts");
}

#[test]
fn memory_capped_builds_equal_uncapped_builds() {
    let f = Fixture::new();
    let simple = &["--res", "0.05", "--simple", "--threads", "1"][..];
    let runs =
        [(&["--res", "0.1"][..], "a", &[("4K", "9"), ("1", "12"), ("64M", "3")][..]), (simple, "s", &[("1", "11")])];
    for (flags, name, caps) in runs {
        let want_ot = tiled_build_bytes(&f, f.p(&format!("{name}-plain.ot")), flags);
        let want_bt = tiled_build_bytes(&f, f.p(&format!("{name}-plain.bt")), flags);
        for &(cap, depth) in caps {
            let capped = [flags, &["--memory-cap", cap, "--tile-depth", depth]].concat();
            assert!(tiled_build_bytes(&f, f.p(&format!("{name}{cap}.ot")), &capped) == want_ot, "{name} {cap}");
            assert!(tiled_build_bytes(&f, f.p(&format!("{name}{cap}.bt")), &capped) == want_bt, "{name} {cap}");
            let set = f.p(&format!("{name}{cap}.tiles"));
            let mut args = vec!["build", f.p("s.graph"), "-o", set];
            args.extend(&capped);
            ok(&args);
            assert!(converted(&f, set, &format!("{name}{cap}-set.ot")) == want_ot, "{name} {cap} tile set");
        }
    }
    // the tiles written out during a capped build are gone with it
    let left: Vec<String> = std::fs::read_dir(f.dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("spill"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

/// A capped build from a `.graph` file goes group by group, one from
/// standard input scan by scan: both give the plain build's bytes, with
/// the options that change the scans (--scans, --discretize, --max-range,
/// --out-of-map skip); a truncated file is an error and writes nothing.
#[test]
fn capped_builds_from_a_file_and_from_standard_input_equal_plain_builds() {
    let f = Fixture::new();
    let graph = std::fs::read(f.path("s.graph")).unwrap();
    let options: [&[&str]; 4] = [
        &["--res", "0.1", "--scans", "4"],
        &["--res", "0.05", "--discretize"],
        &["--res", "0.1", "--max-range", "3"],
        &["--res", "0.1", "--out-of-map", "skip", "--threads", "2"],
    ];
    for (i, flags) in options.into_iter().enumerate() {
        for ext in ["bt", "olm"] {
            let want = tiled_build_bytes(&f, f.p(&format!("p{i}.{ext}")), flags);
            for cap in ["1", "300K"] {
                let capped = [flags, &["--memory-cap", cap, "--tile-depth", "10"]].concat();
                let out = f.p(&format!("g{i}-{cap}.{ext}"));
                assert!(tiled_build_bytes(&f, out, &capped) == want, "{flags:?} {cap} .{ext} from the file");
                let piped = f.p(&format!("s{i}-{cap}.{ext}"));
                let args = [&["build", "-", "-o", piped][..], &capped].concat();
                let run = run_with_stdin(&args, graph.clone());
                assert!(run.status.success(), "{args:?}: {}", String::from_utf8_lossy(&run.stderr));
                assert!(std::fs::read(piped).unwrap() == want, "{flags:?} {cap} .{ext} from standard input");
            }
        }
        // a tile set: its bytes through convert
        let want = tiled_build_bytes(&f, f.p(&format!("p{i}.ot")), flags);
        for cap in ["1", "300K"] {
            let set = f.p(&format!("g{i}-{cap}.tiles"));
            let mut args = vec!["build", f.p("s.graph"), "-o", set, "--memory-cap", cap, "--tile-depth", "10"];
            args.extend(flags);
            ok(&args);
            assert!(converted(&f, set, &format!("g{i}-{cap}.ot")) == want, "{flags:?} {cap} tiles");
        }
    }
    let cut = f.write("cut.graph", &graph[..graph.len() * 2 / 3]);
    fail(&["build", cut, "-o", f.p("cut.ot"), "--memory-cap", "1"], "cut.graph");
    assert!(!f.path("cut.ot").exists());
}

/// A capped build reads every group's pass from the input it opened first:
/// another log renamed over the input's path mid-build (the safe way to
/// replace a file) changes nothing, so the map is the plain build's of the
/// original log, wherever in the build the rename lands.
#[test]
fn capped_builds_read_the_input_first_opened_to_the_end() {
    let f = Fixture::new();
    ok(&["simulate", "--scans", "12", "--beams", "16", "--steps", "240", "-o", f.p("in.graph")]);
    ok(&["simulate", "--scans", "12", "--beams", "16", "--steps", "240", "--seed", "9", "-o", f.p("other.graph")]);
    let original = std::fs::read(f.path("in.graph")).unwrap();
    ok(&["build", f.p("in.graph"), "-o", f.p("plain.ot"), "--res", "0.1"]);
    let want = std::fs::read(f.path("plain.ot")).unwrap();
    for (i, delay) in [5u64, 40, 150].into_iter().enumerate() {
        std::fs::write(f.path("in.graph"), &original).unwrap();
        std::fs::copy(f.path("other.graph"), f.path("next.graph")).unwrap();
        let out = f.p(&format!("capped{i}.ot"));
        let args = ["build", f.p("in.graph"), "-o", out, "--res", "0.1", "--memory-cap", "1", "--tile-depth", "10"];
        let child = bin().args(args).stderr(std::process::Stdio::piped()).spawn().unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay));
        std::fs::rename(f.path("next.graph"), f.path("in.graph")).unwrap();
        let done = child.wait_with_output().unwrap();
        assert!(done.status.success(), "{}", String::from_utf8_lossy(&done.stderr));
        assert!(std::fs::read(out).unwrap() == want, "renamed after {delay} ms: not the original's map");
    }
}

/// A capped build's tile set records how it was built, as an uncapped
/// one's does: the same manifest either way.
#[test]
fn capped_tile_sets_record_their_options() {
    let f = Fixture::new();
    let flags = ["--res", "0.1", "--tile-depth", "10", "--max-range", "5", "--discretize"];
    ok(&[&["build", f.p("s.graph"), "-o", f.p("plain.tiles")], &flags[..]].concat());
    ok(&[&["build", f.p("s.graph"), "-o", f.p("capped.tiles"), "--memory-cap", "1"], &flags[..]].concat());
    let [plain, capped] = ["plain", "capped"]
        .map(|name| octolinear::tiles::read_manifest(&f.path(&format!("{name}.tiles/manifest"))).unwrap());
    let record = capped.build.as_ref().expect("a capped build records its options");
    assert_eq!((record.max_range, record.discretize), (Some(5.0), true));
    assert_eq!(capped, plain);
}

#[test]
fn damaged_tile_sets_are_errors_naming_the_tile_or_manifest_line() {
    let f = Fixture::new();
    let set = f.p("bad.tiles");
    ok(&["build", f.p("s.graph"), "-o", set, "--tile-depth", "6"]);
    let manifest_path = f.path("bad.tiles/manifest");
    let manifest = octolinear::tiles::read_manifest(&manifest_path).unwrap();
    let tile = manifest.tiles.iter().max_by_key(|t| t.bytes).unwrap().id;
    let tile_path = f.path(&format!("bad.tiles/{}", tile.file_name()));
    let original = std::fs::read(&tile_path).unwrap();
    // a flipped bit in the nodes, then a truncated file
    let mut flipped = original.clone();
    let at = flipped.len() - 5;
    flipped[at] ^= 0x10;
    for damaged in [flipped, original[..original.len() - 64].to_vec()] {
        std::fs::write(&tile_path, &damaged).unwrap();
        for args in [vec!["verify", set], vec!["convert", set, f.p("x.ot")], vec!["info", set, "--json"]] {
            if args[0] == "info" {
                ok(&args); // the manifest alone: no tile read
                continue;
            }
            fail(&args, &format!("tile {tile}"));
        }
    }
    std::fs::write(&tile_path, &original).unwrap();
    assert!(ok(&["verify", set]).contains(": ok"));
    let text = std::fs::read_to_string(&manifest_path).unwrap();
    std::fs::write(&manifest_path, text.replacen("tile_depth 6", "tile_depth 7", 1)).unwrap();
    for args in [vec!["verify", set], vec!["info", set], vec!["convert", set, f.p("x.ot")]] {
        fail(&args, "manifest: line");
    }
    std::fs::write(&manifest_path, &text[..text.len() - 3]).unwrap();
    fail(&["verify", set], "does not end with a newline");
    std::fs::remove_file(&manifest_path).unwrap();
    fail(&["info", set], "manifest");
}

#[test]
fn tile_flags_that_cannot_apply_are_refused() {
    let f = Fixture::new();
    let g = f.p("s.graph");
    fail(&["build", g, "-o", f.p("t.tiles"), "--tile-depth", "0"], "--tile-depth must be between 1 and 15");
    fail(&["build", g, "-o", f.p("t.ot"), "--tile-depth", "16"], "--tile-depth must be between 1 and 15");
    fail(&["build", g, "-o", f.p("t.ot"), "--task", "0/2"], "the output must be NAME.tiles");
    fail(&["build", g, "-o", f.p("t.tiles"), "--task", "2/2"], "--task must be K/N");
    fail(&["build", g, "-o", f.p("t.ot"), "--memory-cap", "12X"], "--memory-cap");
    fail(&["build", g, "-o", f.p("t.ot"), "--memory-cap", "0"], "--memory-cap");
    fail(&["build", g, "-o", f.p("t.tiles"), "--compress-ml"], "--compress-ml cannot be tiled");
    fail(&["tiles", "manifest", f.p("none.tiles")], "none.tiles");
    fail_usage(&["tiles", "merge", f.p("x.tiles")], "unrecognized subcommand");
}

#[test]
fn forget_beyond_drops_far_tiles_and_a_wide_window_drops_nothing() {
    let f = Fixture::new();
    let plain = tiled_build_bytes(&f, f.p("plain.ot"), &["--res", "0.1"]);
    // wider than the scene: the map is the plain one
    let wide =
        tiled_build_bytes(&f, f.p("wide.ot"), &["--res", "0.1", "--tile-depth", "11", "--forget-beyond", "1000"]);
    assert!(wide == plain, "a window wider than the scene changed the map");
    let narrow =
        tiled_build_bytes(&f, f.p("narrow.ot"), &["--res", "0.1", "--tile-depth", "11", "--forget-beyond", "2"]);
    assert!(narrow.len() < plain.len(), "{} bytes against {}", narrow.len(), plain.len());
    // the same through a tile set and a memory cap
    let set = f.p("narrow.tiles");
    ok(&["build", f.p("s.graph"), "-o", set, "--res", "0.1", "--tile-depth", "11", "--forget-beyond", "2"]);
    assert!(converted(&f, set, "narrow-set.ot") == narrow);
    let capped = ["--res", "0.1", "--tile-depth", "11", "--forget-beyond", "2", "--memory-cap", "1"];
    assert!(tiled_build_bytes(&f, f.p("narrow-capped.ot"), &capped) == narrow);
    for bad in ["-1", "nan", "inf"] {
        fail(&["build", f.p("s.graph"), "-o", f.p("x.ot"), "--forget-beyond", bad], "--forget-beyond");
    }
    assert!(!f.path("x.ot").exists());
}

// ----- simulate: unlimited range

/// `--range inf` keeps returns beyond the outdoor default of 100 m; a range
/// that is not a number is refused with the field named.
#[test]
fn simulate_takes_an_unlimited_range() {
    let f = Fixture::new();
    let far = |name: &str| {
        let g = graph::read_file(f.path(name)).unwrap();
        g.nodes.iter().flat_map(|n| &n.scan).filter(|p| p.norm() > 100.0).count()
    };
    let args = ["simulate", "--scene", "outdoor", "--scans", "1", "--beams", "8", "--steps", "90"];
    ok(&[&args[..], &["-o", f.p("limited.graph")]].concat());
    ok(&[&args[..], &["--range", "inf", "-o", f.p("unlimited.graph")]].concat());
    assert_eq!(far("limited.graph"), 0);
    assert!(far("unlimited.graph") > 0);
    fail(&["simulate", "--range", "NaN", "-o", f.p("nan.graph")], "max_range = NaN");
}

// ---- tiled maps written to .ot and .bt tile by tile ----

/// `build --json` of `s.graph` to `out`, without the timings and the output name.
fn build_statistics(f: &Fixture, out: &str, flags: &[&str]) -> serde_json::Value {
    let mut args = vec!["build", f.p("s.graph"), "-o", out, "--json"];
    args.extend(flags);
    let mut v = json(&ok(&args));
    for k in ["insert_seconds", "read_seconds", "points_per_second", "output"] {
        v.as_object_mut().unwrap().remove(k);
    }
    v
}

#[test]
fn tiled_builds_to_ot_and_bt_are_written_tile_by_tile_with_the_plain_bytes_and_statistics() {
    let f = Fixture::new();
    let runs =
        [(&["--res", "0.1"][..], &[("1", "5"), ("64M", "9"), ("4K", "13")][..]), (&["--res", "0.2"], &[("1", "2")])];
    for (flags, caps) in runs {
        for ext in ["ot", "bt"] {
            let plain = f.p(&format!("plain.{ext}"));
            let want = build_statistics(&f, plain, flags);
            let want_bytes = std::fs::read(plain).unwrap();
            for &(cap, depth) in caps {
                let out = f.p(&format!("c{cap}-{depth}.{ext}"));
                let capped = [flags, &["--memory-cap", cap, "--tile-depth", depth]].concat();
                assert_eq!(build_statistics(&f, out, &capped), want, "{flags:?} {cap} {depth} .{ext}");
                assert!(std::fs::read(out).unwrap() == want_bytes, "{flags:?} {cap} {depth} .{ext}");
                // tiled without a cap: every tile in memory, the same walk
                let tiled = [flags, &["--tile-depth", depth]].concat();
                assert_eq!(build_statistics(&f, out, &tiled), want, "{flags:?} depth {depth} .{ext}");
                assert!(std::fs::read(out).unwrap() == want_bytes, "{flags:?} depth {depth} .{ext}");
            }
        }
        // a tile set converts to .ot and .bt tile by tile, and to .olm merged
        let set = f.p("streamed.tiles");
        let _ = std::fs::remove_dir_all(set);
        let mut args = vec!["build", f.p("s.graph"), "-o", set, "--tile-depth", "7"];
        args.extend(flags);
        ok(&args);
        for ext in ["ot", "bt", "olm"] {
            let plain = f.p(&format!("plain.{ext}"));
            let mut args = vec!["build", f.p("s.graph"), "-o", plain];
            args.extend(flags);
            ok(&args);
            let want = std::fs::read(plain).unwrap();
            assert!(converted(&f, set, &format!("set.{ext}")) == want, "{flags:?} convert to .{ext}");
        }
    }
}

#[test]
fn a_tile_set_with_a_missing_tile_is_an_error_naming_it_and_leaves_no_output() {
    let f = Fixture::new();
    let set = f.p("gone.tiles");
    ok(&["build", f.p("s.graph"), "-o", set, "--tile-depth", "6"]);
    let manifest = octolinear::tiles::read_manifest(&f.path("gone.tiles/manifest")).unwrap();
    let tile = manifest.tiles.iter().max_by_key(|t| t.bytes).unwrap().id;
    std::fs::remove_file(f.path(&format!("gone.tiles/{}", tile.file_name()))).unwrap();
    for ext in ["ot", "bt"] {
        let out = f.p(&format!("gone.{ext}"));
        fail(&["convert", set, out], &format!("tile {tile}"));
        assert!(!std::path::Path::new(out).exists(), ".{ext} written half");
    }
}

// ---- build statistics against graph2tree

/// The statistics `build` prints are graph2tree's: node, leaf and
/// threshold counts, OctoMap's memory figure, the full grid and the size,
/// for the full and the maximum-likelihood tree, at two resolutions.
#[test]
fn build_prints_the_statistics_graph2tree_prints() {
    let Some(g2t) = tool("graph2tree") else { return };
    let f = Fixture::new();
    let pick = |out: &str| -> Vec<String> {
        out.lines()
            .filter(|l| ["Tree size:", "Memory:", "Full grid:", "Size:"].iter().any(|p| l.starts_with(p)))
            // ours adds what octolinear holds after OctoMap's memory figure
            .map(|l| l.split(" as OctoMap counts it").next().unwrap().to_string())
            .collect()
    };
    for res in ["0.1", "0.05"] {
        let theirs = oracle(&g2t, &["-i", f.p("s.graph"), "-o", f.p("g.bt"), "-res", res]);
        let ours = ok(&["build", f.p("s.graph"), "-o", f.p("o.bt"), "--res", res]);
        let (theirs, ours) = (pick(&theirs), pick(&ours));
        assert_eq!(theirs.len(), 8, "graph2tree printed {theirs:?}");
        assert_eq!(ours, theirs, "res {res}");
    }
}

// ---- planned tile tasks: plan, build --task K/N --plan, tiles manifest

/// Tasks built from a plan combine into the plain build's .ot and .bt
/// bytes; `plan` prints its table and JSON and writes the plan file.
#[test]
fn planned_tasks_combine_to_the_plain_build() {
    let f = Fixture::new();
    let flags = ["--res", "0.1", "--max-range", "6"];
    let want_ot = tiled_build_bytes(&f, f.p("plain.ot"), &flags);
    let want_bt = tiled_build_bytes(&f, f.p("plain.bt"), &flags);
    let plan = f.p("map.plan");
    let mut args = vec!["plan", f.p("s.graph"), "--tile-depth", "10", "--tasks", "3", "-o", plan];
    args.extend(flags);
    let table = ok(&args);
    assert!(table.contains("3 tasks over the tiles of depth 10") && table.contains("Plan written to"), "{table}");
    let text = std::fs::read_to_string(plan).unwrap();
    assert!(text.starts_with("octolinear-tile-plan 1\nresolution 0.1\ntile_depth 10\ntasks 3\ntask 0 0 "), "{text}");
    args.push("--json");
    let json = json(&ok(&args));
    assert_eq!(json["tasks"].as_array().unwrap().len(), 3);
    assert_eq!(json["tasks"][2]["prefix_end"], 1u64 << 30);
    let set = f.p("planned.tiles");
    for k in 0..3 {
        let task = format!("{k}/3");
        let mut args = vec!["build", f.p("s.graph"), "-o", set, "--task", &task, "--plan", plan];
        args.extend(flags);
        assert!(ok(&args).contains(&format!("task {k} of 3")));
    }
    let part = std::fs::read_to_string(f.path("planned.tiles/task-1-of-3.manifest")).unwrap();
    assert!(part.starts_with("octolinear-tiles 2\ntask 1 3 prefixes "), "{part}");
    assert!(part.contains("\nmax_range 4018000000000000\n") && part.contains("\ninput file "), "{part}");
    ok(&["tiles", "manifest", set]);
    assert!(converted(&f, set, "planned.ot") == want_ot);
    assert!(converted(&f, set, "planned.bt") == want_bt);
    assert!(ok(&["plan", "--help"]).contains("Example: octolinear plan scans.graph"));
    assert!(ok(&["build", "--help"]).contains("--plan <PLAN>"));
}

/// A plan that does not fit the build, a damaged plan file, and parts of
/// different splits are refused with the file and the reason.
#[test]
fn bad_and_mismatched_plans_are_refused() {
    let f = Fixture::new();
    let g = f.p("s.graph");
    let plan = f.p("p.plan");
    ok(&["plan", g, "--tile-depth", "6", "--tasks", "2", "-o", plan]);
    let set = f.p("m.tiles");
    fail(&["build", g, "-o", set, "--task", "0/3", "--plan", plan], "--task 0/3 does not match the plan's 2 tasks");
    fail(
        &["build", g, "-o", set, "--task", "0/2", "--plan", plan, "--res", "0.05"],
        "does not match the plan's resolution 0.1",
    );
    fail(
        &["build", g, "-o", set, "--task", "0/2", "--plan", plan, "--tile-depth", "7"],
        "--tile-depth 7 does not match the plan's tile depth 6",
    );
    fail_usage(&["build", g, "-o", set, "--plan", plan], "--task");
    let text = std::fs::read_to_string(plan).unwrap();
    let bad = f.write("bad.plan", text.replace("task 1 ", "task 2 "));
    fail(&["build", g, "-o", set, "--task", "0/2", "--plan", bad], "line 6: task 2 where task 1 comes");
    fail(&["build", g, "-o", set, "--task", "0/2", "--plan", f.p("none.plan")], "cannot read the plan");
    fail(&["plan", g, "--tile-depth", "2", "--tasks", "65"], "--tasks must be between 1 and 64");
    // a planned part beside a hashed one
    ok(&["build", g, "-o", set, "--task", "0/2", "--plan", plan]);
    ok(&["build", g, "-o", set, "--task", "1/2", "--tile-depth", "6"]);
    fail(&["tiles", "manifest", set], "task-1-of-2.manifest shares the tiles by hash");
}

/// Parts built with other options are not combined: the option is named;
/// a part claiming four billion tasks is refused as it is read; a plan or
/// manifest that is a device or a FIFO is refused at once.
#[test]
fn parts_built_otherwise_and_files_that_are_not_files_are_refused() {
    let f = Fixture::new();
    let g = f.p("s.graph");
    let set = f.p("m.tiles");
    ok(&["build", g, "-o", set, "--task", "0/2", "--tile-depth", "6", "--max-range", "20"]);
    ok(&["build", g, "-o", set, "--task", "1/2", "--tile-depth", "6"]);
    fail(&["tiles", "manifest", set], "max_range: none in task-1-of-2.manifest, 20 m in task-0-of-2.manifest");
    ok(&["build", g, "-o", set, "--task", "1/2", "--tile-depth", "6", "--max-range", "20", "--simple"]);
    fail(&["tiles", "manifest", set], "insertion: rays in task-1-of-2.manifest, sets in task-0-of-2.manifest");
    ok(&["build", g, "-o", set, "--task", "1/2", "--tile-depth", "6", "--max-range", "20", "--scans", "2"]);
    fail(&["tiles", "manifest", set], "scans: 2 in task-1-of-2.manifest, all in task-0-of-2.manifest");
    ok(&["build", g, "-o", set, "--task", "1/2", "--tile-depth", "6", "--max-range", "20"]);
    ok(&["tiles", "manifest", set]);
    // a part claiming 2^32 - 1 tasks
    let part = f.path("n.tiles/task-0-of-4294967295.manifest");
    std::fs::create_dir(f.path("n.tiles")).unwrap();
    let body = "octolinear-tiles 1\ntask 0 4294967295\nresolution 3fb999999999999a\ntile_depth 6\ntree_kind OcTree\n\
                hit 3f333333\nmiss bf0a3d71\nclamping_min c0000000\nclamping_max 40000000\n\
                occupancy_threshold 00000000\ntiles 0\n";
    std::fs::write(&part, format!("{body}crc32 {:08x}\n", crc32fast::hash(body.as_bytes()))).unwrap();
    fail_within(10, &["tiles", "manifest", f.p("n.tiles")], "line 2: expected `task K N`");
    fail(&["build", g, "-o", set, "--task", "0/65537"], "--task must be K/N with 0 <= K < N <= 65536");
    fail(&["plan", g, "--tile-depth", "8", "--tasks", "65537"], "--tasks must be between 1 and 65536");
    // devices and FIFOs
    fail_within(10, &["build", g, "-o", f.p("p.tiles"), "--task", "0/2", "--plan", "/dev/zero"], "not a regular file");
    let fifo = f.path("fifo.plan");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    fail_within(10, &["build", g, "-o", f.p("p.tiles"), "--task", "0/2", "--plan", s(&fifo)], "a FIFO");
    std::fs::create_dir(f.path("q.tiles")).unwrap();
    assert!(Command::new("mkfifo").arg(f.path("q.tiles/manifest")).status().unwrap().success());
    fail_within(10, &["info", f.p("q.tiles")], "a FIFO, not a regular file");
}

/// Runs and requires a failure as [`fail`] does, within `secs` seconds: a
/// run still going then is killed and the test fails instead of hanging.
fn fail_within(secs: u64, args: &[&str], needle: &str) {
    use std::io::Read;
    let mut child = bin()
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("binary runs");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(secs);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if std::time::Instant::now() > deadline {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("{args:?} still ran after {secs} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let mut err = String::new();
    child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert!(!status.success(), "{args:?} succeeded: {err}");
    assert!(!err.contains("panicked") && status.code() == Some(1), "{args:?}: {status} {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    assert!(err.starts_with("octolinear: error: "), "{args:?}: {err}");
    assert!(err.contains(needle), "{args:?}: {err:?} lacks {needle:?}");
}

/// A LAS 1.4 file of two points whose header announces one EVLR after
/// them, of `claim` bytes, and holds only that record's 60-byte header.
fn las_with_evlr_claim(f: &Fixture, name: &str, claim: u64) -> Vec<u8> {
    let path = f.path(name);
    let mut w = las::Writer::from_path(&path, las::Builder::from((1, 4)).into_header().unwrap()).unwrap();
    for x in [1.0, 2.0] {
        w.write_point(las::Point { x, y: 1.0, z: 0.5, ..Default::default() }).unwrap();
    }
    w.close().unwrap();
    drop(w);
    let mut bytes = std::fs::read(&path).unwrap();
    let start = bytes.len() as u64;
    bytes[235..243].copy_from_slice(&start.to_le_bytes());
    bytes[243..247].copy_from_slice(&1u32.to_le_bytes());
    let mut evlr = [0u8; 60];
    evlr[20..28].copy_from_slice(&claim.to_le_bytes());
    bytes.extend_from_slice(&evlr);
    bytes
}

#[test]
fn las_headers_claiming_more_than_the_file_holds_are_refused() {
    let f = Fixture::new();
    // the untouched file reads
    let good = las_with_evlr_claim(&f, "good.las", 0);
    ok(&["build", "--points", f.write("good.las", &good), "-o", f.p("good.bt")]);
    for claim in [1u64 << 40, 3 << 30] {
        let bytes = las_with_evlr_claim(&f, "evlr.las", claim);
        let len = bytes.len();
        let path = f.write("evlr.las", &bytes);
        let started = std::time::Instant::now();
        let needle = format!("evlr.las: not a valid .las file: EVLR 0's record length ({claim}) runs past the end of the file ({len} bytes)");
        fail_within(20, &["build", "--points", path, "-o", f.p("x.bt")], &needle);
        assert!(started.elapsed() < std::time::Duration::from_secs(5), "{claim}: {:?}", started.elapsed());
        assert!(!f.path("x.bt").exists());
    }
    let patched = |at: usize, value: &[u8]| {
        let mut b = good.clone();
        b[at..at + value.len()].copy_from_slice(value);
        // the legacy point count gives way to the 64-bit one
        if at == 247 {
            b[107..111].fill(0);
        }
        b
    };
    let len = good.len();
    let cases: [(&str, Vec<u8>, String); 5] = [
        (
            "vlrs.las",
            patched(100, &u32::MAX.to_le_bytes()),
            format!("number of VLRs ({}) needs more than the file's {len} bytes", u32::MAX),
        ),
        (
            "data.las",
            patched(96, &(1u32 << 31).to_le_bytes()),
            format!("offset to point data ({}) lies beyond the end of the file ({len} bytes)", 1u32 << 31),
        ),
        (
            "points.las",
            patched(247, &(1u64 << 40).to_le_bytes()),
            format!("{} point records of 20 bytes from byte 375 need more than the file's {len} bytes", 1u64 << 40),
        ),
        (
            "evlrs.las",
            patched(243, &u32::MAX.to_le_bytes()),
            format!("number of EVLRs ({}) needs more than the file's {len} bytes", u32::MAX),
        ),
        (
            "start.las",
            patched(235, &(1u64 << 40).to_le_bytes()),
            format!("start of the first EVLR ({}) lies beyond the end of the file ({len} bytes)", 1u64 << 40),
        ),
    ];
    for (name, bytes, needle) in cases {
        fail_within(20, &["build", "--points", f.write(name, &bytes), "-o", f.p("x.bt")], &needle);
    }
}

#[test]
fn endless_inputs_are_refused_quickly() {
    let f = Fixture::new();
    for name in ["z.xyz", "z.ply", "z.pcd", "z.las", "z.binvox", "z.log", "z.txt"] {
        std::os::unix::fs::symlink("/dev/zero", f.path(name)).unwrap();
    }
    f.write("c.xyz", "1 0 0\n0 1 0\n");
    let long = format!("line 1 is longer than {} bytes", 1 << 20);
    let header = format!("header line 1 is longer than {} bytes", 1 << 20);
    let out = f.p("out.bt");
    fail_within(20, &["build", "--points", f.p("z.xyz"), "-o", out], &format!("z.xyz: not a valid .xyz file: {long}"));
    fail_within(
        20,
        &["build", "--points", "/dev/zero", "-o", out],
        &format!("/dev/zero: not a valid xyz file: {long}"),
    );
    fail_within(
        20,
        &["build", "--points", f.p("z.ply"), "-o", out],
        &format!("z.ply: not a valid .ply file: {header}"),
    );
    fail_within(
        20,
        &["build", "--points", f.p("z.pcd"), "-o", out],
        &format!("z.pcd: not a valid .pcd file: {header}"),
    );
    fail_within(20, &["build", "--points", f.p("z.las"), "-o", out], "z.las: not a LAS/LAZ file");
    fail_within(
        20,
        &["build", "--points", f.p("c.xyz"), "--trajectory", f.p("z.txt"), "-o", out],
        &format!("z.txt {long}"),
    );
    fail_within(20, &["binvox", f.p("z.binvox"), "-o", out], &format!("z.binvox: not a binvox file: {header}"));
    assert!(!f.path("out.bt").exists());
    fail_within(20, &["log2graph", f.p("z.log"), f.p("out.graph")], &format!("z.log: not a valid scan log: {long}"));
    assert!(!f.path("out.graph").exists());
    fail_within(20, &["query", f.p("a.bt"), "--points", f.p("z.xyz")], &format!("z.xyz: {long}"));
    fail_within(20, &["eval", f.p("a.bt"), "/dev/zero"], "/dev/zero holds no scans");
    fail_within(20, &["eval", "/dev/zero"], "/dev/zero holds no scans");
}

#[test]
fn eval_without_known_voxels_is_an_error() {
    let f = Fixture::new();
    // one scan far from the map: every voxel it observes is unknown
    f.write("far.log", "NODE 500 500 500 0 0 0\n501 500 500\n");
    ok(&["log2graph", f.p("far.log"), f.p("far.graph")]);
    fail(&["eval", f.p("a.bt"), f.p("far.graph")], "none of them known to the map: the accuracy is undefined");
}

/// A map whose root has one occupied child at `depth`, a leaf standing for
/// `8^(16 - depth)` voxels, as the library writes it (138 bytes at depth 1).
fn one_coarse_leaf_bt(depth: u8) -> Vec<u8> {
    let mut b = octolinear::tree::PreorderBuilder::new();
    for d in 0..=depth {
        b.push(2.0, if d == depth { 0 } else { 1 }, u64::from(d)).unwrap();
    }
    let tree = b.finish(0.1, Default::default()).unwrap().unwrap();
    let mut file = Vec::new();
    octolinear::formats::bt::write(&tree, &mut file).unwrap();
    file
}

#[test]
fn expanding_coarse_leaves_is_counted_and_refused_past_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let bytes = one_coarse_leaf_bt(1);
    assert_eq!(bytes.len(), 138);
    std::fs::write(p("one.bt"), bytes).unwrap();
    let added = (8u64.pow(16) - 8) / 7;
    let want = format!("--expand: expand: {added} nodes to add exceed the limit of 268435456 (2^28)");
    fail(&["edit", &p("one.bt"), &p("x.ot"), "--expand"], &want);
    fail(&["edit", &p("one.bt"), &p("x.ot"), "--expand"], "--max-nodes");
    fail(&["edit", &p("one.bt"), &p("x.ot"), "--expand", "--max-nodes", "1000"], "exceed the limit of 1000;");
    assert!(!dir.path().join("x.ot").exists());
    fail(&["to-points", &p("one.bt"), "-o", &p("x.xyz")], "exceed the limit of 268435456 (2^28) points");
    // a leaf at depth 14 adds 8 + 64 nodes: the limit is the nodes added
    std::fs::write(p("d14.bt"), one_coarse_leaf_bt(14)).unwrap();
    fail(
        &["edit", &p("d14.bt"), &p("y.ot"), "--expand", "--max-nodes", "71"],
        "72 nodes to add exceed the limit of 71",
    );
    ok(&["edit", &p("d14.bt"), &p("y.ot"), "--expand", "--max-nodes", "72"]);
    let info = ok(&["info", &p("y.ot"), "--json"]);
    assert!(info.contains("\"nodes\": 87") || info.contains("\"nodes\":87"), "{info}");
}

#[test]
fn cropping_through_coarse_leaves_is_counted_and_refused_past_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    std::fs::write(p("one.bt"), one_coarse_leaf_bt(1)).unwrap();
    let (one, out) = (p("one.bt"), p("x.ot"));
    // a box whose faces cut the depth-1 leaf: 3600743495 nodes along them
    let big = ["--min", "-2000.05", "-2000.05", "-2000.05", "--max", "-0.15", "-0.15", "-0.15"];
    let args: Vec<&str> = ["crop", &one, &out].into_iter().chain(big).collect();
    fail(&args, "crop: splitting the pruned nodes that straddle the box makes 3600743495 nodes, more than the limit");
    let args: Vec<&str> = ["edit", &one, &out].into_iter().chain(big).collect();
    fail(&args, "of 268435456; a higher --max-nodes allows it");
    assert!(!dir.path().join("x.ot").exists());
    // the count is exact: the root and the leaf, and the split nodes
    let small = ["--min", "-10.05", "-3.35", "-7.15", "--max", "-0.15", "-0.25", "-1.05"];
    let with = |limit: &'static str| -> Vec<&str> {
        ["crop", one.as_str(), out.as_str()].into_iter().chain(small).chain(["--max-nodes", limit]).collect()
    };
    fail(&with("11540"), "makes 11541 nodes, more than the limit of 11540;");
    // rendering at a coarser depth enumerates the leaf's nodes of that depth
    let png = p("view.png");
    let view = ["render", one.as_str(), "-o", png.as_str(), "--view", "perspective", "--depth", "15"];
    fail(&view, &format!("render: {} points exceed the limit of 268435456 (2^28)", 8u64.pow(14)));
    assert!(!dir.path().join("view.png").exists());
    ok(&with("11541"));
    let info = ok(&["info", &out, "--json"]);
    assert!(info.contains("\"nodes\": 11543") || info.contains("\"nodes\":11543"), "{info}");
}

#[test]
fn resolutions_outside_the_usable_range_are_refused_by_every_command() {
    let f = Fixture::new();
    let (a, out) = (f.p("a.bt"), f.p("x.bt"));
    fail(&["edit", a, out, "--res", "1e-300"], "--res 1e-300: resolution 1e-300 m is below the smallest usable");
    fail(&["edit", a, out, "--res", "1e300"], "--res 1e300: resolution 1e300 m is above the largest usable");
    fail(&["edit", a, out, "--scale", "1e300"], "--scale 1e300 (of resolution 0.1 m): resolution 1");
    fail(&["edit", a, out, "--scale", "1e300"], "m is above the largest usable resolution");
    fail(&["edit", a, out, "--scale", "1e-300"], "m is below the smallest usable resolution");
    assert!(!f.path("x.bt").exists());
    ok(&["edit", a, out, "--scale", "2"]);
    let (g, plan) = (f.p("s.graph"), f.p("p.plan"));
    fail(&["plan", g, "--tile-depth", "4", "--tasks", "2", "-o", plan, "--res", "1e-300"], "--res: resolution 1e-300");
    fail(&["build", g, "-o", f.p("t.tiles"), "--tile-depth", "4", "--res", "1e300"], "--res: resolution 1e300 m");
    // a map file claiming such a resolution: the value and its offset
    let good = std::fs::read(f.path("a.bt")).unwrap();
    let at = good.windows(8).position(|w| w == b"res 0.1\n").unwrap() + 4;
    let mut bad = good[..at].to_vec();
    bad.extend_from_slice(b"1e-300");
    bad.extend_from_slice(&good[at + 3..]);
    let bad = f.write("bad.bt", bad);
    fail(&["info", bad], "resolution 1e-300 m is below the smallest usable resolution");
    fail(&["info", bad], &format!("at byte {at}"));
}

// ---- tile sets: tiles checked against the manifest, one writer, links, spills

/// The set's manifest with the CRC-32 of its largest tile changed (as if
/// that tile's file had been swapped for the same tile of another build:
/// same length, node count and root); the tile.
fn mislabel_largest_tile(set: &Path) -> octolinear::tiles::TileId {
    let path = set.join("manifest");
    let mut m = octolinear::tiles::read_manifest(&path).unwrap();
    let entry = m.tiles.iter_mut().max_by_key(|t| t.bytes).unwrap();
    entry.crc32 ^= 0x0100_0001;
    let tile = entry.id;
    std::fs::write(&path, m.to_bytes()).unwrap();
    tile
}

#[test]
fn a_tile_file_other_than_the_manifests_fails_every_reader_and_writes_nothing() {
    let f = Fixture::new();
    let set = f.p("swap.tiles");
    ok(&["build", f.p("s.graph"), "-o", set, "--tile-depth", "6"]);
    let tile = mislabel_largest_tile(Path::new(set));
    let needle = format!("tile {tile} ({}", f.path("swap.tiles").join(tile.file_name()).display());
    fail(&["verify", set], &needle);
    for ext in ["ot", "bt", "olm"] {
        let out = f.p(&format!("swap.{ext}"));
        fail(&["convert", set, out], &needle);
        fail(&["convert", set, out], "CRC-32");
        assert!(!Path::new(out).exists(), ".{ext} written");
    }
    fail(&["compare", set, f.p("a.ot")], &needle);
}

/// A build into a set another build holds (or a task build beside a whole
/// build, the same task twice, `tiles manifest` meanwhile) fails at once,
/// naming the set and the lock; tasks of one set build side by side.
#[test]
fn one_build_at_a_time_writes_a_tile_set() {
    use octolinear::tiles::{SetLock, TaskPart};
    let f = Fixture::new();
    let g = f.p("s.graph");
    let set = f.p("locked.tiles");
    ok(&["build", g, "-o", set, "--tile-depth", "6"]);
    let before = std::fs::read(f.path("locked.tiles/manifest")).unwrap();
    let held = SetLock::acquire(Path::new(set)).unwrap();
    let needle = format!("{set}: another build (or `tiles manifest`) is writing this tile set");
    fail(&["build", g, "-o", set, "--tile-depth", "6", "--max-range", "2"], &needle);
    fail(&["build", g, "-o", set, "--tile-depth", "6", "--memory-cap", "1M"], &needle);
    fail(&["build", g, "-o", set, "--tile-depth", "6", "--task", "0/2"], "a build of the whole set");
    fail(&["tiles", "manifest", set], "is writing this tile set");
    assert!(std::fs::read(f.path("locked.tiles/manifest")).unwrap() == before, "the set changed under its lock");
    drop(held);
    let task = SetLock::acquire_task(Path::new(set), TaskPart::hashed(0, 2)).unwrap();
    fail(&["build", g, "-o", set, "--tile-depth", "6", "--task", "0/2"], "another build of task 0 of 2");
    fail(&["build", g, "-o", set, "--tile-depth", "6"], "is writing this tile set");
    ok(&["build", g, "-o", set, "--tile-depth", "6", "--task", "1/2"]);
    drop(task);
    ok(&["build", g, "-o", set, "--tile-depth", "6", "--task", "0/2"]);
    ok(&["tiles", "manifest", set]);
    assert!(converted(&f, set, "locked.ot") == std::fs::read(f.path("a.ot")).unwrap());
    // no lock file stays behind
    assert!(!f.path("locked.tiles/.lock").exists());
    // two builds started together: one writes, the other fails at once
    ok(&["simulate", "--scans", "12", "--beams", "32", "--steps", "720", "-o", f.p("big.graph")]);
    let args = ["build", f.p("big.graph"), "-o", f.p("race.tiles"), "--tile-depth", "9"];
    let spawn = || bin().args(args).stdout(std::process::Stdio::null()).stderr(std::process::Stdio::piped()).spawn();
    let children: Vec<_> = (0..2).map(|_| spawn().unwrap()).collect();
    let done: Vec<_> = children.into_iter().map(|c| c.wait_with_output().unwrap()).collect();
    let failed: Vec<_> = done.iter().filter(|d| !d.status.success()).collect();
    assert!(failed.len() <= 1, "both failed");
    for d in failed {
        assert!(String::from_utf8_lossy(&d.stderr).contains("is writing this tile set"));
    }
    assert!(ok(&["verify", f.p("race.tiles")]).contains(": ok"));
}

/// Links inside a set named like its tiles, its manifest or a task's part,
/// pointing outside, are replaced by the build's files (or refuse the
/// build); what they point to is never written.
#[cfg(unix)]
#[test]
fn builds_into_a_set_never_write_through_links_inside_it() {
    let f = Fixture::new();
    let g = f.p("s.graph");
    let set = f.path("links.tiles");
    ok(&["build", g, "-o", s(&set), "--tile-depth", "6"]);
    let manifest = octolinear::tiles::read_manifest(&set.join("manifest")).unwrap();
    let outside = f.path("outside");
    std::fs::create_dir(&outside).unwrap();
    let mut names: Vec<String> = manifest.tiles.iter().map(|t| t.id.file_name()).collect();
    names.push("task-0-of-2.manifest".into());
    let link = |name: &str| {
        std::fs::write(outside.join(name), "precious").unwrap();
        let _ = std::fs::remove_file(set.join(name));
        std::os::unix::fs::symlink(outside.join(name), set.join(name)).unwrap();
    };
    for name in &names[..names.len() - 1] {
        link(name);
    }
    ok(&["build", g, "-o", s(&set), "--tile-depth", "6"]);
    ok(&["build", g, "-o", s(&set), "--tile-depth", "6", "--memory-cap", "1"]);
    for name in &names[..names.len() - 1] {
        link(name);
    }
    ok(&["build", g, "-o", s(&set), "--tile-depth", "6", "--task", "0/2"]);
    // links named like the manifest or a part: refused, or replaced
    link("manifest");
    link("task-0-of-2.manifest");
    let _ = run(&["build", g, "-o", s(&set), "--tile-depth", "6", "--task", "0/2"]);
    let _ = run(&["build", g, "-o", s(&set), "--tile-depth", "6"]);
    for name in names.iter().chain([&"manifest".to_string()]) {
        assert_eq!(std::fs::read_to_string(outside.join(name)).unwrap(), "precious", "{name} written through");
    }
}

/// `build -o NAME.tiles` where NAME.tiles is a file says so once, and
/// what to do.
#[test]
fn a_tile_set_output_that_is_a_file_is_refused_with_what_to_do() {
    let f = Fixture::new();
    let out = f.write("file.tiles", "not a set");
    for flags in [&[][..], &["--memory-cap", "1M"], &["--task", "0/2"]] {
        let mut args = vec!["build", f.p("s.graph"), "-o", out];
        args.extend(flags);
        fail(&args, &format!("{out} exists and is not a directory (a tile set is a directory): remove it"));
        let err = String::from_utf8_lossy(&run(&args).stderr).into_owned();
        assert!(!err.contains("os error"), "{err}");
    }
    assert_eq!(std::fs::read_to_string(out).unwrap(), "not a set");
}

/// A set of far more tile bytes than its map is built with a warning
/// saying so; `build --help` says how to choose the depth.
#[test]
fn tile_sets_far_larger_than_their_map_are_warned_about() {
    let f = Fixture::new();
    let sample = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/indoor.graph");
    let build = |depth: &str| {
        let out = bin()
            .args(["build", sample, "-o", f.p(&format!("d{depth}.tiles")), "--tile-depth", depth])
            .output()
            .unwrap();
        assert!(out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    assert_eq!(build("8"), "");
    let warned = build("14");
    assert!(warned.starts_with("octolinear: warning: ") && warned.contains("the 3907 tiles at depth 14"), "{warned}");
    assert!(warned.contains("smaller tile depth") && warned.trim_end().lines().count() == 1, "{warned}");
    let help = ok(&["build", "--help"]);
    assert!(help.contains("res * 2^(16-D)") && help.contains("aim for"), "{help}");
}

/// A capped build to `.ot` ended by a signal leaves no spill directory;
/// one killed outright leaves it to the next write of the same output,
/// which removes it.
#[cfg(unix)]
#[test]
fn spill_directories_go_with_signals_and_after_a_kill() {
    let f = Fixture::new();
    ok(&["simulate", "--scans", "24", "--beams", "64", "--steps", "1250", "-o", f.p("big.graph")]);
    let spill = |pid: u32| f.path(&format!(".big.ot.spill-{pid}"));
    for signal in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP, libc::SIGKILL] {
        let args = ["build", f.p("big.graph"), "-o", f.p("big.ot"), "--memory-cap", "1M", "--tile-depth", "10"];
        let mut child = bin().args(args).stdout(std::process::Stdio::null()).spawn().unwrap();
        let pid = child.id();
        let started = std::time::Instant::now();
        while !spill(pid).exists() {
            assert!(started.elapsed().as_secs() < 20, "no spill directory appeared");
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        // a few tiles written out first
        std::thread::sleep(std::time::Duration::from_millis(100));
        // SAFETY: kill(2) on the child's pid, which has not been waited for
        assert_eq!(unsafe { libc::kill(pid as libc::pid_t, signal) }, 0);
        let status = child.wait().unwrap();
        assert_eq!(std::os::unix::process::ExitStatusExt::signal(&status), Some(signal), "{status:?}");
        if signal == libc::SIGKILL {
            assert!(spill(pid).is_dir(), "a killed build leaves its spill directory");
            ok(&["build", f.p("s.graph"), "-o", f.p("big.ot")]);
        }
        assert!(!spill(pid).exists(), "signal {signal}: {} left", spill(pid).display());
        assert!(!f.path("big.ot").exists() || signal == libc::SIGKILL);
    }
}

#[test]
fn a_fifo_named_twice_is_refused_before_it_is_opened() {
    let f = Fixture::new();
    let fifo = f.path("points.xyz");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let p = f.p("points.xyz");
    // no writer ever opens the FIFO: opening it would wait for ever
    fail_within(20, &["build", "--points", p, "--points", p, "-o", f.p("x.bt")], "--points names");
    fail_within(20, &["build", "--points", "-", "--points", "-", "-o", f.p("x.bt")], "more than once");
    std::os::unix::fs::symlink("/dev/zero", f.path("z.binvox")).unwrap();
    fail_within(
        20,
        &["binvox", f.p("z.binvox"), "/dev/zero", "-o", f.p("x.bt")],
        "binvox names /dev/zero more than once",
    );
    assert!(!f.path("x.bt").exists());
}
