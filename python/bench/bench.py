"""octolinear against octomap-python (the real OctoMap 1.10), side by side in
one process, on the same scans: insertion, point queries, leaf extraction,
.bt files, opening an .olm map.

    python python/bench/bench.py                     # simulated scans, made with the CLI
    python python/bench/bench.py --graph scans.graph --res 0.05

Without --graph the scans are simulated by `octolinear simulate` (64-beam
lidar, 2048 firings a revolution: about 130k points a scan indoors), run
through `cargo run --release -p octolinear-cli`. Every comparison first
checks that both libraries give the same answer (map bytes, labels).
Prints a Markdown table; the figures are the best of --repeat runs.
"""

import argparse
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import octomap

import octolinear

REPO = pathlib.Path(__file__).resolve().parents[2]


def best_time(run, repeat):
    """Smallest wall time of `repeat` calls of `run`."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def simulated_graph(directory, scene, scans):
    path = pathlib.Path(directory) / f"{scene}.graph"
    subprocess.run(
        ["cargo", "run", "--quiet", "--release", "-p", "octolinear-cli", "--", "simulate"]
        + ["--scene", scene, "--scans", str(scans), "--seed", "1", "--beams", "64", "--steps", "2048"]
        + ["-o", str(path)],
        cwd=REPO,
        check=True,
    )
    return path


def insert_all(tree, scans):
    for points, origin in scans:
        tree.insertPointCloud(points, origin)


def fmt(seconds):
    if seconds < 1e-3:
        return f"{seconds * 1e6:.0f} µs"
    if seconds < 1:
        return f"{seconds * 1e3:.1f} ms"
    return f"{seconds:.2f} s"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--graph", type=pathlib.Path, help="scans to insert (default: simulated)")
    parser.add_argument("--scene", default="indoor", choices=["indoor", "outdoor"], help="simulated scene")
    parser.add_argument("--scans", type=int, default=6, help="simulated scans")
    parser.add_argument("--res", type=float, default=0.1, help="voxel edge, metres")
    parser.add_argument("--queries", type=int, default=1_000_000, help="random points to look up")
    parser.add_argument("--repeat", type=int, default=3, help="runs per figure (the best is kept)")
    args = parser.parse_args()

    rows = []

    def row(what, theirs, ours1, ours2=None):
        best_ours = min(t for t in (ours1, ours2) if t is not None)
        rows.append((what, theirs, ours1, ours2, theirs / best_ours if theirs else None, theirs / ours1 if theirs else None))

    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        graph = args.graph or simulated_graph(tmp, args.scene, args.scans)
        scans = octolinear.read_graph(graph)
        points = sum(len(p) for p, _ in scans)
        print(f"{graph.name}: {len(scans)} scans, {points} points ({points // len(scans)} a scan), res {args.res} m")

        # insertion (octomap-python is single-threaded: its wheel has no OpenMP)
        theirs = octomap.OcTree(args.res)
        t_theirs = best_time(lambda: insert_all(theirs, scans), 1)
        ours_by_threads = {}
        for threads in (1, 2):
            octolinear.set_num_threads(threads)
            ours_by_threads[threads] = best_time(lambda: insert_all(octolinear.OcTree(args.res), scans), args.repeat)
        octolinear.set_num_threads(0)
        ours = octolinear.OcTree(args.res)
        insert_all(ours, scans)
        assert ours.write() == theirs.write(), "the maps differ"
        row(f"insertPointCloud, {len(scans)} scans ({points / t_theirs / 1e6:.2f} M points/s for octomap-python)",
            t_theirs, ours_by_threads[1], ours_by_threads[2])

        # point queries
        rng = np.random.default_rng(1)
        lo, hi = theirs.getMetricMin(), theirs.getMetricMax()
        queries = rng.uniform(lo, hi, (args.queries, 3))
        labels = theirs.getLabels(queries)
        assert np.array_equal(ours.getLabels(queries), labels)
        assert np.array_equal(ours.occupancy(queries)[0], labels)
        t_labels = best_time(lambda: theirs.getLabels(queries), 1)
        loop_n = min(100_000, args.queries)

        def their_loop():
            for p in queries[:loop_n]:
                node = theirs.search(p)
                try:
                    theirs.isNodeOccupied(node)
                except octomap.NullPointerException:
                    pass

        t_loop = best_time(their_loop, 1) * (args.queries / loop_n)
        occ = {}
        for threads in (1, 2):
            octolinear.set_num_threads(threads)
            occ[threads] = best_time(lambda: ours.occupancy(queries), args.repeat)
        octolinear.set_num_threads(0)
        n = f"{args.queries // 1000}k" if args.queries < 1_000_000 else f"{args.queries / 1e6:g}M"
        row(f"{n} point queries: their search loop (timed on {loop_n // 1000}k) vs `occupancy()`", t_loop, occ[1], occ[2])
        row(f"{n} point queries: their `getLabels` vs `occupancy()`", t_labels, occ[1], occ[2])

        # rays from the scans' origins
        origins = np.repeat(np.stack([o for _, o in scans]), 10_000 // len(scans) + 1, axis=0)[:10_000]
        directions = rng.normal(size=(10_000, 3))
        ends = np.zeros((10_000, 3))

        def their_rays():
            for i in range(len(origins)):
                theirs.castRay(origins[i], directions[i], ends[i])

        their_rays()
        hits, ray_ends = ours.cast_rays(origins, directions)
        assert np.array_equal(ray_ends, ends)
        rays = {}
        for threads in (1, 2):
            octolinear.set_num_threads(threads)
            rays[threads] = best_time(lambda: ours.cast_rays(origins, directions), args.repeat)
        octolinear.set_num_threads(0)
        row("10k rays: their `castRay` loop vs `cast_rays()`", best_time(their_rays, 1), rays[1], rays[2])

        # leaves
        def their_leaves():
            return [(it.getCoordinate(), it.getSize(), it.getValue()) for it in theirs.begin_leafs()]

        assert len(their_leaves()) == len(ours.leaves())
        row(f"leaves ({ours.getNumLeafNodes()}): their `begin_leafs()` loop vs `leaves()`",
            best_time(their_leaves, 1), best_time(ours.leaves, args.repeat))
        # extractPointCloud gives every voxel centre of coarse leaves: skip it where that is huge
        voxels = int((8.0 ** (16 - ours.leaves()["depth"].astype(np.float64))).sum())
        if voxels <= 5_000_000:
            row(f"`extractPointCloud()` ({voxels} voxel centres)",
                best_time(theirs.extractPointCloud, 1), best_time(ours.extractPointCloud, args.repeat))
        else:
            print(f"extractPointCloud skipped: it would give {voxels} voxel centres")

        # .bt files (writeBinary converts the tree to maximum likelihood: do it once first)
        theirs.writeBinary()
        ours.writeBinary()
        assert theirs.writeBinary() == ours.writeBinary()
        row(".bt to bytes (`writeBinary()`)",
            best_time(theirs.writeBinary, args.repeat), best_time(ours.writeBinary, args.repeat))
        bt_a, bt_b = tmp / "theirs.bt", tmp / "ours.bt"
        # octolinear writes files atomically: a temporary file, synced, renamed
        row(".bt file (`writeBinary(path)`; octolinear syncs the file)",
            best_time(lambda: theirs.writeBinary(str(bt_a)), args.repeat),
            best_time(lambda: ours.writeBinary(str(bt_b)), args.repeat))
        assert bt_a.read_bytes() == bt_b.read_bytes()
        reader_a, reader_b = octomap.OcTree(args.res), octolinear.OcTree(args.res)
        row(".bt read (`readBinary(path)`)",
            best_time(lambda: reader_a.readBinary(str(bt_a)), args.repeat),
            best_time(lambda: reader_b.readBinary(str(bt_b)), args.repeat))

        # .olm: opened memory-mapped, then queried in place
        full = octolinear.OcTree(args.res)
        insert_all(full, scans)
        olm = tmp / "map.olm"
        full.save(olm)
        size = f"{olm.stat().st_size / 1e6:.1f} MB"
        opens = []
        for _ in range(200):
            start = time.perf_counter()
            mapped = octolinear.open_mapped(olm)
            opens.append(time.perf_counter() - start)
        assert np.array_equal(mapped.occupancy(queries)[0], full.occupancy(queries)[0])
        t_mapped = best_time(lambda: mapped.occupancy(queries), args.repeat)

    print()
    print("| operation | octomap-python | octolinear, 1 thread | octolinear, 2 threads | speed-up (best) | speed-up (1 thread) |")
    print("| --- | --- | --- | --- | --- | --- |")
    for what, theirs_t, one, two, best, single in rows:
        cells = [fmt(theirs_t), fmt(one), fmt(two) if two is not None else "", f"{best:.1f}x", f"{single:.1f}x"]
        print(f"| {what} | " + " | ".join(cells) + " |")
    print()
    print(f"`open_mapped` of a {size} .olm: median {fmt(statistics.median(opens))}, "
          f"max {fmt(max(opens))} over {len(opens)} opens; `occupancy()` of {n} points on it: {fmt(t_mapped)}")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, octolinear threads by default: {octolinear.get_num_threads()}")


if __name__ == "__main__":
    main()
