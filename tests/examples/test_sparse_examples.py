"""examples/sparse_poisson.py and examples/sparse_advection.py at reduced size."""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_sparse_poisson_solves_on_the_disk_blocks_only(tmp_path):
    import sparse_poisson

    r = sparse_poisson.main(["--n", "128", "--block", "8", "--out", str(tmp_path)])
    assert r["residual"] < 1e-4 and r["iterations"] < 400
    assert r["error"] < 1e-4  # the discrete solution is the harmonic quadratic itself
    # the disk of radius 0.42 plus its ring covers ~56% of the square: the blocks outside it are never allocated
    assert 0.45 * r["total_blocks"] < r["live_blocks"] < 0.75 * r["total_blocks"]
    assert (tmp_path / "solution.png").exists()


def test_sparse_advection_follows_the_blob_and_matches_dense(tmp_path):
    import sparse_advection

    r = sparse_advection.main(["--n", "128", "--block", "8", "--steps", "120", "--out", str(tmp_path)])
    assert r["diff"] < 5e-4  # against the same steps on a dense field (blocks with < 1e-4 density are dropped)
    assert abs(r["mass"] - r["dense_mass"]) < 1e-3 * r["dense_mass"]
    assert max(r["counts"]) < 0.3 * r["total_blocks"] and min(r["counts"]) > 0
    assert (tmp_path / "advection.png").exists()
