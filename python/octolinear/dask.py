"""Tile sets built on a Dask cluster: one Dask task per share of the tiles.

``build_tiles(input, out_dir, resolution=..., tile_depth=..., client=...)``
runs ``octolinear.build_tiles(..., task=(k, n))`` for every task ``k`` of
``n`` on the cluster's workers, then combines their parts into the tile
set's manifest (``octolinear.write_tile_manifest``). The tile set is the one
a single ``octolinear.build_tiles`` writes: ``octolinear.convert_tiles``
gives the ``.ot`` and ``.bt`` bytes of ``octolinear.build``.

Every file is read and written by the workers: the ``.graph`` file and
``out_dir`` must be at the same path on every worker (a shared filesystem);
the client only schedules. Needs ``dask[distributed]``.
"""

import os
import re
import time
import uuid
from typing import Any, Optional, Union

try:
    import distributed
except ImportError as error:
    raise ImportError(
        "octolinear.dask needs Dask's distributed scheduler: pip install 'dask[distributed]'"
    ) from error

import octolinear

__all__ = ["build_tiles"]

# the options of octolinear.build_tiles a Dask build passes on to every task
_BUILD_OPTIONS = frozenset({"max_range", "discretize", "sensor", "clamping", "scans", "threads"})
# those of them that also shape the plan (which rays reach which tiles)
_PLAN_OPTIONS = ("max_range", "discretize", "scans")

# a task's part file, and the temporary file of a tile whose writer was killed
_PART_FILE = re.compile(r"task-\d+-of-(\d+)\.manifest")
_TILE_TEMP_FILE = re.compile(r"\.d\d+-\d+-\d+-\d+\.olm\.\d+\.\d+\.tmp")


def build_tiles(
    input: Union[str, os.PathLike],
    out_dir: Union[str, os.PathLike],
    *,
    resolution: float,
    tile_depth: int,
    client: "distributed.Client",
    tasks: Optional[int] = None,
    resume: bool = True,
    **build_options: Any,
) -> dict[str, Any]:
    """Builds the tile set of the ``.graph`` file ``input`` (one file: a list
    of files is a ``TypeError``) in ``out_dir`` on the Dask cluster of
    ``client``, as ``octolinear.build_tiles(input, out_dir,
    resolution=..., tile_depth=...)`` does on one machine.

    The tiles are shared by ``tasks`` Dask tasks (default: the cluster's
    worker threads), each ``octolinear.build_tiles(..., task=(k, tasks))``
    on one thread (``threads=1`` unless ``build_options`` says otherwise),
    each a contiguous range of tiles of about equal estimated work from
    ``octolinear.plan_tiles`` (the first Dask task), casting only the rays
    that reach it. Tasks are retried twice on errors, and run again
    elsewhere when their worker dies; tile files are replaced atomically,
    so a killed task leaves no partial tile. Once all are done, their parts
    are combined into the manifest (part files of another task count and
    temporary files of killed writers are removed first).

    With ``resume`` (the default) a task whose part file
    (``task-K-of-N.manifest``) is already in ``out_dir``, built with the
    same parameters, options (``max_range``, ``discretize``, ``sensor``,
    ``clamping``, ``scans``), input (its length and modification time) and
    range of tiles, and whose tiles all verify (lengths, CRC-32s,
    structure) is not run again; a part built otherwise is built again, and
    so is a task interrupted before its part file was written, and a
    finished set (its parts combined into the manifest). ``out_dir`` must be
    named ``NAME.tiles``, or be an empty directory or a tile set.

    ``build_options``: ``max_range``, ``discretize``, ``sensor``,
    ``clamping``, ``scans``, ``threads``, as for ``octolinear.build_tiles``.
    Paths are made absolute on the client. An error of a task (a missing
    input, a damaged file) is raised here, after its retries.

    Returns a dict: ``tiles``, ``nodes`` (of the whole map), ``bytes`` (of
    tile files), ``seconds`` (wall time), ``plan`` (the plan's text), ``skipped`` (the tasks resumed), and
    ``tasks``: per task, in task order, ``task``, ``worker`` (its address),
    ``seconds``, ``tiles``, ``bytes``, ``skipped``, ``scans``, ``points``.
    """
    if isinstance(input, (list, tuple)):
        raise TypeError(
            "build_tiles() builds the tile set of one .graph file: input must be a path (str or os.PathLike), "
            f"got a {type(input).__name__}"
        )
    unknown = set(build_options) - _BUILD_OPTIONS
    if unknown:
        raise TypeError(f"build_tiles() got unexpected keyword arguments: {', '.join(sorted(unknown))}")
    if tasks is None:
        tasks = sum(client.nthreads().values())
    if not isinstance(tasks, int) or tasks < 1:
        raise ValueError(f"tasks must be a whole number >= 1, got {tasks!r} (a cluster without workers has 0)")
    build_options.setdefault("threads", 1)
    graph = os.path.abspath(os.fspath(input))
    out = os.path.abspath(os.fspath(out_dir))
    started = time.perf_counter()
    token = uuid.uuid4().hex
    plan_options = {name: build_options[name] for name in _PLAN_OPTIONS if name in build_options}
    plan = client.submit(
        octolinear.plan_tiles,
        graph,
        resolution=resolution,
        tile_depth=tile_depth,
        tasks=tasks,
        key=f"octolinear-plan-tiles-{token}",
        pure=False,
        retries=2,
        **plan_options,
    )
    parts = [
        client.submit(
            _build_task,
            graph,
            out,
            (k, tasks),
            plan,
            resolution,
            tile_depth,
            resume,
            build_options,
            key=f"octolinear-build-tiles-{k}-of-{tasks}-{token}",
            pure=False,
            retries=2,
        )
        for k in range(tasks)
    ]
    try:
        built = client.gather(parts)
        combined = client.submit(
            _finish_tile_set, out, tasks, key=f"octolinear-tile-manifest-{token}", pure=False, retries=2
        ).result()
        plan_text = plan.result()
    except BaseException:
        client.cancel(parts + [plan])
        raise
    return {
        "tiles": combined["tiles"],
        "nodes": combined["nodes"],
        "bytes": combined["bytes"],
        "seconds": time.perf_counter() - started,
        "plan": plan_text,
        "skipped": [part["task"] for part in built if part["skipped"]],
        "tasks": built,
    }


def _build_task(graph, out_dir, task, plan, resolution, tile_depth, resume, build_options):
    """One Dask task: ``octolinear.build_tiles`` of task ``task`` (``(k, n)``),
    with the worker's address and the task's wall time."""
    started = time.perf_counter()
    part = octolinear.build_tiles(
        graph,
        out_dir,
        resolution=resolution,
        tile_depth=tile_depth,
        task=task,
        plan=plan,
        resume=resume,
        **build_options,
    )
    return {
        "task": task[0],
        "worker": distributed.get_worker().address,
        "seconds": time.perf_counter() - started,
        "tiles": part["tiles"],
        "bytes": part["bytes"],
        "skipped": part["skipped"],
        "scans": part["scans"],
        "points": part["points"],
    }


def _finish_tile_set(out_dir, tasks):
    """The last Dask task: removes part files of other task counts than
    ``tasks`` (an abandoned build's) and temporary tile files of killed
    writers, then writes the manifest from the parts."""
    for name in os.listdir(out_dir):
        part = _PART_FILE.fullmatch(name)
        if (part and int(part.group(1)) != tasks) or _TILE_TEMP_FILE.fullmatch(name):
            os.remove(os.path.join(out_dir, name))
    return octolinear.write_tile_manifest(out_dir)
