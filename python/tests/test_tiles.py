"""Tile sets from Python: build_tiles (whole, in tasks combined by
write_tile_manifest, and within a memory cap) converted by convert_tiles
gives the bytes of build;
resume keeps only builds whose tiles verify; bad arguments and damaged
sets are exceptions naming the problem."""

import os
import re
import time
import zlib

import pytest
from conftest import SAMPLE_GRAPH

import octolinear


def built_bytes(tmp_path, options):
    """The .ot, .bt and .olm bytes of octolinear.build with `options`."""
    out = {}
    for ext in ("ot", "bt", "olm"):
        path = tmp_path / f"reference.{ext}"
        octolinear.build(SAMPLE_GRAPH, output=path, **options)
        out[ext] = path.read_bytes()
    return out


def converted_bytes(tiles_dir, tmp_path):
    """The .ot, .bt and .olm bytes convert_tiles writes from a tile set."""
    out = {}
    for ext in ("ot", "bt", "olm"):
        path = tmp_path / f"converted.{ext}"
        octolinear.convert_tiles(tiles_dir, path)
        out[ext] = path.read_bytes()
    return out


def part_tiles(out_dir, task):
    """The tile file names a task's part file lists."""
    text = (out_dir / f"task-{task[0]}-of-{task[1]}.manifest").read_text()
    return re.findall(r"^tile (\S+) ", text, re.MULTILINE)


OPTIONS = [
    dict(resolution=0.1),
    dict(resolution=0.2, max_range=4.0),
    dict(resolution=0.1, discretize=True, scans=3),
    dict(resolution=0.15, sensor=(0.3, 0.8), clamping=(0.15, 0.95)),
]


@pytest.mark.parametrize("options", OPTIONS)
@pytest.mark.parametrize("tile_depth", [6, 12])
def test_a_tile_set_gives_the_bytes_of_build(tmp_path, options, tile_depth):
    reference = built_bytes(tmp_path, options)
    whole = tmp_path / "whole.tiles"
    summary = octolinear.build_tiles(SAMPLE_GRAPH, whole, tile_depth=tile_depth, **options)
    assert converted_bytes(whole, tmp_path) == reference
    tree = octolinear.build(SAMPLE_GRAPH, **options)
    scans = octolinear.read_graph(SAMPLE_GRAPH)[: options.get("scans", 6)]
    assert summary["nodes"] == tree.size()
    assert (summary["scans"], summary["points"]) == (len(scans), sum(len(p) for p, _ in scans))
    assert summary["task"] is None and not summary["skipped"]
    tiles = sorted(p for p in whole.iterdir() if p.suffix == ".olm")
    assert summary["tiles"] == len(tiles) > 0
    assert summary["bytes"] == sum(p.stat().st_size for p in tiles)

    parts = tmp_path / "parts.tiles"
    built = [octolinear.build_tiles(SAMPLE_GRAPH, parts, tile_depth=tile_depth, task=(k, 3), **options) for k in range(3)]
    assert [b["task"] for b in built] == [(0, 3), (1, 3), (2, 3)]
    assert all(b["nodes"] is None for b in built)
    combined = octolinear.write_tile_manifest(parts)
    assert not list(parts.glob("task-*"))
    assert (combined["tiles"], combined["nodes"], combined["bytes"]) == (
        summary["tiles"],
        summary["nodes"],
        summary["bytes"],
    )
    assert sum(b["tiles"] for b in built) == summary["tiles"]
    assert converted_bytes(parts, tmp_path) == reference

    # within a memory cap: groups split down to single tiles, or one group
    for cap in (1, 1 << 30):
        capped_dir = tmp_path / f"capped-{cap}.tiles"
        capped = octolinear.build_tiles(SAMPLE_GRAPH, capped_dir, tile_depth=tile_depth, memory_cap=cap, **options)
        assert {k: capped[k] for k in ("tiles", "nodes", "bytes", "scans", "points")} == {
            k: summary[k] for k in ("tiles", "nodes", "bytes", "scans", "points")
        }
        assert converted_bytes(capped_dir, tmp_path) == reference


def test_tasks_share_the_tiles_by_plan(tmp_path):
    plan = octolinear.plan_tiles(SAMPLE_GRAPH, tile_depth=12, tasks=3)
    assert plan.splitlines()[0].startswith("octolinear-tile-plan ")
    out = tmp_path / "planned.tiles"
    for k in range(3):
        octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(k, 3), plan=plan)
    octolinear.write_tile_manifest(out)
    assert converted_bytes(out, tmp_path) == built_bytes(tmp_path, {})


