"""The abi3 wheel: built by maturin, installed into a fresh venv, imported
and used there (away from the source tree)."""

import os
import pathlib
import subprocess
import sys
import venv

import pytest

PYTHON_DIR = pathlib.Path(__file__).resolve().parents[1]

SMOKE = """
import numpy as np, octolinear, pathlib, sys
assert pathlib.Path(octolinear.__file__).is_relative_to(pathlib.Path(sys.prefix)), octolinear.__file__
tree = octolinear.OcTree(0.1)
tree.insertPointCloud(np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.5]]), np.zeros(3))
assert tree.getLabels(np.array([[1.0, 0.0, 0.0], [0.5, 0.0, 0.0], [9.0, 9.0, 9.0]])).tolist() == [1, 0, -1]
assert tree.writeBinary().startswith(b"# Octomap OcTree binary file")
state, _ = tree.occupancy(np.zeros((1, 3), dtype=np.float32))
print("smoke ok", octolinear.__file__, state.tolist())
"""


def built_wheel(out):
    """The wheel the test harness built (OCTOLINEAR_WHEEL), else a new one."""
    given = os.environ.get("OCTOLINEAR_WHEEL")
    if given:
        return pathlib.Path(given)
    subprocess.run(
        [sys.executable, "-m", "maturin", "build", "--release", "-m", str(PYTHON_DIR / "Cargo.toml"), "-o", str(out)],
        check=True,
    )
    (wheel,) = out.glob("octolinear-*.whl")
    return wheel


@pytest.mark.wheel
def test_wheel_installs_into_a_fresh_venv_and_works(tmp_path):
    wheel = built_wheel(tmp_path / "dist")
    assert "-cp39-abi3-" in wheel.name, wheel.name
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    python = env_dir / "bin" / "python"
    subprocess.run([python, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", wheel], check=True)
    result = subprocess.run([python, "-c", SMOKE], cwd=tmp_path, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("smoke ok")
    assert result.stdout.strip().endswith("[0]")  # the sensor's own voxel is free
