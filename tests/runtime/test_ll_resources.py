"""The hand-written LLVM IR in simgrad/runtime/ll: each file parses and verifies with llvmlite for every
parameter combination simgrad uses, parameters are all given (and only those), and the files ship with the
package and are part of the kernel cache's source hash."""

from __future__ import annotations

import os
from pathlib import Path

import llvmlite.binding as llvm
import pytest

from simgrad.codegen import sparse as cg_sparse
from simgrad.frontend import fingerprint
from simgrad.runtime import half, ll, threadpool

ROOT = Path(__file__).resolve().parents[2]
LL_DIR = ROOT / "simgrad" / "runtime" / "ll"
# what the kernel module around the sparse allocator declares (codegen/llvm.py, codegen/sparse.py)
_SPARSE_CONTEXT = "declare void @sg_report(ptr, i64, i64)\ndeclare void @llvm.memset.p0.i64(ptr, i8, i64, i1)\n"


def _verify(text: str) -> None:
    mod = llvm.parse_assembly(text)
    mod.verify()


def _pool_variants():
    machines = sorted(threadpool._FUTEX_NR) + ["ppc64le"]  # the last: no futex, no spin hint
    return [(m, threadpool._FUTEX_NR.get(m, -1)) for m in machines]


@pytest.mark.parametrize("stats", [False, True])  # SIMGRAD_POOL_STATS's counters in the ${st_*} places
@pytest.mark.parametrize("machine, futex_nr", _pool_variants())
def test_threadpool_ll_verifies(machine, futex_nr, stats):
    text = threadpool.pool_ir(futex_nr, machine, stats)
    _verify(text)
    assert ("atomicrmw add ptr %stp." in text) == stats
    assert f"@syscall(i64 {futex_nr}," in text
    assert ("sse2.pause" in text) == (machine in ("x86_64", "amd64"))
    assert ("aarch64.hint" in text) == (machine in ("aarch64", "arm64"))


@pytest.mark.parametrize("batched", [True, False], ids=["cpu", "gpu"])
def test_sparse_alloc_ll_verifies(batched):
    helpers = cg_sparse._HELPERS[batched]
    _verify(helpers + _SPARSE_CONTEXT)
    for name in ("sg_sparse_alloc", "sg_sparse_free", "sg_pool_push", "sg_dyn_link", "sg_dyn_chunk", "sg_dyn_clear"):
        assert f"@{name}(" in helpers


def test_half_ll_verifies():
    _verify(half.IR)
    mod = llvm.parse_assembly(half.IR)
    assert sorted(f.name for f in mod.functions) == sorted(half.SYMBOLS)


def test_sim_blocks_ll_verifies():
    _verify(ll.load("sim_blocks", symbol="sg_kernel_blocks"))


def test_sequence_ll_verifies():
    _verify(ll.load("sequence"))


def test_sim_grid_ll_verifies():
    _verify(ll.load("sim_grid", pfor_slot=3) + ll.load("sim_blocks", symbol="simgrad_sim_blocks"))


def test_every_ll_file_is_loaded_and_checked_here():
    assert sorted(p.stem for p in LL_DIR.glob("*.ll")) == ["half", "sequence", "sim_blocks", "sim_grid",
                                                                 "sparse_alloc", "threadpool"]


def test_load_refuses_missing_and_unknown_parameters():
    with pytest.raises(KeyError):
        ll.load("threadpool", futex_nr=202)
    params = {k: 0 for k in ll.parameters("threadpool")}
    ll.load("threadpool", **params)
    with pytest.raises(TypeError, match="no parameter"):
        ll.load("threadpool", **params, bogus=1)
    assert ll.parameters("half") == set()


def test_ll_files_ship_as_package_data():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    patterns = config["tool"]["setuptools"]["package-data"]["simgrad.runtime.ll"]
    assert all(any(p.match(pat) for pat in patterns) for p in LL_DIR.glob("*.ll"))


def test_ll_files_are_in_the_kernel_cache_source_hash():
    files = {os.path.relpath(p, ROOT / "simgrad") for p in fingerprint.source_files(str(ROOT / "simgrad"))}
    assert {"runtime/ll/half.ll", "runtime/ll/sparse_alloc.ll", "runtime/ll/threadpool.ll"} <= files
    assert "runtime/threadpool.py" in files
