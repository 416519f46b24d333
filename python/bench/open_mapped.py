"""Opening a large .olm from Python: the time of open_mapped and of the first
query after it, over 200 rounds with the file in the page cache, or over 20
rounds each after dropping the page cache (--cold: needs root).

    python python/bench/open_mapped.py MAP.olm [--cold]
"""
import os, sys, time, statistics
import numpy as np
import octolinear

path = sys.argv[1]
cold = "--cold" in sys.argv
size = os.path.getsize(path)
print(f"{path}: {size / 2**30:.2f} GiB")
opens, firsts = [], []
for i in range(20 if cold else 200):
    if cold:
        os.sync()
        with open("/proc/sys/vm/drop_caches", "w") as f:
            f.write("3\n")
    t0 = time.perf_counter()
    m = octolinear.open_mapped(path)
    t1 = time.perf_counter()
    p = np.random.default_rng(i).uniform(-40.0, 40.0, (1, 3))
    t2 = time.perf_counter()
    m.occupancy(p)
    t3 = time.perf_counter()
    opens.append(t1 - t0)
    firsts.append(t3 - t2)
    del m
fmt = lambda xs: f"median {statistics.median(xs) * 1e6:.0f} µs, max {max(xs) * 1e6:.0f} µs"
print(("cold" if cold else "warm") + f" over {len(opens)}: open {fmt(opens)}; first query {fmt(firsts)}")
