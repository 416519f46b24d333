//! `side_by_side -- --full`: the full-size sequences (tens of thousands of
//! points per scan), insertion in one process against OctoMap, and
//! `octolinear build` against Debian's `graph2tree` as subprocesses on the
//! same `.graph` file, with their wall time and peak memory.

use super::common::{build_counting, num_points, Scan};
use super::{median, secs, Stat};
use octolinear::formats::{graph, ot};
use octolinear::internals::TreeInternals;
use octolinear::OccupancyTree;
use octolinear_oracle::{OracleTree, ScanBatch};
use octolinear_sim::{simulate, LidarConfig, SceneKind};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The full-size sequences: a 64-beam lidar indoors (about 80k points a
/// scan, 30 m range) and a 128-beam one outdoors (about 200k points a scan,
/// every return however far).
pub fn sequence(kind: SceneKind) -> (&'static str, usize, LidarConfig) {
    match kind {
        SceneKind::Indoor => (
            "--scene indoor --scans 64 --beams 64 --steps 1250",
            64,
            LidarConfig { beams: 64, horizontal_steps: 1250, ..LidarConfig::indoor() },
        ),
        SceneKind::Outdoor => (
            "--scene outdoor --scans 6 --beams 128 --steps 2048 --range inf",
            6,
            LidarConfig { beams: 128, horizontal_steps: 2048, max_range: f64::INFINITY, ..LidarConfig::outdoor() },
        ),
    }
}

/// Options of the full-size mode.
pub struct FullArgs {
    /// Jobs to run: scene and resolution.
    pub jobs: Vec<(SceneKind, f64)>,
    /// Runs of our insertion per job (OctoMap's: see `octomap_budget`).
    pub reps: usize,
    /// OctoMap's insertion runs again (up to `reps`) while its runs so far
    /// took less than this many seconds.
    pub octomap_budget: f64,
    /// Where the `.graph` files and the maps go (a temporary directory when
    /// `None`).
    pub dir: Option<PathBuf>,
    /// The `octolinear` binary.
    pub octolinear: PathBuf,
    pub graph2tree: PathBuf,
}

impl FullArgs {
    pub fn new() -> FullArgs {
        // `cargo bench` runs target/release/deps/side_by_side-*: the CLI
        // is built next to `deps`
        let exe = std::env::current_exe().expect("the bench's path");
        let octolinear =
            exe.parent().and_then(Path::parent).map_or_else(|| "octolinear".into(), |d| d.join("octolinear"));
        FullArgs {
            jobs: vec![
                (SceneKind::Indoor, 0.05),
                (SceneKind::Indoor, 0.1),
                (SceneKind::Indoor, 0.2),
                (SceneKind::Outdoor, 0.1),
                (SceneKind::Outdoor, 0.2),
            ],
            reps: 3,
            octomap_budget: 30.0,
            dir: None,
            octolinear,
            graph2tree: "/usr/bin/graph2tree".into(),
        }
    }

    /// `indoor:0.1,outdoor:0.2`.
    pub fn parse_jobs(list: &str) -> Vec<(SceneKind, f64)> {
        list.split(',')
            .map(|job| {
                let (scene, res) = job.split_once(':').unwrap_or_else(|| panic!("--jobs SCENE:RES[,...], not {job}"));
                let kind = match scene {
                    "indoor" => SceneKind::Indoor,
                    "outdoor" => SceneKind::Outdoor,
                    s => panic!("--jobs: scene indoor or outdoor, not {s}"),
                };
                (kind, res.parse().unwrap_or_else(|_| panic!("--jobs: resolution {res}")))
            })
            .collect()
    }
}

/// What one job measured.
struct JobResult {
    name: String,
    points: usize,
    nodes: usize,
    /// Voxels the rays enter, repeats included: origin voxels and DDA steps.
    ray_steps: usize,
    updates: usize,
    octomap: Stat,
    octomap_runs: usize,
    one: Stat,
    two: Stat,
    graph2tree: Process,
    /// graph2tree's own "time to insert scans".
    graph2tree_insert: f64,
    build1: Process,
    build2: Process,
}

/// A finished subprocess: wall time and peak resident memory.
#[derive(Clone, Copy)]
struct Process {
    wall: Duration,
    peak_kb: i64,
}

impl Process {
    /// The median wall time of `runs` and the highest peak among them.
    fn median(runs: Vec<Process>) -> Process {
        let peak_kb = runs.iter().map(|p| p.peak_kb).max().expect("a run");
        Process { wall: median(runs.iter().map(|p| p.wall).collect()).median, peak_kb }
    }
}

/// The argument that makes this bench a launcher ([`launch`]).
pub const LAUNCH: &str = "--launch";

/// Runs `cmd` to its end, its output to `log`; its wall time and peak
/// resident set size. Through a launcher, this bench started again with
/// [`LAUNCH`]: a child's peak counts the memory of the process it was
/// started from (Linux keeps it across `exec`), and the launcher holds a
/// few megabytes where this process holds the scans.
fn run(cmd: &Command, log: &Path) -> Process {
    let exe = std::env::current_exe().expect("the bench's path");
    let out = Command::new(exe)
        .arg(LAUNCH)
        .arg(log)
        .arg(cmd.get_program())
        .args(cmd.get_args())
        .stdin(Stdio::null())
        .output()
        .expect("the launcher runs");
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{cmd:?} failed: {report}{}; its output is in {}",
        String::from_utf8_lossy(&out.stderr),
        log.display()
    );
    let (wall, peak_kb) = report.trim().split_once(' ').expect("the launcher's report");
    Process { wall: Duration::from_secs_f64(wall.parse().expect("seconds")), peak_kb: peak_kb.parse().expect("kB") }
}

