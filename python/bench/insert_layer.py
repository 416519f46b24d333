"""The Python layer's cost over the Rust call: insertPointCloud scan by scan
from Python, fastest of 9 in wall time, on one and on two threads; compare
with `occupancy_probe GRAPH RES`, which times insert_point_cloud in Rust the
same way.

    python python/bench/insert_layer.py GRAPH RES
"""
import sys, time
import octolinear

scans = octolinear.read_graph(sys.argv[1])
resolution = float(sys.argv[2])
for threads in (1, 2):
    octolinear.set_num_threads(threads)
    best = float("inf")
    for _ in range(9):
        t = time.perf_counter()
        tree = octolinear.OcTree(resolution)
        for points, origin in scans:
            tree.insertPointCloud(points, origin)
        best = min(best, time.perf_counter() - t)
    print(f"insertPointCloud, {len(scans)} scans, {threads} thread(s): {best * 1e3:.1f} ms (wall)")
