"""Writes the collider switch (engine/colliders/switch.py) from the registry of kinds.

The switch is the one place the engine branches on a collider kind: each of its
functions takes a kind code and calls that kind's own function. numba compiles those
branches, so they cannot be looked up at run time from a table; instead this script
writes them out, one branch per kind of the registry (events.COLLIDER_KINDS), from the
expressions each kind's module declares in ``SWITCH``. The result is an ordinary
module, cached by numba and found by grep, and a test holds it equal to what this
script writes (tests/test_colliders.py). A tool beside the package, not the engine's:
it reads and writes source text, and the engine imports numpy and numba only.

A kind's module declares, for every function of the switch, the expression that
answers it, in the switch function's own parameter names, with ``group`` for the kind's
own geometry (``geometry[code]``); a call of one of the module's functions is written
as a bare name (``normal(x, ia, other, group)``) and qualified here (``plane.normal``).

It reads the registry and the kinds' modules as text, importing nothing of physdbg: the
package refuses to load while its switch is not the registry's (colliders/__init__), which
is just when this has to run. Run it by its path after adding or changing a kind
(docs/colliders.md, "Adding an integrator or a collider kind")::

    python physdbg/write_switch.py
"""

from __future__ import annotations

import ast
import hashlib
import sys
from pathlib import Path
from typing import NamedTuple

PACKAGE = Path(__file__).resolve().parent  # physdbg/
HERE = PACKAGE / "engine" / "colliders"  # the kinds' modules
SWITCH_FILE = HERE / "switch.py"
EVENTS_FILE = PACKAGE / "events.py"  # the registry, events.COLLIDER_KINDS
COMPILED = '@njit(cache=True, inline="always")'
BORROWING = "@borrowing"


class SwitchFunction(NamedTuple):
    """One function of the switch: its name, its parameters after ``kind`` (ending in
    ``geometry`` or the parameters after it), how it is compiled (COMPILED, BORROWING, or
    "" for a Python function) and its docstring."""

    name: str
    parameters: str
    decorator: str
    doc: str


FUNCTIONS = (
    SwitchFunction("time_of_impact", "ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, "
                                     "tolerance, geometry", COMPILED, """\
Swept test of (kind, ia, other) on the paths (x, v, a: (N, 3)) from their anchors
    sigma (s): (start, t, work), the test's start in the step, the time of impact after it
    (s; inf or beyond step_end: none) and the work it counts against the swept-test budget
    (1, or a moving triangle's passes: mesh.time_of_impact). tolerance (m): the sphere
    pairs' root tolerance."""),
    SwitchFunction("contact_normal", "x, sigma, ia, other, geometry", COMPILED, """\
Unit normal (3 floats) from the partner to sphere ia at the anchors (times sigma (N,)
    s in the step: where a moving partner is then)."""),
    SwitchFunction("contact_feature", "x, sigma, ia, other, geometry", COMPILED, """\
Where sphere ia touches the partner, for the contact's row: 1 + the feature of a
    mesh's triangle (events.FEATURE_NAMES: face, edge, corner), 0 for a kind without
    features."""),
    SwitchFunction("partner_surface", "x, sigma, radius, ia, other, n0, n1, n2, geometry", COMPILED, """\
(u0, u1, u2, moving): the velocity (m/s) of an immovable partner's surface where
    sphere ia touches it along the normal n (a kinematic mesh's); (0, 0, 0, False) for a
    partner that stands still (and for a sphere, whose velocity the resolver reads itself)."""),
    SwitchFunction("partner_normal_motion", "x, v, sigma, radius, ia, other, n0, n1, n2, geometry", COMPILED, """\
(velocity m/s, acceleration m/s²) of the partner's surface along the normal n where
    sphere ia touches it, at ia's anchor time: what a held contact's relative normal
    velocity and acceleration are measured from (resting.HeldContacts.surface). (0, 0)
    for a partner that stands still; a sphere's own motion is the solve's, not this."""),
    SwitchFunction("partner_moves", "other, geometry", COMPILED, """\
Whether the immovable partner ``other`` moves by a prescribed motion (a kinematic
    mesh's triangle); False for a partner that stands still and for a sphere."""),
    SwitchFunction("surface_gap", "x, v, a, radius, ia, other, geometry", BORROWING, """\
(gap m, n0, n1, n2, on_face): sphere ia's gap to the partner's whole surface where it is
    nearest, the normal there and whether that point is inside a face (a mesh: any
    triangle of ``other``'s mesh, ``mesh.surface_gap``; a wall is one face; a sphere has
    no face)."""),
    SwitchFunction("contact_gap", "x, v, a, radius, ia, other, geometry", BORROWING, """\
(gap (m, < 0: overlap), n0, n1, n2, renewed) of a held contact at the anchors: where
    renewed, (n0, n1, n2) is the contact's normal now (a sphere pair turns as it rolls)."""),
    SwitchFunction("partner_restitution", "other, restitution, geometry", COMPILED, """\
The partner's restitution coefficient: restitution (N,) for spheres, each immovable
    partner's own."""),
    SwitchFunction("partners_of", "p, box, adj_start, adj, path_lo, path_hi, batch_mark, batch, geometry, out, scan",
                   COMPILED, """\
The candidates of ``kind`` that sphere p's new path must be swept-tested against, as
    rows (a, other) of out (K, 2); returns how many. box (2, 3): the new path's box, also
    p's row of path_lo, path_hi (N, 3), the boxes of every sphere's current path;
    adj_start, adj: the broad phase's partners (CSR); batch_mark (N,): the batch that last
    changed each sphere (batch: this one); scan: no lists, every sphere a partner
    (sphere.partners_of)."""),
    SwitchFunction("immovable_partners_in", "p, lo, hi, geometry, out", COMPILED, """\
The immovable partners of ``kind`` (walls, triangles) the box of row p of lo, hi
    (N, 3) m reaches, as rows (p, other) of out (K, 2), in the order of their numbers;
    returns how many (out has rows for every partner of the kind: most_partners). A kind
    whose partners are spheres has none here (the caller lists those: the event
    calendar's neighbour lists)."""),
    SwitchFunction("partner_count", "geometry", COMPILED, """\
How many immovable partners of ``kind`` the scene has (every wall, every triangle):
    each is a candidate of every sphere where no broad phase stands between them (the
    event calendar's walls). A kind whose partners are spheres has none here."""),
    SwitchFunction("deepest_of_kind", "x, radius, pairs, geometry, ignore_tunnelled", BORROWING, """\
(depth m >= 0, sphere, partner) of the deepest overlap with partners of ``kind``:
    the candidate sphere pairs (M, 2), every wall, every triangle ((0, -1, -1) when none).
    ignore_tunnelled: a sphere past the middle of a thin partner went through it and is
    not counted as overlapping it."""),
    SwitchFunction("narrow_candidates", "pairs, lo, hi, geometry, together=False", "", """\
The narrow phase's candidates of ``kind`` at step start, (a (M,), other (M,)) int64:
    the broad phase's sphere pairs (M, 2) whose path boxes lo, hi (N, 3) meet, or the walls
    and triangles each path box reaches (``together``: the triangles by the simultaneous
    descent, mesh.reachable_together; the same candidates)."""),
    SwitchFunction("every_candidate", "count, geometry", "", """\
Every candidate of ``kind`` among ``count`` spheres, with no broad phase (the slow
    reference loop's): (a (M,), other (M,)) int64, every pair i < j, or every sphere with
    every immovable partner of the kind."""),
)