/// The launcher: `LAUNCH LOG PROGRAM ARGS...` runs the program, its output
/// to LOG, and prints its wall time in seconds and its peak resident set
/// size in kB (from `wait4`); fails when the program does.
pub fn launch(args: &[String]) -> ! {
    let [log, program, rest @ ..] = args else { panic!("{LAUNCH} LOG PROGRAM [ARGS...]") };
    let out = std::fs::File::create(log).expect("log file");
    let err = out.try_clone().expect("log file");
    let start = Instant::now();
    let child = Command::new(program)
        .args(rest)
        .stdout(out)
        .stderr(err)
        .stdin(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("{program}: {e}"));
    let mut status = 0;
    // SAFETY: an all-zero rusage is a valid value for wait4 to fill in
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: the pid is our unreaped child's; status and usage are
    // writable for the call. `Child` is not waited on afterwards.
    let pid = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    let wall = start.elapsed();
    assert!(pid > 0, "wait4 for {program} failed");
    if !(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0) {
        eprintln!("{program} failed (wait status {status})");
        std::process::exit(1);
    }
    println!("{} {}", wall.as_secs_f64(), usage.ru_maxrss);
    std::process::exit(0);
}

fn scans_of(g: &graph::ScanGraph) -> Vec<Scan> {
    g.nodes.iter().map(|n| n.graph2tree()).map(|(c, o)| (c.points, o)).collect()
}

fn ot_bytes(tree: &OccupancyTree) -> Vec<u8> {
    let mut v = Vec::new();
    ot::write(tree, &mut v).expect("write .ot");
    v
}

fn kind_name(kind: SceneKind) -> &'static str {
    super::common::kind_name(kind)
}

/// Runs the jobs of `args` and prints their tables.
pub fn run_full(args: &FullArgs) {
    assert!(
        args.octolinear.exists(),
        "{} not found: build it first (cargo build --release -p octolinear-cli) or give --octolinear PATH",
        args.octolinear.display()
    );
    assert!(args.graph2tree.exists(), "{} not found (apt-get install -y octomap-tools)", args.graph2tree.display());
    let temp;
    let dir = match &args.dir {
        Some(d) => {
            std::fs::create_dir_all(d).expect("create --dir");
            d.clone()
        }
        None => {
            temp = tempfile::tempdir().expect("temporary directory");
            temp.path().to_path_buf()
        }
    };
    println!(
        "side_by_side --full: OctoMap {} (insertion: the oracle shim in this process; end to end: {}) vs \
         octolinear; our insertion the median of {} runs (before OctoMap's in the process), OctoMap's of as many \
         while its runs total under {} s; times in seconds",
        octolinear_oracle::octomap_version().unwrap_or("?"),
        args.graph2tree.display(),
        args.reps,
        args.octomap_budget
    );
    let mut results = Vec::new();
    for kind in [SceneKind::Indoor, SceneKind::Outdoor] {
        let resolutions: Vec<f64> = args.jobs.iter().filter(|j| j.0 == kind).map(|j| j.1).collect();
        if resolutions.is_empty() {
            continue;
        }
        let (flags, count, cfg) = sequence(kind);
        let g = simulate(kind, count, super::common::SEED, &cfg).expect("simulate");
        let file = dir.join(format!("{}.graph", kind_name(kind)));
        graph::write_file(&g, &file).expect("write the .graph file");
        let scans = scans_of(&g);
        drop(g);
        println!();
        println!(
            "{}: `octolinear simulate {flags} --seed {}`: {} scans, {} points",
            kind_name(kind),
            super::common::SEED,
            scans.len(),
            num_points(&scans)
        );
        for res in resolutions {
            let r = run_job(args, kind, res, &scans, &file, &dir);
            results.push(r);
        }
    }
    print_tables(&results);
    println!();
    println!(
        "The machine's floor for one ray's step (a chain of dependent double compares and adds): {:.2} ns",
        super::common::dependent_step_ns()
    );
}

