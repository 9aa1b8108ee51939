"""engine/jit.py: one compiled version per argument type, whatever constants a caller passes."""

import importlib
import pkgutil
import sys

import physdbg.engine

from numba.core.registry import CPUDispatcher

from physdbg.engine.jit import _OneVersionPerType


def _uncached(**options):
    """jit.py's dispatcher without its disk cache. Cached, the caller would be loaded from
    disk on any run after the first (numba keys its cache by the source's contents) without
    compiling its callee, and the callee's versions are what this test counts: it passed
    once and failed on every later run with the same cache."""
    def decorate(function):
        return _OneVersionPerType(py_func=function, locals={}, targetoptions={"nopython": True, **options})
    return decorate


@_uncached()
def _add_if(value, flag):
    return value + 1 if flag else value


@_uncached(_nrt=False)
def _calls_with_constants(value):
    # three constant flags and one computed: numba's default compiles _add_if twice here
    # (Literal[bool](True) and Literal[bool](False)) besides the run-time bool version
    return _add_if(value, True) + _add_if(value, False) + _add_if(value, value > 0)


def test_constant_arguments_compile_one_version():
    assert _calls_with_constants(1) == 2 + 1 + 2
    assert [str(s) for s in _add_if.signatures] == ["(int64, bool)"]


def _engine_dispatchers():
    for name, module in list(sys.modules.items()):
        if name.startswith("physdbg.engine"):
            for attribute, value in vars(module).items():
                if isinstance(value, CPUDispatcher) and value.__module__ == name:
                    yield f"{name}.{attribute}", value


def test_every_engine_kernel_compiles_one_version_per_type():
    """Every compiled engine function goes through jit.py's dispatcher (those inlined into
    their callers at numba's level excepted: they are never compiled on their own)."""
    for module in pkgutil.walk_packages(physdbg.engine.__path__, "physdbg.engine."):
        importlib.import_module(module.name)
    dispatchers = dict(_engine_dispatchers())
    assert {"physdbg.engine.resting.solves.solve_contacts", "physdbg.engine.broadphase.bvh.build_lbvh"} <= set(dispatchers)
    plain = sorted(name for name, d in dispatchers.items()
                   if not isinstance(d, _OneVersionPerType) and d.targetoptions.get("inline") != "always")
    assert plain == []
