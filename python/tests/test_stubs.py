"""The type stubs describe the compiled module as it is, and everything
public has a docstring."""

import ast
import inspect
import pathlib

import octolinear
from octolinear import _octolinear

STUB = pathlib.Path(octolinear.__file__).with_name("_octolinear.pyi")


def stub_names():
    """Top-level names of the stub, and the public methods of its classes."""
    tree = ast.parse(STUB.read_text())
    names, classes = set(), {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            classes[node.name] = {
                n.name for n in node.body if isinstance(n, ast.FunctionDef) and not n.name.startswith("_")
            }
            names.add(node.name)
        elif isinstance(node, ast.FunctionDef):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign):
            names.add(node.target.id)
    return names, classes


def runtime_public():
    return {n for n in dir(_octolinear) if not n.startswith("_")}


def test_stub_lists_the_module():
    names, classes = stub_names()
    assert runtime_public() <= names
    for name, methods in classes.items():
        cls = getattr(_octolinear, name)
        own = {n for n in vars(cls) if not n.startswith("_")}
        assert own == methods, name
    assert (pathlib.Path(octolinear.__file__).parent / "py.typed").exists()


def test_everything_public_is_documented():
    for name in runtime_public():
        obj = getattr(_octolinear, name)
        if isinstance(obj, int):
            continue
        assert inspect.getdoc(obj), name
        if inspect.isclass(obj):
            for member, value in vars(obj).items():
                if not member.startswith("_"):
                    assert inspect.getdoc(value), f"{name}.{member}"
