"""The kernel cache (frontend-level): a second process takes forward and adjoint kernels from the disk
cache, and anything the generated code depends on (a captured constant, a field's shape, a ti.func's body,
a ti.init option) makes it compile again instead of reusing stale code."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import json
    import numpy as np
    import simgrad as ti
    from simgrad.runtime.jit import get_jit

    ti.init(arch=ti.cpu, offline_cache_file_path=r"{cache}", debug={debug})
    SCALE = {scale}
    x = ti.field(ti.f32, shape={n}, needs_grad=True)
    y = ti.field(ti.f32, shape={n}, needs_grad=True)

    @ti.func
    def shape_fn(v):
        return v * {func_factor}

    @ti.kernel
    def f(a: ti.f32):
        for i in x:
            v = shape_fn(ti.sin(x[i])) * a * SCALE
            assert v < 1000.0  # compiled in debug mode only
            y[i] = v

    x.from_numpy(np.linspace(0.0, 1.0, {n}, dtype=np.float32))
    out = {{}}
    try:
        f(2.0)
        y.grad.fill(1.0)
        f.grad(2.0)
        (inst,) = f._caches["grad"].values()
        out["ir_stmts"] = len(inst.ir.body.stmts)  # rebuilt on demand when the kernel came from the cache
    except ti.SimgradError as e:
        out["error"] = type(e).__name__
    out["y"] = y.to_numpy().tolist()
    out["xgrad"] = x.grad.to_numpy().tolist()
    out["stats"] = get_jit().stats
    print("RESULT " + json.dumps(out))
""")

BASE = {"scale": "3.0", "n": 16, "func_factor": "2.0", "debug": False}


def run(tmp_path, **changes) -> dict:
    params = dict(BASE, **changes, cache=tmp_path / "cache")
    script = tmp_path / "prog.py"  # one path: the file and line numbers are part of the key
    script.write_text(SCRIPT.format(**params))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=dict(os.environ),
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = next(s for s in proc.stdout.splitlines() if s.startswith("RESULT "))
    return json.loads(line[7:])


def expected(scale=3.0, n=16, factor=2.0):
    import numpy as np

    x = np.linspace(0.0, 1.0, n, dtype=np.float32).astype(np.float64)
    return np.sin(x) * factor * 2.0 * scale, np.cos(x) * factor * 2.0 * scale


def check(out, **kw):
    import numpy as np

    y, g = expected(**kw)
    np.testing.assert_allclose(out["y"], y, rtol=1e-5)
    np.testing.assert_allclose(out["xgrad"], g, rtol=1e-5)


def test_second_process_takes_forward_and_grad_from_the_cache(tmp_path):
    first = run(tmp_path)
    second = run(tmp_path)
    check(first)
    assert first["stats"]["kernel_hits"] == 0
    assert second["stats"]["kernel_hits"] == 2  # the forward and the adjoint kernel
    assert second["stats"]["compiled"] == 0
    assert second["y"] == first["y"] and second["xgrad"] == first["xgrad"]
    assert second["ir_stmts"] == first["ir_stmts"] > 0


@pytest.mark.parametrize("change, expect", [
    ({"scale": "5.0"}, {"scale": 5.0}),  # a captured Python constant (the kernel's source is unchanged)
    ({"n": 24}, {"n": 24}),  # a field's shape, seen only through the field
    ({"func_factor": "7.0"}, {"factor": 7.0}),  # the body of an inlined ti.func
])
def test_a_change_the_code_depends_on_misses_the_cache(tmp_path, change, expect):
    check(run(tmp_path))
    changed = run(tmp_path, **change)
    assert changed["stats"]["kernel_hits"] == 0
    check(changed, **expect)
    again = run(tmp_path, **change)  # and the new instantiation is cached in turn
    assert again["stats"]["kernel_hits"] == 2
    check(again, **expect)


def test_init_options_are_part_of_the_key(tmp_path):
    """The assertion exists only in debug mode: stale non-debug code would not raise it."""
    plain = run(tmp_path, scale="1e9")
    assert "error" not in plain
    debug = run(tmp_path, scale="1e9", debug=True)
    assert debug["stats"]["kernel_hits"] == 0 and debug["error"] == "SimgradAssertionError"


def test_assertion_reaches_the_cached_kernel(tmp_path):
    """The error table travels with the cached object: a debug-mode kernel from the cache still reports."""
    first = run(tmp_path, debug=True, scale="1e9")
    second = run(tmp_path, debug=True, scale="1e9")
    assert first["error"] == second["error"] == "SimgradAssertionError"
    assert second["stats"]["kernel_hits"] == 1  # the forward, which raised before the adjoint was built


GUARDED = textwrap.dedent("""
    import json
    import simgrad as ti
    from simgrad.runtime.jit import get_jit

    ti.init(arch=ti.cpu, offline_cache_file_path=r"{cache}")
    x = ti.field(ti.f32, shape=4)
    LOG = []


    def helper(v):  # plain Python: its code is not part of any key
        return v * 2.0


    @ti.kernel
    def k():
        for i in x:
            x[i] = {body}

    k()
    print("RESULT " + json.dumps({{"x": x.to_numpy().tolist(), "hits": get_jit().stats["kernel_hits"]}}))
""")


@pytest.mark.parametrize("body, value, cached", [
    ("3.0", 3.0, True),
    ("helper(3.0)", 6.0, False),  # a call into user Python code: not described by the key
    ("ti.static(LOG.append(1) or 3.0)", 3.0, False),  # a compile-time side effect a cache hit would skip
    ("ti.static(ti.static_print('hello') or 3.0)", 3.0, False),  # output a cache hit would not print
])
def test_what_the_key_cannot_describe_is_never_cached(tmp_path, body, value, cached):
    script = tmp_path / "prog.py"
    script.write_text(GUARDED.format(cache=tmp_path / "cache", body=body))
    outs = []
    for _ in range(2):
        proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=dict(os.environ),
                              timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
        outs.append(json.loads(next(s for s in proc.stdout.splitlines() if s.startswith("RESULT "))[7:]))
        assert ("hello" in proc.stdout) == ("static_print" in body)
    assert outs[0]["x"] == outs[1]["x"] == [value] * 4
    assert outs[1]["hits"] == (1 if cached else 0)