def test_resume_keeps_only_builds_that_verify(tmp_path):
    out = tmp_path / "map.tiles"
    first = octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2), resume=True)
    assert not first["skipped"]
    again = octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2), resume=True)
    assert again["skipped"] and (again["scans"], again["points"]) == (None, None)
    assert (again["tiles"], again["bytes"]) == (first["tiles"], first["bytes"])
    assert not octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2))["skipped"]
    # other parameters than the part's: built again
    assert not octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2), sensor=(0.3, 0.8), resume=True)[
        "skipped"
    ]
    octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2))
    # a tile damaged (same length) or missing: built again, and whole after
    tile = out / part_tiles(out, (1, 2))[0]
    damaged = bytearray(tile.read_bytes())
    damaged[len(damaged) // 2] ^= 0x10
    tile.write_bytes(bytes(damaged))
    assert not octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2), resume=True)["skipped"]
    tile.unlink()
    assert not octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2), resume=True)["skipped"]
    assert octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2), resume=True)["skipped"]
    octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 2), resume=True)
    octolinear.write_tile_manifest(out)
    assert converted_bytes(out, tmp_path) == built_bytes(tmp_path, {})
    # a whole set resumes too, with the map's node count
    whole = octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, resume=True)
    assert whole["skipped"] and whole["nodes"] == octolinear.build(SAMPLE_GRAPH).size()


@pytest.mark.parametrize(
    "arguments, message",
    [
        (dict(tile_depth=0), "tile_depth must be between 1 and 15, got 0"),
        (dict(tile_depth=16), "got 16"),
        (dict(tile_depth=8, resolution=-0.1), "resolution"),
        (dict(tile_depth=8, max_range=-1.0), "max_range must be a positive"),
        (dict(tile_depth=8, scans=0), "scans must be at least 1"),
        (dict(tile_depth=8, threads=0), "threads must be at least 1"),
        (dict(tile_depth=8, task=(2, 2)), r"0 <= k < n <= 65536, got \(2, 2\)"),
        (dict(tile_depth=8, task=(0, 0)), r"got \(0, 0\)"),
        (dict(tile_depth=8, plan="plan"), "plan needs task"),
        (dict(tile_depth=8, sensor=(0.9, 0.7)), "prob_miss = 0.9"),
        (dict(tile_depth=8, memory_cap=0), "memory_cap must be at least 1 byte"),
        (dict(tile_depth=8, memory_cap=1 << 20, task=(0, 2)), "does not take a task"),
    ],
)
def test_bad_arguments_are_refused_before_anything_is_written(tmp_path, arguments, message):
    out = tmp_path / "map.tiles"
    with pytest.raises(ValueError, match=message):
        octolinear.build_tiles(SAMPLE_GRAPH, out, **arguments)
    assert not out.exists()


def test_plan_arguments_are_checked():
    for arguments, message in [
        (dict(tile_depth=8, tasks=0), "tasks must be at least 1"),
        (dict(tile_depth=0, tasks=2), "tile_depth"),
        (dict(tile_depth=8, tasks=2, resolution=0.0), "resolution"),
        (dict(tile_depth=8, tasks=2, max_range=float("nan")), "max_range"),
    ]:
        with pytest.raises(ValueError, match=message):
            octolinear.plan_tiles(SAMPLE_GRAPH, **arguments)
    with pytest.raises(TypeError):
        octolinear.plan_tiles(SAMPLE_GRAPH, tasks=2)  # tile_depth is required


def test_plans_that_do_not_fit_the_build_are_refused(tmp_path):
    plan = octolinear.plan_tiles(SAMPLE_GRAPH, tile_depth=12, tasks=3)
    out = tmp_path / "p.tiles"
    for arguments, message in [
        (dict(tile_depth=12, task=(0, 2), plan=plan), "3 tasks"),
        (dict(tile_depth=11, task=(0, 3), plan=plan), "tile_depth 12"),
        (dict(tile_depth=12, task=(0, 3), resolution=0.2, plan=plan), "resolution 0.1"),
        (dict(tile_depth=12, task=(0, 3), plan="not a plan"), "plan: \"not a plan\" is neither"),
    ]:
        with pytest.raises(ValueError, match=message):
            octolinear.build_tiles(SAMPLE_GRAPH, out, **arguments)
    assert not out.exists()


