"""A tile build on a Dask LocalCluster of 1 and of 2 worker processes (one
thread each) against the same build in this process, on one .graph file;
every run's tile files are compared byte for byte with the first run's.

    python python/bench/dask_build.py SCANS.graph [--res 0.1] [--tile-depth 8]
        [--rounds 3] [--workers 1,2] [--tasks-per-worker 1]

Prints each run's wall time (median over the rounds) and the speed-up of W
workers over one.
"""
import argparse, filecmp, os, shutil, statistics, tempfile, time
from dask.distributed import Client, LocalCluster
import octolinear
import octolinear.dask


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("graph")
    ap.add_argument("--res", type=float, default=0.1)
    ap.add_argument("--tile-depth", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--tasks-per-worker", type=int, default=1)
    a = ap.parse_args()
    work = tempfile.mkdtemp(prefix="dask-bench-", dir=os.path.dirname(os.path.abspath(a.graph)))
    reference = None

    def same_tiles(x, y):
        names = sorted(os.listdir(x))
        if names != sorted(os.listdir(y)):
            return False
        return all(filecmp.cmp(os.path.join(x, n), os.path.join(y, n), shallow=False) for n in names)

    def timed(label, build):
        nonlocal reference
        times = []
        for r in range(a.rounds):
            out = os.path.join(work, f"{label}-{r}.tiles")
            t0 = time.perf_counter()
            summary = build(out)
            times.append(time.perf_counter() - t0)
            if reference is None:
                reference = out
            elif not same_tiles(reference, out):
                raise SystemExit(f"{out} differs from {reference}")
            if out != reference:
                shutil.rmtree(out)
        print(f"{label}: median {statistics.median(times):.2f} s over {a.rounds} ({', '.join(f'{t:.2f}' for t in times)})"
              + (f"; tiles {summary['tiles']}, nodes {summary['nodes']}" if isinstance(summary, dict) and 'nodes' in summary else ""),
              flush=True)
        return statistics.median(times)

    try:
        timed("in process, 1 thread", lambda out: octolinear.build_tiles(
            a.graph, out, resolution=a.res, tile_depth=a.tile_depth, threads=1))
        per_workers = {}
        for w in (int(x) for x in a.workers.split(",")):
            with LocalCluster(n_workers=w, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                    Client(cluster) as client:
                per_workers[w] = timed(f"Dask, {w} worker(s)", lambda out: octolinear.dask.build_tiles(
                    a.graph, out, resolution=a.res, tile_depth=a.tile_depth, client=client,
                    tasks=w * a.tasks_per_worker))
        if 1 in per_workers:
            for w, t in per_workers.items():
                if w != 1:
                    print(f"{w} workers over 1: {per_workers[1] / t:.2f}x")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":  # the workers are processes that import this file
    main()
