//! The programs in `examples/` run, on the bundled samples (their defaults)
//! and on inputs made here, and their outputs say what the library says:
//! maps byte for byte, query answers, a wall on a drone's path, every
//! occupied voxel exported.

use octolinear::formats::{bt, graph, ot, pcd, ply, xyz};
use octolinear::geometry::graph2tree_transform;
use octolinear::{mapped, CastOptions, CastOutcome, OccupancyTree, Point3, Pose6D, ScanOptions};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

const SAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/samples");

/// The example programs by name, built by cargo with this test's profile
/// (a no-op when they are up to date; a filtered `cargo test --test
/// examples` builds no examples itself).
fn examples() -> &'static HashMap<String, PathBuf> {
    static BUILT: OnceLock<HashMap<String, PathBuf>> = OnceLock::new();
    BUILT.get_or_init(|| {
        // this test runs from target/<profile directory>/deps/
        let exe = std::env::current_exe().expect("test executable path");
        let dir = exe.parent().and_then(Path::parent).and_then(Path::file_name).expect("target/<profile>/deps");
        // `cargo test` builds into target/debug with the test profile
        let profile = match dir.to_str().expect("utf-8 profile directory") {
            "debug" => "test",
            other => other,
        };
        let out = Command::new(env!("CARGO"))
            .args(["build", "--package", "octolinear", "--examples", "--profile", profile])
            .arg("--message-format=json-render-diagnostics")
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .expect("cargo runs");
        assert!(out.status.success(), "building the examples failed: {}", String::from_utf8_lossy(&out.stderr));
        let mut built = HashMap::new();
        for line in String::from_utf8(out.stdout).expect("utf-8 cargo messages").lines() {
            let message: serde_json::Value = serde_json::from_str(line).expect("cargo's JSON messages");
            let target = &message["target"];
            if message["reason"] == "compiler-artifact" && target["kind"][0] == "example" {
                let name = target["name"].as_str().expect("target name").to_string();
                built.insert(name, PathBuf::from(message["executable"].as_str().expect("an example's executable")));
            }
        }
        built
    })
}

/// Runs an example in `dir`.
fn run(example: &str, dir: &Path, args: &[&str]) -> Output {
    let exe = examples().get(example).unwrap_or_else(|| panic!("no example named {example}"));
    Command::new(exe).args(args).current_dir(dir).output().expect("the example runs")
}

