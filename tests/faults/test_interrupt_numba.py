"""Ctrl-C while numba compiles (learn's first EM iteration): one line, exit 130, the folder
as it was (issue 25).

LLVM calls back into Python through ctypes while numba compiles (llvmlite's object cache);
a KeyboardInterrupt raised there was printed as "Exception ignored" and dropped, and numba
then failed with a 41-line traceback and exit 1 (or learn ran on and replaced the model).
"""

import ctypes
import os
import signal
import subprocess
import sys
import time
import types

import pytest

from tooling.faults import SMALL, _env, leftovers, run, snapshot

# Sends Ctrl-C to itself at LLVM's first object-cache callback (numba compiling), then runs
# the CLI: the moment the traceback came from, made certain.
DRIVER = """
import os, signal, sys
from numba.core import codegen

original = codegen.CPUCodeLibrary._object_compiled_hook.__func__
sent = []

def hook(cls, ll_module, buf):  # LLVM calls it through llvmlite's ctypes callback
    if not sent:
        sent.append(True)
        os.kill(os.getpid(), signal.SIGINT)
        sum(range(10000))  # the handler runs here, inside the callback
    return original(cls, ll_module, buf)

codegen.CPUCodeLibrary._object_compiled_hook = classmethod(hook)
from hemg_drake.cli import main
status = main(sys.argv[1:])
print("notified" if sent else "never compiled", file=sys.stderr)
sys.exit(status)
"""


@pytest.mark.slow
def test_ctrl_c_while_numba_compiles_gives_one_line_and_130(tmp_path):
    run(["demonstrate", "cotter_pin", "--out", "run", "--seed", "3", *SMALL], cwd=tmp_path)
    before = snapshot(tmp_path / "run")
    env = _env({"NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")})  # nothing compiled yet
    done = subprocess.run(
        [sys.executable, "-c", DRIVER, "learn", "run", "--set", "learning.num_states=3"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.stderr == "hemg-drake learn: interrupted; no partial output kept\nnotified\n"
    assert done.returncode == 130
    assert snapshot(tmp_path / "run") == before and not leftovers(tmp_path / "run")


def _in_a_ctypes_callback(body):
    """Run ``body`` inside a ctypes callback whose code is llvmlite's (as LLVM's object
    cache calls back into llvmlite while numba compiles)."""
    compare_type = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
    source = "def compare(a, b):\n    body()\n    return 0\n"
    namespace = {"__name__": "llvmlite.binding.stand_in", "body": body}
    exec(compile(source, "<llvmlite stand-in>", "exec"), namespace)
    values = (ctypes.c_int * 2)(1, 2)
    compare = compare_type(namespace["compare"])
    ctypes.CDLL(None).qsort(values, 2, ctypes.sizeof(ctypes.c_int), compare)


@pytest.mark.parametrize("signum, exception", [(signal.SIGINT, KeyboardInterrupt),
                                               (signal.SIGTERM, "Terminated")])  # fmt: skip
def test_a_signal_inside_an_llvm_callback_arrives_after_it(signum, exception):
    from hemg_drake import cli

    if exception == "Terminated":
        exception = cli.Terminated
    previous = signal.signal(signum, cli._raising(exception))
    try:
        with pytest.raises(exception):
            _in_a_ctypes_callback(lambda: os.kill(os.getpid(), signum))
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline:  # raised here, out of the callback
                time.sleep(0.001)
    finally:
        signal.signal(signum, previous)


def test_outside_llvm_the_signal_raises_at_once():
    from hemg_drake import cli

    handler = cli._raising(KeyboardInterrupt)
    with pytest.raises(KeyboardInterrupt):
        handler(signal.SIGINT, sys._getframe())
    frame = types.SimpleNamespace(f_globals={"__name__": "llvmlite.binding.ffi"}, f_back=None)
    assert cli._in_llvm(frame) and not cli._in_llvm(sys._getframe())
