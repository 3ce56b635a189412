"""Taichi's own test suite as a yardstick: run its tests/python files under taichi (CPU) and under simgrad.

    python benchmarks/taichi_tests.py --taichi-repo PATH [--files test_struct.py ...] [--framework both]
                                      [--json OUT] [--markdown]

PATH is a checkout of taichi-dev/taichi at v1.7.4 (only tests/ is read; nothing is copied into this repo).
Under taichi, the upstream tests/test_utils.py runs with TI_WANTED_ARCHS=cpu. Under simgrad, `import taichi`
and `from tests import test_utils` are served by benchmarks/taichi_suite/shim (taichi -> simgrad, a CPU-only
test_utils). Each file runs in its own pytest process (a crash or hang costs one file). A test counts for
simgrad when it passes under both, minus EXCLUDED (tests of Taichi's internals).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
SHIM = os.path.join(HERE, "taichi_suite", "shim")
PLUGINS = os.path.join(HERE, "taichi_suite", "plugins")
ROOT = os.path.dirname(HERE)

# the files issue 9 names (globs under tests/python)
DEFAULT_FILES = ["test_ad_*.py", "test_loops.py", "test_field*.py", "test_matrix*.py", "test_struct*.py",
                 "test_dataclass.py", "test_ndarray.py", "test_function*.py", "test_return.py", "test_atomic.py",
                 "test_cast.py", "test_types.py", "test_static*.py", "test_offset.py", "test_math_module.py",
                 "test_linalg.py", "test_svd.py", "test_polar_decomp.py", "test_eig.py", "test_custom_struct.py",
                 "test_api.py", "test_ast_refactor.py", "test_exception.py", "test_print.py", "test_assert.py",
                 "test_random.py", "test_sparse_matrix.py", "test_sparse_linear_solver.py", "test_matrixfree_*.py"]

_OFFLINE_CACHE_LAYOUT = (
    "counts the files of Taichi's offline cache directory: one .tic per compiled kernel plus ticache.tcb, written when "
    "the program is reset, including the kernels Taichi compiles for itself (Python-scope field readers/writers, "
    "the Tape's gradient clearing) and its size-based cleaning of .tic files. simgrad's kernel cache keeps an object "
    "and an entry per instantiation, written when compiled, and compiles no accessor kernels; the observable "
    "behaviour is tested in tests/runtime/test_warm_cache.py and tests/lang/test_runtime_features.py (a second "
    "process compiles nothing, the key covers code and ti.init options, offline_cache=False writes nothing: "
    "test_closing_offline_cache passes)")

# tests of Taichi's internals, not of the language: (file, test name prefix) -> why
EXCLUDED = {
    ("test_api.py", "test_api"): "compares dir() of Taichi's internal modules (taichi.lang.*, ti.ad submodules) "
                                 "name by name",
    ("test_exception.py", "test_"): "asserts Taichi's exact error text and its AST transformer's "
                                              "traceback layout",
    ("test_ad_ndarray.py", "test_ad_sum_vector"): "passes under Taichi only because bool() of any Taichi Matrix is "
                                                  "True: `assert p[i] == [a[i] * 2, a[i] * 3]` compares a vector "
                                                  "with two vectors and is false entry by entry",
    ("test_ad_ndarray.py", "test_ad_vector_arg"): "`assert p[i] == [a[i] * 2, a[i] * 2]` broadcasts a 2-vector "
                                                  "against a 2x2 nested list (Taichi's Python scope follows numpy; "
                                                  "simgrad refuses operands of different shapes) and asserts the "
                                                  "truth of a Matrix, which is always True",
    ("test_torch_io.py", "test_fused_kernels"): "counts the copy kernels Taichi compiles for to_torch/from_torch (one "
                                                "each); simgrad copies a dense field through its numpy view and "
                                                "compiles none (the values are checked by test_io_simple, "
                                                "test_shape_matrix and tests/interop)",
    ("test_ad_global_data_access_rule_checker.py", "test_adjoint_checkbit"): "reads Taichi's C++ SNode "
                                                                             "(x.snode.ptr.has_adjoint_checkbit())",
    **{("test_ad_global_data_access_rule_checker.py", name): "expects Taichi's validation to refuse a kernel that "
                                                             "reads b[None] and then updates it; simgrad's Tape rolls "
                                                             "the updated fields back before that launch's adjoint "
                                                             "and gives the right gradient instead (tests/lang/"
                                                             "test_taichi_suite_compat.py test_read_then_update_in_"
                                                             "one_kernel_has_the_right_gradient)"
       for name in ("test_break_gdar_rule_1", "test_skip_grad_replaced")},
    ("test_ad_global_data_access_rule_checker.py", "test_validation_kernel_capture"): "reads the Tape's internal "
                                                                                      "lists of calls and autodiff "
                                                                                      "modes (t.calls, t.modes)",
    ("test_ad_global_data_access_rule_checker.py", "test_autodiff_mode_recovered"): "reads the kernel's internal "
                                                                                    "autodiff_mode enum",
    ("test_ad_snode_grad_type.py", "test_"): "reads Taichi's C++ SNode (x.snode.ptr.get_snode_grad_type())",
    ("test_return.py", "test_func_multiple_return"): "Taichi refuses a return inside a run-time if in a ti.func; "
                                                     "simgrad compiles it (tests/frontend/test_control_flow.py, early "
                                                     "returns)",
    ("test_field.py", "test_field_needs_grad_dtype"): "its last case expects needs_grad=True on a struct field "
                                                      "with an integer member to be refused; simgrad gives the "
                                                      "float members gradients and the integer ones none "
                                                      "(tests/lang/test_structs.py); the other cases pass",
    ("test_field.py", "test_field_needs_dual_dtype"): "its last case expects needs_dual=True on a struct field with "
                                                      "an integer member to be refused; simgrad gives the float "
                                                      "members duals and the integer ones none, as for needs_grad "
                                                      "(test_field_needs_grad_dtype above); the other cases pass",
    ("test_field.py", "test_field_shape_0"): "Taichi refuses a zero dimension; simgrad keeps empty fields on purpose "
                                             "(sorting or scanning nothing: tests/lang/test_algorithms.py; "
                                             "tests/lang/test_taichi_suite_compat.py)",
    ("test_ast_refactor.py", "test_binop"): "calls taichi.lang.impl.ti_float (an internal of Taichi's AST "
                                            "builder)",
    ("test_ast_refactor.py", "test_func_in_python_func"): "drives impl.get_runtime().compiling_callable."
                                                          "ast_builder() (Taichi's internal AST builder)",
    ("test_ast_refactor.py", "test_taichi_other_than_ti"): "drives impl.get_runtime().compiling_callable."
                                                           "ast_builder() (Taichi's internal AST builder)",
    ("test_ast_refactor.py", "test_range_for_three_arguments"): "Taichi refuses range(a, b, step) in kernels; "
                                                                "simgrad runs it (tests/frontend/"
                                                                "test_python_forms.py)",
    ("test_ast_refactor.py", "test_static_assign_element"): "Taichi refuses assigning an element of a ti.static "
                                                            "list; simgrad assigns the compile-time list as "
                                                            "Python does (tests/frontend/test_python_forms.py)",
    ("test_ast_refactor.py", "test_recreate_variable"): "Taichi refuses `a = 1; a = ti.static(2)`; simgrad "
                                                        "assigns the variable (tests/frontend/test_python_forms.py)",
    ("test_cast.py", "test_int_extension"): "stores -128 into a u8 field from Python scope, which Taichi wraps "
                                            "silently to 128; simgrad refuses the out-of-range value "
                                            "(tests/lang/test_fill_and_ranges.py)",
    ("test_struct.py", "test_struct_field_with_bool"): "stores 0xFFFF into an i16 struct member from Python scope, "
                                                       "which Taichi wraps silently to -1; simgrad refuses the "
                                                       "out-of-range value (tests/lang/test_fill_and_ranges.py)",
    ("test_runtime.py", "test_xdg_basedir"): "reads the repository directory of Taichi's C++ core "
                                              "(import_ti_python_core().get_repo_dir())",
    ("test_kernel_arg_errors.py", "test_pass_struct_mismatch"): "matches the repr of Taichi's own Python classes "
                                                                "(<class 'taichi.lang.struct.Struct...>, <taichi.lang."
                                                                "matrix.VectorType object at ...>); simgrad refuses "
                                                                "the mismatched struct too, naming the member",
    **{("test_offline_cache.py", name): _OFFLINE_CACHE_LAYOUT for name in (
        "test_offline_cache_per_kernel", "test_multiple_ib_with_offline_cache",
        "test_calling_a_kernel_with_different_param_list", "test_snode_reader_and_writer_with_offline_cache",
        "test_calling_many_kernels", "test_offline_cache_with_different_snode_trees",
        "test_offline_cache_with_changing_compile_config", "test_offline_cache_cleaning",
        "test_offline_cache_for_kernels_calling_real_func")},
    ("test_cli.py", "test_cli"): "drives Taichi's command-line tool (taichi._main.TaichiMain: `ti example`, gif, "
                                 "video, regression, cache ...), not the language; simgrad ships no `ti` command",
    ("test_ast_resolver.py", "test_"): "tests taichi.lang.ast.symbol_resolver.ASTResolver, a helper of Taichi's AST "
                                       "transformer (simgrad resolves names in frontend/lower.py its own way)",
    **{("test_internal_func.py", name): "calls Taichi's C++ runtime test hooks by name (impl.call_internal("
                                        "\"do_nothing\"), \"test_internal_func_args\", ...)"
       for name in ("test_basic", "test_list_manager", "test_node_manager", "test_return")},
    ("test_type_system.py", "test_"): "type-checks calls of Taichi's C++ runtime test hook "
                                      "(impl.call_internal(\"test_internal_func_args\", ...))",
    **{("test_matrix.py", f"test_matrix_field_dynamic_index_{name}"): "asserts the dynamic-index stride Taichi "
                                                                      "computes for a matrix field's members "
                                                                      "(v._get_dynamic_index_stride(), after impl."
                                                                      "get_runtime().materialize())"
       for name in ("stride", "different_path_length", "not_pure_dense", "different_cell_size_bytes",
                    "different_offset_bytes_in_parent_cell", "different_stride")},
    ("test_matrix.py", "test_matrix_dtype"): "the second test of that name reads Taichi's Matrix storage (a.entries "
                                             "is a numpy array there, a list here); it hides the first, which "
                                             "pytest never runs",
    ("test_callable_template_mapper.py", "test_"): "tests TaichiCallableTemplateMapper and KernelArgument, the "
                                                   "instance cache of Taichi's kernel_impl (simgrad keys its "
                                                   "instances in compiler/kernel.py)",
    ("test_compare.py", "test_no_duplicate_eval_func"): "drives impl.get_runtime().compiling_callable.ast_builder() "
                                                        "(Taichi's internal AST builder)",
    ("test_indices.py", "test_indices["): "reads SNode._physical_index_position(), Taichi's internal axis map",
    ("test_tensor_reflection.py", "test_unordered"): "walks Taichi's SNode internals (_get_children(), "
                                                     "impl.get_runtime().materialize_root_fb(), FieldsBuilder."
                                                     "_finalized_roots(), _path_from_root())",
    ("test_fill.py", "test_fill_vector_field_recompile"): "counts the kernels Taichi compiles for x.fill() "
                                                          "(get_num_compiled_functions() == 1); simgrad fills a dense "
                                                          "field through its numpy view and compiles none",
    ("test_ad_if.py", "test_stack"): "calls Taichi's C++ runtime test hook impl.call_internal(\"test_stack\")",
    ("test_binding.py", "test_binding"): "reads Taichi's C++ binding (ti._lib.core.BinaryOpType)",
    ("test_threading.py", "test_while"): "calls Taichi's C++ test hook ti._lib.core.test_threading()",
    ("test_clear_all_gradients.py", "test_clear_all_gradients"): "counts the kernels Taichi compiles to clear "
                                                                 "gradients (get_num_compiled_functions() == 3); "
                                                                 "simgrad clears them with one fill kernel per "
                                                                 "gradient layout or numpy (the values are checked "
                                                                 "by its other asserts and tests/lang)",
    ("test_arg_alignment.py", "test_arg_read"): "passes 255 to an i8 parameter, which Taichi wraps silently to -1; "
                                                "simgrad refuses the out-of-range value (runtime/args.py, "
                                                "tests/runtime/test_arg_conversion.py)",
    ("test_ad_basics.py", "test_ad_rand"): "asserts Taichi's C++ message 'RandStmt not supported' (simgrad "
                                           "refuses ti.random in a differentiated kernel too, in its own words)",
}


def _excluded(file: str, name: str) -> str | None:
    for (f, prefix), why in EXCLUDED.items():
        if f == file and name.startswith(prefix):
            return why
    return None


def run_file(python: str, path: str, framework: str, repo: str, timeout: float) -> dict:
    """{test name: outcome} for one file ('passed', 'failed', 'error', 'skipped'), or {'<file>': 'crash'}."""
    with tempfile.TemporaryDirectory() as tmp:
        xml = os.path.join(tmp, "out.xml")
        env = dict(os.environ)
        if framework == "simgrad":
            # upstream tests/ is a package whose test_utils needs taichi's C++ core: the file runs from a
            # stand-in package (tests/ with the shim's test_utils, tests/python linked to upstream's)
            cwd = tmp
            pkg = os.path.join(tmp, "tests")
            os.mkdir(pkg)
            open(os.path.join(pkg, "__init__.py"), "w").close()
            os.symlink(os.path.join(SHIM, "tests", "test_utils.py"), os.path.join(pkg, "test_utils.py"))
            os.symlink(os.path.dirname(os.path.abspath(path)), os.path.join(pkg, "python"))
            path = os.path.join(pkg, "python", os.path.basename(path))
            env["PYTHONPATH"] = os.pathsep.join([SHIM, PLUGINS, ROOT, env.get("PYTHONPATH", "")])
        else:
            cwd = repo
            env["PYTHONPATH"] = os.pathsep.join([repo, PLUGINS, env.get("PYTHONPATH", "")])
            env["TI_WANTED_ARCHS"] = "cpu"
        env["TI_OFFLINE_CACHE"] = "0"
        cmd = [python, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly", "--rootdir", tmp,
               f"--junitxml={xml}", "-o", "junit_family=xunit1", path]
        try:
            proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"<file>": "timeout"}
        if not os.path.exists(xml):
            return {"<file>": "crash", "<tail>": proc.stdout[-2000:] + proc.stderr[-2000:]}
        out = {}
        for case in ET.parse(xml).getroot().iter("testcase"):
            name = case.get("name", "?")
            tags = {c.tag for c in case}
            out[name] = ("failed" if "failure" in tags else "error" if "error" in tags
                         else "skipped" if "skipped" in tags else "passed")
        if not out and proc.returncode not in (0, 5):  # nothing ran: a conftest or import error
            return {"<file>": "error", "<tail>": proc.stdout[-2000:]}
        return out


def summarise(results: dict) -> list[dict]:
    rows = []
    for file in sorted(results):
        ti_res = results[file].get("taichi", {})
        sg_res = results[file].get("simgrad", {})
        counted = [n for n, o in ti_res.items() if o == "passed" and not _excluded(file, n)]
        both = [n for n in counted if sg_res.get(n) == "passed"]
        rows.append({"file": file, "taichi_passed": len(counted), "simgrad_passed": len(both),
                     "simgrad_total_passed": sum(o == "passed" for o in sg_res.values()),
                     "excluded": sum(1 for n in ti_res if _excluded(file, n)),
                     "failing": sorted(set(counted) - set(both))})
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| file | taichi passed (CPU) | simgrad passed of those | excluded |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['file']} | {r['taichi_passed']} | {r['simgrad_passed']} | {r['excluded']} |")
    t = sum(r["taichi_passed"] for r in rows)
    s = sum(r["simgrad_passed"] for r in rows)
    lines.append(f"| **total** | **{t}** | **{s}** ({100 * s / max(t, 1):.0f}%) | "
                 f"{sum(r['excluded'] for r in rows)} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--taichi-repo", required=True, help="checkout of taichi-dev/taichi at v1.7.4")
    ap.add_argument("--files", nargs="*", help="file names or globs under tests/python")
    ap.add_argument("--framework", choices=["both", "simgrad", "taichi"], default="both")
    ap.add_argument("--simgrad-python", default=sys.executable)
    ap.add_argument("--taichi-python", default=os.environ.get("TAICHI_PYTHON", sys.executable))
    ap.add_argument("--timeout", type=float, default=600, help="seconds per file")
    ap.add_argument("--json", help="results file; merged with what it already holds")
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    tests_dir = os.path.join(args.taichi_repo, "tests", "python")
    paths: list[str] = []
    for pattern in args.files or DEFAULT_FILES:
        paths += sorted(glob.glob(os.path.join(tests_dir, pattern)))
    results: dict = {}
    if args.json and os.path.exists(args.json):
        with open(args.json) as fh:
            results = json.load(fh)
    frameworks = ["taichi", "simgrad"] if args.framework == "both" else [args.framework]
    for path in dict.fromkeys(paths):
        file = os.path.basename(path)
        for fw in frameworks:
            python = args.simgrad_python if fw == "simgrad" else args.taichi_python
            res = run_file(python, path, fw, args.taichi_repo, args.timeout)
            results.setdefault(file, {})[fw] = res
            print(f"{file:40s} {fw:8s} " + " ".join(f"{o}={sum(v == o for v in res.values())}"
                                                      for o in ("passed", "failed", "error", "skipped"))
                  + (f" [{res['<file>']}]" if "<file>" in res else ""), flush=True)
            if args.json:
                with open(args.json, "w") as fh:
                    json.dump(results, fh, indent=1)
    if args.markdown:
        print(markdown(summarise(results)))


if __name__ == "__main__":
    main()