/// Runs an example in `dir` and requires success; returns its stdout.
fn ok(example: &str, dir: &Path, args: &[&str]) -> String {
    let out = run(example, dir, args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{example} {args:?} failed: {stderr}");
    String::from_utf8(out.stdout).expect("utf-8 output")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// The bundled clouds and poses built here the long way: each cloud read
/// by its format's reader, each pose line parsed, the scans inserted one
/// at a time.
fn sample_clouds_map() -> OccupancyTree {
    let dir = Path::new(SAMPLES).join("scans");
    let clouds = [
        ply::read(&std::fs::read(dir.join("scan0.ply")).unwrap(), false).unwrap().cloud,
        pcd::read(&std::fs::read(dir.join("scan1.pcd")).unwrap(), false).unwrap().cloud,
        xyz::read_file(dir.join("scan2.xyz")).unwrap(),
    ];
    let poses: Vec<Pose6D> = std::fs::read_to_string(dir.join("poses.txt"))
        .unwrap()
        .lines()
        .filter(|line| !line.starts_with('#'))
        .map(|line| {
            let v: Vec<f64> = line.split_whitespace().map(|c| c.parse().unwrap()).collect();
            Pose6D::from_euler(v[0] as f32, v[1] as f32, v[2] as f32, v[3], v[4], v[5])
        })
        .collect();
    assert_eq!(poses.len(), clouds.len());
    let mut tree = OccupancyTree::new(0.1).unwrap();
    for (cloud, pose) in clouds.iter().zip(&poses) {
        assert!(cloud.len() > 1000, "a sample cloud holds {} points", cloud.len());
        let (points, origin) = graph2tree_transform(pose, cloud);
        tree.insert_point_cloud(&points.points, origin, &ScanOptions::default()).unwrap();
    }
    tree
}

/// The map of `samples/indoor.graph`, as `graph2tree` builds it.
fn sample_graph_map() -> OccupancyTree {
    let mut tree = OccupancyTree::new(0.1).unwrap();
    for node in graph::read_file(Path::new(SAMPLES).join("indoor.graph")).unwrap().nodes {
        let (points, origin) = node.graph2tree();
        tree.insert_point_cloud(&points.points, origin, &ScanOptions::default()).unwrap();
    }
    tree
}

fn bt_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut bytes = Vec::new();
    bt::write(tree, &mut bytes).unwrap();
    bytes
}

/// A 2 x 2 m wall at x = 2 (the voxels with centres x = 2.05), scanned
/// from the origin: free space in the cone between, unknown elsewhere.
fn wall_map() -> OccupancyTree {
    let mut tree = OccupancyTree::new(0.1).unwrap();
    let wall: Vec<Point3> = (0..=40)
        .flat_map(|i| (0..=40).map(move |j| Point3::new(2.0, -1.0 + 0.05 * i as f32, -1.0 + 0.05 * j as f32)))
        .collect();
    tree.insert_point_cloud(&wall, Point3::new(0.0, 0.0, 0.0), &ScanOptions::default()).unwrap();
    tree
}

#[test]
fn build_map_writes_what_the_library_builds() {
    let dir = tempfile::tempdir().unwrap();
    let expected = sample_clouds_map();

    // defaults: the bundled clouds and poses, into scans.bt
    let stdout = ok("build_map", dir.path(), &[]);
    assert_eq!(stdout.lines().filter(|l| l.starts_with("scan ")).count(), 3, "{stdout}");
    assert!(stdout.contains(&format!("{} leaves", expected.num_leaves())), "{stdout}");
    assert_eq!(std::fs::read(dir.path().join("scans.bt")).unwrap(), bt_bytes(&expected));

    // the same inputs named, into a memory-mapped map
    let clouds = ["poses.txt", "scan0.ply", "scan1.pcd", "scan2.xyz"].map(|f| format!("{SAMPLES}/scans/{f}"));
    let olm = dir.path().join("scans.olm");
    let args: Vec<&str> = [s(&olm)].into_iter().chain(clouds.iter().map(String::as_str)).collect();
    ok("build_map", dir.path(), &args);
    let map = mapped::read_file(&olm).unwrap();
    assert_eq!(map.num_leaves(), expected.num_leaves());
    assert!(map.leaves(0).zip(expected.leaves(0)).all(|(a, b)| (a.key, a.depth, a.value) == (b.key, b.depth, b.value)));

    // a scan graph, into an .ot file; its .bt is the bundled sample map
    let full = sample_graph_map();
    let out = dir.path().join("indoor.ot");
    ok("build_map", dir.path(), &[s(&out), &format!("{SAMPLES}/indoor.graph")]);
    let mut ot_bytes = Vec::new();
    ot::write(&full, &mut ot_bytes).unwrap();
    assert_eq!(std::fs::read(&out).unwrap(), ot_bytes);
    let bundled = std::fs::read(Path::new(SAMPLES).join("indoor.bt")).unwrap();
    assert!(bundled == bt_bytes(&full), "samples/indoor.bt is not the map of samples/indoor.graph");
}

#[test]
fn build_map_refuses_poses_that_do_not_match_the_clouds() {
    let dir = tempfile::tempdir().unwrap();
    let poses = dir.path().join("poses.txt");
    std::fs::write(&poses, "0 0 1 0 0 0\n").unwrap();
    let cloud = format!("{SAMPLES}/scans/scan2.xyz");
    let out = dir.path().join("map.bt");
    let failed = run("build_map", dir.path(), &[s(&out), s(&poses), &cloud, &cloud]);
    assert!(!failed.status.success());
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert!(stderr.contains("has 1 poses for 2 clouds") && stderr.contains(s(&poses)), "{stderr}");
    assert!(!out.exists());

    std::fs::write(&poses, "0 0 1 0 0\n").unwrap();
    let failed = run("build_map", dir.path(), &[s(&out), s(&poses), &cloud]);
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert!(!failed.status.success() && stderr.contains("line 1") && stderr.contains("not six numbers"), "{stderr}");
}

#[test]
fn mapped_queries_answers_as_the_tree() {
    let dir = tempfile::tempdir().unwrap();
    bt::write_file(&wall_map(), dir.path().join("wall.bt")).unwrap();
    // what the example maps is the map as its .bt file holds it
    let tree = bt::read_file(dir.path().join("wall.bt")).unwrap();

    let stdout = ok("mapped_queries", dir.path(), &["wall.bt", "0.3", "0", "0"]);
    assert!(stdout.starts_with("wall.olm written from wall.bt\n"), "{stdout}");
    let map = mapped::read_file(&dir.path().join("wall.olm")).unwrap();
    assert_eq!(bt_bytes(&map), bt_bytes(&tree));
    let verified = format!("{} nodes, {} leaves", tree.size(), tree.num_leaves());
    assert!(stdout.contains(&verified), "{stdout} lacks {verified:?}");
    assert!(stdout.contains("position (0.3, 0, 0): free (p = 0.119"), "{stdout}");
    assert!(stdout.contains("100 m above (0.3, 0, 100): unknown"), "{stdout}");

    // the line of 40 voxels along +y, as the tree answers
    let along: String = (0..40)
        .map(|i| match tree.search_point(Point3::new(0.3, 0.1 * i as f32, 0.0), 0).unwrap() {
            None => '?',
            Some(node) if tree.is_occupied(node.value) => '#',
            Some(_) => '.',
        })
        .collect();
    assert!(along.starts_with("..") && along.ends_with('?'), "{along}");
    assert!(stdout.contains(&format!("along +y: {along}\n")), "{stdout}");

    // the ray towards the wall meets it where the tree's ray does; the one
    // away from it meets unknown space
    let opts = CastOptions { ignore_unknown: false, max_range: Some(20.0) };
    let origin = Point3::new(0.3, 0.0, 0.0);
    let CastOutcome::Occupied { end } = tree.cast_ray(origin, Point3::new(1.0, 0.0, 0.0), opts).unwrap() else {
        panic!("the wall is not in the way")
    };
    assert_eq!(end.x, 2.05);
    let hit = format!("ray towards   0 degrees hits an occupied voxel at {:.2} m", end.distance(origin));
    assert!(stdout.contains(&hit), "{stdout} lacks {hit:?}");
    assert!(stdout.contains("ray towards 180 degrees meets unknown space"), "{stdout}");

    // an .olm map is opened as it is
    let stdout = ok("mapped_queries", dir.path(), &[s(&dir.path().join("wall.olm")), "0.3", "0", "0"]);
    assert!(!stdout.contains("written") && stdout.contains(&hit), "{stdout}");
}

#[test]
fn collision_check_stops_at_the_wall() {
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("wall.bt");
    bt::write_file(&wall_map(), &map).unwrap();
    let path = dir.path().join("path.xyz");
    // towards the wall, sideways, then through the wall
    std::fs::write(&path, "0.5 0 0\n1.2 0 0\n1.2 0.3 0  # y 0.3: voxel centres 0.35\n3 0.3 0\n").unwrap();

    // the first voxel of the path within 3 voxels of the wall's (x 2.05)
    let stdout = ok("collision_check", dir.path(), &[s(&map), s(&path)]);
    assert!(stdout.contains("segment 1 (waypoint 1 to 2, 0.70 m): clear"), "{stdout}");
    assert!(stdout.contains("segment 2 (waypoint 2 to 3, 0.30 m): clear"), "{stdout}");
    let collision = "first collision: segment 3 (waypoint 3 to 4), path voxel at (1.75, 0.35, 0.05), 0.55 m along it; \
                     occupied voxel at (2.05, 0.35, 0.05)";
    assert!(stdout.contains(collision), "{stdout} lacks {collision:?}");
    // a margin of one voxel lets the path come closer
    let stdout = ok("collision_check", dir.path(), &["--margin", "0.1", s(&map), s(&path)]);
    assert!(stdout.contains("segment 3 (waypoint 3 to 4), path voxel at (1.95, 0.35, 0.05)"), "{stdout}");

    // the first two segments keep their distance from the wall; the cube
    // around the first waypoint reaches past the scanned cone (|z| < 0.25
    // at x = 0.5), which counts with --unknown-is-obstacle
    std::fs::write(&path, "0.5 0 0\n1.2 0 0\n1.2 0.3 0\n").unwrap();
    let stdout = ok("collision_check", dir.path(), &[s(&map), s(&path)]);
    assert!(stdout.ends_with("the path is clear\n"), "{stdout}");
    let stdout = ok("collision_check", dir.path(), &["--unknown-is-obstacle", s(&map), s(&path)]);
    assert!(
        stdout.contains("first collision: segment 1 (waypoint 1 to 2), path voxel at (0.55, 0.05, 0.05)"),
        "{stdout}"
    );
    assert!(stdout.contains("; unknown voxel at"), "{stdout}");

    // the bundled path turns into the sample corridor's wall
    let stdout = ok("collision_check", dir.path(), &[]);
    assert!(
        stdout.contains("first collision: segment 3 (waypoint 3 to 4)") && stdout.contains("; occupied voxel"),
        "{stdout}"
    );
}

#[test]
fn export_voxels_writes_every_occupied_leaf() {
    let dir = tempfile::tempdir().unwrap();
    let tree = bt::read_file(Path::new(SAMPLES).join("indoor.bt")).unwrap();
    let occupied: Vec<_> = tree.leaves(0).filter(|leaf| tree.is_occupied(leaf.value)).collect();
    assert!(occupied.iter().any(|leaf| leaf.depth < 16), "the sample has no occupied leaf larger than a voxel");

    // defaults: the bundled map, into occupied.csv
    ok("export_voxels", dir.path(), &[]);
    let csv = std::fs::read_to_string(dir.path().join("occupied.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("x,y,z,size,probability"));
    let rows: Vec<Vec<f32>> = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), occupied.len());
    for (row, leaf) in rows.iter().zip(&occupied) {
        assert_eq!(row[..3], leaf.center_point().to_array());
        assert_eq!(row[3], leaf.size() as f32);
        assert!(row[4] > 0.5 && row[4] <= 1.0, "{row:?}");
    }

    // a PLY file any reader takes the centres from
    let out = dir.path().join("occupied.ply");
    ok("export_voxels", dir.path(), &[&format!("{SAMPLES}/indoor.bt"), s(&out)]);
    let cloud = ply::read(&std::fs::read(&out).unwrap(), false).unwrap().cloud;
    let centres: Vec<Point3> = occupied.iter().map(|leaf| leaf.center_point()).collect();
    assert_eq!(cloud.points, centres);
}