def _parameters(function: SwitchFunction) -> set[str]:
    return {part.split("=")[0].strip() for part in function.parameters.split(",")}


class KindModule(NamedTuple):
    """What the switch needs of a kind's module, read from its text: its registry row's
    name and module, its SWITCH table and the names it defines or imports."""

    name: str
    module: str
    switch: dict
    names: frozenset


def read_registry(events_file: Path = EVENTS_FILE) -> list[tuple[str, str]]:
    """(name, module) of each row of events.COLLIDER_KINDS, in order, read from its text."""
    for node in ast.parse(events_file.read_text()).body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "COLLIDER_KINDS"
                                                for t in node.targets):
            return [(ast.literal_eval(row.args[0]), ast.literal_eval(row.args[1])) for row in node.value.elts]
    raise ValueError(f"{events_file}: no COLLIDER_KINDS")


def read_kind(name: str, module: str, folder: Path = HERE) -> KindModule:
    """The SWITCH table of engine/colliders/<module>.py and the names the module defines."""
    path = folder / f"{module}.py"
    where = f"engine/colliders/{module}.py"
    if not path.exists():
        raise ValueError(f"the registry (events.COLLIDER_KINDS) lists kind '{name}' in module '{module}', "
                                f"but there is no {where}")
    tree = ast.parse(path.read_text())
    names, switch = set(), None
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((alias.asname or alias.name).split(".")[0] for alias in node.names)
        elif isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "SWITCH" for t in node.targets):
            switch = ast.literal_eval(node.value)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
    if not isinstance(switch, dict):
        raise ValueError(f"{where}: no SWITCH table (the expression answering each function of the collider "
                                f"switch: {', '.join(f.name for f in FUNCTIONS)})")
    extra = sorted(set(switch) - {f.name for f in FUNCTIONS})
    if extra:
        raise ValueError(f"{where}: SWITCH names {', '.join(extra)}, which the switch does not have")
    return KindModule(name, module, switch, frozenset(names))