def test_files_that_cannot_be_read_are_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.graph"):
        octolinear.build_tiles(tmp_path / "missing.graph", tmp_path / "a.tiles", tile_depth=8)
    truncated = tmp_path / "truncated.graph"
    truncated.write_bytes(SAMPLE_GRAPH.read_bytes()[:5000])
    with pytest.raises(ValueError, match="truncated.graph"):
        octolinear.build_tiles(truncated, tmp_path / "b.tiles", tile_depth=8)
    with pytest.raises(FileNotFoundError, match="nothing.tiles"):
        octolinear.convert_tiles(tmp_path / "nothing.tiles", tmp_path / "map.ot")
    with pytest.raises(ValueError, match="no task parts"):
        (tmp_path / "empty.tiles").mkdir()
        octolinear.write_tile_manifest(tmp_path / "empty.tiles")


def test_incomplete_or_damaged_sets_are_refused(tmp_path):
    out = tmp_path / "map.tiles"
    octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 2))
    with pytest.raises(ValueError, match="the part of task 1 of 2 is missing"):
        octolinear.write_tile_manifest(out)
    octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2))
    octolinear.write_tile_manifest(out)
    with pytest.raises(ValueError, match=r"\.bt, \.ot or \.olm"):
        octolinear.convert_tiles(out, tmp_path / "map.txt")
    tile = sorted(out.glob("*.olm"))[0]
    damaged = bytearray(tile.read_bytes())
    damaged[-20] ^= 0x01
    tile.write_bytes(bytes(damaged))
    for ext in ("ot", "bt", "olm"):
        with pytest.raises(ValueError, match=tile.stem):
            octolinear.convert_tiles(out, tmp_path / f"map.{ext}")
        assert not (tmp_path / f"map.{ext}").exists()


def test_a_part_built_otherwise_is_built_again_and_never_combined(tmp_path):
    graph = tmp_path / "scans.graph"
    graph.write_bytes(SAMPLE_GRAPH.read_bytes())
    out = tmp_path / "map.tiles"
    assert not octolinear.build_tiles(graph, out, tile_depth=12, task=(0, 2), max_range=20.0, resume=True)["skipped"]
    assert octolinear.build_tiles(graph, out, tile_depth=12, task=(0, 2), max_range=20.0, resume=True)["skipped"]
    part = (out / "task-0-of-2.manifest").read_text()
    assert part.startswith("octolinear-tiles 2\ntask 0 2\n") and "\nmax_range 4034000000000000\n" in part
    # another max range, scan count or input: not the same part
    for options in (dict(), dict(max_range=5.0), dict(max_range=20.0, scans=3), dict(max_range=20.0, discretize=True)):
        again = octolinear.build_tiles(graph, out, tile_depth=12, task=(0, 2), resume=True, **options)
        assert not again["skipped"], options
    octolinear.build_tiles(graph, out, tile_depth=12, task=(0, 2), max_range=20.0)
    stat = graph.stat()
    os.utime(graph, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    assert not octolinear.build_tiles(graph, out, tile_depth=12, task=(0, 2), max_range=20.0, resume=True)["skipped"]
    # parts of other options are not combined: the option is named
    octolinear.build_tiles(graph, out, tile_depth=12, task=(1, 2), max_range=5.0)
    with pytest.raises(ValueError, match=r"max_range: 5 m in task-1-of-2\.manifest, 20 m in task-0-of-2\.manifest"):
        octolinear.write_tile_manifest(out)
    assert not (out / "manifest").exists()
    octolinear.build_tiles(graph, out, tile_depth=12, task=(1, 2), max_range=20.0)
    octolinear.write_tile_manifest(out)
    assert converted_bytes(out, tmp_path) == built_bytes(tmp_path, dict(max_range=20.0))
    # a whole set resumes only with its options too
    assert octolinear.build_tiles(graph, out, tile_depth=12, max_range=20.0)["nodes"] > 0
    assert octolinear.build_tiles(graph, out, tile_depth=12, max_range=20.0, resume=True)["skipped"]
    assert not octolinear.build_tiles(graph, out, tile_depth=12, resume=True)["skipped"]
    capped = octolinear.build_tiles(graph, out, tile_depth=12, memory_cap=1 << 30)
    assert octolinear.build_tiles(graph, out, tile_depth=12, memory_cap=1 << 30, resume=True)["skipped"]
    assert converted_bytes(out, tmp_path) == built_bytes(tmp_path, {}) and capped["nodes"] > 0


def test_build_tiles_writes_only_where_a_set_belongs(tmp_path):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "manifest").write_text("my own manifest\n")
    (user / "d12-2048-2048-2048.olm").write_bytes(b"my own map")
    for out in (user, tmp_path / "mine.tiles"):
        if out.name == "mine.tiles":
            out.mkdir()
            (out / "manifest").write_text("my own manifest\n")
        with pytest.raises(ValueError, match="not a tile set's manifest"):
            octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12)
        assert (out / "manifest").read_text() == "my own manifest\n"
    assert (user / "d12-2048-2048-2048.olm").read_bytes() == b"my own map"
    (user / "manifest").unlink()
    with pytest.raises(ValueError, match="neither named NAME.tiles nor empty nor a tile set"):
        octolinear.build_tiles(SAMPLE_GRAPH, user, tile_depth=12)
    assert sorted(p.name for p in user.iterdir()) == ["d12-2048-2048-2048.olm"]
    with pytest.raises(ValueError, match=r"x\.bt: a tile set is a directory named NAME\.tiles"):
        octolinear.build_tiles(SAMPLE_GRAPH, tmp_path / "x.bt", tile_depth=12)
    assert not (tmp_path / "x.bt").exists()
    (tmp_path / "file.tiles").write_bytes(b"a file")
    with pytest.raises(NotADirectoryError, match="file.tiles exists and is not a directory"):
        octolinear.build_tiles(SAMPLE_GRAPH, tmp_path / "file.tiles", tile_depth=12)
    # an empty directory, or a set already there, of any name
    empty = tmp_path / "empty"
    empty.mkdir()
    assert octolinear.build_tiles(SAMPLE_GRAPH, empty, tile_depth=12)["tiles"] > 0
    assert octolinear.build_tiles(SAMPLE_GRAPH, empty, tile_depth=12, resume=True)["skipped"]


