"""Run the examples shipped in a taichi wheel under simgrad and under taichi, side by side, and compare end states.

    python benchmarks/taichi_examples.py --examples PATH [--only NAME ...] [--frames N] [--json F] [--table]

PATH is an installed wheel's ``taichi/examples/`` folder; nothing of it is copied into this repository. Each
(framework, example) runs in a fresh child process (this file with ``--child``) inside its own temporary
working directory. The child

- serves ``import taichi`` (and every ``taichi.X`` simgrad has, e.g. taichi.math, taichi._lib.core) with
  simgrad, and ``taichi.examples.*`` from PATH, or imports the real taichi,
- forces ``ti.init(arch=cpu, random_seed=0)`` (TI_ARCH=x64 as well, for programs without ti.init), seeds
  ``random`` and ``numpy.random`` with 0, uses matplotlib's Agg backend,
- makes ``ti.GUI`` headless (show_gui=False), without ``gui.text`` (the fonts differ; TAICHI_EXAMPLES_TEXT=1
  draws it), and ``ti.ui.Window`` hidden (show_window=False): their
  ``running`` turns False after N shown frames, and a program that never asks (``for i in range(10**6)``)
  is stopped at its (N+1)-th ``show()``,
- gives the program a frame clock instead of the wall clock (``time.time``/``perf_counter``/``time_ns`` in
  the ``time`` module the program imports advance 1/60 s per shown frame, and 1 us per read by the program
  itself), so clock-driven animations agree; ``ti.tools.imshow`` keeps its picture as the last image,
- at exit (normal end, frame limit, SystemExit or exception) dumps every field, ndarray, numpy array and
  number reachable from the program's globals (one level into lists, dicts and objects of the program's own
  classes; gradients too) with ``to_numpy``, and the last shown image (ti.GUI's canvas, the GGUI window's
  image buffer), into an .npz; stdout is captured.

The parent records exit status (signal names for SIGSEGV, SIGKILL...), wall time, peak RSS (the child's
VmHWM, polled every 50 ms) and a timeout, then compares simgrad against taichi: every array both dumped (relative
to the taichi array's largest magnitude), the last image, and stdout (numbers with a relative tolerance,
the rest as text; ``[Taichi]`` banner lines dropped). taichi comes from --taichi-python or $TAICHI_PYTHON.

N is --frames, or more where taichi's frames are short (``--min-seconds``, see steady_frames): both frameworks
show the same N frames, and --speed reports the median frame time from the 3rd on.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
RTOL = 1e-4  # "match": every compared array within this, relative to the taichi array's magnitude
CLOSE = 1e-2  # "close": within this
IMAGE_TOL = 2 / 255  # last image: largest channel difference
#: examples that show a frame only every so many steps: fewer frames (sdf_renderer: 10 path-traced
#: 1280x720 samples per frame)
FRAMES = {"rendering/sdf_renderer.py": 1}
MAX_ELEMENTS = 1 << 24  # larger arrays are summarised (sum, min, max) instead of dumped


# ---------------------------------------------------------------------------------------------- child
class FrameLimit(BaseException):
    """Raised from show() when a program shows more frames than allowed without asking ``running``."""


class _State:
    frames = 0
    limit = 3
    ticks = 0
    image = None  # last shown image (numpy)
    script = ""  # the program's file
    frame_s: list = []  # per shown frame: the program's work since the last show() plus the framework's show()
    last_show = None  # real clock when the last show() returned
    after_copy: list = []  # per entry of frame_s: whether the harness copied the picture just before that frame
    copied_last = False

    @classmethod
    def keep_image(cls, img):
        """Copy the shown picture into one float32 buffer kept across frames: a fresh 4 MB array per frame (and
        freeing the last) made the next frame's Python and numpy work up to 7x slower in a framework that
        allocates as it draws (glibc returning and faulting back pages), outside what the program itself does."""
        import numpy as np

        img = np.asarray(img)
        if cls.image is None or cls.image.shape != img.shape:
            cls.image = np.empty(img.shape, np.float32)
        np.copyto(cls.image, img, casting="unsafe")


def _clock_module():
    """A copy of ``time`` whose clocks advance 1/60 s per shown frame (and 1 us per call, so deltas are > 0)."""
    import types

    real = sys.modules["time"]
    fake = types.ModuleType("time")
    fake.__dict__.update({k: v for k, v in real.__dict__.items() if not k.startswith("__")})

    def now():
        f = sys._getframe(1)
        while f.f_code.co_filename == __file__:  # this module's wrappers (perf_counter, time_ns...)
            f = f.f_back
        if f.f_code.co_filename == _State.script:  # the program's own reads, not the frameworks'
            _State.ticks += 1
        return 1.0e9 + _State.frames / 60.0 + _State.ticks * 1e-6

    fake.time = now
    fake.perf_counter = lambda: now() - 1.0e9
    fake.monotonic = fake.perf_counter
    fake.process_time = fake.perf_counter
    fake.time_ns = lambda: int(now() * 1e9)
    fake.perf_counter_ns = lambda: int(fake.perf_counter() * 1e9)
    fake.sleep = lambda s: None
    return fake


def _alias_simgrad(examples):
    """``import taichi[.X]`` -> simgrad[.X] for every loaded simgrad module; taichi.examples -> PATH."""
    import importlib
    import types

    import simgrad

    for sub in ("math", "_lib", "_lib.core", "ui", "linalg", "tools", "types", "lang", "ad"):
        try:
            importlib.import_module("simgrad." + sub)
        except ImportError:
            pass
    for name, mod in list(sys.modules.items()):
        if name == "simgrad" or name.startswith("simgrad."):
            sys.modules["taichi" + name[len("simgrad"):]] = mod
    for sub in ("math", "ui", "tools", "ad", "linalg", "types"):  # namespaces that are attributes, not files
        mod = getattr(simgrad, sub, None)
        if isinstance(mod, types.ModuleType):
            sys.modules.setdefault("taichi." + sub, mod)
    pkg = types.ModuleType("taichi.examples")
    pkg.__path__ = [examples]
    sys.modules["taichi.examples"] = pkg
    simgrad.examples = pkg  # type: ignore[attr-defined]
    return simgrad


def _is_fast(gui):
    """taichi's fast_gui keeps the picture as packed uint32 in ``gui.img``, and its get_image() would write
    float RGBA over that smaller buffer (heap corruption: SIGABRT / SIGSEGV), so it is decoded instead."""
    import numpy as np

    if not getattr(gui, "fast_gui", True):  # both frameworks' GUI says so (simgrad's gui.img would be one more
        return False  # get_image: a copy of the whole picture per frame, just to learn its dtype)
    img = getattr(gui, "img", None)
    return isinstance(img, np.ndarray) and img.dtype == np.uint32


def _fast_gui_image(gui):
    """0x00RRGGBB words, top row first -> float32 (W, H, 3) indexed [x, y] like get_image()."""
    import numpy as np

    w, h = gui.res
    words = gui.img.reshape(h, w)[::-1].T
    return np.stack([(words >> s) & 255 for s in (16, 8, 0)], axis=-1).astype(np.float32) / 255


_real_clock = time.perf_counter


#: the picture is copied every CAPTURE_EVERY-th frame and at the last frame the harness allows
CAPTURE_EVERY = 3


def _timed_show(capture, show, draw=lambda: None):
    """draw(), capture() (the harness's copy of the picture, not timed), then show(); the frame's time is the
    program's work since the previous show() returned plus draw() and show() (the real clock, not the program's
    frame clock). draw() makes the pixels a window would show where the framework defers drawing until they are
    looked at (simgrad's ti.GUI canvas): a headless show() never looks, taichi's canvas draws at each call, so
    without it the drawing would fall into the untimed capture.

    The copy (megabytes) evicts the program's own working set from the caches, so the frame after a copy runs
    slower for reasons of the harness's making (a 31 us simgrad GUI frame took 217 us after one). Copies are made
    every CAPTURE_EVERY-th frame and at the last allowed one, and the frames after a copy are marked and left out
    of the steady time (steady_ms). A program that ends on its own before the limit is compared at its last copied
    frame, the same frame in both frameworks."""
    draw()
    t1 = _real_clock()
    copied = _State.frames % CAPTURE_EVERY == 0 or _State.frames >= _State.limit
    if copied:
        capture()
    t2 = _real_clock()
    show()
    t3 = _real_clock()
    if _State.last_show is not None:
        _State.frame_s.append((t1 - _State.last_show) + (t3 - t2))
        _State.after_copy.append(_State.copied_last)
    _State.copied_last = copied
    _State.last_show = t3


def _headless(ti, cache_dir):
    """arch, seed, GUI and Window patches, applied to the framework module (never to the program's text)."""
    import numpy as np

    init = ti.init

    def cpu_init(*args, **kw):
        kw["arch"] = ti.cpu
        kw["random_seed"] = 0
        kw.setdefault("offline_cache_file_path", cache_dir)
        kw.update(json.loads(os.environ.get("TAICHI_EXAMPLES_INIT", "{}")))
        return init(**kw)

    ti.init = cpu_init
    gui_cls = ti.GUI

    class HeadlessGUI(gui_cls):
        def __init__(self, *args, **kw):
            if len(args) > 3:
                args = args[:3] + (False,) + args[4:]
            else:
                kw["show_gui"] = False
            super().__init__(*args, **kw)

        def text(self, *args, **kw):
            if os.environ.get("TAICHI_EXAMPLES_TEXT") == "1":
                return super().text(*args, **kw)
            return None  # the two frameworks' fonts differ; everything else in the picture is compared

        @property
        def running(self):
            return gui_cls.running.fget(self) and _State.frames < _State.limit

        @running.setter
        def running(self, value):
            gui_cls.running.fset(self, value)

        def show(self, file=None):
            def capture():
                try:
                    _State.keep_image(_fast_gui_image(self) if _is_fast(self) else self.get_image())
                except Exception as e:  # noqa: BLE001 - recorded, not fatal
                    print(f"@@harness: get_image failed: {e!r}", file=sys.stderr)

            def draw():
                canvas = getattr(self, "canvas", None)  # simgrad's; a fast_gui window shows the packed words
                if type(canvas).__module__.startswith("simgrad") and getattr(self, "_fast", None) is None:
                    _ = canvas.img  # (not _is_fast: simgrad's gui.img of a float canvas is a copy of it)

            _State.frames += 1
            _State.ticks = 0
            _timed_show(capture, lambda: super(HeadlessGUI, self).show(file), draw)
            if _State.frames > _State.limit:
                raise FrameLimit()

    HeadlessGUI.__name__ = HeadlessGUI.__qualname__ = "GUI"
    HeadlessGUI.__module__ = gui_cls.__module__  # not one of the program's classes (see dump_state)
    ti.GUI = HeadlessGUI

    def imshow(img, title="imshow"):
        """The picture is kept as the last image; no frames shown (taichi's loops until its window closes,
        simgrad's returns at once without a display)."""
        arr = img if isinstance(img, np.ndarray) else img.to_numpy()
        gui = gui_cls(title, res=arr.shape[:2], show_gui=False)
        gui.set_image(arr)
        _State.image = np.array(gui.get_image(), np.float32)

    ti.tools.imshow = imshow
    win_cls = getattr(getattr(ti, "ui", None), "Window", None)
    if win_cls is None:
        return

    class HeadlessWindow(win_cls):
        def __init__(self, name, res, vsync=False, show_window=True, *args, **kw):
            super().__init__(name, res, vsync, False, *args, **kw)

        @property
        def running(self):
            return win_cls.running.fget(self) and _State.frames < _State.limit

        @running.setter
        def running(self, value):
            win_cls.running.fset(self, value)

        def show(self):
            def capture():
                try:
                    _State.keep_image(self.get_image_buffer_as_numpy())
                except Exception as e:  # noqa: BLE001
                    print(f"@@harness: get_image_buffer_as_numpy failed: {e!r}", file=sys.stderr)

            def draw():
                image = getattr(self, "_image", None)  # simgrad's frame canvas draws when looked at
                if type(image).__module__.startswith("simgrad"):
                    _ = image.img

            _State.frames += 1
            _State.ticks = 0
            _timed_show(capture, lambda: super(HeadlessWindow, self).show(), draw)
            if _State.frames > _State.limit:
                raise FrameLimit()

    HeadlessWindow.__name__ = HeadlessWindow.__qualname__ = "Window"
    HeadlessWindow.__module__ = win_cls.__module__
    ti.ui.Window = HeadlessWindow


def _arrays(value, np):
    """name suffix -> numpy array for a field / ndarray / numpy array / number, else {}."""
    out = {}
    if isinstance(value, bool):
        return {"": np.asarray(int(value))}
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return {"": np.asarray(value)}
    if isinstance(value, np.ndarray):
        return {"": value} if value.dtype.kind in "biuf" else {}
    if isinstance(value, type) or not hasattr(value, "to_numpy"):
        return {}
    shape = getattr(value, "shape", None)
    if isinstance(shape, tuple) and all(isinstance(n, int) for n in shape) and math.prod(shape) > MAX_ELEMENTS:
        # e.g. oit_renderer's dense(1000^2).dynamic(2048) lists: to_numpy would need 32 GB
        raise ValueError(f"not dumped: {math.prod(shape)} cells (shape {shape})")
    data = value.to_numpy()
    if isinstance(data, dict):  # struct fields
        for k, v in data.items():
            out[f".{k}"] = np.asarray(v)
    else:
        out[""] = np.asarray(data)
    try:
        grad = getattr(value, "grad", None)
    except Exception:  # noqa: BLE001
        grad = None
    if grad is not None and hasattr(grad, "to_numpy") and not isinstance(grad, type):
        try:
            out[".grad"] = np.asarray(grad.to_numpy())
        except Exception:  # noqa: BLE001
            pass
    return out


def dump_state(glb, path):
    """Every array reachable from the program's globals (see the module docstring) into ``path`` (.npz)."""
    import types

    import numpy as np

    found, errors, seen = {}, {}, set()

    def visit(name, value, depth):
        if id(value) in seen or name.startswith("__"):
            return
        if not isinstance(value, (int, float)):  # small ints are shared objects
            seen.add(id(value))
        try:
            for suffix, arr in _arrays(value, np).items():
                arr = np.asarray(arr)
                if arr.dtype.kind not in "biuf":
                    continue
                if arr.size > MAX_ELEMENTS:
                    a64 = arr.astype(np.float64)
                    arr = np.array([a64.sum(), a64.min(), a64.max()])
                    suffix += ".summary"
                found[name + suffix] = arr
        except Exception as e:  # noqa: BLE001 - recorded per array
            errors[name] = f"{type(e).__name__}: {e}"[:300]
            return
        if depth >= 2:
            return
        if isinstance(value, (list, tuple)) and len(value) <= 64:
            for i, v in enumerate(value):
                visit(f"{name}[{i}]", v, depth + 1)
        elif isinstance(value, dict) and len(value) <= 64:
            for k, v in value.items():
                if isinstance(k, (str, int)):
                    visit(f"{name}[{k!r}]", v, depth + 1)
        elif getattr(type(value), "__module__", "") == "__main__" and hasattr(value, "__dict__"):
            for k, v in vars(value).items():
                visit(f"{name}.{k}", v, depth + 1)

    for k, v in list(glb.items()):
        if k.startswith("_") or isinstance(v, (type, types.ModuleType)) or (callable(v) and not hasattr(v, "to_numpy")):
            continue  # kernels, functions, classes, modules
        visit(k, v, 0)
    if _State.image is not None:
        found["@image"] = _State.image
    np.savez(path, **found)
    return errors


def child(framework, script, examples, frames, out):
    import builtins
    import random
    import types

    _State.limit, _State.script = frames, script
    if framework == "simgrad":
        ti = _alias_simgrad(examples)
    else:
        import taichi as ti
    _headless(ti, os.path.join(os.getcwd(), ".cache"))
    import numpy as np

    random.seed(0)
    np.random.seed(0)
    sys.modules["time"] = _clock_module()  # the program (imported after this) gets the frame clock
    sys.argv = [script]
    sys.path.insert(0, os.path.dirname(script))
    mod = types.ModuleType("__main__")
    mod.__dict__.update(__file__=script, __builtins__=builtins, __name__="__main__")
    main_mod = sys.modules["__main__"]
    sys.modules["__main__"] = mod
    with open(script) as fh:
        code = compile(fh.read(), script, "exec", dont_inherit=True)  # not our __future__ flags
    how, rc = "end", 0
    try:
        exec(code, mod.__dict__)
    except FrameLimit:
        how = "frame limit"
    except SystemExit as e:
        how = f"SystemExit({e.code!r})"
        rc = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except BaseException:
        import traceback

        traceback.print_exc()
        how, rc = "exception", 1
    finally:
        sys.modules["__main__"] = main_mod
        sys.stdout.flush()
    errors = dump_state(mod.__dict__, os.path.join(out, f"{framework}.npz"))
    with open(os.path.join(out, f"{framework}.json"), "w") as fh:
        json.dump({"how": how, "frames": _State.frames, "dump_errors": errors, "frame_s": _State.frame_s,
                   "after_copy": _State.after_copy}, fh)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)  # skip framework teardown: what happens at exit is not what is compared


# --------------------------------------------------------------------------------------------- parent
def _signal_name(rc):
    try:
        return signal.Signals(-rc).name
    except ValueError:
        return f"signal {-rc}"


def run_child(python, framework, script, args, out, frames=None):
    """Runs one child (`frames` shown frames, else the example's default); returns its record (rc/status, wall,
    peak RSS, stdout, stderr tail, child's json)."""
    work = os.path.join(out, f"work-{framework}")
    os.makedirs(work, exist_ok=True)
    env = dict(os.environ, MPLBACKEND="Agg", TI_ARCH="x64", TI_GUI_SHOW="0", TI_LOG_LEVEL="error")
    for k in ("DISPLAY", "WAYLAND_DISPLAY", "SIMGRAD_UI_FRAMES", "SIMGRAD_UI_MAX_FRAMES"):
        env.pop(k, None)
    init = dict(args.taichi_init) if framework == "taichi" else {}
    if args.threads:
        init["cpu_max_num_threads"] = args.threads
    env["TAICHI_EXAMPLES_INIT"] = json.dumps(init)
    if framework == "simgrad":
        env["PYTHONPATH"] = os.pathsep.join(p for p in [args.simgrad_path, os.environ.get("PYTHONPATH", "")] if p)
    if frames is None:
        frames = FRAMES.get(os.path.relpath(script, args.examples), args.frames)
    cmd = [python, os.path.abspath(__file__), "--child", framework, script, args.examples, str(frames), out]
    if args.nice:
        cmd = ["nice", "-n", str(args.nice), *cmd]
    so, se = os.path.join(out, f"{framework}.stdout"), os.path.join(out, f"{framework}.stderr")
    t0 = time.perf_counter()
    with open(so, "w") as fo, open(se, "w") as fe:
        proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=fo, stderr=fe, start_new_session=True)
        timed_out, hwm = False, 0
        while True:
            hwm = max(hwm, _vm_hwm_kib(proc.pid))
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t0 > args.timeout:
                timed_out = True
                os.killpg(proc.pid, signal.SIGKILL)
                pid, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.05)
        proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    rc = proc.returncode
    with open(so, errors="replace") as fh:
        stdout = fh.read()
    with open(se, errors="replace") as fh:
        stderr = fh.read()
    rec = {"rc": rc, "wall_s": round(wall, 2), "peak_rss_mib": round(hwm / 1024, 1),
           "status": "timeout" if timed_out else ("ok" if rc == 0 else
                                                  (_signal_name(rc) if rc < 0 else f"exit {rc}"))}
    meta = os.path.join(out, f"{framework}.json")
    if os.path.exists(meta):
        with open(meta) as fh:
            rec.update(json.load(fh))
    rec["stdout"] = _clean_stdout(stdout)
    if rc != 0 or timed_out or rec.get("how") == "exception":
        rec["error"] = _last_error(stderr)
        rec["stderr_tail"] = stderr[-2000:]
    return rec


