//! What a planned task of a tile set built in parts costs against the
//! whole build: `cargo run --release -p octolinear-probes --bin plan_probe
//! -- indoor|outdoor|FILE.graph RES [DEPTH [TASKS]]` (tile depth 8 and 2
//! tasks by default). Plans the tasks (`TileWork`), then per task times the
//! scans' casting restricted to the task's range (`compute_update_in`)
//! and the tiled map's insertion of the task (casting and applying), each
//! on one thread, in thread CPU time, against the whole map's and against
//! the same task under the hash split (which casts every ray); REPS=n gives
//! the fastest of n runs. A probe, not a benchmark of record.

#[path = "../../../benches/common/mod.rs"]
mod common;

use octolinear::tiles::{TaskPart, TileWork, TiledMap};
use octolinear::{NodeKind, OccupancyTree, ScanOptions, SensorModel};
use std::ops::Range;

fn main() {
    let (_, res, scans) = common::scene_from_args();
    let arg = |i: usize, default: u32| std::env::args().nth(i).map_or(default, |s| s.parse().expect("a number"));
    let (depth, tasks) = (arg(3, 8) as u8, arg(4, 2));
    let reps: usize = std::env::var("REPS").map_or(3, |s| s.parse().expect("REPS"));
    let one = ScanOptions::default().with_threads(Some(1));

    let t = thread_cpu();
    let mut work = TileWork::new(res, depth).expect("tile depth");
    for (points, origin) in &scans {
        work.add_scan(points, *origin, None);
    }
    let plan = work.split(tasks).expect("tasks");
    println!("plan: {:.1} ms of thread CPU", (thread_cpu() - t) * 1e3);
    let total: u64 = plan.tasks.iter().map(|t| t.work).sum();

    let tree = OccupancyTree::new(res).expect("resolution");
    let shift = 3 * (16 - u32::from(depth));
    let cast = |codes: Range<u64>| {
        best_of(reps, || {
            for (points, origin) in &scans {
                tree.compute_update_in(points, *origin, &one, codes.clone()).expect("scan");
            }
        })
    };
    let insert = |task: Option<TaskPart>| {
        best_of(reps, || {
            let mut map = TiledMap::new(res, SensorModel::default(), NodeKind::Plain, depth).expect("map");
            if let Some(task) = task {
                map.set_task(task);
            }
            for (points, origin) in &scans {
                map.insert_point_cloud(points, *origin, &one).expect("scan");
            }
        })
    };
    let (whole_cast, whole_insert) = (cast(0..u64::MAX), insert(None));
    println!(
        "| part | estimated work | casting (ms) | casting vs whole | insertion (ms) | insertion vs whole | \
         hash split task's insertion vs whole |"
    );
    println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: |");
    println!("| whole map | 100% | {:.0} | 100% | {:.0} | 100% | |", whole_cast * 1e3, whole_insert * 1e3);
    for (k, t) in plan.tasks.iter().enumerate() {
        let c = cast((t.prefixes.start << shift)..(t.prefixes.end << shift));
        let i = insert(Some(plan.task(k as u32).expect("task")));
        let hashed = insert(Some(TaskPart::hashed(k as u32, tasks)));
        println!(
            "| task {k}/{tasks} (prefixes {}..{}) | {:.0}% | {:.0} | {:.0}% | {:.0} | {:.0}% | {:.0}% |",
            t.prefixes.start,
            t.prefixes.end,
            100.0 * t.work as f64 / total.max(1) as f64,
            c * 1e3,
            100.0 * c / whole_cast,
            i * 1e3,
            100.0 * i / whole_insert,
            100.0 * hashed / whole_insert
        );
    }
}

/// The fastest of `reps` runs of `f`, in seconds of thread CPU time.
fn best_of(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = thread_cpu();
            f();
            thread_cpu() - t
        })
        .fold(f64::MAX, f64::min)
}

/// CPU time of the calling thread, in seconds.
fn thread_cpu() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec for the call.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}
