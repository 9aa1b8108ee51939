"""What a run looks like, shared by every picture of it (the Rerun sink and the Foxglove
channels of the MCAP file): which way is up, the box around the scene, the walls'
outlines, the spheres' colours, and each contact in words.
"""

from __future__ import annotations

import math

import numpy as np

from ..events import Contacts, feature_words, partner_words
from .header import RecordingHeader

LOG_LINES_PER_STEP = 20  # contacts described in words per step; the rest are counted
DRAWN_CONTACTS_PER_STEP = 1000  # contacts drawn (ghosts, arrows) per step; all are in the MCAP channel


def up_axis(h: RecordingHeader) -> np.ndarray:
    """+z when gravity points down z, else +y (the engine's default gravity is -y)."""
    gravity = np.asarray(h.meta.get("settings", {}).get("gravity", (0.0, -9.81, 0.0)), dtype=float)
    if abs(gravity[2]) > abs(gravity[1]) and abs(gravity[2]) >= abs(gravity[0]) and gravity[2] < 0:
        return np.array([0.0, 0.0, 1.0])
    return np.array([0.0, 1.0, 0.0])


def contact_centres(c: Contacts, radius: np.ndarray) -> np.ndarray:
    """(M, 3) centre of sphere a at each contact: the point lies on a's surface, against the normal."""
    if not len(c):
        return np.zeros((0, 3))
    return c.point + c.normal * radius[c.a][:, None]


def scene_bounds(h: RecordingHeader) -> tuple[np.ndarray, np.ndarray]:
    """A box around the initial spheres, every axis-aligned wall, every mesh (a turning
    one's whole sweep about its pivot) and the partners of a kind that draws itself
    (kind_drawings), at least half as deep
    on each axis as on its longest, so a lone floor is drawn bigger than one ball."""
    r = float(h.radius.max()) if h.count else 0.5
    lo = h.positions.min(axis=0) - r if h.count else np.full(3, -1.0)
    hi = h.positions.max(axis=0) + r if h.count else np.full(3, 1.0)
    for normal, offset in zip(h.walls.normals, h.walls.offsets, strict=True):
        axis = int(np.argmax(np.abs(normal)))
        if abs(normal[axis]) > 1 - 1e-12:
            coordinate = offset / normal[axis]
            lo[axis], hi[axis] = min(lo[axis], coordinate), max(hi[axis], coordinate)
    if h.walls.meshes.triangles:  # and every mesh, a turning one wherever its turn takes it
        meshes = h.walls.meshes
        corners = meshes.corners.reshape(-1, 3)
        lo, hi = np.minimum(lo, corners.min(axis=0)), np.maximum(hi, corners.max(axis=0))
        turning = np.flatnonzero(np.any(meshes.angular_velocity != 0.0, axis=1))
        if len(turning):
            reach = meshes.turn_radii()[turning][:, None]
            lo = np.minimum(lo, (meshes.pivot[turning] - reach).min(axis=0))
            hi = np.maximum(hi, (meshes.pivot[turning] + reach).max(axis=0))
    for _kind, drawing in kind_drawings(h.walls):  # and the partners of a kind that draws itself
        if len(drawing.radii):
            lo = np.minimum(lo, (drawing.centres - drawing.radii[:, None]).min(axis=0))
            hi = np.maximum(hi, (drawing.centres + drawing.radii[:, None]).max(axis=0))
        if len(drawing.triangles):
            corners = drawing.triangles.reshape(-1, 3)
            lo, hi = np.minimum(lo, corners.min(axis=0)), np.maximum(hi, corners.max(axis=0))
    periodic = h.walls.period > 0
    lo[periodic] = np.minimum(lo, h.walls.period_origin)[periodic]
    hi[periodic] = np.maximum(hi, h.walls.period_origin + h.walls.period)[periodic]
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    half = np.maximum(half, max(half.max() / 2, r))
    return centre - half, centre + half


def wall_outlines(walls, lo: np.ndarray, hi: np.ndarray):
    """(name, (5, 3) closed outline) of each wall inside the box lo..hi."""
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    for name, normal, offset in zip(walls.names, walls.normals, walls.offsets, strict=True):
        on_plane = centre + (offset - normal @ centre) * normal
        helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
        u = np.cross(normal, helper)
        u /= np.linalg.norm(u)
        w = np.cross(normal, u)
        su, sw = float(np.abs(u) @ half), float(np.abs(w) @ half)
        corners = [on_plane + a * su * u + b * sw * w for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))]
        yield name, np.asarray(corners, dtype=np.float32)


def periodic_faces(walls, lo: np.ndarray, hi: np.ndarray):
    """(name, (5, 3) closed outline) of the two faces of each periodic axis (where a sphere
    leaves and comes back), inside the box lo..hi."""
    for axis in np.nonzero(walls.period > 0)[0]:
        for side, at in (("-", walls.period_origin[axis]), ("+", walls.period_origin[axis] + walls.period[axis])):
            u, w = [c for c in range(3) if c != axis]
            corners = np.empty((5, 3))
            corners[:, axis] = at
            for k, (a, b) in enumerate(((0, 0), (1, 0), (1, 1), (0, 1), (0, 0))):
                corners[k, u] = (lo, hi)[a][u]
                corners[k, w] = (lo, hi)[b][w]
            yield f"{'xyz'[axis]}{side}", corners.astype(np.float32)


# a sleeping sphere (engine/sleep.py): a cool grey-blue beside the moving spheres' orange
ASLEEP_COLOR = (110, 135, 170)
SLEEP_IDS_PER_LINE = 12  # spheres named in a "fell asleep" / "woke" log line; the rest are counted


