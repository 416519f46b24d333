"""octolinear.dask: tile sets built on Dask clusters (two and four worker
processes, and threads in this process) give the .ot and .bt bytes of
octolinear.build; so do a build whose worker dies mid-task, an
interrupted build resumed, and golden cases (OctoMap's own bytes). Importing octolinear never imports Dask, and
octolinear.dask without it names the package to install."""

import gzip
import os
import re
import subprocess
import sys

import pytest
from conftest import REPO, SAMPLE_GRAPH

import octolinear

MAP = dict(resolution=0.1, tile_depth=12)
OPTIONS = dict(max_range=5.0)


def distributed():
    """dask.distributed; the test skips without it, or fails where CI is set."""
    try:
        import distributed
    except ImportError:
        if os.environ.get("CI", "").lower() not in ("", "0", "false"):
            pytest.fail("dask[distributed] is not installed, and CI is set")
        pytest.skip("dask[distributed] is not installed (pip install 'dask[distributed]')")
    return distributed


def local_cluster(workers):
    d = distributed()
    cluster = d.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0")
    return cluster, d.Client(cluster)


@pytest.fixture(scope="module")
def clients():
    """Clients made on first use: `2` and `4` worker processes of one thread,
    `threads` two worker threads in this process (processes=False)."""
    made, closers = {}, []

    def client(name):
        if name not in made:
            if name == "threads":
                c = distributed().Client(processes=False, n_workers=1, threads_per_worker=2, dashboard_address=":0")
                closers.append(c.close)
            else:
                cluster, c = local_cluster(name)
                closers.extend([cluster.close, c.close])
            made[name] = c
        return made[name]

    yield client
    for close in reversed(closers):
        close()


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The .ot and .bt bytes of octolinear.build on one machine."""
    out = tmp_path_factory.mktemp("reference")
    maps = {}
    for ext in ("ot", "bt"):
        octolinear.build(SAMPLE_GRAPH, output=out / f"map.{ext}", resolution=MAP["resolution"], **OPTIONS)
        maps[ext] = (out / f"map.{ext}").read_bytes()
    return maps


def converted(out_dir, tmp_path):
    """The .ot and .bt bytes of a tile set."""
    maps = {}
    for ext in ("ot", "bt"):
        octolinear.convert_tiles(out_dir, tmp_path / f"converted.{ext}")
        maps[ext] = (tmp_path / f"converted.{ext}").read_bytes()
    return maps


def leftovers(out_dir):
    """Files of a finished set besides its tiles and manifest."""
    return sorted(p.name for p in out_dir.iterdir() if p.name != "manifest" and not re.fullmatch(r"d[-\d]+\.olm", p.name))


@pytest.mark.parametrize("cluster, tasks", [(2, None), (4, None), ("threads", None), (2, 5)])
def test_a_dask_build_gives_the_bytes_of_one_machine(clients, reference, tmp_path, cluster, tasks):
    from octolinear.dask import build_tiles

    client = clients(cluster)
    out = tmp_path / "map.tiles"
    summary = build_tiles(SAMPLE_GRAPH, out, client=client, tasks=tasks, **MAP, **OPTIONS)
    assert converted(out, tmp_path) == reference
    threads = sum(client.nthreads().values())
    assert [t["task"] for t in summary["tasks"]] == list(range(tasks or threads))
    assert {t["worker"] for t in summary["tasks"]} <= set(client.nthreads())
    assert summary["skipped"] == [] and not any(t["skipped"] for t in summary["tasks"])
    assert all(t["scans"] == 6 and t["seconds"] > 0 for t in summary["tasks"])
    assert summary["tiles"] == sum(t["tiles"] for t in summary["tasks"]) == len(list(out.glob("*.olm")))
    assert summary["bytes"] == sum(t["bytes"] for t in summary["tasks"])
    assert summary["nodes"] == octolinear.build(SAMPLE_GRAPH, resolution=MAP["resolution"], **OPTIONS).size()
    assert leftovers(out) == []


def crash_first_attempt(marker):
    """Makes task 1's first attempt in this worker process die halfway: its
    tiles from the first scan only are on disk, no part file, and the
    process exits at once (as when killed)."""
    real = octolinear.build_tiles

    def build_tiles(graph, out_dir, *, task, **options):
        if task[0] == 1:
            try:
                open(marker, "x").close()
            except FileExistsError:
                pass
            else:
                real(graph, out_dir, task=task, **{**options, "scans": 1, "resume": False})
                os.remove(os.path.join(out_dir, f"task-1-of-{task[1]}.manifest"))
                os._exit(1)
        return real(graph, out_dir, task=task, **options)

    octolinear.build_tiles = build_tiles


def test_a_worker_dying_mid_build_still_gives_the_map(reference, tmp_path):
    from octolinear.dask import build_tiles

    cluster, client = local_cluster(2)
    with cluster, client:
        marker = tmp_path / "task-1-died"
        client.run(crash_first_attempt, str(marker))
        out = tmp_path / "map.tiles"
        summary = build_tiles(SAMPLE_GRAPH, out, client=client, tasks=4, **MAP, **OPTIONS)
        assert marker.exists()  # the first attempt of task 1 did die
    # task 1 built again; tasks whose results died with the worker ran
    # again too, and found their parts done (skipped)
    assert summary["tasks"][1]["scans"] == 6 and 1 not in summary["skipped"]
    assert converted(out, tmp_path) == reference
    assert leftovers(out) == []


def test_an_interrupted_build_resumes(clients, reference, tmp_path):
    from octolinear.dask import build_tiles

    out = tmp_path / "map.tiles"

    def task(k, n, **options):
        # the plan build_tiles makes, from the build's options
        plan = octolinear.plan_tiles(SAMPLE_GRAPH, tasks=n, **MAP, **OPTIONS)
        return octolinear.build_tiles(SAMPLE_GRAPH, out, task=(k, n), plan=plan, **MAP, **{**OPTIONS, **options})

    # what an interrupted build of 4 tasks leaves, after an abandoned build
    # of 3 tasks: tasks 0 and 1 done, but a tile of task 1 damaged since;
    # task 2 killed while writing (tiles of its first scan, no part file,
    # a temporary file); task 3 not started
    task(0, 3)
    task(0, 4)
    task(1, 4)
    part = (out / "task-1-of-4.manifest").read_text()
    tile = out / re.search(r"^tile (\S+) ", part, re.MULTILINE).group(1)
    damaged = bytearray(tile.read_bytes())
    damaged[len(damaged) // 2] ^= 0x04
    tile.write_bytes(bytes(damaged))
    task(2, 4, scans=1)
    (out / "task-2-of-4.manifest").unlink()
    (out / ".d12-2047-2047-2047.olm.999999.0.tmp").write_bytes(b"a killed writer's")

    summary = build_tiles(SAMPLE_GRAPH, out, client=clients("threads"), tasks=4, **MAP, **OPTIONS)
    assert summary["skipped"] == [0]
    assert [t["scans"] for t in summary["tasks"]] == [None, 6, 6, 6]
    assert converted(out, tmp_path) == reference
    assert leftovers(out) == []


def test_parts_built_with_other_options_are_built_again(clients, reference, tmp_path):
    from octolinear.dask import build_tiles

    out = tmp_path / "map.tiles"
    # what a build with max_range=20 left, on the tiles of the plan the
    # build below makes (max_range=5): every part, none combined yet
    plan = octolinear.plan_tiles(SAMPLE_GRAPH, tasks=2, **MAP, **OPTIONS)
    for k in range(2):
        octolinear.build_tiles(SAMPLE_GRAPH, out, task=(k, 2), plan=plan, **MAP, max_range=20.0)
    summary = build_tiles(SAMPLE_GRAPH, out, client=clients("threads"), tasks=2, **MAP, **OPTIONS)
    assert summary["skipped"] == [] and [t["scans"] for t in summary["tasks"]] == [6, 6]
    assert converted(out, tmp_path) == reference
    assert leftovers(out) == []


def test_the_input_is_one_graph_file(clients, tmp_path):
    from octolinear.dask import build_tiles

    with pytest.raises(TypeError, match="one .graph file: input must be a path"):
        build_tiles([SAMPLE_GRAPH, SAMPLE_GRAPH], tmp_path / "a.tiles", client=clients("threads"), **MAP)
    assert not (tmp_path / "a.tiles").exists()
    summary = build_tiles(input=SAMPLE_GRAPH, out_dir=tmp_path / "b.tiles", client=clients("threads"), tasks=2, **MAP)
    assert summary["tiles"] > 0


def test_errors_of_tasks_reach_the_caller(clients, tmp_path):
    from octolinear.dask import build_tiles

    client = clients("threads")
    with pytest.raises(FileNotFoundError, match="missing.graph"):
        build_tiles(tmp_path / "missing.graph", tmp_path / "a.tiles", client=client, **MAP)
    with pytest.raises(ValueError, match="tile_depth"):
        build_tiles(SAMPLE_GRAPH, tmp_path / "b.tiles", client=client, resolution=0.1, tile_depth=0)
    with pytest.raises(TypeError, match="compress_ml"):
        build_tiles(SAMPLE_GRAPH, tmp_path / "c.tiles", client=client, compress_ml=True, **MAP)
    with pytest.raises(ValueError, match="tasks must be"):
        build_tiles(SAMPLE_GRAPH, tmp_path / "d.tiles", client=client, tasks=0, **MAP)


def run_python(code, tmp_path):
    """Runs `code` in a new interpreter, away from the source tree."""
    return subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)


def test_octolinear_does_not_import_dask(tmp_path):
    done = run_python("import sys, octolinear; print(sorted({'dask', 'distributed'} & set(sys.modules)))", tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_octolinear_dask_without_dask_names_what_to_install(tmp_path):
    code = "import sys\nsys.modules['dask'] = sys.modules['distributed'] = None\nimport octolinear.dask"
    done = run_python(code, tmp_path)
    assert done.returncode != 0
    assert "ImportError: octolinear.dask needs Dask's distributed scheduler: pip install 'dask[distributed]'" in done.stderr


GOLDEN = REPO / "tests" / "golden"


def golden_bytes(case, name):
    """A file of a golden case, produced by OctoMap 1.10 (gzipped or not)."""
    plain = GOLDEN / "cases" / case / name
    if plain.exists():
        return plain.read_bytes()
    return gzip.decompress(plain.with_name(name + ".gz").read_bytes())


@pytest.mark.parametrize(
    "case, graph, resolution, max_range, discretize",
    [
        ("spherical_scan_r0.1_mrm1_d0_l0_def", "spherical_scan.graph", 0.1, None, False),
        ("syn_edges_r0.05_mr5_d1_l0_def", "syn_edges.graph", 0.05, 5.0, True),
        ("syn_mapedge_r010_mrm1_d0", "syn_mapedge_r010.graph", 0.1, None, False),
    ],
)
def test_golden_cases_built_on_dask_give_octomaps_bytes(
    clients, tmp_path, case, graph, resolution, max_range, discretize
):
    from octolinear.dask import build_tiles

    out = tmp_path / "map.tiles"
    build_tiles(
        GOLDEN / "inputs" / graph,
        out,
        client=clients(2),
        tasks=3,
        resolution=resolution,
        tile_depth=10,
        max_range=max_range,
        discretize=discretize,
    )
    assert converted(out, tmp_path) == {"ot": golden_bytes(case, "tree.ot"), "bt": golden_bytes(case, "tree.bt")}
