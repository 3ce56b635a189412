import os
import tempfile

import pytest

# compiled objects of the test session go to a private cache, so runs never depend on ~/.cache
os.environ.setdefault("SIMGRAD_CACHE_DIR", tempfile.mkdtemp(prefix="simgrad-test-cache-"))
os.environ.setdefault("SIMGRAD_VERIFY", "1")  # the IR verifier runs after every pass in tests

import simgrad as ti  # noqa: E402


@pytest.fixture(autouse=True)
def fresh_program():
    """Every test starts from ti.init() with defaults (f32, i32, no debug)."""
    ti.init(arch=ti.cpu)
    yield
    ti.reset()


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true", help="rewrite golden IR files")