SPHERE_COLOR = (240, 140, 50)  # a moving sphere: warm orange


FINDING_MARKER_SCALE = 1.6  # a finding's marker is this many times the largest radius involved


def finding_marker_radius(h: RecordingHeader, finding) -> float:
    """Radius (m) of the marker drawn where an audit finding happened (Rerun and Foxglove)."""
    involved = h.radius[list(finding.particles)] if finding.particles else h.radius
    return FINDING_MARKER_SCALE * float(involved.max())


def finding_frame(h: RecordingHeader, finding) -> tuple[np.ndarray, float] | None:
    """(centre (3,), extent m) that frames an audit finding: where it happened, wide enough
    for its spheres, the way they went in the step (speed·dt, when the finding says) and
    the triangle it names; None when the finding has no one place."""
    if finding.position is None:
        return None
    centre = np.asarray(finding.position, dtype=float)
    if not np.all(np.isfinite(centre)):
        return None
    radius = float(h.radius[list(finding.particles)].max()) if finding.particles else float(h.radius.max())
    extent = 6.0 * radius
    evidence = finding.evidence or {}
    travel = float(evidence.get("speed", 0.0)) * float(evidence.get("dt", 0.0))
    triangle = evidence.get("triangle_index")
    meshes = h.walls.meshes
    if triangle is not None and 0 <= int(triangle) < len(meshes.corners):
        corners = np.asarray(meshes.corners[int(triangle)], dtype=float)
        size = 2.0 * float(np.max(np.linalg.norm(corners - centre, axis=1)))
        extent = max(extent, size)
        travel = min(travel, 2.0 * size)  # a path far longer than the triangle: its part near it
    if math.isfinite(travel):
        extent = max(extent, travel + 4.0 * radius)
    return centre, extent


def finding_line(finding) -> tuple[str, str]:
    """An audit finding as a log line (text, level), the same in Rerun and Foxglove."""
    return f"step {finding.step}: [{finding.kind}] {finding.message}", "WARN"


def sphere_colors(inverse_mass: np.ndarray, asleep: np.ndarray | None = None,
                  moving: tuple[int, int, int] = SPHERE_COLOR) -> np.ndarray:
    """(N, 3) uint8: immovable spheres grey, the rest ``moving`` (a warm orange unless a
    picture of two runs tells them apart by colour), and those ``asleep`` ((N,) bool, as
    StepEnd and the recording's state carry it) a cool grey-blue."""
    colors = np.tile(np.array([moving], dtype=np.uint8), (len(inverse_mass), 1))
    if asleep is not None:
        colors[asleep] = ASLEEP_COLOR
    colors[inverse_mass == 0] = (140, 140, 140)
    return colors


def sleep_changed(before: np.ndarray | None, after: np.ndarray | None) -> bool:
    """Whether the set of sleeping spheres differs ((N,) bool masks; None = none asleep)."""
    if before is None or after is None:
        return before is not after and bool((before if after is None else after).any())
    return not np.array_equal(before, after)


def describe_sleep(frame: int, before: np.ndarray | None, after: np.ndarray | None) -> list[tuple[str, str]]:
    """(text, level) lines naming the spheres that fell asleep and those that woke in the
    step that ends at ``frame``; before, after: (N,) bool masks (None: none asleep)."""
    if after is None:
        return []
    was = before if before is not None else np.zeros_like(after)
    lines = []
    for verb, who in (("fell asleep", after & ~was), ("woke", was & ~after)):
        ids = np.flatnonzero(who)
        if len(ids):
            named = ", ".join(str(int(i)) for i in ids[:SLEEP_IDS_PER_LINE])
            more = f" and {len(ids) - SLEEP_IDS_PER_LINE} more" if len(ids) > SLEEP_IDS_PER_LINE else ""
            noun = "sphere" if len(ids) == 1 else "spheres"
            lines.append((f"step {frame}: {len(ids)} {noun} {verb}: {named}{more}", "INFO"))
    return lines


def describe_contacts(frame: int, c: Contacts, dt: float, names) -> list[tuple[str, str]]:
    """(text, level) lines for a step's first LOG_LINES_PER_STEP contacts, in words, and
    one line counting the rest (names: Walls.partner_names). level: "INFO" for impacts, "DEBUG" for held contacts."""
    lines = []
    resting = c.resting
    for row in range(min(len(c), LOG_LINES_PER_STEP)):
        other = partner_words(int(c.kind[row]), int(c.other[row]), names)
        where = feature_words(int(c.feature[row]))
        other += f" ({where})" if where else ""  # a mesh's triangle: on its face, an edge or a corner
        verb = "rests on" if resting[row] else "hit"
        lines.append((
            f"step {frame}: sphere {int(c.a[row])} {verb} {other} at {c.time_in_step[row] / dt:.3f}·dt "
            f"({c.time_in_step[row]:.4g} s into the step), "
            f"j = {c.impulse[row]:.3g} N·s, closing {c.closing_speed[row]:.3g} m/s, e = {c.restitution[row]:.3g}",
            "DEBUG" if resting[row] else "INFO"))
    if len(c) > LOG_LINES_PER_STEP:
        lines.append((f"step {frame}: ... and {len(c) - LOG_LINES_PER_STEP} more contacts", "INFO"))
    return lines


def kind_drawings(walls) -> list:
    """(kind name, colliders.kinds.Drawing) of each collider kind beyond the wall and the
    mesh that the scene has partners of, as the kind's module draws them (its
    ``drawing(partners)``): both views show them."""
    from ..engine.colliders import extra_kinds

    out = []
    for _code, name, module in extra_kinds():
        partners = walls.partners.get(name)
        if partners is not None and len(partners):
            out.append((name, module.drawing(partners)))
    return out
