"""engine/jit.py: one compiled version per argument type, whatever constants a caller passes."""

import sys

from numba.core import types
from numba.core.registry import CPUDispatcher

from physdbg.engine.jit import borrowing, kernel
from physdbg.engine.world import warm_up


@kernel
def _add_if(value, flag):
    return value + 1 if flag else value


@borrowing
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


def test_no_engine_kernel_is_specialised_on_a_constant():
    for broad_phase in ("grid", "bvh-sah", "bvh-lbvh"):
        warm_up(broad_phase)
    dispatchers = dict(_engine_dispatchers())
    assert "physdbg.engine.resting.solve_contacts" in dispatchers
    literal = {name: [str(s) for s in d.signatures]
               for name, d in dispatchers.items()
               if any(isinstance(t, types.Literal) for s in d.signatures for t in s)}
    assert literal == {}
    # the held-contact solve is reached from several callers with constant flags: one version
    assert len(dispatchers["physdbg.engine.resting.solve_contacts"].signatures) == 1
