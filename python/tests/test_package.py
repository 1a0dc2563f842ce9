"""The package as users install it: the README's PyTorch example runs, the native module's type
stubs name what it has, and an installed distribution carries its licences and ``py.typed``."""

import ast
import importlib.metadata
import os
import pathlib
import re

import pytest

import softvk
from softvk import _native

from conftest import REPO


def readme_example():
    """The first Python block of README.md's "PyTorch" section."""
    text = (REPO / "README.md").read_text()
    section = text[text.index("\n## PyTorch\n"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_readme_pytorch_example_runs(gpu, monkeypatch):
    monkeypatch.chdir(REPO)  # its mesh path is relative to the repository
    scope = {}
    exec(compile(readme_example(), "README.md (PyTorch)", "exec"), scope)
    assert tuple(scope["images"].shape) == (1, 4, 128, 128)
    grad = scope["vertices"].grad
    assert grad is not None and bool(grad.isfinite().all()) and float(grad.abs().max()) > 0


def test_the_stubs_name_every_function_and_class_of_the_native_module():
    stubs = ast.parse((pathlib.Path(softvk.__file__).parent / "_native.pyi").read_text())
    stubbed = {node.name for node in stubs.body
               if isinstance(node, (ast.FunctionDef, ast.ClassDef))}
    public = {name for name in dir(_native) if not name.startswith("_")}
    assert stubbed == public


def test_the_package_is_typed():
    assert (pathlib.Path(softvk.__file__).parent / "py.typed").exists()


@pytest.mark.skipif(os.environ.get("SOFTVK_TEST_INSTALLED") != "1",
                    reason="the source tree has no installed distribution to read")
def test_the_installed_distribution_carries_its_licences_and_metadata():
    dist = importlib.metadata.distribution("softvk")
    names = {pathlib.PurePath(str(f)).name for f in dist.files}
    assert {"LICENSE-MIT", "LICENSE-APACHE", "LICENSE-SoftRas", "py.typed", "_native.pyi"} <= names
    meta = dist.metadata
    assert meta["License-Expression"] == "MIT OR Apache-2.0"
    assert "torch" in (meta.get_all("Provides-Extra") or [])
    assert meta["Requires-Python"] == ">=3.9"