def test_a_plan_is_its_text_or_its_file(tmp_path):
    text = octolinear.plan_tiles(SAMPLE_GRAPH, tile_depth=12, tasks=2)
    plan = tmp_path / "map.plan"
    plan.write_text(text)
    out = tmp_path / "planned.tiles"
    octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 2), plan=plan)
    octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(1, 2), plan=str(plan))
    assert "prefixes" in (out / "task-1-of-2.manifest").read_text()
    octolinear.write_tile_manifest(out)
    assert converted_bytes(out, tmp_path) == built_bytes(tmp_path, {})
    with pytest.raises(TypeError, match="plan must be the text plan_tiles returns or the path of a plan file"):
        octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 2), plan=2)
    with pytest.raises(ValueError, match="neither a plan's text"):
        octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 2), plan="missing.plan")
    with pytest.raises(FileNotFoundError, match="missing.plan"):
        octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 2), plan=tmp_path / "missing.plan")
    (tmp_path / "bad.plan").write_text(text.replace("tasks 2", "tasks 3"))
    with pytest.raises(ValueError, match=r"bad\.plan: line 7"):
        octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 3), plan=tmp_path / "bad.plan")
    with pytest.raises(OSError, match="/dev/zero.*not a regular file"):
        octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 2), plan="/dev/zero")


def test_counts_and_files_a_part_claims_are_bounded(tmp_path):
    out = tmp_path / "claims.tiles"
    octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 2))
    part = (out / "task-0-of-2.manifest").read_text()
    body = part[: part.rindex("crc32 ")].replace("task 0 2\n", "task 0 4294967295\n")
    (out / "task-0-of-2.manifest").unlink()
    (out / "task-0-of-4294967295.manifest").write_text(body + f"crc32 {zlib.crc32(body.encode()):08x}\n")
    started = time.monotonic()
    with pytest.raises(ValueError, match="line 2: expected `task K N`"):
        octolinear.write_tile_manifest(out)
    assert time.monotonic() - started < 5
    (out / "task-0-of-4294967295.manifest").unlink()
    with pytest.raises(ValueError, match=r"task must be \(k, n\) with 0 <= k < n <= 65536"):
        octolinear.build_tiles(SAMPLE_GRAPH, out, tile_depth=12, task=(0, 65537))
    os.mkfifo(out / "manifest")
    with pytest.raises(OSError, match="a FIFO, not a regular file"):
        octolinear.convert_tiles(out, tmp_path / "map.ot")
