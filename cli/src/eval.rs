//! `octolinear eval`: OctoMap's `eval_octree_accuracy` — how many of the
//! voxels a scan observes (free along rays, occupied at end points) a map
//! classifies the same way (OctoMap paper, Sect. 5.3).

use super::build::{max_range_arg, resolution_arg, scans_arg};
use super::common::{load_map, spinner};
use super::input;
use anyhow::{bail, Context, Result};
use octolinear::formats::graph::ScanGraph;
use octolinear::{OccupancyTree, ScanOptions};
use std::path::PathBuf;

/// Accuracy of a map against scans (like OctoMap's eval_octree_accuracy).
///
/// Each scan's free voxels (along its
/// rays) and occupied voxels (its end points) are looked up in the map and
/// counted as correct, wrong or unknown; accuracy = correct / (correct +
/// wrong).
///
/// With one input (a `.graph`), the map is built from the scans themselves
/// with hold-out as in OctoMap's eval_octree_accuracy: with `--holdout K`
/// (default 5) every K-th scan is left out of the map and evaluated; with
/// `--folds K` each of the K folds is held out in turn (cross-validation).
/// With two inputs (MAP SCANS.graph), the given map is evaluated on every
/// scan. The `.graph` may be `-` for standard input. A `.graph` without
/// scans, or scans none of whose voxels the map knows, is an error (the
/// accuracy would be undefined).
///
/// Example: octolinear eval map.bt scans.graph --json
///
/// Example: octolinear eval scans.graph --res 0.1 --folds 5
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// `MAP SCANS.graph`, or only `SCANS.graph` to build and hold out
    /// (`-` reads the scans from standard input).
    #[arg(num_args = 1..=2, required = true, value_names = ["MAP", "SCANS"])]
    inputs: Vec<PathBuf>,
    /// Voxel size when building (metres; as for `build`).
    #[arg(long, default_value_t = 0.1)]
    res: f64,
    /// Cut rays at this range (metres, positive; leave it out for no
    /// limit), when building and evaluating.
    #[arg(long)]
    max_range: Option<f64>,
    /// Only use the first N scans (at least 1).
    #[arg(long, value_name = "N")]
    scans: Option<usize>,
    /// Hold out every K-th scan (eval_octree_accuracy uses 5); K from 2 to
    /// the number of scans.
    #[arg(long, value_name = "K", conflicts_with = "folds")]
    holdout: Option<usize>,
    /// K-fold cross-validation: build K maps, each without one fold; K from
    /// 2 to the number of scans.
    #[arg(long, value_name = "K")]
    folds: Option<usize>,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Counts of one evaluation.
#[derive(Clone, Copy, Default, Debug, PartialEq, Eq)]
pub struct Accuracy {
    pub scans: usize,
    pub points: usize,
    pub correct: u64,
    pub wrong: u64,
    pub unknown: u64,
}

impl Accuracy {
    pub fn ratio(&self) -> f64 {
        self.correct as f64 / (self.correct + self.wrong) as f64
    }

    fn add(&mut self, o: &Accuracy) {
        self.scans += o.scans;
        self.points += o.points;
        self.correct += o.correct;
        self.wrong += o.wrong;
        self.unknown += o.unknown;
    }

    fn json(&self) -> serde_json::Value {
        let r = self.ratio();
        serde_json::json!({
            "scans": self.scans, "points": self.points,
            "correct": self.correct, "wrong": self.wrong, "unknown": self.unknown,
            "accuracy": if r.is_finite() { Some(r) } else { None },
        })
    }
}

fn options(max_range: Option<f64>) -> ScanOptions {
    ScanOptions::default().with_max_range(max_range)
}

/// Evaluates `tree` on the scans `which` selects (by 0-based index).
pub fn evaluate(
    tree: &OccupancyTree,
    g: &ScanGraph,
    n: usize,
    max_range: Option<f64>,
    which: impl Fn(usize) -> bool,
) -> Result<Accuracy> {
    let opts = options(max_range);
    let mut acc = Accuracy::default();
    for (i, node) in g.nodes[..n].iter().enumerate() {
        if !which(i) {
            continue;
        }
        let (cloud, origin) = node.graph2tree();
        let (update, _) =
            tree.compute_update(&cloud.points, origin, &opts).with_context(|| format!("scan {}", node.id))?;
        acc.scans += 1;
        acc.points += cloud.len();
        let mut count = |codes: &[u64], occupied: bool| {
            for &code in codes {
                match tree.search(octolinear::MortonCode(code).decode(), 0) {
                    Some(f) if tree.is_occupied(f.value) == occupied => acc.correct += 1,
                    Some(_) => acc.wrong += 1,
                    None => acc.unknown += 1,
                }
            }
        };
        count(&update.free, false);
        count(&update.occupied, true);
    }
    Ok(acc)
}

