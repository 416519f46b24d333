"""Endless inputs given to read_points: a line without an end is refused
at the library's 1 MiB bound, quickly, as a ValueError naming the file."""

import os
import threading
import time

import pytest

import octolinear


@pytest.mark.parametrize(
    "suffix, message",
    [(".xyz", "line 1 is longer than 1048576 bytes"), (".ply", "header line 1 is longer than 1048576 bytes"),
     (".pcd", "header line 1 is longer than 1048576 bytes")],
)
def test_read_points_refuses_an_endless_line(tmp_path, suffix, message):
    path = tmp_path / ("zeros" + suffix)
    os.symlink("/dev/zero", path)
    started = time.monotonic()
    with pytest.raises(ValueError, match=f"zeros\\{suffix}: {message}"):
        octolinear.read_points(path)
    assert time.monotonic() - started < 10


def test_read_points_reads_a_ply_stream(tmp_path):
    fifo = tmp_path / "cloud.ply"
    os.mkfifo(fifo)
    text = (
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n1 2 3\n4 5 6\n"
    )
    writer = threading.Thread(target=lambda: fifo.write_text(text))
    writer.start()
    try:
        assert octolinear.read_points(fifo).tolist() == [[1, 2, 3], [4, 5, 6]]
    finally:
        writer.join()