def _branch(function: SwitchFunction, kind: KindModule, code: int) -> str:
    """The expression answering ``function`` for ``kind`` (code ``code``), its own
    function calls qualified by the module's name, ``group`` its geometry."""
    where = f"engine/colliders/{kind.module}.py"
    if function.name not in kind.switch:
        raise ValueError(f"{where}: SWITCH has no entry for {function.name!r} (every function of the switch "
                                f"needs one: {', '.join(f.name for f in FUNCTIONS)})")
    tree = ast.parse(kind.switch[function.name], mode="eval")
    allowed = _parameters(function) - {"geometry"} | {"group"}

    class Qualify(ast.NodeTransformer):
        def visit_Call(self, node):
            if not isinstance(node.func, ast.Name):
                return self.generic_visit(node)
            if node.func.id not in kind.names:
                raise ValueError(f"{where}: SWITCH[{function.name!r}] calls {node.func.id}, which the module "
                                        f"neither defines nor imports")
            node.func = ast.Attribute(ast.Name(kind.module, ast.Load()), node.func.id, ast.Load())
            node.args = [self.visit(arg) for arg in node.args]
            node.keywords = [self.visit(keyword) for keyword in node.keywords]
            return node

        def visit_Name(self, node):
            if node.id == "group":
                return ast.Subscript(ast.Name("geometry", ast.Load()), ast.Constant(code), ast.Load())
            if node.id not in allowed:
                raise ValueError(f"{where}: SWITCH[{function.name!r}] reads {node.id}, which is not one of "
                                        f"the function's parameters ({', '.join(sorted(allowed))})")
            return node

    return ast.unparse(Qualify().visit(tree))


def switch_fingerprint(kinds) -> str:
    """A digest of the registry and the kinds' SWITCH tables, [(name, module, SWITCH)] in
    the order of their codes: the same one colliders/__init__ computes from the modules it
    loads (check_kind_modules), so a SWITCH changed since the switch was written is seen."""
    text = repr([(name, module, sorted(switch.items())) for name, module, switch in kinds])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def switch_source(registry: list[tuple[str, str]] | None = None, folder: Path = HERE) -> str:
    """The text of colliders/switch.py for ``registry`` ((name, module) of each kind in the
    order of their codes; default: events.COLLIDER_KINDS, read from its text), the kinds'
    modules read from ``folder``."""
    kinds = [read_kind(name, module, folder) for name, module in (registry if registry is not None else read_registry())]
    names = ", ".join(f'"{kind.module}"' for kind in kinds)
    lines = [
        '"""The collider switch: each function takes a collider kind and calls that kind\'s own.',
        "",
        "WRITTEN BY physdbg/write_switch.py from the registry of kinds",
        "(events.COLLIDER_KINDS) and each kind module's SWITCH: do not edit it; after adding or",
        "changing a kind, run ``python physdbg/write_switch.py``",
        '(docs/colliders.md, "Adding an integrator or a collider kind"). A test holds this',
        "file equal to what that script writes. Every function names each kind it handles and",
        "raises UNKNOWN_KIND for any other, so a kind missing here fails at its first use and",
        'never runs another kind\'s code."""',
        "",
        "from __future__ import annotations",
        "",
        "from numba import njit",
        "",
        "from ..jit import borrowing",
        f"from . import {', '.join(kind.module for kind in kinds)}",
        "",
        "# the kinds' modules this switch was written for, in the order of their codes",
        f"WRITTEN_FOR = ({names}{',' if len(kinds) == 1 else ''})",
        f"KIND_MODULES = ({', '.join(kind.module for kind in kinds)}{',' if len(kinds) == 1 else ''})",
        "# the registry and the kinds' SWITCH tables it was written from (switch_fingerprint): colliders/",
        "# __init__ refuses to load a switch whose tables have changed since",
        f'WRITTEN_FROM = "{switch_fingerprint([(k.name, k.module, k.switch) for k in kinds])}"',
        "# what every function raises for a kind it has no branch for",
        'UNKNOWN_KIND = ("engine/colliders: a collider kind with no branch in this function of the switch '
        '(docs/colliders.md, "',
        '                "\\"Adding an integrator or a collider kind\\")")',
    ]
    for function in FUNCTIONS:
        lines += ["", ""]
        if function.decorator:
            lines.append(function.decorator)
        lines.append(f"def {function.name}(kind, {function.parameters}):")
        lines.append(f'    """{function.doc}"""')
        for code, kind in enumerate(kinds):
            lines.append(f"    if kind == {code}:  # {kind.name}")
            lines.append(f"        return {_branch(function, kind, code)}")
        lines.append("    raise ValueError(UNKNOWN_KIND)" if function.decorator
                     else '    raise ValueError(f"{UNKNOWN_KIND}: {kind}")')
    return "\n".join(lines) + "\n"


def main() -> int:
    try:
        text = switch_source()
    except ValueError as error:  # what is wrong with the registry or a kind's SWITCH, and where
        print(f"error: {error}", file=sys.stderr)
        return 2
    if SWITCH_FILE.exists() and SWITCH_FILE.read_text() == text:
        print(f"{SWITCH_FILE} is up to date")
        return 0
    SWITCH_FILE.write_text(text)
    print(f"wrote {SWITCH_FILE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