def _vm_hwm_kib(pid):
    """The child's resident high-water mark (VmHWM), 0 once it is gone. Polled rather than read from wait4's
    ru_maxrss, which also counts the parent's pages the child had between fork and exec."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except (OSError, ValueError):
        pass
    return 0


def _clean_stdout(text):
    return "\n".join(ln for ln in text.splitlines() if not ln.startswith("[Taichi]") and not ln.startswith("@@"))


def _last_error(stderr):
    lines = [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith("@@harness")]
    starts = [i for i, ln in enumerate(lines) if ln.startswith("Traceback (most recent call last)")]
    if starts:
        block = lines[starts[-1] + 1:]
        at = next((i for i, ln in enumerate(block) if not ln[0].isspace()), None)
        if at is not None:
            rest = [ln.strip() for ln in block[at + 1:]]
            return (block[at] + (" … " + rest[-1] if rest else ""))[:400]
    return (lines[-1] if lines else "no output")[:400]


NUM = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?|nan|inf")


def compare_stdout(a, b, rtol=RTOL):
    """(agrees, first differing line pair): same text with numbers replaced, numbers within rtol."""
    la, lb = a.splitlines(), b.splitlines()
    if len(la) != len(lb):
        return False, f"{len(la)} vs {len(lb)} lines"
    for x, y in zip(la, lb):
        if NUM.sub("#", x) != NUM.sub("#", y):
            return False, f"{x[:80]!r} vs {y[:80]!r}"
        for u, v in zip(NUM.findall(x), NUM.findall(y)):
            fu, fv = float(u), float(v)
            if not (fu == fv or abs(fu - fv) <= rtol * max(abs(fu), abs(fv)) or (math.isnan(fu) and math.isnan(fv))):
                return False, f"{x[:80]!r} vs {y[:80]!r}"
    return True, ""


def array_error(a, b):
    """(largest |a - b| relative to max |b|, fraction of elements off by more than RTOL of it); (inf, 1) on
    a shape mismatch; NaNs and infinities must sit in the same places."""
    import numpy as np

    if a.shape != b.shape:
        return math.inf, 1.0
    if a.size == 0:
        return 0.0, 0.0
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    na, nb = np.isnan(a64), np.isnan(b64)
    if (na != nb).any():
        return math.inf, float((na != nb).mean())
    a64, b64 = np.where(na, 0, a64), np.where(nb, 0, b64)
    fa, fb = np.isfinite(a64), np.isfinite(b64)
    if (fa != fb).any() or (a64[~fa] != b64[~fb]).any():
        return math.inf, float((fa != fb).mean())
    a64, b64 = a64[fa], b64[fb]
    if a64.size == 0:
        return 0.0, 0.0
    scale = max(float(np.abs(b64).max()), 1e-30)
    diff = np.abs(a64 - b64) / scale
    return float(diff.max()), float((diff > RTOL).sum() / a.size)


def compare_states(out, s_path=None):
    """Compares simgrad.npz (or ``s_path``) against taichi.npz in ``out``: per-array errors, image difference,
    worst array."""
    import numpy as np

    s_path, t_path = s_path or os.path.join(out, "simgrad.npz"), os.path.join(out, "taichi.npz")
    if not (os.path.exists(s_path) and os.path.exists(t_path)):
        return None
    s, t = np.load(s_path), np.load(t_path)
    res = {"only_simgrad": sorted(set(s.files) - set(t.files)), "only_taichi": sorted(set(t.files) - set(s.files)),
           "arrays": {}, "fraction": {}, "image": None}
    for k in sorted(set(s.files) & set(t.files)):
        a, b = s[k], t[k]
        if k == "@image":
            if a.ndim == 3 and b.ndim == 3 and a.shape[:2] == b.shape[:2]:  # colour only: alpha is not shown
                c = min(a.shape[2], b.shape[2], 3)
                a, b = a[..., :c], b[..., :c]
            res["image"] = (float(np.abs(a.astype(np.float64) - b).max()) if a.shape == b.shape else math.inf)
            res["image_shapes"] = [list(s[k].shape), list(t[k].shape)]
            continue
        res["arrays"][k], res["fraction"][k] = array_error(a, b)
    errs = res["arrays"]
    res["worst"] = max(errs, key=lambda k: errs[k]) if errs else None
    res["worst_err"] = errs[res["worst"]] if errs else 0.0
    res["worst_fraction"] = res["fraction"][res["worst"]] if errs else 0.0
    return res


def verdict(entry):
    """'yes' (arrays within RTOL, image within IMAGE_TOL, same stdout, same arrays dumped) / 'close' (arrays
    within CLOSE, image within 0.1) / 'no', or '-' when either framework did not finish cleanly."""
    s, t, c = entry.get("simgrad"), entry.get("taichi"), entry.get("compare")
    if not s or not t or s["status"] != "ok" or t["status"] != "ok" or c is None:
        return "-"
    same_keys = not (c["only_simgrad"] or c["only_taichi"])
    image = 0.0 if c["image"] is None else c["image"]
    if c["worst_err"] <= RTOL and image <= IMAGE_TOL and entry.get("stdout_agrees") and same_keys:
        return "yes"
    if c["worst_err"] <= CLOSE and image <= 0.1:
        return "close"
    return "no"


def run_example(rel, args, pythons):
    script = os.path.join(args.examples, rel)
    out = tempfile.mkdtemp(prefix="tiex-")
    entry = {"example": rel}
    try:
        fws = args.frameworks.split(",")
        frames, probe = steady_frames(rel, args, pythons, script, out) if "taichi" in fws else (None, None)
        for fw in fws:
            entry[fw] = probe if fw == "taichi" and probe is not None else \
                run_child(pythons[fw], fw, script, args, out, frames)
        if "simgrad" in entry and "taichi" in entry:
            entry["compare"] = compare_states(out)
            ok, why = compare_stdout(entry["simgrad"]["stdout"], entry["taichi"]["stdout"])
            entry["stdout_agrees"], entry["stdout_diff"] = ok, why
            entry["match"] = verdict(entry)
        if args.self_check and entry.get("taichi", {}).get("status") == "ok":
            again = os.path.join(out, "again")  # taichi against itself: its run-to-run noise
            os.makedirs(again)
            entry["taichi_again"] = run_child(pythons["taichi"], "taichi", script, args, again, frames)
            c = compare_states(out, os.path.join(again, "taichi.npz"))
            ok, _ = compare_stdout(entry["taichi_again"]["stdout"], entry["taichi"]["stdout"])
            entry["taichi_self"] = c and {"worst": c["worst"], "worst_err": c["worst_err"], "image": c["image"],
                                          "stdout_agrees": ok}
    finally:
        if args.keep:
            entry["dir"] = out
        else:
            shutil.rmtree(out, ignore_errors=True)
    for fw in ("simgrad", "taichi"):
        if fw in entry and len(entry[fw].get("stdout", "")) > 4000:
            entry[fw]["stdout"] = entry[fw]["stdout"][:2000] + "\n…\n" + entry[fw]["stdout"][-2000:]
    return entry


def steady_frames(rel, args, pythons, script, out):
    """(frames, taichi's record or None): how many frames both frameworks show so that taichi's frames last at
    least --min-seconds together (at most --max-frames). A steady time needs that many: a frame of tens of
    microseconds is mostly interpreter warm-up for its first ten (Python 3.11 specialises a function's bytecode
    after its first eight calls), whatever the framework. Taichi's own run at the default count measures its frame;
    it is kept when no more frames are needed. Both run the same count: their pictures and arrays are compared."""
    base = FRAMES.get(rel, args.frames)
    if not args.min_seconds:
        return base, None
    probe = run_child(pythons["taichi"], "taichi", script, args, out, base)
    t = steady_ms(probe)
    if t is None:
        return base, probe
    frames = min(args.max_frames, max(base, math.ceil(args.min_seconds * 1e3 / t)))
    return frames, (probe if frames == base else None)


def _keyval(s):
    key, _, value = s.partition("=")
    return key, json.loads(value.lower() if value.lower() in ("true", "false") else value)


def list_examples(path):
    found = []
    for dirpath, dirs, files in os.walk(path):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        found += [os.path.relpath(os.path.join(dirpath, f), path) for f in sorted(files) if f.endswith(".py")]
    return sorted(found)


# ---------------------------------------------------------------------------------------------- table
_RANDOM = "ti.random streams differ (initial state drawn in a kernel)"
_VULKAN = "GGUI: taichi needs Vulkan here (no GPU); simgrad renders on the CPU"
#: why an example does not match, as found by reading it and its two runs (see benchmarks/RESULTS.md)
WHY = {
    "algorithm/circle-packing/circle_packing_image.py": "needs pycairo and opencv, not installed: both fail alike",
    "algorithm/mciso_advanced.py": "close: every array equal; picture within 0.023 (edges; not investigated)",
    "algorithm/mgpcg.py": "float32 sums over 2M cells in another order: printed residuals 3e-4 apart",
    "algorithm/mgpcg_advanced.py": "as mgpcg; and the kernel profiler's tables differ (format, timings)",
    "algorithm/poisson_disk_sampling.py": _VULKAN,
    "algorithm/print_offset.py": "stdout only: taichi prints its IR (ti.init(print_ir=True)); the offsets "
                                 "(ti.get_addr) and the picture are equal",
    "autodiff/diff_sph/diff_sph.py": _VULKAN,
    "features/gui/gui_image_io.py": _RANDOM,
    "features/io/export_ply.py": _RANDOM,
    "features/io/export_videos.py": "taichi fails here: no ffmpeg (simgrad writes the GIF, warns about the MP4)",
    "graph/texture_graph.py": "textures: taichi aborts here (no Vulkan); simgrad: located not-supported error",
    "machine_learning/differential_evolution.py": _RANDOM + " (populations drawn in kernels); it writes one row past "
                                                  "two fields, which crashed simgrad (SIGSEGV) until fields got their "
                                                  "own mappings",
    "real_func/algorithm/poisson_disk_sampling.py": _VULKAN,
    "real_func/rendering/cornell_box.py": "taichi: GGUI needs Vulkan; simgrad runs it (its invalid IR, a struct "
                                          "ti.func parameter rebound in a loop, is fixed)",
    "real_func/rendering/taichi_ngp.py": "needs cv2, wget, scipy and downloaded weights: both fail alike",
    "rendering/cornell_box.py": "taichi: GGUI needs Vulkan; simgrad runs it (its invalid IR, a struct ti.func "
                                "parameter rebound in a loop, is fixed)",
    "rendering/simple_texture.py": "textures and GGUI: taichi needs Vulkan; simgrad: located not-supported error",
    "rendering/taichi_ngp.py": "needs cv2, wget, scipy and downloaded weights: both fail alike",
    "simulation/euler.py": "matplotlib 3.9 removed cm.get_cmap: both fail alike",
    "simulation/eulerfluid2d.py": "taichi fails here: SIGSEGV (outside the harness too)",
    **{f"ggui_examples/{n}.py": _VULKAN for n in ("fem128_ggui", "fractal3d_ggui", "mass_spring_3d_ggui",
                                                  "mass_spring_game_ggui", "mpm128_ggui", "mpm3d_ggui",
                                                  "stable_fluid_ggui")},
    "graph/mpm88_graph.py": _RANDOM,
    "rendering/oit_renderer.py": _RANDOM + "; both peak near 0.9 GB (its 1000^2 dynamic lists grow by 64-cell "
                                           "chunks; the SIGKILL was an endless headless loop, fixed)",
    "rendering/sdf_renderer.py": _RANDOM + "; taichi differs from itself as much (path tracing)",
    "simulation/implicit_fem.py": "close in state (positions 6e-8, velocities 2e-6, picture 2e-5); the CG "
                                  "residual/direction fields at convergence are rounding noise (1e-8 absolute)",
    "simulation/implicit_mass_spring.py": "close: last picture within 0.011 (not investigated; state is local)",
    "simulation/initial_value_problem.py": "close: last picture within 0.012 (not investigated)",
    "simulation/mpm_lagrangian_forces.py": "x.grad is a sum of float atomics: taichi differs from itself as much; "
                                           "positions agree (picture 0.005)",
    **{f"simulation/{n}.py": _RANDOM for n in ("game_of_life", "nbody", "odop_solar", "pbf2d", "two_stream_instability",
                                               "vortex_rings")},
    **{f"simulation/{n}.py": _RANDOM + "; taichi differs from itself as much (per-thread streams, float atomics)"
       for n in ("ad_gravity", "comet", "mpm128", "mpm3d", "mpm88", "mpm99", "physarum")},
}


def _cell(rec):
    if rec is None:
        return "not run"
    txt = rec["status"]
    if rec["status"] == "ok" and rec.get("how") not in (None, "end"):
        txt += f" ({rec['how']})"
    if rec.get("how") == "exception" or rec["status"] != "ok":
        txt += f": `{rec.get('error', '?')[:160]}`"
    txt += f", {rec['wall_s']:.1f} s, {rec['peak_rss_mib']:.0f} MiB"
    return txt.replace("|", "\\|")


def table(entries, why=None):
    why = why or {}
    rows = ["| example | taichi | simgrad | match? | worst array (rel. err) / image / stdout | taichi vs itself "
            "| why not |",
            "|---|---|---|---|---|---|---|"]
    for e in entries:
        c = e.get("compare")
        detail = "-"
        if c:
            img = "-" if c["image"] is None else f"{c['image']:.3g}"
            worst = (f"{c['worst']} {c['worst_err']:.2g} ({c['worst_fraction']:.2%} off)" if c["worst"]
                     else "no arrays")
            detail = f"{worst} / {img} / {'same' if e.get('stdout_agrees') else 'differs'}".replace("|", "\\|")
        me = e.get("taichi_self")
        self_detail = "-" if not me else (f"{me['worst']} {me['worst_err']:.2g} / "
                                          f"{'-' if me['image'] is None else format(me['image'], '.3g')} / "
                                          f"{'same' if me['stdout_agrees'] else 'differs'}").replace("|", "\\|")
        rows.append(f"| {e['example']} | {_cell(e.get('taichi'))} | {_cell(e.get('simgrad'))} | "
                    f"{e.get('match', '-')} | {detail} | {self_detail} | {why.get(e['example'], '')} |")
    return "\n".join(rows)


def steady_ms(rec):
    """Median frame time from the 3rd shown frame on (the 1st and 2nd compile), frames right after a picture copy
    left out (see _timed_show), or None."""
    times = (rec or {}).get("frame_s") or []
    if rec is None or rec.get("status") != "ok" or len(times) < 2:
        return None
    after_copy = rec.get("after_copy") or [False] * len(times)  # (older records: every frame followed one)
    clean = [t for t, dirty in zip(times[1:], after_copy[1:]) if not dirty] or times[1:]
    return 1e3 * sorted(clean)[(len(clean) - 1) // 2]


def speed_table(entries):
    rows = ["| example | taichi ms/frame | simgrad ms/frame | simgrad / taichi |", "|---|---|---|---|"]
    ratios = []
    for e in entries:
        t, g = steady_ms(e.get("taichi")), steady_ms(e.get("simgrad"))
        if t is None or g is None:
            continue
        ratios.append(g / t)
        rows.append(f"| {e['example']} | {t:.2f} | {g:.2f} | {g / t:.2f} |")
    if ratios:
        ratios.sort()
        rows.append(f"\n{len(ratios)} examples timed by both: median ratio {ratios[len(ratios) // 2]:.2f}, "
                    f"{sum(r <= 0.5 for r in ratios)} at <= 0.5, {sum(r > 1 for r in ratios)} slower than taichi")
    return "\n".join(rows)


def main():
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        framework, script, examples, frames, out = sys.argv[2:7]
        child(framework, script, examples, int(frames), out)
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--examples", required=True, help="an installed taichi wheel's taichi/examples folder")
    ap.add_argument("--only", nargs="*", help="examples by path below PATH or by file name (without .py)")
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--min-seconds", type=float, default=0.25,
                    help="more frames (both frameworks alike) until taichi's frames last this long (0: --frames)")
    ap.add_argument("--max-frames", type=int, default=300)
    ap.add_argument("--json", default=None, help="write the records here (rewritten after each example)")
    ap.add_argument("--table", action="store_true", help="print the markdown table at the end")
    ap.add_argument("--frameworks", default="simgrad,taichi")
    ap.add_argument("--simgrad-python", default=sys.executable)
    ap.add_argument("--simgrad-path", default=ROOT, help="directory holding the simgrad package to test")
    ap.add_argument("--taichi-python", default=os.environ.get("TAICHI_PYTHON", "/work/tivenv/bin/python"))
    ap.add_argument("--taichi-init", type=_keyval, action="append", default=[],
                    help="extra ti.init argument for taichi, e.g. fast_math=False (taichi's default is True)")
    ap.add_argument("--threads", type=int, default=0, help="ti.init(cpu_max_num_threads=N) for both frameworks")
    ap.add_argument("--speed", action="store_true",
                    help="print the steady frame times (median from the 3rd shown frame on) and their ratios")
    ap.add_argument("--timeout", type=float, default=300)
    ap.add_argument("--nice", type=int, default=0)
    ap.add_argument("--keep", action="store_true", help="keep each example's output folder")
    ap.add_argument("--self-check", action="store_true",
                    help="run taichi twice and compare it with itself too (its run-to-run noise: float atomics)")
    ap.add_argument("--update", action="store_true",
                    help="replace only the examples run now in an existing --json file (its header lists the reruns)")
    ap.add_argument("--table-only", action="store_true", help="print the table of an existing --json, run nothing")
    args = ap.parse_args()
    if args.table_only:
        with open(args.json) as fh:
            entries = json.load(fh)["entries"]
        print(speed_table(entries) if args.speed else table(entries, WHY))
        return 0
    args.examples = os.path.abspath(args.examples)
    names = list_examples(args.examples)
    if args.only:
        want = set(args.only)
        names = [n for n in names if n in want or n[:-3] in want or os.path.basename(n)[:-3] in want]
    pythons = {"simgrad": args.simgrad_python, "taichi": args.taichi_python}
    entries = []
    header = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": platform.node(),
              "cpus": os.cpu_count(), "command": " ".join(sys.argv), "frames": args.frames,
              "min_seconds": args.min_seconds, "max_frames": args.max_frames,
              "load": os.getloadavg()}
    if args.update and args.json and os.path.exists(args.json):
        with open(args.json) as fh:
            old = json.load(fh)
        entries = [e for e in old["entries"] if e["example"] not in names]
        header = dict(old["header"], reruns=old["header"].get("reruns", []) + [header])
    for name in names:
        e = run_example(name, args, pythons)
        entries.append(e)
        entries.sort(key=lambda x: x["example"])
        print(f"{name:55s} taichi={e.get('taichi', {}).get('status', '-'):8s} "
              f"simgrad={e.get('simgrad', {}).get('status', '-'):8s} match={e.get('match', '-')}", flush=True)
        if args.json:  # rewritten whole after each example, atomically (it can be read while a run goes on)
            with open(args.json + ".tmp", "w") as fh:
                json.dump({"header": header, "entries": entries}, fh, indent=1, default=str)
            os.replace(args.json + ".tmp", args.json)
    if args.table:
        print(table(entries, WHY))
    if args.speed:
        print(speed_table(entries))
    bad = [e for e in entries if e.get("simgrad", {}).get("status", "ok") != "ok"]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