fn run_job(args: &FullArgs, kind: SceneKind, res: f64, scans: &[Scan], file: &Path, dir: &Path) -> JobResult {
    let name = format!("{} {res} m", kind_name(kind));
    eprintln!("{name}: insertion");
    // ----- insertion in this process
    let mut batch = ScanBatch::new();
    for (points, origin) in scans {
        batch.push(&points.iter().map(|p| p.to_array()).collect::<Vec<_>>(), origin.to_array());
    }
    let (mut t_om, mut t_1, mut t_2) = (Vec::new(), Vec::new(), Vec::new());
    // ours first: a process in which OctoMap built and freed a large tree
    // (millions of small allocations) slowed a later two-thread insertion
    // outdoors at 0.1 m by a tenth (docs/benchmarks.md, "Full-size sequences")
    let (mut ours, mut ours_ot, mut updates) = (None, [Vec::new(), Vec::new()], 0);
    for rep in 0..args.reps {
        for (ot, (threads, times)) in ours_ot.iter_mut().zip([(1, &mut t_1), (2, &mut t_2)]) {
            drop(ours.take());
            let t = Instant::now();
            let (tree, n) = build_counting(scans, res, Some(threads));
            times.push(t.elapsed());
            if rep == 0 {
                *ot = ot_bytes(&tree);
            }
            (ours, updates) = (Some(tree), n);
        }
    }
    let tree = ours.expect("ran");
    let nodes = tree.size();
    let ray_steps = scans.iter().map(|(p, o)| tree.cast_codes(p, *o).0.len()).sum();
    drop(tree);
    while t_om.is_empty()
        || (t_om.len() < args.reps && t_om.iter().sum::<Duration>().as_secs_f64() < args.octomap_budget)
    {
        let t = Instant::now();
        let mut om = OracleTree::new(res).expect("oracle tree");
        om.insert_scans(&batch, -1.0, false, false).expect("insert");
        t_om.push(t.elapsed());
        if t_om.len() == 1 {
            let om_ot = om.write_ot().expect("oracle .ot");
            for (ot, threads) in ours_ot.iter().zip([1, 2]) {
                assert!(*ot == om_ot, "{name}: {threads}-thread tree differs from OctoMap's");
            }
        }
    }
    drop(batch);
    drop(ours_ot);

    // ----- end to end, as subprocesses on the same file
    eprintln!("{name}: graph2tree and octolinear build");
    let res_arg = res.to_string();
    let g2t_out = dir.join("graph2tree.bt");
    // graph2tree's runs, and its own "time to insert scans" of each
    let (mut g2t_runs, mut g2t_inserts) = (Vec::new(), Vec::new());
    while g2t_runs.len() < args.reps
        && g2t_runs.iter().map(|p: &Process| secs(p.wall)).sum::<f64>() < args.octomap_budget
    {
        let log_path = dir.join("graph2tree.log");
        g2t_runs.push(run(
            Command::new(&args.graph2tree)
                .args(["-i".as_ref(), file.as_os_str(), "-o".as_ref(), g2t_out.as_os_str()])
                .args(["-res", &res_arg]),
            &log_path,
        ));
        let log = std::fs::read_to_string(&log_path).expect("graph2tree's log");
        let insert: f64 = log
            .lines()
            .find_map(|l| l.strip_prefix("time to insert scans: ")?.strip_suffix(" sec")?.parse().ok())
            .expect("graph2tree prints its insertion time");
        g2t_inserts.push(Duration::from_secs_f64(insert));
    }
    let graph2tree = Process::median(g2t_runs);
    let graph2tree_insert = secs(median(g2t_inserts).median);
    let expected = std::fs::read(&g2t_out).expect("graph2tree's .bt");
    for suffix in ["", ".ot", "_ml.ot"] {
        let _ = std::fs::remove_file(dir.join(format!("graph2tree.bt{suffix}")));
    }
    let build = |threads: &str| {
        let out = dir.join("octolinear.bt");
        let p = run(
            Command::new(&args.octolinear).arg("build").arg(file).arg("-o").arg(&out).args([
                "--res",
                &res_arg,
                "--threads",
                threads,
            ]),
            &dir.join("octolinear.log"),
        );
        assert!(std::fs::read(&out).expect("octolinear's .bt") == expected, "{name}: .bt differs from graph2tree's");
        let _ = std::fs::remove_file(&out);
        p
    };
    // alternately, so that a slow phase of the machine touches both
    let (mut ones, mut twos) = (Vec::new(), Vec::new());
    for _ in 0..args.reps {
        ones.push(build("1"));
        twos.push(build("2"));
    }
    let (build1, build2) = (Process::median(ones), Process::median(twos));
    JobResult {
        name,
        points: num_points(scans),
        nodes,
        ray_steps,
        updates,
        octomap_runs: t_om.len(),
        octomap: median(t_om),
        one: median(t_1),
        two: median(t_2),
        graph2tree,
        graph2tree_insert,
        build1,
        build2,
    }
}

