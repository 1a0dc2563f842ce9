"""Shared fixtures of the Python package's tests.

GPU tests fail when no Vulkan device exists, unless ``SOFTVK_NO_GPU=1`` says there is none (then
they are skipped). Meshes come from ``SOFTVK_ASSETS`` or the repository's ``assets/``; the
``softvk`` command line from ``SOFTVK_BIN`` or the repository's ``target/release/softvk``
(``cargo build --release`` makes it).

With ``SOFTVK_TEST_INSTALLED=1`` (CI's wheel and sdist runs) the tests refuse to run against the
source tree's ``python/softvk``: the package must come from the environment's site-packages, as a
user's does.
"""

import os
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


def pytest_configure(config):
    if os.environ.get("SOFTVK_TEST_INSTALLED") == "1":
        import softvk

        where = pathlib.Path(softvk.__file__).resolve()
        if REPO / "python" in where.parents or "site-packages" not in where.parts:
            raise pytest.UsageError(f"SOFTVK_TEST_INSTALLED=1, but softvk was imported from {where}")


def assets_dir():
    return pathlib.Path(os.environ.get("SOFTVK_ASSETS") or REPO / "assets")


@pytest.fixture(scope="session")
def gpu():
    """The device name; fails the test when there is none, unless SOFTVK_NO_GPU=1."""
    import softvk

    if os.environ.get("SOFTVK_NO_GPU") == "1":
        pytest.skip("SOFTVK_NO_GPU=1: no Vulkan device on this machine")
    return softvk.device_name()


@pytest.fixture(scope="session")
def assets():
    return assets_dir()


@pytest.fixture(scope="session")
def softvk_bin():
    path = pathlib.Path(os.environ.get("SOFTVK_BIN") or REPO / "target" / "release" / "softvk")
    if not path.exists():
        pytest.fail(f"{path} is missing: build it with `cargo build --release` first")
    return path


@pytest.fixture
def engine_calls(monkeypatch):
    """Counts the SoftRenderer fast path's engine calls (``softvk.torch.render_mesh``), keeping
    each call's keyword arguments."""
    import softvk.torch as st

    calls = []
    original = st.render_mesh

    def counted(*args, **kwargs):
        calls.append(kwargs)
        return original(*args, **kwargs)

    monkeypatch.setattr(st, "render_mesh", counted)
    return calls