/// Builds a map from the scans `which` selects, as eval_octree_accuracy does.
fn build(
    g: &ScanGraph,
    n: usize,
    res: f64,
    max_range: Option<f64>,
    which: impl Fn(usize) -> bool,
) -> Result<OccupancyTree> {
    let mut tree = OccupancyTree::new(res)?;
    let opts = options(max_range);
    for (i, node) in g.nodes[..n].iter().enumerate() {
        if which(i) {
            let (cloud, origin) = node.graph2tree();
            tree.insert_point_cloud(&cloud.points, origin, &opts).with_context(|| format!("scan {}", node.id))?;
        }
    }
    Ok(tree)
}

/// Refuses an evaluation without a single voxel the map knows: its
/// accuracy (correct / (correct + wrong)) is not a number.
fn defined(a: &Accuracy, graph: &std::path::Path) -> Result<()> {
    if a.correct + a.wrong == 0 {
        bail!(
            "{}: the {} evaluated scans ({} points) observe {} voxels, none of them known to the map: the accuracy is undefined",
            input::name(graph),
            a.scans,
            a.points,
            a.unknown
        );
    }
    Ok(())
}

fn print(label: &str, a: &Accuracy) {
    println!(
        "{label}: {} scans, {} points. Voxels correct: {} #wrong: {} #unknown: {}. % correct: {}",
        a.scans,
        a.points,
        a.correct,
        a.wrong,
        a.unknown,
        super::common::format_g6(a.ratio())
    );
}

pub fn run(a: Args) -> Result<()> {
    let max_range = max_range_arg(a.max_range)?;
    scans_arg(a.scans)?;
    if a.inputs.len() == 2 && (a.holdout.is_some() || a.folds.is_some()) {
        bail!("--holdout and --folds build their own map: give only the .graph file");
    }
    if a.inputs.len() == 1 {
        resolution_arg(a.res)?;
    }
    let graph_path = a.inputs.last().expect("one input at least");
    let phase = spinner(&format!("reading {}", input::name(graph_path)));
    let g = input::open_graph(graph_path)?
        .into_graph()
        .with_context(|| format!("cannot read {}", input::name(graph_path)))?;
    let n = a.scans.unwrap_or(g.nodes.len()).min(g.nodes.len());
    if n == 0 {
        bail!("{} holds no scans: there is nothing to evaluate", input::name(graph_path));
    }
    if a.inputs.len() == 2 {
        phase.set_message(format!("loading {}", a.inputs[0].display()));
        let tree = load_map(&a.inputs[0])?.tree;
        phase.set_message(format!("evaluating {n} scans"));
        let acc = evaluate(&tree, &g, n, max_range, |_| true)?;
        phase.finish_and_clear();
        defined(&acc, graph_path)?;
        if a.json {
            println!("{}", acc.json());
        } else {
            print("All scans", &acc);
        }
        return Ok(());
    }
    let (k, folds, flag) = match (a.holdout, a.folds) {
        (_, Some(k)) => (k, k, "--folds"),
        (Some(k), None) => (k, 1, "--holdout"),
        (None, None) => (5, 1, "the default --holdout"),
    };
    if k < 2 {
        bail!("--holdout / --folds must be at least 2, got {k}");
    }
    if k > n {
        // scan k (1-based) is the first held out by fold 0
        bail!("{flag} {k} needs at least {k} scans, only {n} are used (a held-out set would be empty)");
    }
    // fold f holds out the scans whose 1-based number is f modulo k
    // (eval_octree_accuracy's held-out scans are fold 0)
    let mut results = Vec::new();
    for f in 0..folds {
        let held_out = |i: usize| (i + 1) % k == f;
        // eval_octree_accuracy expands the tree first; lookups give the
        // same answers on the pruned tree, so we skip that
        phase.set_message(format!("fold {}/{folds}: building the map", f + 1));
        let tree = build(&g, n, a.res, max_range, |i| !held_out(i))?;
        phase.set_message(format!("fold {}/{folds}: evaluating", f + 1));
        results.push(evaluate(&tree, &g, n, max_range, held_out)?);
    }
    phase.finish_and_clear();
    let mut total = Accuracy::default();
    for r in &results {
        total.add(r);
    }
    defined(&total, graph_path)?;
    if a.json {
        let out = serde_json::json!({
            "k": k,
            "folds": results.iter().map(Accuracy::json).collect::<Vec<_>>(),
            "total": total.json(),
            "mean_accuracy": results.iter().map(Accuracy::ratio).sum::<f64>() / results.len() as f64,
        });
        println!("{out}");
    } else {
        for (f, r) in results.iter().enumerate() {
            print(&format!("Fold {f}"), r);
        }
        if results.len() > 1 {
            print("Total", &total);
        }
    }
    Ok(())
}