fn print_tables(results: &[JobResult]) {
    let s = |d: Duration| format!("{:.2}", secs(d));
    let x = |a: Duration, b: Duration| format!("{:.1}x", secs(a) / secs(b));
    println!();
    println!("Insertion (in this process; speed-up = OctoMap / octolinear, of the medians; rates on 2 threads):");
    println!();
    println!(
        "| job | points | nodes | ray steps | voxel updates | OctoMap | 1 thread | speed-up | 2 threads | speed-up \
         | ns / ray step: OctoMap, 1 thread | ns / voxel update: OctoMap, 1 thread | points/s | voxel updates/s |"
    );
    println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for r in results {
        let runs = if r.octomap_runs == 1 { " (1 run)".to_string() } else { String::new() };
        println!(
            "| {} | {} | {} | {} | {} | {}{runs} | {} | {} | {} | {} | {:.1}, {:.2} | {:.0}, {:.1} | {:.2}M | {:.1}M |",
            r.name,
            r.points,
            r.nodes,
            r.ray_steps,
            r.updates,
            s(r.octomap.median),
            s(r.one.median),
            x(r.octomap.median, r.one.median),
            s(r.two.median),
            x(r.octomap.median, r.two.median),
            secs(r.octomap.median) * 1e9 / r.ray_steps as f64,
            secs(r.one.median) * 1e9 / r.ray_steps as f64,
            secs(r.octomap.median) * 1e9 / r.updates as f64,
            secs(r.one.median) * 1e9 / r.updates as f64,
            r.points as f64 / secs(r.two.median) / 1e6,
            r.updates as f64 / secs(r.two.median) / 1e6,
        );
    }
    println!();
    println!(
        "End to end (wall time of the process: read the .graph, insert, write the .bt; graph2tree also writes \
         two .ot files; medians of as many runs as above, the builds' 1- and 2-thread runs alternating; the \
         highest peak RSS from wait4):"
    );
    println!();
    println!(
        "| job | graph2tree | its insertion | peak RSS | build, 1 thread | speed-up | peak RSS | build, 2 threads \
         | speed-up | peak RSS |"
    );
    println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    let mb = |p: Process| format!("{:.0} MB", p.peak_kb as f64 / 1024.0);
    for r in results {
        println!(
            "| {} | {} | {:.2} | {} | {} | {} | {} | {} | {} | {} |",
            r.name,
            s(r.graph2tree.wall),
            r.graph2tree_insert,
            mb(r.graph2tree),
            s(r.build1.wall),
            x(r.graph2tree.wall, r.build1.wall),
            mb(r.build1),
            s(r.build2.wall),
            x(r.graph2tree.wall, r.build2.wall),
            mb(r.build2),
        );
    }
}
