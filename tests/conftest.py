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


def normalise_ir(text: str) -> str:
    """IR text that only changes when the IR's shape does: statement ids renumbered in order of
    appearance, fields reduced to their names, source locations dropped."""
    import re

    text = re.sub(r"<(?:Scalar|Matrix)Field (\S+)[^>]*>", r"\1", text)
    text = re.sub(r"[ \t]+#[^\n]*", "", text)
    ids: dict[str, str] = {}
    text = re.sub(r"%\d+\b(?!\.)", lambda m: ids.setdefault(m.group(0), f"%{len(ids)}"), text)
    return "\n".join(line.rstrip() for line in text.strip().splitlines()) + "\n"


class Golden:
    """Compares text with tests/<dir>/golden/<name>; `pytest --update-golden` rewrites the file (review
    the diff)."""

    def __init__(self, request):
        self.dir = os.path.join(os.path.dirname(str(request.fspath)), "golden")
        self.update = request.config.getoption("--update-golden")

    def check(self, name: str, text: str) -> None:
        path = os.path.join(self.dir, name)
        if self.update:
            os.makedirs(self.dir, exist_ok=True)
            with open(path, "w") as fh:
                fh.write(text)
        assert os.path.exists(path), f"{path} is missing: run pytest with --update-golden"
        with open(path) as fh:
            expected = fh.read()
        assert text == expected, f"{name} changed; review and rerun with --update-golden:\n{text}"

    @staticmethod
    def ir(kernel) -> str:
        from simgrad.ir.printer import print_kernel

        return normalise_ir(print_kernel(kernel))


@pytest.fixture
def golden(request):
    return Golden(request)
